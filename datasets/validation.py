"""Checks on IMU logs: time order, gaps, non-finite values and plausible units.

Every reader calls :func:`validate` (through :func:`~imu_ground.datasets.skeleton.finish`); it works on any
:class:`~imu_ground.imu.data.ImuData`: ``imu, report = validate(imu); print(report.summary())``.
What is checked, in this order:

1. **Empty input** raises :class:`ImuValidationError`.
2. **Non-finite values** in ``t``, ``gyro`` or ``accel``, or sensor values beyond :data:`READING_LIMIT` (a
   corrupt sample): raise naming the columns, first rows (1-based file lines when known) and time, or drop
   those rows with a :class:`NonFiniteWarning` (``nonfinite="drop"``). All-equal timestamps are refused.
3. **Time order** under ``policy`` (:mod:`imu_ground.datasets.timestamps`).
4. **Gaps**: steps longer than ``gap_threshold`` (default ``gap_factor`` x the median step): a :class:`GapWarning`.
5. **Units**: a median step outside 1-2000 Hz, an angular rate sustained above ``gyro_limit`` or a median
   specific-force magnitude far from 1 g: a :class:`UnitsWarning` (or raise, ``units``) naming the option.
6. **Sensors**: a gyro reading exactly 0, an accelerometer reading one value, or a vehicle that never moves
   (every rate below ``rest_gyro``, the specific force within :data:`STILL_SPREAD` on every axis): one
   :class:`SensorWarning` (silent with ``units="ignore"`` or ``warn=False``).

Report indices are input rows unless named ``out_index`` (rows of the returned data); times in s.
"""
from __future__ import annotations

from typing import Any, Literal

import numpy as np

from imu_ground.errors import (GapWarning as GapWarning, ImuValidationError,  # (re-exported, like the report's names)
                               ImuValidationWarning as ImuValidationWarning, MalformedFileError as MalformedFileError,
                               NonFiniteWarning, SensorWarning, TimestampWarning as TimestampWarning, UnitsWarning)
from imu_ground.imu.data import ImuData

from . import report as _report
from .order_stats import median
from .report import STANDARD_GRAVITY, Gap as Gap, ValidationReport, row_names
from .unit_checks import RATE_RANGE
from .timestamps import (POLICIES, Action, Policy, act, check_choice, check_gaps, check_timestamps, fmt_list,
                         gap_action, order_samples)

#: The readers' helpers of :mod:`~imu_ground.datasets.report` that are not re-exported here.
_READER_HELPERS = ("row_names", "warn_user")
# this module's own names, and the report's public ones (errors, warnings, ValidationReport)
__all__ = ["POLICIES", "READING_LIMIT", "STILL_SPREAD", "check_timestamps", "validate"] + [
    name for name in _report.__all__ if name not in _READER_HELPERS]

_NONFINITE = ("raise", "drop")
#: Largest gyro or accelerometer value a sensor reads in any unit the readers take (a 16 g accelerometer:
#: 1.6e5 mm/s^2); beyond it a sample is corrupt, treated as non-finite.
READING_LIMIT = 1e6
#: Spread (1st to 99th percentile, m/s^2) of the specific force on every axis below which, every rate below
#: ``rest_gyro``, a log never moves.
STILL_SPREAD = 0.5
#: Leading rows compared first when looking for a stuck accelerometer (a working one differs within them).
_STUCK_PROBE = 1024


def _longest_run(flags: np.ndarray, t: np.ndarray, step: float) -> tuple[float, int]:
    """Longest time span of consecutive True flags, ``step`` (s) added: (duration s, first index)."""
    if not flags.any():
        return 0.0, -1
    padded = np.concatenate(([0], flags.astype(np.int8), [0]))
    edges = np.diff(padded)
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1  # inclusive
    durations = t[ends] - t[starts] + step
    k = int(np.argmax(durations))
    return float(durations[k]), int(starts[k])


def _sq_norms(v: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Squared row norms of an (N, 3) array (einsum: one pass, no (N, 3) temporary); ``out`` (>= N,): scratch."""
    return np.einsum("ij,ij->i", v, v, out=None if out is None else out[:v.shape[0]])


class _RowStats:
    """The rows' squared norms, block by block: ``total`` (sum of all), ``top`` (largest squared rate), the squared
    specific forces ``rest_accel`` of the ``n_rest`` rows with a squared rate below ``rest_bound`` (-1: no bound)."""

    def __init__(self, gyro: np.ndarray, accel: np.ndarray, rest_bound: float | None, block: int = 1 << 15) -> None:
        n = gyro.shape[0]
        sums, tops, rest = [], [], []
        sg_buf, sa_buf = np.empty(min(n, block)), np.empty(min(n, block))
        with np.errstate(all="ignore"):
            for lo in range(0, n, block):
                sg = _sq_norms(gyro[lo:lo + block], sg_buf)
                sa = _sq_norms(accel[lo:lo + block], sa_buf)
                sums.append(sg.sum() + sa.sum())
                tops.append(sg.max())
                if rest_bound is not None:
                    rest.append(sa[sg < rest_bound])
            self.total = float(np.sum(sums))
        self.top = float(np.max(tops)) if tops else float("nan")
        self.rest_accel = np.concatenate(rest) if rest else np.zeros(0)
        self.n_rest = self.rest_accel.size if rest_bound is not None else -1


def _sqrt_below(limit: float) -> float | None:
    """The least ``s`` with ``sqrt(s) >= limit`` (so ``sqrt(x) < limit`` iff ``x < s``); None if not found."""
    if not 1e-150 < limit < 1e150:               # (its square a normal float)
        return None
    s = np.float64(limit) * np.float64(limit)
    for _ in range(8):
        below = np.nextafter(s, -np.inf)
        if np.sqrt(s) >= limit and not np.sqrt(below) >= limit:
            return float(s)
        s = below if np.sqrt(below) >= limit else np.nextafter(s, np.inf)
    return None


def _nonfinite(imu: ImuData, report: ValidationReport, nonfinite: str, warn: bool, row_lines,
               sq_total: float) -> np.ndarray | None:
    """Rows to keep (finite, within :data:`READING_LIMIT`; None: all), raising or warning about the others."""
    names = ["t", "wx", "wy", "wz", "ax", "ay", "az"]
    t_sum = imu.t.sum()
    with np.errstate(all="ignore"):
        # fast path: a sum is finite iff all terms are; each square is at most the sum of the squares
        if np.isfinite(t_sum + sq_total) and sq_total <= READING_LIMIT * READING_LIMIT:
            return None
        finite = np.column_stack([np.isfinite(imu.t), np.abs(imu.gyro) <= READING_LIMIT,
                                  np.abs(imu.accel) <= READING_LIMIT])
    row_ok = finite.all(axis=1)
    rows = np.flatnonzero(~row_ok)
    report.nonfinite_index = rows
    if not rows.size:
        return None
    src = imu.source or "<ImuData>"
    counts = (~finite).sum(axis=0)
    report.nonfinite_columns = {nm: int(c) for nm, c in zip(names, counts, strict=True) if c}
    kind, where = row_names(rows[:5], row_lines)
    parts = []
    for j, (nm, c) in enumerate(zip(names, counts, strict=True)):
        if c:
            k, w = row_names(np.flatnonzero(~finite[:, j])[:3], row_lines)
            parts.append(f"{nm} ({c} value(s), first {k}s {fmt_list(w, 3)})")
    r0 = int(rows[0])
    t_r0 = f"t={imu.t[r0]:.6f} s" if np.isfinite(imu.t[r0]) else "t not finite"
    sensors = np.column_stack([imu.gyro, imu.accel])[rows]
    huge = np.isfinite(sensors) & ~finite[rows][:, 1:]
    what = (f"NaN/inf or a value beyond {READING_LIMIT:g} (no sensor reads that in any unit: a corrupt sample; "
            f"largest {np.abs(sensors[huge]).max():.3g})" if huge.any() else "NaN/inf")
    msg = (f"{src}: {rows.size} row(s) with {what}: columns {', '.join(parts)}; first bad {kind} "
           f"{where[0]} ({t_r0}); {kind}s {fmt_list(where + [None] * (rows.size - len(where)))}")
    if nonfinite == "raise":
        report.issues.append(msg)
        raise ImuValidationError(msg + " ({hint} drops these rows)", option="nonfinite", value="drop")
    report.nonfinite_dropped = True
    act("warn" if warn else "ignore", msg + f"; dropped {rows.size} of {len(imu)} samples (nonfinite='drop')",
        NonFiniteWarning, report)
    return np.flatnonzero(row_ok)


def _units(report, t, gyro, accel, stats, keep, units, src, gyro_limit, gyro_min_duration, accel_tol, rest_gyro,
           row_lines) -> None:
    """Magnitude checks of the cleaned data (rate, gyro, specific force); ``stats``: their :class:`_RowStats`."""
    step = 0.0
    if t.size > 1:
        # the gap check's median step of these same times, when it ran (one median of the log, not two)
        step = report.median_step if np.isfinite(report.median_step) else median(t[1:] - t[:-1])
        if step > 0 and not RATE_RANGE[0] <= 1.0 / step <= RATE_RANGE[1]:
            act(units, f"{src}: median time step {step:.6g} s ({1 / step:.6g} Hz) is outside the plausible IMU "
                       f"rates {RATE_RANGE[0]:g}-{RATE_RANGE[1]:g} Hz: is the time column in another unit? "
                       f"(pass {{hint}})", UnitsWarning, report, option="time_unit")
    report.gyro_max_norm = float(np.sqrt(stats.top))
    over = None
    dur, first = 0.0, -1
    if report.gyro_max_norm > gyro_limit:       # some sample above the limit (else no run of them)
        over = np.sqrt(_sq_norms(gyro)) > gyro_limit
        dur, first = _longest_run(over, t, step)
    report.gyro_sustained = dur
    if dur >= gyro_min_duration:
        if over is None:
            over = np.sqrt(_sq_norms(gyro)) > gyro_limit
        kind, where = row_names(np.array([range(t.size)[first]]) if keep is None else keep[[first]], row_lines)
        act(units, f"{src}: angular rate above {gyro_limit:g} rad/s for {dur:.3g} s from {kind} {where[0]} "
                   f"(t={t[first]:.6f} s), max {report.gyro_max_norm:.4g}: implausible for a car in rad/s; is "
                   f"the gyro in deg/s? (pass {{hint}}; {int(over.sum())} samples above)", UnitsWarning, report,
            option="gyro_unit", value="deg/s")
    rest_accel = stats.rest_accel
    if stats.n_rest < 0:                         # no bound on the squares: the rates themselves
        rest_accel = _sq_norms(accel)[np.sqrt(_sq_norms(gyro)) < rest_gyro]
    at_rest = rest_accel.size >= 10
    med = median(rest_accel if at_rest else _sq_norms(accel), sqrt=True)
    report.accel_median_norm = med
    report.accel_norm_at_rest = at_rest
    g = STANDARD_GRAVITY
    if abs(med - g) > accel_tol:
        basis = "at rest" if at_rest else "over all samples"
        value = None
        if abs(med - 1.0) < 0.2:
            why, value = "looks like units of g (pass {hint})", "g"
        elif med < 4.0:
            why = "gravity seems to be missing (linear acceleration instead of specific force?)"
        elif abs(med / 1000.0 - 1.0) < 0.2:
            why = "looks like units of mg"
        elif abs(med / (1000.0 * g) - 1.0) < 0.2:
            why = "looks like units of mm/s^2"
        else:
            why = "check the accelerometer units and scale"
        act(units, f"{src}: median specific-force magnitude {basis} is {med:.4g} m/s^2, expected about "
                   f"{g:.4g} (1 g) +- {accel_tol:g}: {why}", UnitsWarning, report,
            option="accel_unit" if value else None, value=value)


def validate(imu: ImuData, policy: Policy = "retime", *,
             nonfinite: Literal["raise", "drop"] = "raise",
             gaps: Action | None = None, units: Action | None = None,
             gap_factor: float = 5.0, gap_threshold: float | None = None,
             gyro_limit: float = 10.0, gyro_min_duration: float = 0.5,
             accel_tol: float = 1.5, rest_gyro: float = 0.05,
             min_samples: int = 1, warn: bool = True) -> tuple[ImuData, ValidationReport]:
    """Check an IMU log and return a cleaned copy with the report in ``meta["validation"]``.

    Parameters
    ----------
    imu : ImuData
        The log (``t`` s, ``gyro`` rad/s, ``accel`` m/s^2, any frame); ``meta["row_lines"]`` may map input
        rows to 1-based file lines.
    policy : {"retime", "drop", "sort", "strict", "recorded"}
        Unsorted/duplicate times (:mod:`imu_ground.datasets.timestamps`).
    nonfinite : {"raise", "drop"}
        NaN/inf rows: raise (default) or drop.
    gaps, units : {"warn", "raise", "ignore"}, optional
        Gaps, implausible magnitudes; default ``"raise"`` if ``policy="strict"`` else ``"warn"``.
    gap_factor : float
        Gap threshold as a multiple of the median step.
    gap_threshold : float, optional
        Absolute gap threshold, s (overrides ``gap_factor``).
    gyro_limit, gyro_min_duration : float
        An angular rate, rad/s, that a car does not sustain for this long, s.
    accel_tol : float
        Allowed distance, m/s^2, of the median specific-force magnitude from 1 g.
    rest_gyro : float
        Rate, rad/s, below which a sample is at rest (the specific-force check uses those if 10 or more).
    min_samples : int
        Fewer samples than this after cleaning raises.
    warn : bool
        Issue warnings (False: record issues in the report only).

    Returns
    -------
    imu : ImuData
        The cleaned log, a new object (times strictly increasing except under ``"recorded"``), the report
        in ``meta["validation"]``.
    report : ValidationReport

    Raises
    ------
    ImuValidationError
        Empty log, non-finite values (``nonfinite="raise"``), unsorted times (``"strict"``), or gaps / units
        with action ``"raise"``; the message names the option that changes the outcome.
    """
    # the options, checked before any work
    check_choice("policy", policy, POLICIES)
    check_choice("nonfinite", nonfinite, _NONFINITE)
    units = units if units is not None else ("raise" if policy == "strict" else "warn")
    check_choice("units", units, ("warn", "raise", "ignore"))
    if not warn and units == "warn":
        units = "ignore"
    gaps = gap_action(gaps, policy, warn)
    src = imu.source or "<ImuData>"
    row_lines = imu.meta.get("row_lines")
    n = len(imu)
    report = ValidationReport(source=imu.source, policy=policy, n_in=n, gyro_limit=gyro_limit)

    # 1. empty input
    if n == 0:
        report.issues.append(f"{src}: no samples (empty log)")
        raise ImuValidationError(report.issues[-1])

    # 2. non-finite values: raise, or the rows to keep (None: every row)
    rest_bound = _sqrt_below(rest_gyro)
    stats = _RowStats(imu.gyro, imu.accel, rest_bound)
    good = _nonfinite(imu, report, nonfinite, warn, row_lines, stats.total)

    # 3. time order under the policy (the times left are finite): positions of those rows kept, new times
    keep_pos, t, steps = order_samples(imu.t if good is None else imu.t[good], policy, src, good, report, warn,
                                       row_lines, finite=True)

    # 4. gaps in the ordered times
    check_gaps(t, steps, keep_pos, good, report, gaps, gap_factor, gap_threshold, src, row_lines)

    # 5. input rows kept, in output order (None: every row, in order); enough of them?
    keep = (good if keep_pos is None else good[keep_pos]) if good is not None else keep_pos
    report.n_out = n if keep is None else int(keep.size)
    if report.n_out < n:                # (keep holds distinct rows)
        dropped = np.ones(n, dtype=bool)
        dropped[keep] = False
        report.dropped_index = np.flatnonzero(dropped)
    if report.n_out == 1 and n > 1:
        _all_equal_times(imu.t if good is None else imu.t[good], src, report, float(imu.meta.get("t0") or 0.0))
    if report.n_out < max(min_samples, 1):
        report.issues.append(f"{src}: {report.n_out} sample(s) left after cleaning ({n} read), "
                             f"need at least {max(min_samples, 1)}")
        raise ImuValidationError(report.issues[-1])

    # 6. units and magnitudes of the rows kept
    same = keep is None or (report.n_out == n and (policy != "sort" or bool((keep == np.arange(n)).all())))
    gyro = imu.gyro if same else imu.gyro[keep]
    accel = imu.accel if same else imu.accel[keep]
    _units(report, t, gyro, accel, stats if same else _RowStats(gyro, accel, rest_bound), keep, units, src,
           gyro_limit, gyro_min_duration, accel_tol, rest_gyro, row_lines)

    # 7. sensors that do not work, or a vehicle that never moves
    _sensors(report, gyro, accel, rest_gyro, src, "ignore" if units == "ignore" else "warn")

    # 8. the cleaned log, the report in its meta
    extra = imu.extra if same or keep is None or not len(imu.extra) else imu.extra.iloc[keep].reset_index(drop=True)
    meta: dict[str, Any] = dict(imu.meta)
    meta["validation"] = report
    return ImuData(t, gyro, accel, imu.frame, extra, dict(imu.units), imu.source, meta), report


def _all_equal_times(t: np.ndarray, src: str, report: ValidationReport, t0: float = 0.0) -> None:
    """Raise when every timestamp is the same (``t0``: the reader's shift, s, added back for the message)."""
    if t.size > 1 and np.all(t == t[0]):
        report.issues.append(f"{src}: all {t.size} timestamps are equal (t = {t[0] + t0:.6g} s): the time column "
                             "does not advance")
        raise ImuValidationError(report.issues[-1] + "; is it the time column? ({hint})", option="columns",
                                 value="t=NAME")


def _sensors(report: ValidationReport, gyro: np.ndarray, accel: np.ndarray, rest_gyro: float, src: str,
             action: str) -> None:
    """One :class:`SensorWarning` for a dead gyro, a stuck accelerometer or a log that never moves (the first found)."""
    n = gyro.shape[0]
    msg = None
    if n >= 2 and report.gyro_max_norm == 0.0:
        msg = (f"{src}: the gyro reads exactly 0 on all {n} samples: a dead or disconnected gyro? (no rotation "
               "can be measured)")
    elif n >= 2 and not np.any(accel[1:_STUCK_PROBE] != accel[0]) and not np.any(accel != accel[0]):
        a = ", ".join(f"{v:.6g}" for v in accel[0])
        msg = (f"{src}: the accelerometer reads the same value ({a} m/s^2) on all {n} samples: a stuck "
               "accelerometer?")
    elif n >= 2 and report.gyro_max_norm < rest_gyro:
        spread = np.percentile(accel, 99, axis=0) - np.percentile(accel, 1, axis=0)
        if np.all(spread < STILL_SPREAD):
            msg = (f"{src}: the vehicle never moves in this log: every angular rate is below {rest_gyro:g} rad/s "
                   f"and the specific force varies by less than {STILL_SPREAD:g} m/s^2 on every axis; only the "
                   "standstill tilt can be estimated")
    if msg is not None:
        act(action, msg, SensorWarning, report)
