"""Time order, duplicates and gaps of raw stamps, and the policy that applies the retiming.

:func:`check_timestamps` applies a time-order policy to raw stamps:

- ``"retime"`` (the readers' default): where the stamps step back or repeat but the sample count agrees
  with a steady rate, the sample index is the clock (:func:`~imu_ground.datasets.retime.retime`), nothing
  dropped; strictly increasing stamps are left as they are; without a steady rate it falls back to
  ``"drop"`` and says why.
- ``"drop"``: keep only samples later than every earlier one;
- ``"sort"``: sort by time (stable) and drop repeated times;
- ``"strict"``: raise.
- ``"recorded"``: every sample in file order with its stamp (listed in the report, not warned about; a gap
  is a stamp that far past the latest before it): for the live front end's causal
  :class:`~imu_ground.imu.live.sample_clock.SampleClock` only, as the times are not increasing.
"""
from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Literal, cast

import numpy as np

from imu_ground.errors import GapWarning, ImuValidationError, TimestampWarning, option_hint, warn_user
from .order_stats import median
from .report import ValidationReport, row_names
from .retime import RetimeResult, _apply_retime, _rows, retime

__all__ = ["POLICIES", "Action", "Policy", "RetimeResult", "act", "check_gaps", "check_timestamps", "fmt_list",
           "gap_action", "order_samples", "retime"]

Policy = Literal["retime", "drop", "sort", "strict", "recorded"]
Action = Literal["warn", "raise", "ignore"]
#: Time-order policies, the default first.
POLICIES: tuple[str, ...] = ("retime", "drop", "sort", "strict", "recorded")
ACTIONS: tuple[str, ...] = ("warn", "raise", "ignore")


def fmt_list(values, limit: int = 5, fmt: str = "{}") -> str:
    """``[a, b, c, ... (n more)]`` for a message."""
    values = list(values)
    items = [fmt.format(v) for v in values[:limit]]
    more = f", ... ({len(values) - limit} more)" if len(values) > limit else ""
    return "[" + ", ".join(items) + more + "]"


def check_choice(name: str, value, allowed: tuple[str, ...]) -> None:
    """Raise ``ImuValidationError`` naming ``name`` when ``value`` is not allowed."""
    if value not in allowed:
        raise ImuValidationError(f"{name}={value!r} is not one of {list(allowed)}",
                                 option=name if name in ("policy", "nonfinite") else None)


def act(action: str, message: str, category: type[Warning], report: ValidationReport,
        option: str | None = None, value=None) -> None:
    """Record ``message`` in the report and warn, raise or stay silent as ``action`` says."""
    report.issues.append(message.replace("{hint}", option_hint(option, value)) if option else message)
    if action == "raise":
        raise ImuValidationError(message, option=option, value=value)
    if action == "warn":
        warn_user(message, category, option, value)


#: Backsteps up to which :func:`_ooo_dup` follows each one instead of a running maximum of the log.
_LOCAL_BACKSTEPS = 2048


# --------------------------------------------------------------------------- check
def _order_message(src, t, rows, back, steps, ooo, dup, row_lines) -> str:
    parts = []
    if ooo.size:
        b0 = int(back[0])  # the first out-of-order sample is always the first backward step
        kind, where = row_names(rows(back[:1]), row_lines)
        parts.append(f"{ooo.size} sample(s) out of order (time steps back {back.size} time(s), "
                     f"first at {kind} {where[0]}, t={t[b0]:.6f} s, step {steps[b0 - 1]:+.6f} s)")
    if dup.size:
        d0 = int(dup[0])
        kind, where = row_names(rows(dup[:1]), row_lines)
        parts.append(f"{dup.size} duplicate timestamp(s) (first at {kind} {where[0]}, t={t[d0]:.6f} s)")
    return " and ".join(parts)


def _stretch_end(t: np.ndarray, b: int, top: float) -> int:
    """The first position from ``b`` on with a time later than ``top`` (``t.size`` if none)."""
    lo, span = b, 16
    while lo < t.size:
        hit = t[lo:lo + span] > top
        j = int(hit.argmax())
        if hit[j]:
            return lo + j
        lo, span = lo + span, span * 4
    return t.size


def _ooo_dup(t: np.ndarray, steps: np.ndarray, back: np.ndarray, zero: np.ndarray,
             finite: bool) -> tuple[np.ndarray, np.ndarray]:
    """Positions earlier than (out of order) and equal to (duplicates) the latest time before them.

    ``back``, ``zero``: positions after a backward and a zero step; ``finite``: ``t`` is known finite. With few
    backsteps only the stretches from each until the stamps pass the time before it are looked at, else the
    running maximum of the log.
    """
    if not back.size:
        return back[:0], zero
    if not finite:
        with np.errstate(all="ignore"):
            finite = bool(np.isfinite(np.add.reduce(steps)))  # all finite (or inf - inf: the slow way too)
    if back.size > _LOCAL_BACKSTEPS or not finite:
        prev_max = np.maximum.accumulate(t)[:-1]
        return np.flatnonzero(t[1:] < prev_max) + 1, np.flatnonzero(t[1:] == prev_max) + 1
    n = t.size
    top = t[back - 1]                      # the latest time before a backstep that starts a stretch
    win = t[np.minimum(back[:, None] + np.arange(16), n - 1)]
    hit = win > top[:, None]
    first = hit.argmax(axis=1)
    found = hit[np.arange(back.size), first].tolist()
    stretch, stops, end = [], [], 0
    for i, (b, j) in enumerate(zip(back.tolist(), first.tolist(), strict=True)):
        if b >= end:                       # not within the stretch of an earlier backstep
            end = b + j if found[i] else _stretch_end(t, b, float(top[i]))
            stretch.append(i)
            stops.append(end)
    sel, start, stop = np.array(stretch), back[stretch], np.array(stops)
    span = stop - start
    short = span <= 16
    ooo: list[np.ndarray] = []
    dup: list[np.ndarray] = []
    if short.any():                        # positions of the short stretches, row by row: in order
        w, tp = win[sel[short]], top[sel[short], None]
        inside = np.arange(16) < span[short, None]
        for part, mask in ((ooo, w < tp), (dup, w == tp)):
            r, c = np.nonzero(mask & inside)
            part.append(start[short][r] + c)
    for i in np.flatnonzero(~short).tolist():
        seg = t[start[i]:stop[i]]
        ooo.append(np.flatnonzero(seg < top[sel[i]]) + start[i])
        dup.append(np.flatnonzero(seg == top[sel[i]]) + start[i])
    j = np.searchsorted(start, zero, side="right") - 1   # a repeated time outside the stretches: a duplicate
    dup.append(zero[(j < 0) | (zero >= stop[np.maximum(j, 0)])])
    return np.sort(np.concatenate(ooo)), np.sort(np.concatenate(dup))


def check_timestamps(t: np.ndarray, policy: Policy = "retime", *, gaps: Action | None = None,
                     gap_factor: float = 5.0, gap_threshold: float | None = None,
                     source: str = "", index: np.ndarray | None = None,
                     report: ValidationReport | None = None, warn: bool = True,
                     row_lines: Callable[[np.ndarray], np.ndarray] | None = None,
                     ) -> tuple[np.ndarray, np.ndarray, ValidationReport]:
    """Check raw timestamps for order, duplicates and gaps, and apply ``policy``.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times, s; must be finite.
    policy : {"retime", "drop", "sort", "strict", "recorded"}
        See the module docstring.
    gaps, gap_factor, gap_threshold, warn
        As in :func:`~imu_ground.datasets.validation.validate`.
    source : str
        Name used in messages (file path).
    index : array_like of int, optional
        Input row numbers of ``t``, default ``arange(N)``.
    report : ValidationReport, optional
        Report to fill in (a new one by default).
    row_lines : callable, optional
        Input rows to 1-based file lines, for messages.

    Returns
    -------
    keep : ndarray of int
        Positions into ``t`` of the samples kept, in output order.
    t_out : ndarray
        Their times, s (retimed under ``"retime"``).
    report : ValidationReport

    Raises
    ------
    ImuValidationError
        ``policy="strict"`` and the times are not strictly increasing, or
        ``gaps="raise"`` and there is a gap.
    """
    check_choice("policy", policy, POLICIES)
    gaps = gap_action(gaps, policy, warn)
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"timestamps must be 1-D, got shape {t.shape}")
    index = None if index is None else np.asarray(index, dtype=np.int64)
    if report is None:
        report = ValidationReport(source=source, policy=policy, n_in=int(t.size))
    keep, t_out, steps = order_samples(t, policy, source, index, report, warn, row_lines)
    check_gaps(t_out, steps, keep, index, report, gaps, gap_factor, gap_threshold, source, row_lines)
    return (np.arange(t_out.size) if keep is None else keep), t_out, report


def gap_action(gaps: str | None, policy: str, warn: bool) -> Action:
    """The gap action asked for, or the default (``"raise"`` under ``"strict"``, else ``"warn"``), checked."""
    gaps = gaps if gaps is not None else ("raise" if policy == "strict" else "warn")
    check_choice("gaps", gaps, ACTIONS)
    return "ignore" if not warn and gaps == "warn" else cast(Action, gaps)     # (a checked choice)


def _reverse_order_error(src: str, n: int, back: np.ndarray, policy: str) -> ImuValidationError | None:
    """The error for a log whose samples are newest first (most steps go back: dropping would keep a few), else None."""
    if policy not in ("retime", "drop", "recorded") or n < 3 or back.size * 2 <= n - 1:
        return None
    how = "in reverse order (newest first)" if back.size == n - 1 else "mostly in reverse order"
    return ImuValidationError(f"{src}: the samples are {how}: {back.size} of {n - 1} time steps go back; "
                              f"pass {{hint}} to sort them by time", option="policy", value="sort")


def order_samples(t, policy, source, index, report, warn, row_lines, finite: bool = False,
                  ) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """Apply the time-order policy: (positions kept in output order or None for all, their times, their steps).

    ``finite``: the times are known finite. Fills the report's order fields, warns (raises under ``"strict"``).
    """
    rows = partial(_rows, index=index)
    report.policy = policy
    src = source or "<timestamps>"
    n = t.size
    steps = t[1:] - t[:-1]
    cand = np.flatnonzero(steps <= 0)
    neg = steps[cand] < 0
    back = cand[neg] + 1
    ooo, dup = _ooo_dup(t, steps, back, cand[~neg] + 1, finite)
    keep: np.ndarray | None = None
    if policy == "sort":                # stable, without the repeated times
        order = np.argsort(t, kind="stable")
        ts = t[order]
        first = np.ones(n, dtype=bool)
        first[1:] = ts[1:] != ts[:-1]
        dup, keep = np.sort(order[~first]), order[first]
    report.backstep_index = rows(back)
    report.backstep_size = steps[back - 1]
    report.out_of_order_index = rows(ooo)
    report.duplicate_index = rows(dup)
    if not (ooo.size or dup.size):      # nothing out of order: every sample kept, in order
        return keep, t.copy(), steps
    what = f"{src}: " + _order_message(src, t, rows, back, steps, ooo, dup, row_lines)
    if policy == "strict":
        msg = f"{src}: timestamps not strictly increasing: {what[len(src) + 2:]}"
        report.issues.append(msg)
        raise ImuValidationError(msg + " (policy='strict'; {hint} retimes them on the sample index, "
                                       "'drop' or 'sort' also accepted)", option="policy", value="retime")
    reverse = _reverse_order_error(src, n, back, policy)
    if reverse is not None:
        report.issues.append(str(reverse))
        raise reverse
    if policy == "recorded":            # for the causal clock: file order and stamps kept, noted in the report
        report.issues.append(what + "; kept as recorded for the causal sample clock (policy='recorded')")
        # a gap is a stamp that far past the latest before it (not the recovery after a back-step)
        return None, t.copy(), t[1:] - np.maximum.accumulate(t)[:-1]
    # the raw steps are not used again: their array may hold the retimed ones
    new_t, dk = _apply_retime(t, index, report, steps) if policy == "retime" else (None, None)
    if new_t is not None:
        kind, where = row_names(report.retime_dropout_index, row_lines)
        gaps_kept = f"{len(where)} dropout(s) kept as gaps (before {kind}s {fmt_list(where)})" if where \
            else "no dropout"
        msg = (f"{what}; retimed on the sample index at {report.retime_rate:.6g} Hz, nothing dropped: "
               f"max shift {report.retime_shift_max:.4g} s, RMS {report.retime_shift_rms:.4g} s; "
               f"{gaps_kept} (policy='retime', report in meta['validation'])")
        act("warn" if warn else "ignore", msg, TimestampWarning, report)
        assert dk is not None                       # retimed: the steps too
        return None, new_t, dk
    if policy == "sort":
        report.reordered = bool(ooo.size)
        acts = (["sorted by time"] if ooo.size else []) + \
            ([f"dropped {dup.size} repeated time(s)"] if dup.size else [])
        msg = (f"{what}; {' and '.join(acts)}, {n - dup.size} of {n} samples kept "
               f"(policy='sort', report in meta['validation'])")
    else:
        keep = np.delete(np.arange(n), np.concatenate([ooo, dup]))    # all but the out-of-order and duplicates
        why = f" (not retimed: {report.retime_note})" if policy == "retime" else ""
        msg = (f"{what}; dropped {n - keep.size} of {n} samples{why} "
               f"(policy={policy!r}, report in meta['validation'])")
    act("warn" if warn else "ignore", msg, TimestampWarning, report)
    t_out = t[keep]
    return keep, t_out, t_out[1:] - t_out[:-1]


def check_gaps(t_out, steps, keep, index, report, gaps, gap_factor, gap_threshold, source, row_lines) -> None:
    """Gaps in the ordered times ``t_out`` (``keep``, ``index``: their positions and rows, as :func:`order_samples`)."""
    if t_out.size < 2:
        if gap_threshold is not None:
            report.gap_threshold = float(gap_threshold)
        return
    report.median_step = median(steps)
    thr = float(gap_threshold) if gap_threshold is not None else gap_factor * report.median_step
    report.gap_threshold = thr
    g = np.flatnonzero(steps > thr)
    report.gap_out_index = g.astype(np.int64)
    report.gap_index = _rows(g if keep is None else keep[g], index)
    report.gap_start = t_out[g]
    report.gap_length = steps[g]
    if g.size:
        k = int(np.argmax(steps[g]))
        how = (f"{gap_threshold:g} s" if gap_threshold is not None else
               f"{thr:.4g} s = {gap_factor:g} x median step {report.median_step:.4g} s")
        kind, where = row_names(report.gap_index[[k]], row_lines)
        msg = (f"{source or '<timestamps>'}: {g.size} gap(s) longer than {how}: longest {steps[g][k]:.4g} s at "
               f"t={t_out[g][k]:.6f} s ({kind} {where[0]}); starts (s) "
               f"{fmt_list(t_out[g], fmt='{:.3f}')}, lengths (s) {fmt_list(steps[g], fmt='{:.3f}')}")
        act(gaps, msg, GapWarning, report)
