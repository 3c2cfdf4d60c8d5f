"""Order statistics of whole logs: the exact median without a full partition, running medians near events.

:func:`median` gives the value ``np.median`` gives (the checks and the
validation take medians of whole logs); :func:`_medians_near` the centred
running medians the retiming needs near the clock's jumps only
(:mod:`~imu_ground.datasets.retime`).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["BLOCK", "median"]

#: Values per block of a pass over a whole log (a few such blocks stay in the CPU cache).
BLOCK = 1 << 15
#: Consecutive windows sharing one partition in :func:`_window_medians`.
_GROUP = 12


def median(x: np.ndarray, sqrt: bool = False) -> float:
    """``float(np.median(x))`` of a 1-D float64 array, found without partitioning all of it.

    The same order statistic(s) (the mean of the middle two for an even count)
    as NumPy's median, so the same value: a random sample brackets the middle
    ranks between two sample values, one pass counts the values below and
    gathers those between, and only these are sorted. NumPy's partition is
    slow on some data (many repeated values, or the extra maximum it
    partitions out for its NaN check). Falls back to ``np.median`` for short
    arrays, a NaN or when the bracket misses (a rare sample).

    ``sqrt=True``: the median of ``np.sqrt(x)`` (``x >= 0``, e.g. squared
    norms), from the square roots of the middle values of ``x`` (a monotone
    map keeps the order, so these are the middle values of ``np.sqrt(x)``).
    """
    x = np.asarray(x)
    n = x.size
    if x.ndim != 1 or x.dtype != np.float64 or n < 1 << 16:
        return float(np.median(np.sqrt(x) if sqrt else x))
    h = n // 2
    r0 = h if n % 2 else h - 1                           # the middle rank(s): r0 and h
    smp = np.sort(x[np.random.default_rng(0).integers(0, n, 1 << 14)])
    if np.isnan(smp[-1]):
        return float(np.median(np.sqrt(x) if sqrt else x))
    lo = smp[max(int(r0 / n * smp.size) - 400, 0)]       # ~6 standard deviations of a sample rank
    hi = smp[min(int(h / n * smp.size) + 400, smp.size - 1)]
    n_ge = n_le = n_mid = 0
    mids: list[np.ndarray] | None = [] if lo < hi else None  # lo == hi: no values to sort, only counts
    for i in range(0, n, BLOCK):
        c = x[i:i + BLOCK]
        ge, le = c >= lo, c <= hi
        n_ge += int(np.count_nonzero(ge))
        n_le += int(np.count_nonzero(le))
        if mids is not None:
            mids.append(c[np.logical_and(ge, le, out=ge)])
            n_mid += mids[-1].size
            if n_mid > n >> 3:           # a wide band (many repeats around the middle): not worth it
                return float(np.median(np.sqrt(x) if sqrt else x))
        else:
            n_mid += int(np.count_nonzero(np.logical_and(ge, le, out=ge)))
    below = n_le - n_mid                                 # values < lo (values > hi: n_ge - n_mid)
    if n_ge + below != n or not below <= r0 <= h < n_le:  # a NaN, or the middle not bracketed
        return float(np.median(np.sqrt(x) if sqrt else x))
    if mids is None:
        pair = np.array([lo, lo])
    else:
        mid = np.concatenate(mids)
        mid.sort()
        pair = mid[[r0 - below, h - below]]
    if sqrt:
        pair = np.sqrt(pair)
    return float(pair[1]) if n % 2 else float(np.mean(pair))


def _near(events: np.ndarray, h: int, n: int) -> np.ndarray:
    """The positions within ``[e - h - 1, e + h + 2)`` of an event ``e``: the union of these (sorted) ranges."""
    starts = np.clip(events - h - 1, 0, n)
    stops = np.clip(events + h + 2, 0, n)
    new = np.concatenate([[True], starts[1:] > stops[:-1]])      # a range not overlapping the one before
    lo = starts[new]
    hi = np.maximum.reduceat(stops, np.flatnonzero(new))
    lens = hi - lo
    return np.repeat(lo - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens) + np.arange(int(lens.sum()))


def _window_medians(xs: np.ndarray, q: np.ndarray, w: int) -> np.ndarray:
    """Medians of ``xs[p:p + w]`` (``w`` odd) for the window starts ``q`` (increasing).

    Consecutive starts share a partition: for ``S`` windows ``q0 .. q0+S-1`` the
    ``w - S + 1`` samples common to all (the core ``C``) hold the median of each
    window between their ranks ``h+1-S`` and ``h`` (0-based, ``h = w // 2``): the
    window adds only ``S - 1`` samples ``E`` to ``C``. Clamping every value to
    that band (a monotone map, which commutes with order statistics) shows the
    window's median is the ``S``-th smallest of ``band + E``, ``2S - 1``
    values. The result is the same order statistic ``np.median`` returns.
    """
    h = w // 2
    out = np.empty(q.size)
    if not q.size:
        return out
    brk = np.flatnonzero(np.diff(q) != 1) + 1
    run_lo = q[np.concatenate([[0], brk])]
    run_len = np.diff(np.concatenate([[0], brk, [q.size]]))
    s = min(_GROUP, h + 1, int(run_len.min()))
    if s < 2 or np.isnan(xs).any():             # short runs (or NaN, which np.median returns): window by window
        win = np.lib.stride_tricks.sliding_window_view(xs, w)
        for i in range(0, q.size, 4096):        # cache-sized batches, whatever the log's length
            out[i:i + 4096] = np.median(win[q[i:i + 4096]], axis=1, overwrite_input=True)
        return out
    ng = -(-run_len // s)                       # groups of s windows per run, the last one ending the run
    first = np.repeat(np.cumsum(ng) - ng, ng)
    g0 = np.minimum(np.repeat(run_lo, ng) + s * (np.arange(int(ng.sum())) - first),
                    np.repeat(run_lo + run_len - s, ng))
    view = np.lib.stride_tricks.sliding_window_view
    core = view(xs, w - s + 1)[g0 + s - 1]      # a gathered copy, (G, w - s + 1)
    core.partition(h, axis=1)                   # (one rank at a time: much faster than two at once)
    band = core[:, :h + 1]
    band.partition(h + 1 - s, axis=1)
    band = band[:, h + 1 - s:]                  # ranks h+1-s .. h of the core, any order
    pool = np.concatenate([view(xs, s - 1)[g0], view(xs, s - 1)[g0 + w]], axis=1)  # E of window i: pool[i:i+s-1]
    z = np.concatenate([np.broadcast_to(band[:, None, :], (g0.size, s, s)),
                        view(pool, s - 1, axis=1)[:, :s]], axis=2)
    z.partition(s - 1, axis=2)
    out[np.searchsorted(q, (g0[:, None] + np.arange(s)).ravel())] = z[:, :, s - 1].ravel()
    return out


def _medians_near(values: Callable[[np.ndarray], np.ndarray], n: int, near: np.ndarray, w: int) -> np.ndarray:
    """Centred running medians over ``w`` samples at positions ``near`` (edges padded with the end values).

    ``values(idx)`` gives the series at positions ``idx``; only the samples
    within ``w // 2`` of a position in ``near`` are asked for.
    """
    h = w // 2
    brk = np.flatnonzero(np.diff(near) != 1) + 1
    lo = near[np.concatenate([[0], brk])]
    length = np.diff(np.concatenate([[0], brk, [near.size]]))
    piece = length + 2 * h                      # each run of positions with its windows' margins
    offset = np.concatenate([[0], np.cumsum(piece)[:-1]])
    idx = np.repeat(lo - h - offset, piece) + np.arange(int(piece.sum()))
    xs = values(np.clip(idx, 0, n - 1))         # clipping pads the ends with the end values
    return _window_medians(xs, near + np.repeat(offset - lo, length), w)


def _running_median(x: np.ndarray, w: int, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centred running median over ``w`` (odd) samples (edges padded with the end values), and where it differs.

    Evaluated only within ``w // 2`` samples of an ``events`` position (a step
    that is not one sample period); elsewhere the window holds one undisturbed
    stretch and the value is taken as it is, so the cost follows the events,
    not the log's length. Returns the medians and the positions evaluated.
    """
    out = x.copy()
    if not events.size:
        return out, events
    near = _near(events, w // 2, x.size)
    out[near] = _medians_near(x.__getitem__, x.size, near, w)
    return out, near
