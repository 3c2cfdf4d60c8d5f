"""Order statistics of whole logs: the exact median without a full partition, running medians near events."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["BLOCK", "median"]

#: Values per block of a pass over a whole log (a few such blocks stay in the CPU cache).
BLOCK = 1 << 15


def median(x: np.ndarray, sqrt: bool = False) -> float:
    """``float(np.median(x))`` of a 1-D float64 array (``np.sqrt(x)``'s with ``sqrt``, ``x >= 0``), exactly.

    A random sample brackets the middle ranks; one pass counts the values below and gathers those
    between, and only these are sorted (NumPy's partition is slow on repeated values). Falls back to
    ``np.median`` for short arrays, a NaN or a missed bracket.
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


def _medians_near(values: Callable[[np.ndarray], np.ndarray], n: int, near: np.ndarray, w: int) -> np.ndarray:
    """Centred running medians over ``w`` (odd) samples of ``values(idx)`` at positions ``near`` (ends padded)."""
    h = w // 2
    brk = np.flatnonzero(np.diff(near) != 1) + 1
    lo = near[np.concatenate([[0], brk])]
    length = np.diff(np.concatenate([[0], brk, [near.size]]))
    piece = length + 2 * h                      # each run of positions with its windows' margins
    offset = np.concatenate([[0], np.cumsum(piece)[:-1]])
    idx = np.repeat(lo - h - offset, piece) + np.arange(int(piece.sum()))
    xs = values(np.clip(idx, 0, n - 1))         # clipping pads the ends with the end values
    at = near + np.repeat(offset - lo, length)  # each window's first value in xs
    import pandas as pd                         # (imported by the readers already)
    return pd.Series(xs).rolling(w).median().to_numpy()[at + w - 1]     # (each window's last value)


def _running_median(x: np.ndarray, w: int, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centred running median over ``w`` (odd) samples, evaluated near ``events`` only; the medians and where."""
    out = x.copy()
    if not events.size:
        return out, events
    near = _near(events, w // 2, x.size)
    out[near] = _medians_near(x.__getitem__, x.size, near, w)
    return out, near
