"""Standstill detection and gyro-bias initialisation from the IMU data alone.

A window of the log counts as standstill when, over at least ``window`` seconds,

- every gyro axis has a standard deviation below ``gyro_std_max`` and the mean
  rate is small (``|mean gyro| <= gyro_norm_max``, which rejects steady turns),
- every accelerometer axis has a standard deviation below ``accel_std_max`` and
  the mean specific force has the magnitude of gravity
  (``| |mean accel| - g | <= accel_norm_tol``, which rejects accelerating),
- no timestamp gap longer than ``max_gap`` lies inside.

Standstill intervals are the unions of such windows. At rest the gyro reads its bias (the Earth's rotation
absorbed into it) and the specific force points *up*: gravity is along ``-mean(accel)`` in the body frame.
Cruising straight on a smooth road looks like standstill too (the bias estimate is still sound there). The
defaults suit an automotive-grade IMU; noisier sensors (phones) need looser limits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imu_ground._jit import njit
from imu_ground.imu.data import ImuData

__all__ = ["ACCEL_NORM_TOL", "ACCEL_STD_MAX", "GYRO_NORM_MAX", "GYRO_STD_MAX", "WINDOW", "GyroBiasEstimate",
           "WindowSums", "detect_standstill", "estimate_gyro_bias", "window_test"]

#: The default thresholds of a standstill window (also the causal detector's): rad/s, rad/s, m/s^2, m/s^2.
GYRO_STD_MAX, GYRO_NORM_MAX, ACCEL_STD_MAX, ACCEL_NORM_TOL = 0.004, 0.05, 0.04, 0.15
#: Shortest standstill, s: the whole-log detector's window and the causal gyro bias's.
WINDOW = 2.0


@njit
def window_test(n: float, s: np.ndarray, q: np.ndarray, mean: np.ndarray, m: np.ndarray, sd: np.ndarray,
                gyro_std_max: float, gyro_norm_max: float, accel_std_max: float) -> float:
    """The still test of one window (module docstring): its mean specific force's norm (m/s^2) when it passes the
    rate and variance tests, else NaN (the caller tests ``|norm - gravity| <= accel_norm_tol``).

    ``n`` samples with sums ``s`` (6: gyro rad/s, specific force m/s^2) of the samples less ``mean``, ``q`` of
    their squares; the window's mean and standard deviation go into ``m`` and ``sd``.
    """
    for r in range(6):
        mm = s[r] / n
        vv = q[r] / n - mm * mm
        if vv < 0.0:
            vv = 0.0
        m[r] = mm + mean[r]
        sd[r] = math.sqrt(vv)
    if not (math.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]) <= gyro_norm_max
            and sd[0] <= gyro_std_max and sd[1] <= gyro_std_max and sd[2] <= gyro_std_max
            and sd[3] <= accel_std_max and sd[4] <= accel_std_max and sd[5] <= accel_std_max):
        return math.nan
    return math.sqrt(m[3] * m[3] + m[4] * m[4] + m[5] * m[5])


@dataclass
class GyroBiasEstimate:
    """Result of :func:`estimate_gyro_bias`.

    Attributes
    ----------
    bias, bias_std : ndarray, shape (3,)
        Gyro bias (the mean rate over all standstill samples; zeros when none) and its standard error (inf when
        none), rad/s, body frame.
    intervals : ndarray, shape (K, 2)
        Standstill intervals ``[start, end]``, s.
    gravity_body : ndarray, shape (3,)
        Unit vector of gravity (down) in the body frame during the first interval (nan when none).
    gravity_body_per_interval : ndarray, shape (K, 3)
        The same for every interval.
    accel_mean : ndarray, shape (K, 3)
        Mean specific force of each interval, m/s^2, body frame.
    n_samples : int
        Samples averaged for ``bias``.
    """

    bias: np.ndarray
    bias_std: np.ndarray
    intervals: np.ndarray
    gravity_body: np.ndarray
    gravity_body_per_interval: np.ndarray
    accel_mean: np.ndarray
    n_samples: int

    @property
    def found(self) -> bool:
        """At least one standstill interval was detected."""
        return self.intervals.shape[0] > 0


@njit
def _advance(s1: np.ndarray, s2: np.ndarray, at: int, to: int, gyro: np.ndarray, accel: np.ndarray,
             mean: np.ndarray) -> int:
    """Running sums ``s1``, ``s2`` (6) of the centred samples and their squares from sample ``at`` to ``to``."""
    while at < to:
        for r in range(6):
            d = (gyro[at, r] if r < 3 else accel[at, r - 3]) - mean[r]
            s1[r] = s1[r] + d
            s2[r] = s2[r] + d * d
        at += 1
    return at


class WindowSums:
    """Cumulative sums of a log's centred gyro and specific force and of their squares, shared by several
    calls of :func:`detect_standstill` and :func:`estimate_gyro_bias` on the same log (``sums``).

    Parameters
    ----------
    imu : ImuData

    Attributes
    ----------
    mean : ndarray, shape (6, 1)
        Mean gyro (rad/s) then specific force (m/s^2) over the log.
    gyro, accel : ndarray, shape (N, 3)
        The log's gyro and specific force (C-contiguous).
    c1, c2 : ndarray, shape (6, N + 1)
        ``c1[:, k]`` sum of the first ``k`` centred samples, ``c2[:, k]`` of their squares (on first use).
    """

    def __init__(self, imu: ImuData) -> None:
        n = len(imu)
        self.n = n
        self.mean = np.concatenate([imu.gyro.mean(axis=0), imu.accel.mean(axis=0)])[:, None]
        self.gyro = np.ascontiguousarray(imu.gyro, dtype=float)
        self.accel = np.ascontiguousarray(imu.accel, dtype=float)
        self._c: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def c1(self) -> np.ndarray:
        """Cumulative sums of the centred samples, (6, N + 1)."""
        return self._sums()[0]

    @property
    def c2(self) -> np.ndarray:
        """Cumulative sums of the squared centred samples, (6, N + 1)."""
        return self._sums()[1]

    def _sums(self) -> tuple[np.ndarray, np.ndarray]:
        if self._c is None:                     # running sums, left to right: _advance's additions
            d = np.concatenate([self.gyro, self.accel], axis=1).T - self.mean
            c1, c2 = np.zeros((6, self.n + 1)), np.zeros((6, self.n + 1))
            np.cumsum(d, axis=1, out=c1[:, 1:])
            np.cumsum(d * d, axis=1, out=c2[:, 1:])
            self._c = c1, c2
        return self._c

    def stats(self, start: np.ndarray, end: np.ndarray, rows: slice = slice(0, 6)) -> tuple[np.ndarray, np.ndarray]:
        """Mean and standard deviation (k, J) over samples ``[start[j], end[j])`` of the components ``rows``."""
        n = np.maximum((end - start).astype(float), 1.0)
        c1, c2 = self.c1[rows], self.c2[rows]
        m = (c1[:, end] - c1[:, start]) / n
        var = np.maximum((c2[:, end] - c2[:, start]) / n - m * m, 0.0)
        return m + self.mean[rows], np.sqrt(var)


@njit
def _quiet_windows(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, mean: np.ndarray, window: float,
                   max_gap: float, gyro_std_max: float, gyro_norm_max: float, accel_std_max: float,
                   norm: np.ndarray, end: np.ndarray) -> None:
    """Every sample's window end and :func:`window_test` of its window (NaN: not quiet), in one forward pass.

    The window of sample ``i``: samples with ``t < t[i] + window`` plus the first at or after it; one past the
    log's end or holding a step longer than ``max_gap`` is not quiet.
    """
    n = t.size
    lo1, lo2, hi1, hi2 = np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(6)
    lo_at = 0
    hi_at = 0
    m, sd, s, q = np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    last = 0                            # first index with t >= t[i] + window
    gap = -1                            # first step j >= i longer than max_gap (n - 1: none)
    for i in range(n):
        until = t[i] + window
        if last < i:
            last = i
        while last < n and t[last] < until:
            last += 1
        e = last + 1 if last + 1 < n else n
        end[i] = e
        norm[i] = np.nan
        if gap < i:
            gap = i
            while gap < n - 1 and not t[gap + 1] - t[gap] > max_gap:
                gap += 1
        if not last < n or gap < e - 1:         # past the log's end, or a gap inside
            continue
        lo_at = _advance(lo1, lo2, lo_at, i, gyro, accel, mean)
        hi_at = _advance(hi1, hi2, hi_at, e, gyro, accel, mean)
        cnt = float(hi_at - lo_at)              # >= 1: e = last + 1 > i here
        for r in range(6):
            s[r] = hi1[r] - lo1[r]
            q[r] = hi2[r] - lo2[r]
        norm[i] = window_test(cnt, s, q, mean, m, sd, gyro_std_max, gyro_norm_max, accel_std_max)


@njit
def _window_union(good: np.ndarray, end: np.ndarray, mask: np.ndarray) -> None:
    """``mask`` = the union of the windows ``[i, end[i])`` of the good samples (ends never decrease)."""
    cover = 0                           # samples before this one are covered by a good window
    for i in range(good.size):
        if good[i] and end[i] > cover:
            cover = end[i]
        mask[i] = cover > i


def _standstill_mask(imu: ImuData, window: float, gyro_std_max: float, gyro_norm_max: float,
                     accel_std_max: float, accel_norm_tol: float, gravity: float | None,
                     max_gap: float, sums: WindowSums | None = None) -> np.ndarray:
    t = np.asarray(imu.t, dtype=float)
    n = t.size
    if n < 2:
        return np.zeros(n, dtype=bool)
    if np.any(np.diff(t) <= 0):
        raise ValueError("IMU timestamps must be strictly increasing (drop non-increasing samples first)")
    if sums is None:
        sums = WindowSums(imu)
    elif sums.n != n:
        raise ValueError(f"sums were computed for a log of {sums.n} samples, this one has {n}")
    if not window >= 0.0:
        raise ValueError(f"the standstill window must be >= 0 s, got {window!r}")
    norm, end = np.empty(n), np.empty(n, dtype=np.int64)
    _quiet_windows(np.ascontiguousarray(t), sums.gyro, sums.accel, np.ascontiguousarray(sums.mean[:, 0]),
                   float(window), float(max_gap), float(gyro_std_max), float(gyro_norm_max), float(accel_std_max),
                   norm, end)
    quiet = ~np.isnan(norm)
    if gravity is None:
        # the log's own |f| at rest
        if not quiet.any():
            return np.zeros(n, dtype=bool)
        gravity = float(np.median(norm[quiet]))
    good = quiet & (np.abs(norm - gravity) <= accel_norm_tol)
    mask = np.empty(n, dtype=bool)
    _window_union(good, end, mask)
    return mask


def _intervals(t: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``[start, end]`` times (s) of the runs of ``mask``, (K, 2)."""
    dm = np.diff(np.concatenate([[False], mask, [False]]).astype(np.int8))
    start, stop = np.flatnonzero(dm == 1), np.flatnonzero(dm == -1)
    return np.stack([t[start], t[stop - 1]], axis=1) if start.size else np.zeros((0, 2))


def detect_standstill(imu: ImuData, *, window: float = WINDOW, gyro_std_max: float = GYRO_STD_MAX,
                      gyro_norm_max: float = GYRO_NORM_MAX, accel_std_max: float = ACCEL_STD_MAX,
                      accel_norm_tol: float = ACCEL_NORM_TOL, gravity: float | None = None,
                      max_gap: float = 0.1, sums: WindowSums | None = None) -> np.ndarray:
    """Standstill intervals of a log (one compiled pass over the samples).

    Parameters
    ----------
    imu : ImuData
        Strictly increasing times (s), gyro (rad/s) and specific force (m/s^2), body frame.
    window : float
        Shortest standstill, s.
    gyro_std_max, gyro_norm_max : float
        Largest per-axis gyro standard deviation over a window, and norm of its mean rate, rad/s.
    accel_std_max, accel_norm_tol : float
        Largest per-axis accelerometer standard deviation, and difference of the mean's norm from ``gravity``,
        m/s^2.
    gravity : float, optional
        Magnitude of the specific force at rest, m/s^2. Default: the log's own (median over the windows that pass
        the other tests), so that an accelerometer bias or scale error does not hide the stops.
    max_gap : float
        Windows containing a longer timestamp step are rejected, s.
    sums : WindowSums, optional
        This log's :class:`WindowSums`, shared between calls.

    Returns
    -------
    ndarray, shape (K, 2)
        ``[start, end]`` times of the standstill intervals, s.
    """
    mask = _standstill_mask(imu, window, gyro_std_max, gyro_norm_max, accel_std_max,
                            accel_norm_tol, gravity, max_gap, sums)
    return _intervals(np.asarray(imu.t, dtype=float), mask)


def estimate_gyro_bias(imu: ImuData, *, window: float = WINDOW, gyro_std_max: float = GYRO_STD_MAX,
                       gyro_norm_max: float = GYRO_NORM_MAX, accel_std_max: float = ACCEL_STD_MAX,
                       accel_norm_tol: float = ACCEL_NORM_TOL, gravity: float | None = None,
                       max_gap: float = 0.1, sums: WindowSums | None = None) -> GyroBiasEstimate:
    """Gyro bias and gravity direction from the standstill periods of a log.

    Parameters
    ----------
    imu : ImuData
        Strictly increasing times (s), gyro (rad/s), specific force (m/s^2), body frame.
    window, gyro_std_max, gyro_norm_max, accel_std_max, accel_norm_tol, gravity, max_gap, sums :
        Standstill criteria and shared sums, see :func:`detect_standstill`.

    Returns
    -------
    GyroBiasEstimate
        ``bias`` (rad/s, body frame; zeros and ``found == False`` if the log has no
        standstill), the intervals, and gravity's direction in the body frame at rest.
    """
    mask = _standstill_mask(imu, window, gyro_std_max, gyro_norm_max, accel_std_max,
                            accel_norm_tol, gravity, max_gap, sums)
    intervals = _intervals(np.asarray(imu.t, dtype=float), mask)
    k = intervals.shape[0]
    if k == 0:
        return GyroBiasEstimate(np.zeros(3), np.full(3, np.inf), np.zeros((0, 2)), np.full(3, np.nan),
                                np.zeros((0, 3)), np.zeros((0, 3)), 0)
    g = imu.gyro[mask]
    bias = g.mean(axis=0)
    bias_std = g.std(axis=0, ddof=1) / np.sqrt(g.shape[0]) if g.shape[0] > 1 else np.full(3, np.inf)
    seg = np.cumsum(np.concatenate([[0], np.diff(mask.astype(np.int8)) == 1]))[mask]
    seg -= seg.min()
    counts = np.bincount(seg, minlength=k).astype(float)
    accel_mean = np.stack([np.bincount(seg, weights=imu.accel[mask, j], minlength=k)
                           for j in range(3)], axis=1) / counts[:, None]
    grav = -accel_mean / np.linalg.norm(accel_mean, axis=1, keepdims=True)
    return GyroBiasEstimate(bias, bias_std, intervals, grav[0].copy(), grav, accel_mean, int(g.shape[0]))
