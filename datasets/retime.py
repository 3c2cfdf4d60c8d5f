"""The retiming of jittered sample clocks: the sample index as the clock, one intercept per stretch.

:func:`retime` fits ``t_k = a_s + k / rate`` to raw stamps that step back or
repeat while the sample count agrees with a steady rate (KITTI OXTS logs);
lasting steps of more than a sample are real dropouts, kept as gaps between
stretches. :func:`~imu_ground.datasets.timestamps.check_timestamps` applies it
under the readers' default policy ``"retime"`` (see that module).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .order_stats import _running_median, median
from .report import ValidationReport

__all__ = ["RetimeResult", "retime"]


def _rows(pos: np.ndarray, index: np.ndarray | None) -> np.ndarray:
    """Input rows (int64) of positions ``pos``: ``index[pos]``, or ``pos`` itself when rows are 0, 1, 2, ..."""
    return np.asarray(pos, dtype=np.int64).copy() if index is None else index[pos]


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


class _RetimeStats(NamedTuple):
    """By-products of a successful retime: the stamps' shift and the retimed steps."""

    shift_max: float
    shift_rms: float
    steps: np.ndarray


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
    return _retime(np.asarray(t, dtype=float), index, window_s, min_inliers)[0]


def _retime(t: np.ndarray, index: np.ndarray | None, window_s: float, min_inliers: float,
            ) -> tuple[RetimeResult, _RetimeStats | None]:
    """:func:`retime`, plus the shift of the stamps and the retimed steps when it applies."""
    n = t.size
    none = np.zeros(0, dtype=np.int64)
    if n < 10:
        return RetimeResult(None, float("nan"), none, "fewer than 10 samples"), None
    k = np.arange(n, dtype=float) if index is None else np.asarray(index, dtype=float)
    stride = max(1, (n - 1) // 200_000)                  # the median step from at most ~200k steps
    sub = t[1::stride] - t[:-1:stride]
    if index is not None:
        sub /= np.maximum(k[1::stride] - k[:-1:stride], 1.0)
    pos = sub[sub > 0]
    if pos.size < sub.size // 2:
        return RetimeResult(None, float("nan"), none, "most time steps are not positive"), None
    dt = median(pos)
    w = int(min(max(21, round(window_s / dt) | 1), (n // 2) | 1))
    r = 1.0 / dt
    off = t - t[0]                                       # offset from the nominal clock, samples
    off *= r
    off -= k
    level, near = _running_median(off, w, np.flatnonzero(np.abs(np.diff(off)) > 0.5))
    # stretches: a lasting step of the smoothed offset by more than one sample
    j = near[near < n - 1]
    jump = level[j + 1] - level[j]
    if np.any(jump < -1.0):
        return RetimeResult(None, r, none, "more samples than the stamps' time span in a stretch "
                                           "(the sample count disagrees with a steady rate)"), None
    breaks = j[jump > 1.0] + 1
    outl = near[~(np.abs(off[near] - level[near]) < 0.5)]     # (elsewhere level is off: inliers)
    bounds = np.concatenate([[0], breaks, [n]])
    n_seg = breaks.size + 1
    cnt = np.diff(bounds) - np.bincount(np.searchsorted(breaks, outl, side="right"), minlength=n_seg)
    ok = cnt >= 2
    if int(cnt[ok].sum()) < n // 2:
        return RetimeResult(None, r, none, f"only {(n - outl.size) / n:.0%} of the stamps lie within half "
                                           f"a sample of a steady {1 / dt:.6g} Hz clock"), None
    # pooled within-stretch least squares (sums left to right): one rate, one intercept per stretch
    fit = np.ones(n, dtype=bool)
    fit[outl] = False
    for s_ in np.flatnonzero(~ok).tolist():
        fit[bounds[s_]:bounds[s_ + 1]] = False
    cf = np.where(ok, cnt, 0)
    sf = np.repeat(np.arange(n_seg), cf)
    dk, dtt = k[fit], t[fit]
    km = np.bincount(sf, dk, n_seg) / np.maximum(cf, 1)
    tm = np.bincount(sf, dtt, n_seg) / np.maximum(cf, 1)
    dk -= km[0] if n_seg == 1 else km[sf]
    dtt -= tm[0] if n_seg == 1 else tm[sf]
    slope = float(np.dot(dk, dtt) / np.dot(dk, dk))
    del dk, dtt, sf, fit
    if not (slope > 0 and 1.0 <= 1.0 / slope <= 1e5):
        return RetimeResult(None, r, none, "no steady positive rate"), None
    icpt = tm - slope * km
    for s_ in np.flatnonzero(cf == 0).tolist():          # tiny stretches: their median
        a_, b_ = bounds[s_], bounds[s_ + 1]
        icpt[s_] = float(np.median(t[a_:b_] - slope * k[a_:b_]))
    out = slope * k
    out += icpt[0] if n_seg == 1 else np.repeat(icpt, np.diff(bounds))
    d = out - t[0]                                       # the clock's offset from the smoothed offset
    d *= r
    d -= k
    d -= level
    share = np.count_nonzero(np.abs(d, out=d) < 1.0) / n
    if share < min_inliers:
        return RetimeResult(None, 1.0 / slope, none, f"the stamps follow the sample clock within a sample "
                                                     f"over only {share:.0%} of the log"), None
    steps = out[1:] - out[:-1]
    if np.any(steps <= 0):
        return RetimeResult(None, 1.0 / slope, none, "stretches between dropouts overlap"), None
    shift = np.subtract(out, t, out=d)
    top = float(np.max(np.abs(shift)))
    stats = _RetimeStats(top, float(np.sqrt(np.mean(np.multiply(shift, shift, out=shift)))), steps)
    return RetimeResult(out, 1.0 / slope, breaks.astype(np.int64), ""), stats


def _apply_retime(t: np.ndarray, index: np.ndarray | None, report: ValidationReport,
                  ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Retime into the report; the new stamps and their steps, or None (then ``drop`` applies).

    ``index`` None: the rows are ``0, 1, 2, ...`` (no row left out).
    """
    res, stats = _retime(t, index, 2.0, 0.95)
    if res.t is None or stats is None:
        report.retime_note = res.note
        return None, None
    report.retimed = True
    report.retime_rate = res.rate
    report.retime_shift_max = stats.shift_max
    report.retime_shift_rms = stats.shift_rms
    report.retime_dropout_index = _rows(res.breaks, index)
    return res.t, stats.steps
