"""Checks on IMU logs: time order, gaps, non-finite values and plausible units.

Every reader in :mod:`imu_ground.datasets` calls :func:`validate` by default, and
it can be used on its own on any :class:`~imu_ground.imu.data.ImuData`::

    imu, report = validate(imu, policy="drop")
    print(report.summary())

What is checked, in this order
------------------------------
1. **Empty input**: no samples raises :class:`ImuValidationError`.
2. **Non-finite values** (NaN, inf) in ``t``, ``gyro`` or ``accel``: raise
   (``nonfinite="raise"``, the default; the message names the columns and the
   first rows) or drop those rows with a :class:`NonFiniteWarning`
   (``nonfinite="drop"``).  ``extra`` columns are not checked.
3. **Time order**: a sample whose time is not later than every earlier sample is
   *out of order* (earlier than the latest time so far) or a *duplicate* (equal
   to it).  ``policy="drop"`` (default) keeps only samples later than all earlier
   ones; ``policy="sort"`` sorts by time (stable) and drops repeated times,
   keeping the first; ``policy="strict"`` raises.  Whatever is dropped or moved is
   counted in the report and announced with a :class:`TimestampWarning`.
4. **Gaps**: steps longer than ``gap_threshold`` (default ``gap_factor`` times the
   median step) are listed in the report (start time, length, index) and
   announced with a :class:`GapWarning` (or raise, see ``gaps``).  Nothing is
   interpolated: a consumer such as a preintegrator decides what to do.
5. **Units**: a sustained angular rate above ``gyro_max`` rad/s (deg/s given as
   rad/s?) and a median specific-force magnitude far from 1 g (units of g?
   gravity removed?) give a :class:`UnitsWarning` (or raise, see ``units``).

Indices in messages and in the report refer to rows of the *input* (``index``)
unless named ``out_index`` (rows of the returned, cleaned data); times are the
input's ``t`` in seconds.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np

from imu_ground.imu.data import ImuData

__all__ = [
    "STANDARD_GRAVITY",
    "ImuValidationError",
    "MalformedFileError",
    "ImuValidationWarning",
    "TimestampWarning",
    "GapWarning",
    "NonFiniteWarning",
    "UnitsWarning",
    "Gap",
    "ValidationReport",
    "check_timestamps",
    "validate",
]

#: Standard gravity, m/s^2.
STANDARD_GRAVITY = 9.80665

Policy = Literal["drop", "sort", "strict"]
Action = Literal["warn", "raise", "ignore"]

_POLICIES = ("drop", "sort", "strict")
_ACTIONS = ("warn", "raise", "ignore")
_NONFINITE = ("raise", "drop")


# --------------------------------------------------------------------------- errors
class ImuValidationError(ValueError):
    """An IMU log failed a check whose policy is to raise."""


class MalformedFileError(ValueError):
    """A log file cannot be parsed: empty, truncated, wrong field count, not a number.

    Attributes
    ----------
    path : str
        The file.
    line : int or None
        1-based line number of the first bad line, when there is one.
    """

    def __init__(self, path: str | Path, message: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        where = f"{self.path}, line {line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")


class ImuValidationWarning(UserWarning):
    """Base class of every warning issued by :func:`validate`."""


class TimestampWarning(ImuValidationWarning):
    """Samples were dropped or reordered because of unsorted or duplicate times."""


class GapWarning(ImuValidationWarning):
    """The log has steps much longer than its usual sample period."""


class NonFiniteWarning(ImuValidationWarning):
    """Rows with NaN or inf were dropped (``nonfinite="drop"``)."""


class UnitsWarning(ImuValidationWarning):
    """Magnitudes suggest wrong units (deg/s as rad/s, g as m/s^2) or missing gravity."""


# --------------------------------------------------------------------------- report
class Gap(NamedTuple):
    """One gap: the sample before it, its start time and its length.

    Attributes
    ----------
    index : int
        Input row of the sample before the gap.
    out_index : int
        Row of that sample in the cleaned output.
    t_start : float
        Time of the sample before the gap, s.
    length : float
        Time to the next kept sample, s.
    """

    index: int
    out_index: int
    t_start: float
    length: float


def _empty_int() -> np.ndarray:
    return np.zeros(0, dtype=np.int64)


def _empty_float() -> np.ndarray:
    return np.zeros(0, dtype=float)


@dataclass
class ValidationReport:
    """What :func:`validate` found and did.

    Attributes
    ----------
    source : str
        Where the data came from.
    policy : str
        Time-order policy used (``"drop"``, ``"sort"``, ``"strict"``).
    n_in, n_out : int
        Samples before and after cleaning.
    nonfinite_index : ndarray of int
        Input rows with NaN/inf in t, gyro or accel.
    nonfinite_columns : dict
        Column name (``t``, ``wx``... ``az``) to number of non-finite values.
    nonfinite_dropped : bool
        Whether those rows were dropped.
    backstep_index : ndarray of int
        Input rows where time steps back (``t[i] < t[i-1]``), among finite rows.
    backstep_size : ndarray of float
        The size of those steps, s (negative).
    out_of_order_index : ndarray of int
        Input rows earlier than the latest time before them.
    duplicate_index : ndarray of int
        Input rows whose time equals an earlier one (``policy="drop"``: the latest
        earlier one; ``policy="sort"``: any earlier one).
    dropped_index : ndarray of int
        Every input row not in the output (non-finite, out of order, duplicate).
    reordered : bool
        Whether samples were sorted (``policy="sort"`` and something was out of order).
    median_step : float
        Median time step of the cleaned data, s (nan for fewer than 2 samples).
    gap_threshold : float
        Steps longer than this are gaps, s.
    gap_index, gap_out_index, gap_start, gap_length : ndarray
        The gaps: input row and output row of the sample before each gap, its time
        and the gap's length (s).  See :attr:`gaps`.
    gyro_max_norm : float
        Largest angular-rate magnitude, rad/s (nan when empty).
    gyro_sustained : float
        Longest time the rate stays above ``gyro_limit``, s.
    gyro_limit : float
        Rate above which a car's gyro is implausible, rad/s.
    accel_median_norm : float
        Median specific-force magnitude, m/s^2 (over samples at rest when there
        are enough, see ``accel_norm_at_rest``).
    accel_norm_at_rest : bool
        Whether ``accel_median_norm`` was taken over samples with small rate.
    issues : list of str
        One message per problem found (the texts of the warnings/errors).
    """

    source: str = ""
    policy: str = "drop"
    n_in: int = 0
    n_out: int = 0
    nonfinite_index: np.ndarray = field(default_factory=_empty_int)
    nonfinite_columns: dict[str, int] = field(default_factory=dict)
    nonfinite_dropped: bool = False
    backstep_index: np.ndarray = field(default_factory=_empty_int)
    backstep_size: np.ndarray = field(default_factory=_empty_float)
    out_of_order_index: np.ndarray = field(default_factory=_empty_int)
    duplicate_index: np.ndarray = field(default_factory=_empty_int)
    dropped_index: np.ndarray = field(default_factory=_empty_int)
    reordered: bool = False
    median_step: float = float("nan")
    gap_threshold: float = float("nan")
    gap_index: np.ndarray = field(default_factory=_empty_int)
    gap_out_index: np.ndarray = field(default_factory=_empty_int)
    gap_start: np.ndarray = field(default_factory=_empty_float)
    gap_length: np.ndarray = field(default_factory=_empty_float)
    gyro_max_norm: float = float("nan")
    gyro_sustained: float = 0.0
    gyro_limit: float = float("nan")
    accel_median_norm: float = float("nan")
    accel_norm_at_rest: bool = False
    issues: list[str] = field(default_factory=list)

    # -- counts
    @property
    def n_dropped(self) -> int:
        """Input samples not in the output."""
        return int(self.dropped_index.size)

    @property
    def n_out_of_order(self) -> int:
        """Samples earlier than the latest time before them."""
        return int(self.out_of_order_index.size)

    @property
    def n_duplicates(self) -> int:
        """Samples repeating an earlier time."""
        return int(self.duplicate_index.size)

    @property
    def n_nonfinite(self) -> int:
        """Rows with NaN/inf in t, gyro or accel."""
        return int(self.nonfinite_index.size)

    @property
    def n_gaps(self) -> int:
        """Number of gaps."""
        return int(self.gap_start.size)

    @property
    def gaps(self) -> list[Gap]:
        """The gaps as a list of :class:`Gap` (index, out_index, t_start, length)."""
        return [Gap(int(i), int(j), float(s), float(g)) for i, j, s, g in
                zip(self.gap_index, self.gap_out_index, self.gap_start, self.gap_length)]

    @property
    def ok(self) -> bool:
        """True when no problem was found."""
        return not self.issues

    def summary(self) -> str:
        """A few lines of text describing the findings."""
        head = (f"{self.source or '<ImuData>'}: {self.n_in} samples in, {self.n_out} out "
                f"(policy={self.policy!r}); {self.n_out_of_order} out of order, "
                f"{self.n_duplicates} duplicate times, {self.n_nonfinite} non-finite rows, "
                f"{self.n_gaps} gaps > {self.gap_threshold:.4g} s")
        return "\n".join([head, *self.issues]) if self.issues else head + "; no issues"

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python (JSON-friendly) version of the report."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                out[k] = v.tolist()
            elif isinstance(v, (list, dict)):
                out[k] = type(v)(v)
            elif isinstance(v, (np.floating, np.integer, np.bool_)):
                out[k] = v.item()
            else:
                out[k] = v
        out.update(n_dropped=self.n_dropped, n_out_of_order=self.n_out_of_order,
                   n_duplicates=self.n_duplicates, n_nonfinite=self.n_nonfinite,
                   n_gaps=self.n_gaps, ok=self.ok)
        return out


# --------------------------------------------------------------------------- helpers
def _fmt_list(values: np.ndarray, limit: int = 5, fmt: str = "{}") -> str:
    items = [fmt.format(v) for v in np.asarray(values)[:limit].tolist()]
    more = f", ... ({len(values) - limit} more)" if len(values) > limit else ""
    return "[" + ", ".join(items) + more + "]"


def _check_choice(name: str, value: Any, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ValueError(f"{name}={value!r} is not one of {list(allowed)}")


def _act(action: str, message: str, category: type[Warning], report: ValidationReport,
         stacklevel: int) -> None:
    report.issues.append(message)
    if action == "raise":
        raise ImuValidationError(message)
    if action == "warn":
        warnings.warn(message, category, stacklevel=stacklevel)


def _longest_run(flags: np.ndarray, t: np.ndarray) -> tuple[float, int]:
    """Longest time span of consecutive True flags (vectorised); (duration s, first index)."""
    if not flags.any():
        return 0.0, -1
    padded = np.concatenate(([0], flags.astype(np.int8), [0]))
    edges = np.diff(padded)
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1  # inclusive
    # a run of one sample lasts one median step; longer runs their span plus one step
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    durations = t[ends] - t[starts] + step
    k = int(np.argmax(durations))
    return float(durations[k]), int(starts[k])


# --------------------------------------------------------------------------- timestamps
def check_timestamps(t: np.ndarray, policy: Policy = "drop", *, gaps: Action | None = None,
                     gap_factor: float = 5.0, gap_threshold: float | None = None,
                     source: str = "", index: np.ndarray | None = None,
                     report: ValidationReport | None = None, warn: bool = True,
                     _stacklevel: int = 2) -> tuple[np.ndarray, ValidationReport]:
    """Check a raw array of timestamps for order, duplicates and gaps.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times, s; must be finite (see :func:`validate` for NaN handling).
    policy : {"drop", "sort", "strict"}
        What to do with samples not later than every earlier one: drop them
        (default), sort by time and drop repeated times, or raise
        :class:`ImuValidationError`.
    gaps : {"warn", "raise", "ignore"}, optional
        What to do about gaps; default ``"raise"`` under ``policy="strict"``,
        else ``"warn"``.  Gaps are always listed in the report.
    gap_factor : float
        A step longer than ``gap_factor`` times the median step is a gap.
    gap_threshold : float, optional
        Absolute gap threshold, s; overrides ``gap_factor``.
    source : str
        Name used in messages (file path).
    index : array_like of int, optional
        Input row numbers of ``t`` (for messages), default ``arange(N)``.
    report : ValidationReport, optional
        Report to fill in (a new one by default).
    warn : bool
        Issue warnings (False: only record the issues in the report).

    Returns
    -------
    keep : ndarray of int
        Positions into ``t`` of the samples to keep, in increasing time order.
    report : ValidationReport
        The findings (order, duplicates, gaps).

    Raises
    ------
    ImuValidationError
        ``policy="strict"`` and the times are not strictly increasing, or
        ``gaps="raise"`` and there is a gap.
    """
    _check_choice("policy", policy, _POLICIES)
    gaps = gaps if gaps is not None else ("raise" if policy == "strict" else "warn")
    _check_choice("gaps", gaps, _ACTIONS)
    if not warn and gaps == "warn":
        gaps = "ignore"
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"timestamps must be 1-D, got shape {t.shape}")
    index = np.arange(t.size) if index is None else np.asarray(index, dtype=np.int64)
    if report is None:
        report = ValidationReport(source=source, policy=policy, n_in=int(t.size))
    report.policy = policy
    src = source or "<timestamps>"
    action = "warn" if warn else "ignore"
    stack = _stacklevel + 1

    n = t.size
    # -- order ------------------------------------------------------------
    steps = np.diff(t)
    back = np.flatnonzero(steps < 0) + 1
    report.backstep_index = index[back]
    report.backstep_size = steps[back - 1]
    if n > 1:
        prev_max = np.maximum.accumulate(t)[:-1]
        ooo = np.flatnonzero(t[1:] < prev_max) + 1
        dup_latest = np.flatnonzero(t[1:] == prev_max) + 1
    else:
        ooo = dup_latest = np.zeros(0, dtype=np.int64)
    report.out_of_order_index = index[ooo]

    if policy == "sort":
        order = np.argsort(t, kind="stable")
        ts = t[order]
        first = np.ones(n, dtype=bool)
        first[1:] = ts[1:] != ts[:-1]
        keep = order[first]
        dup = np.sort(order[~first])
        report.duplicate_index = index[dup]
        report.reordered = bool(ooo.size)
    else:
        report.duplicate_index = index[dup_latest]
        bad = np.zeros(n, dtype=bool)
        bad[ooo] = True
        bad[dup_latest] = True
        keep = np.flatnonzero(~bad)
        dup = dup_latest

    if ooo.size or dup.size:
        parts = []
        if ooo.size:
            # the first out-of-order sample is always the first backward step
            b0 = int(back[0])
            parts.append(f"{ooo.size} sample(s) out of order (time steps back {back.size} time(s), "
                         f"first at index {int(index[b0])}, t={t[b0]:.6f} s, "
                         f"step {steps[b0 - 1]:+.6f} s)")
        if dup.size:
            d0 = int(dup[0])
            parts.append(f"{dup.size} duplicate timestamp(s) (first at index {int(index[d0])}, "
                         f"t={t[d0]:.6f} s)")
        what = " and ".join(parts)
        if policy == "strict":
            msg = f"{src}: timestamps not strictly increasing: {what}"
            report.issues.append(msg)
            raise ImuValidationError(msg + " (policy='strict'; use policy='drop' or 'sort')")
        if policy == "sort":
            acts = (["sorted by time"] if ooo.size else []) + \
                ([f"dropped {dup.size} repeated time(s)"] if dup.size else [])
            msg = (f"{src}: {what}; {' and '.join(acts)}, {keep.size} of {n} samples kept "
                   f"(policy='sort', report in meta['validation'])")
        else:
            msg = (f"{src}: {what}; dropped {n - keep.size} of {n} samples "
                   f"(policy='drop', report in meta['validation'])")
        _act(action, msg, TimestampWarning, report, stack)

    # -- gaps ---------------------------------------------------------------
    tk = t[keep]
    if tk.size > 1:
        dk = np.diff(tk)
        report.median_step = float(np.median(dk))
        thr = float(gap_threshold) if gap_threshold is not None else gap_factor * report.median_step
        report.gap_threshold = thr
        g = np.flatnonzero(dk > thr)
        report.gap_out_index = g.astype(np.int64)
        report.gap_index = index[keep[g]]
        report.gap_start = tk[g]
        report.gap_length = dk[g]
        if g.size:
            k = int(np.argmax(dk[g]))
            how = (f"{gap_threshold:g} s" if gap_threshold is not None else
                   f"{report.gap_threshold:.4g} s = {gap_factor:g} x median step "
                   f"{report.median_step:.4g} s")
            msg = (f"{src}: {g.size} gap(s) longer than {how}: longest {dk[g][k]:.4g} s at "
                   f"t={tk[g][k]:.6f} s (index {int(report.gap_index[k])}); starts (s) "
                   f"{_fmt_list(tk[g], fmt='{:.3f}')}, lengths (s) {_fmt_list(dk[g], fmt='{:.3f}')}")
            _act(gaps, msg, GapWarning, report, stack)
    elif gap_threshold is not None:
        report.gap_threshold = float(gap_threshold)
    return keep, report


# --------------------------------------------------------------------------- validate
def validate(imu: ImuData, policy: Policy = "drop", *,
             nonfinite: Literal["raise", "drop"] = "raise",
             gaps: Action | None = None, units: Action | None = None,
             gap_factor: float = 5.0, gap_threshold: float | None = None,
             gyro_limit: float = 10.0, gyro_min_duration: float = 0.5,
             accel_tol: float = 1.5, rest_gyro: float = 0.05,
             min_samples: int = 1, warn: bool = True,
             _stacklevel: int = 2) -> tuple[ImuData, ValidationReport]:
    """Check an IMU log and return a cleaned copy with the report in ``meta["validation"]``.

    Parameters
    ----------
    imu : ImuData
        The log (``t`` in s, ``gyro`` in rad/s, ``accel`` in m/s^2, any frame).
    policy : {"drop", "sort", "strict"}
        Unsorted/duplicate times: ``"drop"`` keeps only samples later than every
        earlier one (default); ``"sort"`` sorts by time and drops repeated times
        (keeping the first); ``"strict"`` raises :class:`ImuValidationError`.
        Dropping or sorting is announced with a :class:`TimestampWarning`.
    nonfinite : {"raise", "drop"}
        NaN/inf in t, gyro or accel: raise naming the columns and rows (default),
        or drop the rows with a :class:`NonFiniteWarning`.
    gaps : {"warn", "raise", "ignore"}, optional
        Gaps (steps above the threshold); default ``"raise"`` if
        ``policy="strict"`` else ``"warn"`` (:class:`GapWarning`).  They are always
        listed in the report.
    units : {"warn", "raise", "ignore"}, optional
        Implausible magnitudes; default ``"raise"`` if ``policy="strict"`` else
        ``"warn"`` (:class:`UnitsWarning`).
    gap_factor : float
        Gap threshold as a multiple of the median step (default 5).
    gap_threshold : float, optional
        Absolute gap threshold, s (overrides ``gap_factor``).
    gyro_limit : float
        Angular rate, rad/s, that a car does not sustain (default 10 rad/s, about
        570 deg/s): exceeding it for ``gyro_min_duration`` suggests deg/s.
    gyro_min_duration : float
        How long, s, the rate must stay above ``gyro_limit`` (default 0.5 s).
    accel_tol : float
        Allowed distance, m/s^2, of the median specific-force magnitude from
        1 g (default 1.5).
    rest_gyro : float
        Samples with rate below this, rad/s, count as "at rest" for the
        specific-force check (used when at least 10 samples qualify).
    min_samples : int
        Fewer samples than this (after cleaning) raises (default 1: empty raises).
    warn : bool
        Issue warnings (False: record issues in the report only).

    Returns
    -------
    imu : ImuData
        The cleaned log (rows selected, times strictly increasing), a new
        object; ``meta["validation"]`` holds the report.
    report : ValidationReport
        What was found and done.

    Raises
    ------
    ImuValidationError
        Empty log, non-finite values (``nonfinite="raise"``), unsorted times
        (``policy="strict"``), or gaps / units with action ``"raise"``.
    """
    _check_choice("policy", policy, _POLICIES)
    _check_choice("nonfinite", nonfinite, _NONFINITE)
    units = units if units is not None else ("raise" if policy == "strict" else "warn")
    _check_choice("units", units, _ACTIONS)
    if not warn and units == "warn":
        units = "ignore"
    stack = _stacklevel + 1
    src = imu.source or "<ImuData>"
    n = len(imu)
    report = ValidationReport(source=imu.source, policy=policy, n_in=n, gyro_limit=gyro_limit)
    if n == 0:
        msg = f"{src}: no samples (empty log)"
        report.issues.append(msg)
        raise ImuValidationError(msg)

    # -- non-finite ---------------------------------------------------------
    cols = np.column_stack([imu.t, imu.gyro, imu.accel])
    names = ["t", "wx", "wy", "wz", "ax", "ay", "az"]
    finite = np.isfinite(cols)
    row_ok = finite.all(axis=1)
    rows = np.flatnonzero(~row_ok)
    report.nonfinite_index = rows
    if rows.size:
        counts = (~finite).sum(axis=0)
        report.nonfinite_columns = {nm: int(c) for nm, c in zip(names, counts) if c}
        bycol = ", ".join(f"{nm} ({c} value(s), first rows {_fmt_list(np.flatnonzero(~finite[:, j]), 3)})"
                          for j, (nm, c) in enumerate(zip(names, counts)) if c)
        r0 = int(rows[0])
        t_r0 = f"t={imu.t[r0]:.6f} s" if np.isfinite(imu.t[r0]) else "t not finite"
        msg = (f"{src}: {rows.size} row(s) with NaN/inf: columns {bycol}; first bad row "
               f"{r0} ({t_r0}); rows {_fmt_list(rows)}")
        if nonfinite == "raise":
            report.issues.append(msg)
            raise ImuValidationError(msg + " (use nonfinite='drop' to drop these rows)")
        report.nonfinite_dropped = True
        _act("warn" if warn else "ignore",
             msg + f"; dropped {rows.size} of {n} samples (nonfinite='drop')",
             NonFiniteWarning, report, stack)
    good = np.flatnonzero(row_ok)

    # -- order and gaps -----------------------------------------------------
    keep_pos, _ = check_timestamps(imu.t[good], policy, gaps=gaps, gap_factor=gap_factor,
                                   gap_threshold=gap_threshold, source=src, index=good,
                                   report=report, warn=warn, _stacklevel=stack)
    keep = good[keep_pos]
    dropped = np.ones(n, dtype=bool)
    dropped[keep] = False
    report.dropped_index = np.flatnonzero(dropped)
    report.n_out = int(keep.size)
    if keep.size < max(min_samples, 1):
        msg = (f"{src}: {keep.size} sample(s) left after cleaning ({n} read), "
               f"need at least {max(min_samples, 1)}")
        report.issues.append(msg)
        raise ImuValidationError(msg)

    t = imu.t[keep]
    gyro = imu.gyro[keep]
    accel = imu.accel[keep]

    # -- units: gyro ----------------------------------------------------------
    wn = np.linalg.norm(gyro, axis=1)
    report.gyro_max_norm = float(wn.max())
    over = wn > gyro_limit
    dur, first = _longest_run(over, t)
    report.gyro_sustained = dur
    if dur >= gyro_min_duration:
        msg = (f"{src}: angular rate above {gyro_limit:g} rad/s for {dur:.3g} s from index "
               f"{int(keep[first])} (t={t[first]:.6f} s), max {wn.max():.4g}: implausible for "
               f"a car in rad/s; is the gyro in deg/s? ({int(over.sum())} samples above)")
        _act(units, msg, UnitsWarning, report, stack)

    # -- units: accel ---------------------------------------------------------
    an = np.linalg.norm(accel, axis=1)
    rest = wn < rest_gyro
    at_rest = int(rest.sum()) >= 10
    med = float(np.median(an[rest] if at_rest else an))
    report.accel_median_norm = med
    report.accel_norm_at_rest = at_rest
    g = STANDARD_GRAVITY
    if abs(med - g) > accel_tol:
        where = "at rest" if at_rest else "over all samples"
        if abs(med - 1.0) < 0.2:
            why = "looks like units of g (multiply by 9.80665 / pass accel_unit='g')"
        elif med < 4.0:
            why = "gravity seems to be missing (linear acceleration instead of specific force?)"
        elif abs(med / 1000.0 - 1.0) < 0.2:
            why = "looks like units of mg"
        elif abs(med / (1000.0 * g) - 1.0) < 0.2:
            why = "looks like units of mm/s^2"
        else:
            why = "check the accelerometer units and scale"
        msg = (f"{src}: median specific-force magnitude {where} is {med:.4g} m/s^2, expected "
               f"about {g:.4g} (1 g) +- {accel_tol:g}: {why}")
        _act(units, msg, UnitsWarning, report, stack)

    extra = imu.extra.iloc[keep].reset_index(drop=True) if len(imu.extra) else imu.extra
    meta = dict(imu.meta)
    meta["validation"] = report
    out = ImuData(t, gyro, accel, imu.frame, extra, dict(imu.units), imu.source, meta)
    return out, report
