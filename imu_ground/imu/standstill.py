"""Standstill detection and gyro-bias initialisation from the IMU data alone.

A window of the log counts as standstill when, over at least ``window`` seconds,

- every gyro axis has a standard deviation below ``gyro_std_max`` and the mean
  rate is small (``|mean gyro| <= gyro_norm_max``, which rejects steady turns),
- every accelerometer axis has a standard deviation below ``accel_std_max`` and
  the mean specific force has the magnitude of gravity
  (``| |mean accel| - g | <= accel_norm_tol``, which rejects accelerating),
- no timestamp gap longer than ``max_gap`` lies inside.

Standstill intervals are the unions of such windows. At rest the gyro reads its
bias (plus the Earth's rotation, at most 7.3e-5 rad/s, which is absorbed into
the bias) and the accelerometer reads the reaction to gravity: the specific
force points *up*, so gravity points along ``-mean(accel)`` in the body frame.

A vehicle cruising straight at constant speed on a smooth road looks like
standstill to an IMU; the bias estimate is still sound there (the true rate is
close to zero), the thresholds decide how strict to be. The defaults suit an
automotive-grade IMU (the OXTS of the KITTI drives, where every detected interval
is a real stop); noisier sensors (phones) need looser limits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imu_ground._native import STANDSTILL as _NATIVE
from imu_ground.imu.data import ImuData

__all__ = ["GyroBiasEstimate", "WindowSums", "detect_standstill", "estimate_gyro_bias"]


@dataclass
class GyroBiasEstimate:
    """Result of :func:`estimate_gyro_bias`.

    Attributes
    ----------
    bias : ndarray, shape (3,)
        Gyro bias, rad/s, body frame: the mean rate over all standstill samples
        (zeros when none was found).
    bias_std : ndarray, shape (3,)
        Standard error of ``bias`` from the sample scatter, rad/s (inf when none).
    intervals : ndarray, shape (K, 2)
        Standstill intervals ``[start, end]``, s.
    gravity_body : ndarray, shape (3,)
        Unit vector of gravity (pointing down) in the body frame during the first
        standstill interval (nan when none).
    gravity_body_per_interval : ndarray, shape (K, 3)
        The same for every interval (the vehicle may stop on different slopes).
    accel_mean : ndarray, shape (K, 3)
        Mean specific force of each interval, m/s^2, body frame.
    n_samples : int
        Number of samples averaged for ``bias``.
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
        """True when at least one standstill interval was detected."""
        return self.intervals.shape[0] > 0


#: Samples per block of the window statistics (bounded, cache-sized temporaries on long logs).
_BLOCK = 1 << 15


class WindowSums:
    """Cumulative sums of a log's centred gyro and specific force and of their squares.

    What :func:`detect_standstill` and :func:`estimate_gyro_bias` derive every
    window's mean and standard deviation from; they do not depend on the window
    length, so one instance serves several calls on the same log (pass it as
    ``sums``). Component-major, so that every operation runs along contiguous rows.

    Parameters
    ----------
    imu : ImuData
        The log (gyro rad/s, specific force m/s^2, body frame).

    Attributes
    ----------
    mean : ndarray, shape (6, 1)
        Mean gyro (rad/s) then specific force (m/s^2) over the log.
    gyro, accel : ndarray, shape (N, 3)
        The log's gyro and specific force (C-contiguous; the log's own arrays where they are).
    c1, c2 : ndarray, shape (6, N + 1)
        ``c1[:, k]`` sum of the first ``k`` centred samples, ``c2[:, k]`` of their squares.
        Where the compiled kernel runs, computed on first use only: the kernel's
        window tests carry the same running sums at each window's start and end
        instead (equal values, without the arrays' memory).
    """

    def __init__(self, imu: ImuData) -> None:
        n = len(imu)
        self.n = n
        self.mean = np.concatenate([imu.gyro.mean(axis=0), imu.accel.mean(axis=0)])[:, None]
        self.gyro = np.ascontiguousarray(imu.gyro, dtype=float)
        self.accel = np.ascontiguousarray(imu.accel, dtype=float)
        self._c: tuple[np.ndarray, np.ndarray] | None = None
        if _NATIVE is None:
            self._c = self._sums()

    @property
    def c1(self) -> np.ndarray:
        """Cumulative sums of the centred samples, (6, N + 1)."""
        if self._c is None:
            self._c = self._sums()
        return self._c[0]

    @property
    def c2(self) -> np.ndarray:
        """Cumulative sums of the squared centred samples, (6, N + 1)."""
        if self._c is None:
            self._c = self._sums()
        return self._c[1]

    def _sums(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n
        c1 = np.empty((6, n + 1))
        c2 = np.empty((6, n + 1))
        if _NATIVE is not None and n:     # the compiled twin: the same additions in the same order
            _NATIVE.window_sums(self.gyro, self.accel, np.ascontiguousarray(self.mean[:, 0]), c1, c2)
            return c1, c2
        c1[:, 0] = 0.0
        c2[:, 0] = 0.0
        # block by block: each block's running sums start from the previous block's last one, so every
        # entry is the same sequence of additions as one cumulative sum over the whole log
        buf = np.empty((6, min(_BLOCK, n) + 1))
        for a in range(0, n, _BLOCK):
            b = min(a + _BLOCK, n)
            x = buf[:, :b - a + 1]
            np.subtract(self.gyro[a:b].T, self.mean[:3], out=x[:3, 1:])
            np.subtract(self.accel[a:b].T, self.mean[3:], out=x[3:, 1:])
            x[:, 0] = c1[:, a]
            np.cumsum(x, axis=1, out=c1[:, a:b + 1])
            np.multiply(x[:, 1:], x[:, 1:], out=x[:, 1:])
            x[:, 0] = c2[:, a]
            np.cumsum(x, axis=1, out=c2[:, a:b + 1])
        return c1, c2

    def stats(self, start: np.ndarray, end: np.ndarray, rows: slice = slice(0, 6)) -> tuple[np.ndarray, np.ndarray]:
        """Mean and standard deviation over samples ``[start[j], end[j])`` of the components ``rows``.

        Returns two arrays (k, J): rows of :attr:`mean`'s order (gyro rad/s, then
        specific force m/s^2), one column per window.
        """
        n = np.maximum((end - start).astype(float), 1.0)
        c1, c2 = self.c1[rows], self.c2[rows]
        m = (c1[:, end] - c1[:, start]) / n
        var = np.maximum((c2[:, end] - c2[:, start]) / n - m * m, 0.0)
        return m + self.mean[rows], np.sqrt(var)


def _norm3(x: np.ndarray) -> np.ndarray:
    """Euclidean norm of the columns of a (3, N) array (as ``np.linalg.norm`` of its rows: same sum order)."""
    return np.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])


def _quiet_windows(sums: WindowSums, end: np.ndarray, usable: np.ndarray, gyro_std_max: float,
                   gyro_norm_max: float, accel_std_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Windows passing the rate and variance tests, and the mean specific-force norm (m/s^2) of those.

    The specific force's statistics are computed only for the windows whose
    rate passes (the norm is NaN elsewhere; only quiet windows use it).
    """
    n = end.size
    quiet = np.zeros(n, dtype=bool)
    norm = np.full(n, np.nan)
    for lo in range(0, n, _BLOCK):
        hi = min(lo + _BLOCK, n)
        i, e = np.arange(lo, hi), end[lo:hi]
        gm, gs = sums.stats(i, e, slice(0, 3))
        k = np.flatnonzero(usable[lo:hi] & (_norm3(gm) <= gyro_norm_max) & np.all(gs <= gyro_std_max, axis=0))
        am, as_ = sums.stats(i[k], e[k], slice(3, 6))
        quiet[lo + k] = np.all(as_ <= accel_std_max, axis=0)
        norm[lo + k] = _norm3(am)
    return quiet, norm


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
    # window of sample i: samples i .. end[i]-1 with t < t[i] + window, plus the
    # first sample at or after t[i] + window so that it spans >= window seconds
    native = _NATIVE is not None and math.isfinite(window) and window >= 0
    if native:                          # the compiled twin: the same windows, sums and tests in one pass
        assert _NATIVE is not None
        quiet, norm, end = np.empty(n, dtype=bool), np.empty(n), np.empty(n, dtype=np.int64)
        _NATIVE.quiet_windows(np.ascontiguousarray(t), sums.gyro, sums.accel, np.ascontiguousarray(sums.mean[:, 0]),
                              float(window), float(max_gap), float(gyro_std_max), float(gyro_norm_max),
                              float(accel_std_max), quiet, norm, end)
    else:
        last = np.searchsorted(t, t + window, side="left")     # first index with t >= t_i + window
        ok = last < n
        end = np.minimum(last + 1, n)
        gaps = np.concatenate([[0], np.cumsum(np.diff(t) > max_gap)])
        no_gap = gaps[end - 1] == gaps
        quiet, norm = _quiet_windows(sums, end, ok & no_gap, gyro_std_max, gyro_norm_max, accel_std_max)
    if gravity is None:
        # the log's own |f| at rest: an accelerometer bias or scale error moves it
        # away from 9.81 (0.2 m/s^2 is common for MEMS) and must not hide the stops
        if not quiet.any():
            return np.zeros(n, dtype=bool)
        gravity = float(np.median(norm[quiet]))
    good = quiet & (np.abs(norm - gravity) <= accel_norm_tol)
    if native:
        assert _NATIVE is not None
        mask = np.empty(n, dtype=bool)
        _NATIVE.window_union(good, end, mask)
        return mask
    # union of the good windows [i, end[i]) : difference array
    gi = np.flatnonzero(good)
    d = np.bincount(gi, minlength=n + 1) - np.bincount(end[gi], minlength=n + 1)
    return np.cumsum(d[:-1]) > 0


def _runs(mask: np.ndarray) -> np.ndarray:
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    dm = np.diff(m)
    return np.stack([np.flatnonzero(dm == 1), np.flatnonzero(dm == -1)], axis=1)   # [start, stop)


def detect_standstill(imu: ImuData, *, window: float = 2.0, gyro_std_max: float = 0.004,
                      gyro_norm_max: float = 0.05, accel_std_max: float = 0.04,
                      accel_norm_tol: float = 0.15, gravity: float | None = None,
                      max_gap: float = 0.1, sums: WindowSums | None = None) -> np.ndarray:
    """Standstill intervals of a log (vectorised, no loop over samples).

    Parameters
    ----------
    imu : ImuData
        Strictly increasing times (s), gyro (rad/s) and specific force (m/s^2),
        body frame.
    window : float
        Shortest standstill, s.
    gyro_std_max : float
        Largest per-axis gyro standard deviation over a window, rad/s.
    gyro_norm_max : float
        Largest norm of the window's mean rate, rad/s (must exceed the bias).
    accel_std_max : float
        Largest per-axis accelerometer standard deviation, m/s^2.
    accel_norm_tol : float
        Largest difference between the mean specific force's norm and ``gravity``, m/s^2.
    gravity : float, optional
        Magnitude of the specific force at rest, m/s^2. Default: measured from
        the log (median over the windows that pass the rate and variance
        tests), so that an accelerometer bias or scale error does not hide
        the stops; ``accel_norm_tol`` then rejects windows of steady
        acceleration.
    max_gap : float
        Windows containing a longer timestamp step are rejected, s.
    sums : WindowSums, optional
        This log's :class:`WindowSums`, to share between calls (computed when None).

    Returns
    -------
    ndarray, shape (K, 2)
        ``[start, end]`` times of the standstill intervals, s.
    """
    mask = _standstill_mask(imu, window, gyro_std_max, gyro_norm_max, accel_std_max,
                            accel_norm_tol, gravity, max_gap, sums)
    r = _runs(mask)
    t = np.asarray(imu.t, dtype=float)
    return np.stack([t[r[:, 0]], t[r[:, 1] - 1]], axis=1) if r.size else np.zeros((0, 2))


def estimate_gyro_bias(imu: ImuData, *, window: float = 2.0, gyro_std_max: float = 0.004,
                       gyro_norm_max: float = 0.05, accel_std_max: float = 0.04,
                       accel_norm_tol: float = 0.15, gravity: float | None = None,
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
    r = _runs(mask)
    t = np.asarray(imu.t, dtype=float)
    k = r.shape[0]
    if k == 0:
        nan3 = np.full(3, np.nan)
        return GyroBiasEstimate(np.zeros(3), np.full(3, np.inf), np.zeros((0, 2)), nan3,
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
    intervals = np.stack([t[r[:, 0]], t[r[:, 1] - 1]], axis=1)
    return GyroBiasEstimate(bias, bias_std, intervals, grav[0].copy(), grav, accel_mean, int(g.shape[0]))
