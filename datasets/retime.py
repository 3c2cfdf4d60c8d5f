"""The retiming of jittered sample clocks (policy ``"retime"``): the sample index as the clock, one intercept per
stretch between real dropouts (lasting steps of more than a sample, kept as gaps)."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .order_stats import BLOCK, _medians_near, _near, median
from .report import ValidationReport

__all__ = ["RetimeResult", "retime"]


def _rows(pos: np.ndarray, index: np.ndarray | None) -> np.ndarray:
    """Input rows (int64) of positions ``pos``: ``index[pos]``, or ``pos`` itself when rows are 0, 1, 2, ..."""
    return np.asarray(pos, dtype=np.int64).copy() if index is None else index[pos]


# --------------------------------------------------------------------------- retime
class RetimeResult(NamedTuple):
    """Outcome of :func:`retime`: the stamps ``t`` (s; None when it does not apply, ``note`` says why), the
    index clock's ``rate`` (Hz) and the ``breaks``, input positions starting a stretch after a dropout."""

    t: np.ndarray | None
    rate: float
    breaks: np.ndarray
    note: str


class _RetimeStats(NamedTuple):
    """By-products of a successful retime: the stamps' shift and the retimed steps."""

    shift_max: float
    shift_rms: float
    steps: np.ndarray


#: Rounding allowance of the shortcuts in :func:`_retime` (see :class:`_Clock`).
_SLACK = 1e-4


class _Clock:
    """The stamps' offset from a nominal clock, in samples: ``(t - t[0]) / dt - k`` (jitter = bump, dropout = step).

    ``k`` None: the index ``0, 1, 2, ...``, made block by block. Shortcuts (:meth:`shortcuts`, consecutive index
    only): while ``16 u S < 1e-4`` (``u = 2**-53``, ``S`` = :attr:`scale`), an offset's rounding is far below
    1e-3 sample, so raw steps within ``[0.502, 1.498] dt`` cannot step the offset by half a sample, nor shifts
    below ``0.999 dt`` put it a sample away: only the other samples are worked out.
    """

    def __init__(self, t: np.ndarray, k: np.ndarray | None, dt: float) -> None:
        self.t, self.k, self.t0, self.dt, self.r = t, k, t[0], dt, 1.0 / dt
        with np.errstate(all="ignore"):         # (a non-finite stamp: no shortcuts)
            span = float(max(t.max() - self.t0, self.t0 - t.min())) * self.r
        self.scale = span + t.size + 4 if k is None else np.inf

    def shortcuts(self, scale: float = 0.0) -> bool:
        """Whether the shortcuts hold (``scale``: another bound of a clock in samples)."""
        return bool(16 * 2.0 ** -53 * self.scale < _SLACK and 16 * 2.0 ** -53 * scale < _SLACK)

    def kblock(self, lo: int, hi: int) -> np.ndarray:
        """The index at positions ``lo:hi`` as floats."""
        return np.arange(lo, hi, dtype=float) if self.k is None else self.k[lo:hi]

    def block(self, lo: int, hi: int, out: np.ndarray) -> np.ndarray:
        """Offsets at positions ``lo:hi`` into ``out[:hi - lo]``."""
        o = np.subtract(self.t[lo:hi], self.t0, out=out[:hi - lo])
        o *= self.r
        o -= self.kblock(lo, hi)
        return o

    def at(self, idx: np.ndarray) -> np.ndarray:
        """Offsets at positions ``idx``."""
        o = self.t[idx] - self.t0
        o *= self.r
        o -= idx if self.k is None else self.k[idx]
        return o

    def events(self, raw: np.ndarray | None) -> np.ndarray:
        """Positions ``i`` where the offset steps by over half a sample to ``i + 1`` (``raw``: the raw steps)."""
        n = self.t.size
        if raw is not None and self.k is None and self.shortcuts():
            cand = np.flatnonzero((raw < (0.5 + 2e-3) * self.dt) | (raw > (1.5 - 2e-3) * self.dt))
            if cand.size <= n >> 4:
                step = self.at(cand + 1) - self.at(cand)
                return cand[np.abs(step) > 0.5]
        buf, step, found = np.empty(min(n, BLOCK + 1)), np.empty(min(n - 1, BLOCK)), []
        for lo in range(0, n - 1, BLOCK):
            hi = min(lo + BLOCK, n - 1)
            o = self.block(lo, hi + 1, buf)
            s = np.subtract(o[1:], o[:-1], out=step[:hi - lo])
            e = np.flatnonzero(np.abs(s, out=s) > 0.5)
            if e.size:
                found.append(e + lo)
        return np.concatenate(found) if found else np.zeros(0, dtype=np.int64)

    def agree(self, out: np.ndarray, idx: np.ndarray | None = None) -> int:
        """How many samples (at ``idx``, default all) have ``|(out - t0) r - k - offset| < 1``."""
        if idx is not None:
            d = out[idx] - self.t0
            d *= self.r
            d -= idx if self.k is None else self.k[idx]
            d -= self.at(idx)
            return int(np.count_nonzero(np.abs(d, out=d) < 1.0))
        n, count = out.size, 0
        b1, b2 = np.empty(min(n, BLOCK)), np.empty(min(n, BLOCK))
        for lo in range(0, n, BLOCK):
            hi = min(lo + BLOCK, n)
            d = np.subtract(out[lo:hi], self.t0, out=b1[:hi - lo])
            d *= self.r
            d -= self.kblock(lo, hi)
            d -= self.block(lo, hi, b2)
            count += int(np.count_nonzero(np.abs(d, out=d) < 1.0))
        return count


def _seq_sum(x: np.ndarray) -> float:
    """Left-to-right float sum from 0.0 (as ``np.bincount`` adds its weights), block by block."""
    acc = np.float64(0.0)
    buf = np.empty(min(x.size, BLOCK))
    for lo in range(0, x.size, BLOCK):
        c = x[lo:lo + BLOCK]
        first = c[0]
        c[0] = acc + first                # the running sum enters the block's first term
        acc = np.add.accumulate(c, out=buf[:c.size])[-1]
        c[0] = first
    return float(acc)


def _kept_runs(n: int, gone: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and stops of the runs of ``range(n)`` without the (sorted, distinct) positions ``gone``."""
    if not gone.size:
        return np.array([0]), np.array([n])
    new = np.flatnonzero(np.diff(gone) != 1) + 1
    return (np.concatenate([[0], gone[np.concatenate([new - 1, [gone.size - 1]])] + 1]),
            np.concatenate([gone[np.concatenate([[0], new])], [n]]))


def retime(t: np.ndarray, index: np.ndarray | None = None, *, window_s: float = 2.0,
           min_inliers: float = 0.95) -> RetimeResult:
    """Sample index as the clock: ``t_k = a_s + k / rate`` per stretch ``s`` between dropouts.

    The stamps' offset from a nominal clock (samples) is smoothed by a running median over ``window_s``: a
    shorter displacement is jitter, a lasting step of more than one sample a dropout (a new stretch). One rate
    and one intercept per stretch are fitted by least squares to the stamps within half a sample of it.

    Parameters
    ----------
    t : ndarray (N,)
        Finite stamps, s, in file order.
    index : ndarray of int (N,), optional
        Sample number of each stamp (a dropped non-finite row still took a slot); default ``arange(N)``.
    window_s : float
        Length of the running median, s.
    min_inliers : float
        Share of the log over which the smoothed offset must lie within one sample of the fitted clock.

    Returns
    -------
    RetimeResult
        ``t`` None with a ``note`` when the stamps do not follow a steady rate.
    """
    return _retime(np.asarray(t, dtype=float), index, window_s, min_inliers)[0]


def _retime(t: np.ndarray, index: np.ndarray | None, window_s: float, min_inliers: float,
            scratch: np.ndarray | None = None) -> tuple[RetimeResult, _RetimeStats | None]:
    """:func:`retime`, plus the stamps' shift and the retimed steps (into ``scratch``, (N - 1,), if given).

    Block by block, bit for bit the whole-array fit (the same operations in the same order; integer index
    sums in closed form, exact).
    """
    n = t.size
    k = None if index is None else np.asarray(index, dtype=float)
    none = np.zeros(0, dtype=np.int64)
    if n < 10:
        return RetimeResult(None, float("nan"), none, "fewer than 10 samples"), None
    stride = max(1, (n - 1) // 200_000)                  # the median step from at most ~200k steps
    sub = t[1::stride] - t[:-1:stride]
    if k is not None:
        sub /= np.maximum(k[1::stride] - k[:-1:stride], 1.0)
    pos = sub[sub > 0]
    if pos.size < sub.size // 2:
        return RetimeResult(None, float("nan"), none, "most time steps are not positive"), None
    dt = median(pos)
    w = int(min(max(21, round(window_s / dt) | 1), (n // 2) | 1))
    clock = _Clock(t, k, dt)
    raw = scratch if scratch is not None and scratch.shape == (n - 1,) else None
    events = clock.events(raw)
    # the running median of the offset, near the events only (elsewhere it is the offset itself)
    near = _near(events, w // 2, n) if events.size else none
    level = _medians_near(clock.at, n, near, w) if near.size else np.zeros(0)
    off = clock.at(near)
    # stretches: a lasting step of the smoothed offset by more than one sample
    m = int(np.searchsorted(near, n - 1))                # near[:m] < n - 1
    nxt = near[:m] + 1
    i = np.minimum(np.searchsorted(near, nxt), max(near.size - 1, 0))
    inside = near[i] == nxt if m else np.zeros(0, dtype=bool)
    after = np.where(inside, level[i], 0.0)
    after[~inside] = clock.at(nxt[~inside])
    jump = after - level[:m]
    if np.any(jump < -1.0):
        return RetimeResult(None, 1.0 / dt, none, "more samples than the stamps' time span in a stretch "
                                                  "(the sample count disagrees with a steady rate)"), None
    breaks = near[:m][jump > 1.0] + 1
    outl = near[~(np.abs(off - level) < 0.5)]          # elsewhere off == level: inliers
    bounds = np.concatenate([[0], breaks, [n]])
    n_seg = breaks.size + 1
    seg_out = np.searchsorted(breaks, outl, side="right")
    cnt = np.diff(bounds) - np.bincount(seg_out, minlength=n_seg)
    ok = cnt >= 2
    if int(cnt[ok].sum()) < n // 2:
        return RetimeResult(None, 1.0 / dt, none, f"only {(n - outl.size) / n:.0%} of the stamps lie within half "
                                                  f"a sample of a steady {1 / dt:.6g} Hz clock"), None
    # pooled within-stretch least squares: one rate, one intercept per stretch
    cf = np.where(ok, cnt, 0)
    kbuf, tbuf = np.empty(n), np.empty(n)              # later the clock and the squared shifts
    dk, dtt = kbuf[:cf.sum()], tbuf[:cf.sum()]
    if not ok.all() or outl.size > n >> 6 or k is not None:
        fit = np.ones(n, dtype=bool)
        fit[outl] = False
        for s_ in np.flatnonzero(~ok).tolist():
            fit[bounds[s_]:bounds[s_ + 1]] = False
        np.compress(fit, np.arange(n, dtype=float) if k is None else k, out=dk)
        np.compress(fit, t, out=dtt)
    else:                                                # the runs between outliers, copied whole
        p = 0
        for a, b in zip(*(r.tolist() for r in _kept_runs(n, outl)), strict=True):
            dk[p:p + b - a] = clock.kblock(a, b)
            dtt[p:p + b - a] = t[a:b]
            p += b - a
    if k is None and n < 1 << 26:        # integer sums below 2**53: exact in any order
        a, b = bounds[:-1], bounds[1:]
        ksum = np.where(ok, (a + b - 1) * (b - a) // 2 - np.bincount(seg_out, outl.astype(float), n_seg), 0.0)
    else:
        ksum = np.bincount(np.repeat(np.arange(n_seg), cf), dk, n_seg)
    if n_seg <= 64:                       # each stretch's sum, left to right as bincount adds
        co = np.concatenate([[0], np.cumsum(cf)])
        tsum = np.array([_seq_sum(dtt[co[s_]:co[s_ + 1]]) if cf[s_] else 0.0 for s_ in range(n_seg)])
    else:
        tsum = np.bincount(np.repeat(np.arange(n_seg), cf), dtt, n_seg)
    km = ksum / np.maximum(cf, 1)
    tm = tsum / np.maximum(cf, 1)
    dk -= km[0] if n_seg == 1 else np.repeat(km, cf)   # one stretch: the same value for every sample
    dtt -= tm[0] if n_seg == 1 else np.repeat(tm, cf)
    slope = float(np.dot(dk, dtt) / np.dot(dk, dk))
    del dk, dtt
    if not (slope > 0 and 1.0 <= 1.0 / slope <= 1e5):
        return RetimeResult(None, 1.0 / dt, none, "no steady positive rate"), None
    icpt = tm - slope * km
    for s_ in np.flatnonzero(cf == 0).tolist():  # tiny stretches: their median
        a_, b_ = bounds[s_], bounds[s_ + 1]
        icpt[s_] = float(np.median(t[a_:b_] - slope * clock.kblock(a_, b_)))
    # block by block: the clock (slope k + the stretch's intercept), its steps, its shift from the stamps, and
    # the samples shifted by less than 0.999 dt (the smoothed offset is then within a sample of the clock)
    out, sq = kbuf, tbuf
    steps = np.empty(n - 1) if raw is None else raw
    absd = np.empty(min(n, BLOCK))
    thr = 0.999 * dt
    close, far, top, lowest = 0, [], [], []
    for lo in range(0, n, BLOCK):
        hi = min(lo + BLOCK, n)
        o = np.multiply(clock.kblock(lo, hi), slope, out=out[lo:hi])
        for s_ in range(int(np.searchsorted(bounds, lo, "right")) - 1, int(np.searchsorted(bounds, hi - 1, "right"))):
            o[max(bounds[s_], lo) - lo:min(bounds[s_ + 1], hi) - lo] += icpt[s_]
        st = np.subtract(out[max(lo, 1):hi], out[max(lo - 1, 0):hi - 1], out=steps[max(lo - 1, 0):hi - 1])
        lowest.append(np.fmin.reduce(st, initial=np.inf))
        sh = np.subtract(o, t[lo:hi], out=sq[lo:hi])
        a_ = np.abs(sh, out=absd[:hi - lo])
        top.append(a_.max())
        near_clock = a_ < thr
        c_ = int(np.count_nonzero(near_clock))
        close += c_
        if c_ < hi - lo:
            far.append(np.flatnonzero(~near_clock) + lo)
        np.multiply(sh, sh, out=sh)
    ends = np.concatenate([bounds[:-1], bounds[1:] - 1])          # the clock is monotone within a stretch
    with np.errstate(all="ignore"):
        reach = float(np.max(np.abs(out[ends] - clock.t0))) * clock.r + n + 4
    top_ = float(np.max(top))
    if clock.shortcuts(reach + top_ * clock.r):
        agree = close + (clock.agree(out, np.concatenate(far)) if far else 0)
    else:
        agree = clock.agree(out)
    if near.size:                         # where the offset was smoothed: with the smoothed offset
        dn = out[near] - clock.t0
        dn *= clock.r
        dn -= near if k is None else k[near]
        agree += int(np.count_nonzero(np.abs(dn - level) < 1.0)) - int(np.count_nonzero(np.abs(dn - off) < 1.0))
    share = agree / n
    if share < min_inliers:
        return RetimeResult(None, 1.0 / slope, none, f"the stamps follow the sample clock within a sample "
                                                     f"over only {share:.0%} of the log"), None
    if np.fmin.reduce(lowest) <= 0:       # a step not forward (fmin, as any(steps <= 0), passes NaN by)
        return RetimeResult(None, 1.0 / slope, none, "stretches between dropouts overlap"), None
    stats = _RetimeStats(top_, float(np.sqrt(np.mean(sq))), steps)
    return RetimeResult(out, 1.0 / slope, breaks.astype(np.int64), ""), stats


def _apply_retime(t: np.ndarray, index: np.ndarray | None, report: ValidationReport, scratch: np.ndarray,
                  ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Retime into the report: the new stamps and their steps, or None (then ``drop`` applies)."""
    res, stats = _retime(t, index, 2.0, 0.95, scratch)
    if res.t is None or stats is None:
        report.retime_note = res.note
        return None, None
    report.retimed = True
    report.retime_rate = res.rate
    report.retime_shift_max = stats.shift_max
    report.retime_shift_rms = stats.shift_rms
    report.retime_dropout_index = _rows(res.breaks, index)
    return res.t, stats.steps
