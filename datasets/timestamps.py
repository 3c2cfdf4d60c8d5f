"""Time order, duplicates, gaps and the retiming of jittered sample clocks.

:func:`check_timestamps` applies a time-order policy to raw stamps:

- ``"retime"`` (the readers' default): where the stamps step back or repeat but
  the sample count agrees with a steady rate, the sample index is the clock
  (:func:`retime`): ``t_k = a + k / rate``, fitted robustly to the stamps, one
  intercept per stretch between real dropouts, which stay gaps. Nothing is
  dropped. Logs whose stamps increase strictly are left exactly as they are;
  where the rate is not steady it falls back to ``"drop"`` and says why.
- ``"drop"``: keep only samples later than every earlier one;
- ``"sort"``: sort by time (stable) and drop repeated times;
- ``"strict"``: raise.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Literal, NamedTuple

import numpy as np

from .options import option_hint
from .report import (
    GapWarning,
    ImuValidationError,
    TimestampWarning,
    ValidationReport,
    row_names,
    warn_user,
)

__all__ = ["POLICIES", "Action", "Policy", "RetimeResult", "act", "check_timestamps", "fmt_list", "retime"]

Policy = Literal["retime", "drop", "sort", "strict"]
Action = Literal["warn", "raise", "ignore"]
#: Time-order policies, the default first.
POLICIES: tuple[str, ...] = ("retime", "drop", "sort", "strict")
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


# --------------------------------------------------------------------------- retime
class RetimeResult(NamedTuple):
    """Outcome of :func:`retime`.

    Attributes
    ----------
    t : ndarray (N,) or None
        The retimed stamps, s (None when not applicable).
    rate : float
        Fitted rate of the index clock, Hz.
    breaks : ndarray of int
        Positions (into the input) starting a new stretch after a real dropout.
    note : str
        Why retiming does not apply (empty when it does).
    """

    t: np.ndarray | None
    rate: float
    breaks: np.ndarray
    note: str


def _running_median(x: np.ndarray, w: int, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centred running median over ``w`` (odd) samples (edges padded with the end values), and where it differs.

    Evaluated only within ``w // 2`` samples of an ``events`` position (a step
    that is not one sample period); elsewhere the window holds one undisturbed
    stretch and the value is taken as it is, so the cost follows the events,
    not the log's length. Returns the medians and the positions evaluated.
    """
    h = w // 2
    out = x.copy()
    if not events.size:
        return out, events
    # the positions within [e - h - 1, e + h + 2) of an event e: the union of these (sorted) ranges
    starts = np.clip(events - h - 1, 0, x.size)
    stops = np.clip(events + h + 2, 0, x.size)
    new = np.concatenate([[True], starts[1:] > stops[:-1]])      # a range not overlapping the one before
    lo = starts[new]
    hi = np.maximum.reduceat(stops, np.flatnonzero(new))
    lens = hi - lo
    near = np.repeat(lo - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens) + np.arange(int(lens.sum()))
    win = np.lib.stride_tricks.sliding_window_view(np.pad(x, h, mode="edge"), w)
    for s in range(0, near.size, 4096):  # cache-sized windows, whatever the log's length
        rows = near[s:s + 4096]
        out[rows] = np.median(win[rows], axis=1, overwrite_input=True)  # win[rows] is a gathered copy
    return out, near


def _stretches(level: np.ndarray, near: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
    """Stretch number of each sample and the positions starting a new one (None: a negative jump)."""
    if not near.size:
        return np.zeros(level.size, dtype=np.int64), near
    j = near[near < level.size - 1]
    jump = level[j + 1] - level[j]
    if np.any(jump < -1.0):
        return None, near
    breaks = j[jump > 1.0] + 1
    seg = np.zeros(level.size, dtype=np.int64)
    seg[breaks] = 1
    return np.cumsum(seg), breaks


def retime(t: np.ndarray, index: np.ndarray | None = None, *, window_s: float = 2.0,
           min_inliers: float = 0.95) -> RetimeResult:
    """Sample index as the clock: ``t_k = a_s + k / rate`` per stretch ``s`` between dropouts.

    The stamps' offset from a nominal clock (in samples) is smoothed by a running
    median over ``window_s``: a stretch displaced for less than half the window
    is jitter, a lasting step of more than one sample is a dropout (a new
    stretch, kept as a gap). One rate and one intercept per stretch are then
    fitted by least squares to the stamps within half a sample of the smoothed
    offset.

    Parameters
    ----------
    t : ndarray (N,)
        Finite stamps, s, in file order.
    index : ndarray of int (N,), optional
        Sample number of each stamp (input rows: a dropped non-finite row still
        took a slot); default ``arange(N)``.
    window_s : float
        Length of the running median, s.
    min_inliers : float
        Share of the log over which the smoothed offset must lie within one
        sample of the fitted clock (single stamps may jitter further).

    Returns
    -------
    RetimeResult
        ``t`` None with a ``note`` when the stamps do not follow a steady rate.
    """
    t = np.asarray(t, dtype=float)
    k = np.arange(t.size, dtype=float) if index is None else np.asarray(index, dtype=float)
    none = np.zeros(0, dtype=np.int64)
    if t.size < 10:
        return RetimeResult(None, float("nan"), none, "fewer than 10 samples")
    steps = np.diff(t) if index is None else np.diff(t) / np.maximum(np.diff(k), 1.0)
    sub = steps[:: max(1, steps.size // 200_000)]  # the median step from at most ~200k steps
    pos = sub[sub > 0]
    if pos.size < sub.size // 2:
        return RetimeResult(None, float("nan"), none, "most time steps are not positive")
    dt = float(np.median(pos))
    w = int(min(max(21, round(window_s / dt) | 1), (t.size // 2) | 1))
    off = t - t[0]                                   # in samples; jitter = bump, dropout = step
    off *= 1.0 / dt
    off -= k
    step = np.diff(off)
    events = np.flatnonzero(np.abs(step, out=step) > 0.5)
    del step
    level, near = _running_median(off, w, events)
    seg, breaks = _stretches(level, near)
    if seg is None:
        return RetimeResult(None, 1.0 / dt, none, "more samples than the stamps' time span in a stretch "
                                                  "(the sample count disagrees with a steady rate)")
    inl = np.ones(t.size, dtype=bool)
    inl[near] = np.abs(off[near] - level[near]) < 0.5  # elsewhere off == level
    n_seg = int(seg[-1]) + 1
    sf = seg[inl]
    cnt = np.bincount(sf, minlength=n_seg)
    fit = inl if cnt.min() >= 2 else inl & (cnt[seg] >= 2)
    if fit.sum() < t.size // 2:
        return RetimeResult(None, 1.0 / dt, none, f"only {inl.mean():.0%} of the stamps lie within half a "
                                                  f"sample of a steady {1 / dt:.6g} Hz clock")
    # pooled within-stretch least squares: one rate, one intercept per stretch
    if fit is not inl:
        sf = seg[fit]
    cf = np.bincount(sf, minlength=n_seg)
    dk, dtt = k[fit], t[fit]
    km = np.bincount(sf, dk, n_seg) / np.maximum(cf, 1)
    tm = np.bincount(sf, dtt, n_seg) / np.maximum(cf, 1)
    dk -= km[0] if n_seg == 1 else km[sf]             # one stretch: the same value for every sample
    dtt -= tm[0] if n_seg == 1 else tm[sf]
    del sf
    slope = float(np.dot(dk, dtt) / np.dot(dk, dk))
    del dk, dtt
    if not (slope > 0 and 1.0 <= 1.0 / slope <= 1e5):
        return RetimeResult(None, 1.0 / dt, none, "no steady positive rate")
    icpt = tm - slope * km
    for s_ in np.flatnonzero(cf == 0):  # tiny stretches: their median
        icpt[s_] = float(np.median(t[seg == s_] - slope * k[seg == s_]))
    out = slope * k
    out += icpt[0] if n_seg == 1 else icpt[seg]
    dev = out - t[0]                                  # smoothed offset vs clock, in samples
    dev *= 1.0 / dt
    dev -= k
    dev -= level
    agree = float(np.mean(np.abs(dev, out=dev) < 1.0))
    del dev
    if agree < min_inliers:
        return RetimeResult(None, 1.0 / slope, none, f"the stamps follow the sample clock within a sample "
                                                     f"over only {agree:.0%} of the log")
    if np.any(np.diff(out) <= 0):
        return RetimeResult(None, 1.0 / slope, none, "stretches between dropouts overlap")
    return RetimeResult(out, 1.0 / slope, breaks.astype(np.int64), "")


def _apply_retime(t: np.ndarray, index: np.ndarray, report: ValidationReport,
                  consecutive: bool = False) -> np.ndarray | None:
    """Retime into the report; the new stamps, or None (then ``drop`` applies).

    ``consecutive``: ``index`` is ``0, 1, 2, ...`` (no row left out), which
    :func:`retime` then need not divide by.
    """
    res = retime(t, None if consecutive else index)
    if res.t is None:
        report.retime_note = res.note
        return None
    shift = res.t - t
    report.retimed = True
    report.retime_rate = res.rate
    report.retime_shift_max = float(np.abs(shift).max())
    report.retime_shift_rms = float(np.sqrt(np.mean(shift ** 2)))
    report.retime_dropout_index = index[res.breaks]
    return res.t


# --------------------------------------------------------------------------- check
def _order_message(src, t, index, back, steps, ooo, dup, row_lines) -> str:
    parts = []
    if ooo.size:
        b0 = int(back[0])  # the first out-of-order sample is always the first backward step
        kind, where = row_names(index[[b0]], row_lines)
        parts.append(f"{ooo.size} sample(s) out of order (time steps back {back.size} time(s), "
                     f"first at {kind} {where[0]}, t={t[b0]:.6f} s, step {steps[b0 - 1]:+.6f} s)")
    if dup.size:
        d0 = int(dup[0])
        kind, where = row_names(index[[d0]], row_lines)
        parts.append(f"{dup.size} duplicate timestamp(s) (first at {kind} {where[0]}, t={t[d0]:.6f} s)")
    return " and ".join(parts)


def _order(t: np.ndarray, policy: str):
    """(backsteps, out-of-order, duplicates, keep) positions under ``policy`` (not retime)."""
    n = t.size
    steps = np.diff(t)
    back = np.flatnonzero(steps < 0) + 1
    if n > 1:
        prev_max = np.maximum.accumulate(t)[:-1]
        ooo = np.flatnonzero(t[1:] < prev_max) + 1
        dup = np.flatnonzero(t[1:] == prev_max) + 1
    else:
        ooo = dup = np.zeros(0, dtype=np.int64)
    if policy == "sort":
        order = np.argsort(t, kind="stable")
        ts = t[order]
        first = np.ones(n, dtype=bool)
        first[1:] = ts[1:] != ts[:-1]
        return steps, back, ooo, np.sort(order[~first]), order[first]
    bad = np.zeros(n, dtype=bool)
    bad[ooo] = True
    bad[dup] = True
    return steps, back, ooo, dup, np.flatnonzero(~bad)


def _gaps(tk, keep, index, report, gaps, gap_factor, gap_threshold, src, row_lines) -> None:
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
               f"{thr:.4g} s = {gap_factor:g} x median step {report.median_step:.4g} s")
        kind, where = row_names(report.gap_index[[k]], row_lines)
        msg = (f"{src}: {g.size} gap(s) longer than {how}: longest {dk[g][k]:.4g} s at "
               f"t={tk[g][k]:.6f} s ({kind} {where[0]}); starts (s) "
               f"{fmt_list(tk[g], fmt='{:.3f}')}, lengths (s) {fmt_list(dk[g], fmt='{:.3f}')}")
        act(gaps, msg, GapWarning, report)


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
    policy : {"retime", "drop", "sort", "strict"}
        See the module docstring.
    gaps : {"warn", "raise", "ignore"}, optional
        What to do about gaps; default ``"raise"`` under ``"strict"``, else ``"warn"``.
    gap_factor : float
        A step longer than ``gap_factor`` times the median step is a gap.
    gap_threshold : float, optional
        Absolute gap threshold, s; overrides ``gap_factor``.
    source : str
        Name used in messages (file path).
    index : array_like of int, optional
        Input row numbers of ``t``, default ``arange(N)``.
    report : ValidationReport, optional
        Report to fill in (a new one by default).
    warn : bool
        Issue warnings (False: only record the issues in the report).
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
    gaps = gaps if gaps is not None else ("raise" if policy == "strict" else "warn")
    check_choice("gaps", gaps, ACTIONS)
    if not warn and gaps == "warn":
        gaps = "ignore"
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"timestamps must be 1-D, got shape {t.shape}")
    consecutive = index is None
    index = np.arange(t.size) if index is None else np.asarray(index, dtype=np.int64)
    if report is None:
        report = ValidationReport(source=source, policy=policy, n_in=int(t.size))
    report.policy = policy
    src = source or "<timestamps>"
    n = t.size
    steps, back, ooo, dup, keep = _order(t, "sort" if policy == "sort" else "drop")
    report.backstep_index = index[back]
    report.backstep_size = steps[back - 1]
    report.out_of_order_index = index[ooo]
    report.duplicate_index = index[dup]
    if ooo.size or dup.size:
        what = f"{src}: " + _order_message(src, t, index, back, steps, ooo, dup, row_lines)
        if policy == "strict":
            msg = f"{src}: timestamps not strictly increasing: {what[len(src) + 2:]}"
            report.issues.append(msg)
            raise ImuValidationError(msg + " (policy='strict'; {hint} retimes them on the sample index, "
                                           "'drop' or 'sort' also accepted)", option="policy", value="retime")
        new_t = _apply_retime(t, index, report, consecutive) if policy == "retime" else None
        if new_t is not None:
            keep, t_out = np.arange(n), new_t
            kind, where = row_names(report.retime_dropout_index, row_lines)
            gaps_kept = f"{len(where)} dropout(s) kept as gaps (before {kind}s {fmt_list(where)})" if where \
                else "no dropout"
            msg = (f"{what}; retimed on the sample index at {report.retime_rate:.6g} Hz, nothing dropped: "
                   f"max shift {report.retime_shift_max:.4g} s, RMS {report.retime_shift_rms:.4g} s; "
                   f"{gaps_kept} (policy='retime', report in meta['validation'])")
        elif policy == "sort":
            report.reordered = bool(ooo.size)
            acts = (["sorted by time"] if ooo.size else []) + \
                ([f"dropped {dup.size} repeated time(s)"] if dup.size else [])
            msg = (f"{what}; {' and '.join(acts)}, {keep.size} of {n} samples kept "
                   f"(policy='sort', report in meta['validation'])")
        else:
            why = f" (not retimed: {report.retime_note})" if policy == "retime" else ""
            msg = (f"{what}; dropped {n - keep.size} of {n} samples{why} "
                   f"(policy={policy!r}, report in meta['validation'])")
        act("warn" if warn else "ignore", msg, TimestampWarning, report)
        t_out = new_t if new_t is not None else t[keep]
    else:
        t_out = t.copy()                # nothing out of order: every sample kept, in order
    if t_out.size > 1:
        _gaps(t_out, keep, index, report, gaps, gap_factor, gap_threshold, src, row_lines)
    elif gap_threshold is not None:
        report.gap_threshold = float(gap_threshold)
    return keep, t_out, report
