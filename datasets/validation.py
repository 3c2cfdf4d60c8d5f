"""Checks on IMU logs: time order, gaps, non-finite values and plausible units.

Every reader in :mod:`imu_ground.datasets` calls :func:`validate` by default
(through :func:`imu_ground.datasets.skeleton.finish`), and it can be used on its
own on any :class:`~imu_ground.imu.data.ImuData`::

    imu, report = validate(imu, policy="retime")
    print(report.summary())

What is checked, in this order
------------------------------
1. **Empty input**: no samples raises :class:`ImuValidationError`.
2. **Non-finite values** (NaN, inf) in ``t``, ``gyro`` or ``accel``: raise
   (``nonfinite="raise"``, the default; the message names the columns and the
   first rows, as 1-based file lines when the reader knows them) or drop those
   rows with a :class:`NonFiniteWarning` (``nonfinite="drop"``).
3. **Time order** (:mod:`imu_ground.datasets.timestamps`): ``policy="retime"``
   (default) puts jittered stamps back on the sample clock, ``"drop"`` keeps only
   samples later than every earlier one, ``"sort"`` sorts, ``"strict"`` raises.
4. **Gaps**: steps longer than ``gap_threshold`` (default ``gap_factor`` times the
   median step) are listed in the report and announced with a :class:`GapWarning`.
5. **Units**: a median step outside 1-2000 Hz, a sustained angular rate above
   ``gyro_limit`` rad/s and a median specific-force magnitude far from 1 g give
   a :class:`UnitsWarning` (or raise, see ``units``), naming the option to pass.

Indices in the report refer to rows of the *input* (``index``) unless named
``out_index`` (rows of the returned data); times are the input's ``t`` in s.
"""
from __future__ import annotations

from typing import Any, Literal

import numpy as np

from imu_ground.imu.data import ImuData

from . import report as _report
from .report import *  # re-exports the report's public names (errors, warnings, ValidationReport)
from .report import (
    STANDARD_GRAVITY,
    ImuValidationError,
    NonFiniteWarning,
    UnitsWarning,
    ValidationReport,
    row_names,
)
from .timestamps import (
    POLICIES,
    Action,
    Policy,
    act,
    check_choice,
    check_timestamps,
    fmt_list,
)

#: The readers' helpers of :mod:`~imu_ground.datasets.report` that are not re-exported here.
_READER_HELPERS = ("row_names", "warn_user")
# this module's own names, and the report's public ones (errors, warnings, ValidationReport)
__all__ = ["POLICIES", "check_timestamps", "validate"] + [
    name for name in _report.__all__ if name not in _READER_HELPERS]

_NONFINITE = ("raise", "drop")
#: Plausible IMU sample rates, Hz.
RATE_RANGE = (1.0, 2000.0)


def _longest_run(flags: np.ndarray, t: np.ndarray) -> tuple[float, int]:
    """Longest time span of consecutive True flags (vectorised); (duration s, first index)."""
    if not flags.any():
        return 0.0, -1
    padded = np.concatenate(([0], flags.astype(np.int8), [0]))
    edges = np.diff(padded)
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1  # inclusive
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    durations = t[ends] - t[starts] + step
    k = int(np.argmax(durations))
    return float(durations[k]), int(starts[k])


def _norm(v: np.ndarray) -> np.ndarray:
    """Row norms of an (N, 3) array (einsum: one pass, no (N, 3) temporary)."""
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _nonfinite(imu: ImuData, report: ValidationReport, nonfinite: str, warn: bool, row_lines) -> np.ndarray:
    """Rows to keep (finite t, gyro, accel); raise or warn about the others."""
    names = ["t", "wx", "wy", "wz", "ax", "ay", "az"]
    if np.isfinite(imu.t.sum() + imu.gyro.sum() + imu.accel.sum()):  # fast path: a sum is finite iff all are
        return np.arange(len(imu))
    finite = np.column_stack([np.isfinite(imu.t), np.isfinite(imu.gyro), np.isfinite(imu.accel)])
    row_ok = finite.all(axis=1)
    rows = np.flatnonzero(~row_ok)
    report.nonfinite_index = rows
    if not rows.size:
        return np.arange(len(imu))
    src = imu.source or "<ImuData>"
    counts = (~finite).sum(axis=0)
    report.nonfinite_columns = {nm: int(c) for nm, c in zip(names, counts) if c}
    kind, where = row_names(rows[:5], row_lines)
    parts = []
    for j, (nm, c) in enumerate(zip(names, counts)):
        if c:
            k, w = row_names(np.flatnonzero(~finite[:, j])[:3], row_lines)
            parts.append(f"{nm} ({c} value(s), first {k}s {fmt_list(w, 3)})")
    r0 = int(rows[0])
    t_r0 = f"t={imu.t[r0]:.6f} s" if np.isfinite(imu.t[r0]) else "t not finite"
    msg = (f"{src}: {rows.size} row(s) with NaN/inf: columns {', '.join(parts)}; first bad {kind} "
           f"{where[0]} ({t_r0}); {kind}s {fmt_list(where + [None] * (rows.size - len(where)))}")
    if nonfinite == "raise":
        report.issues.append(msg)
        raise ImuValidationError(msg + " ({hint} drops these rows)", option="nonfinite", value="drop")
    report.nonfinite_dropped = True
    act("warn" if warn else "ignore", msg + f"; dropped {rows.size} of {len(imu)} samples (nonfinite='drop')",
        NonFiniteWarning, report)
    return np.flatnonzero(row_ok)


def _units(report, t, gyro, accel, keep, units, src, gyro_limit, gyro_min_duration, accel_tol, rest_gyro,
           row_lines) -> None:
    """Magnitude checks of the cleaned data (rate, gyro, specific force)."""
    if t.size > 1:
        # the gap check's median step of these same times, when it ran (one median of the log, not two)
        step = report.median_step if np.isfinite(report.median_step) else float(np.median(np.diff(t)))
        if step > 0 and not RATE_RANGE[0] <= 1.0 / step <= RATE_RANGE[1]:
            act(units, f"{src}: median time step {step:.6g} s ({1 / step:.6g} Hz) is outside the plausible IMU "
                       f"rates {RATE_RANGE[0]:g}-{RATE_RANGE[1]:g} Hz: is the time column in another unit? "
                       f"(pass {{hint}})", UnitsWarning, report, option="time_unit")
    wn = _norm(gyro)
    report.gyro_max_norm = float(wn.max())
    over = wn > gyro_limit
    dur, first = _longest_run(over, t)
    report.gyro_sustained = dur
    if dur >= gyro_min_duration:
        kind, where = row_names(keep[[first]], row_lines)
        act(units, f"{src}: angular rate above {gyro_limit:g} rad/s for {dur:.3g} s from {kind} {where[0]} "
                   f"(t={t[first]:.6f} s), max {wn.max():.4g}: implausible for a car in rad/s; is the gyro "
                   f"in deg/s? (pass {{hint}}; {int(over.sum())} samples above)", UnitsWarning, report,
            option="gyro_unit", value="deg/s")
    an = _norm(accel)
    rest = wn < rest_gyro
    at_rest = int(rest.sum()) >= 10
    med = float(np.median(an[rest] if at_rest else an))
    report.accel_median_norm = med
    report.accel_norm_at_rest = at_rest
    g = STANDARD_GRAVITY
    if abs(med - g) > accel_tol:
        where = "at rest" if at_rest else "over all samples"
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
        act(units, f"{src}: median specific-force magnitude {where} is {med:.4g} m/s^2, expected about "
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
        The log (``t`` in s, ``gyro`` in rad/s, ``accel`` in m/s^2, any frame).
        ``meta["row_lines"]``, when present, maps input rows to 1-based file
        lines for the messages.
    policy : {"retime", "drop", "sort", "strict"}
        Unsorted/duplicate times (see :mod:`imu_ground.datasets.timestamps`);
        default ``"retime"`` (falls back to ``"drop"`` where the rate is not steady).
    nonfinite : {"raise", "drop"}
        NaN/inf in t, gyro or accel: raise naming the columns and rows (default),
        or drop the rows with a :class:`NonFiniteWarning`.
    gaps : {"warn", "raise", "ignore"}, optional
        Gaps; default ``"raise"`` if ``policy="strict"`` else ``"warn"``.
    units : {"warn", "raise", "ignore"}, optional
        Implausible magnitudes; default ``"raise"`` if ``policy="strict"`` else ``"warn"``.
    gap_factor : float
        Gap threshold as a multiple of the median step (default 5).
    gap_threshold : float, optional
        Absolute gap threshold, s (overrides ``gap_factor``).
    gyro_limit : float
        Angular rate, rad/s, that a car does not sustain (default 10 rad/s).
    gyro_min_duration : float
        How long, s, the rate must stay above ``gyro_limit`` (default 0.5 s).
    accel_tol : float
        Allowed distance, m/s^2, of the median specific-force magnitude from 1 g.
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
        The cleaned log (times strictly increasing), a new object;
        ``meta["validation"]`` holds the report.
    report : ValidationReport

    Raises
    ------
    ImuValidationError
        Empty log, non-finite values (``nonfinite="raise"``), unsorted times
        (``policy="strict"``), or gaps / units with action ``"raise"``; the
        message names the option that changes the outcome.
    """
    check_choice("policy", policy, POLICIES)
    check_choice("nonfinite", nonfinite, _NONFINITE)
    units = units if units is not None else ("raise" if policy == "strict" else "warn")
    check_choice("units", units, ("warn", "raise", "ignore"))
    if not warn and units == "warn":
        units = "ignore"
    src = imu.source or "<ImuData>"
    row_lines = imu.meta.get("row_lines")
    n = len(imu)
    report = ValidationReport(source=imu.source, policy=policy, n_in=n, gyro_limit=gyro_limit)
    if n == 0:
        report.issues.append(f"{src}: no samples (empty log)")
        raise ImuValidationError(report.issues[-1])
    good = _nonfinite(imu, report, nonfinite, warn, row_lines)
    every_row = good.size == n                  # nothing dropped: the rows are 0, 1, 2, ... as they are
    keep_pos, t, _ = check_timestamps(imu.t if every_row else imu.t[good], policy, gaps=gaps,
                                      gap_factor=gap_factor, gap_threshold=gap_threshold, source=src,
                                      index=None if every_row else good, report=report, warn=warn,
                                      row_lines=row_lines)
    keep = keep_pos if every_row else good[keep_pos]
    dropped = np.ones(n, dtype=bool)
    dropped[keep] = False
    report.dropped_index = np.flatnonzero(dropped)
    report.n_out = int(keep.size)
    if keep.size < max(min_samples, 1):
        report.issues.append(f"{src}: {keep.size} sample(s) left after cleaning ({n} read), "
                             f"need at least {max(min_samples, 1)}")
        raise ImuValidationError(report.issues[-1])
    # every row kept in order (only "sort" can keep them all in another order)
    same = keep.size == n and (policy != "sort" or bool((keep == np.arange(n)).all()))
    gyro = imu.gyro if same else imu.gyro[keep]
    accel = imu.accel if same else imu.accel[keep]
    _units(report, t, gyro, accel, keep, units, src, gyro_limit, gyro_min_duration, accel_tol, rest_gyro,
           row_lines)
    extra = imu.extra if same or not len(imu.extra) else imu.extra.iloc[keep].reset_index(drop=True)
    meta: dict[str, Any] = dict(imu.meta)
    meta["validation"] = report
    return ImuData(t, gyro, accel, imu.frame, extra, dict(imu.units), imu.source, meta), report
