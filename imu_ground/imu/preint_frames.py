"""Frame boundaries and the batch result: which samples a frame covers, and what it holds.

:func:`make_frame_times` turns a frame rate or a sample count into boundary times;
:class:`FrameDeltas` holds the preintegrated deltas, covariance and bias
Jacobians of consecutive frames (the output of
:func:`~imu_ground.imu.preint_batch.preintegrate`). Frames: ``delta_R`` is
``R_{start<-end}`` (glossary in :mod:`imu_ground.so3`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from imu_ground import so3
from imu_ground.imu.preint_measurement import PreintegratedImu, right_to_left
from imu_ground.imu.preint_params import ParamsView, PreintegrationParams
from imu_ground.so3.component_major import project_if_needed

__all__ = ["FrameDeltas", "first_rate_boundary", "make_frame_times", "segment_frame_times"]


def first_rate_boundary(t_first: float, rate: float, origin: float, snap_tol: float) -> int:
    """Index of the first boundary ``origin + k / rate`` (k >= 0) at or after ``t_first - snap_tol``.

    The batch (:func:`make_frame_times`) and the streaming front-end both start
    their frames here, so that they cut a log into the same frames.
    """
    k = max(0, math.ceil((t_first - snap_tol - origin) * rate) - 1)
    while origin + k / rate < t_first - snap_tol:
        k += 1
    return k


def make_frame_times(t: np.ndarray, *, rate: float | None = None, every: int | None = None,
                     t_origin: float | None = None, snap_tol: float = 1e-9) -> np.ndarray:
    """Frame boundary times for a log: a frame rate or every N samples.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    rate : float, optional
        Frames per second: boundaries ``t_origin + k / rate`` inside the log.
    every : int, optional
        Boundaries at every ``every``-th sample, starting with the first.
    t_origin : float, optional
        First boundary for ``rate``, s (default ``t[0]``).
    snap_tol : float
        Boundaries within this of the log's ends still count as inside, s.

    Returns
    -------
    ndarray, shape (F + 1,)
        Boundaries; frame ``i`` spans ``[T[i], T[i+1]]``. A trailing part of the
        log after the last boundary belongs to no frame.
    """
    t = np.asarray(t, dtype=float)
    if (rate is None) == (every is None):
        raise ValueError("give exactly one of rate= and every=")
    if every is not None:
        if int(every) < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        return t[::int(every)].copy()
    assert rate is not None                 # exactly one of rate and every
    if not rate > 0:
        raise ValueError(f"rate must be > 0, got {rate}")
    origin = float(t[0]) if t_origin is None else float(t_origin)
    kmin = first_rate_boundary(float(t[0]), rate, origin, snap_tol)
    kmax = math.floor((t[-1] + snap_tol - origin) * rate) + 1
    T = origin + np.arange(kmin, kmax + 1) / rate
    return T[(T >= t[0] - snap_tol) & (T <= t[-1] + snap_tol)]


def segment_frame_times(t: np.ndarray, rate: float, segment_gap: float,
                        snap_tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Frame boundaries at ``rate`` Hz that start again after every step of ``t`` longer than ``segment_gap``.

    Each segment (the samples between two such steps) gets the boundaries
    :func:`make_frame_times` gives it alone (from its first sample); the span from a
    segment's last boundary to the next one's first belongs to no frame, as the tail of a log.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    rate : float
        Frames per second.
    segment_gap : float
        A step longer than this, s, starts a new segment.
    snap_tol : float
        As :func:`make_frame_times`.

    Returns
    -------
    (T, frames, cuts) or None
        None when no step is longer than ``segment_gap`` (the boundaries are those of
        :func:`make_frame_times`); else the boundaries ``T`` (F + 1,), which of the
        ``F`` intervals between them are frames (bool, False across a cut), and the
        sample index before each cut (int).
    """
    t = np.asarray(t, dtype=float)
    cuts = np.flatnonzero(np.diff(t) > segment_gap)
    if not cuts.size:
        return None
    starts = np.concatenate([[0], cuts + 1])
    stops = np.concatenate([cuts + 1, [t.size]])
    parts = [make_frame_times(t[a:b], rate=rate, snap_tol=snap_tol) for a, b in zip(starts, stops, strict=True)]
    T = np.concatenate(parts)
    frames = np.ones(max(T.size - 1, 0), dtype=bool)
    frames[np.cumsum([p.size for p in parts[:-1]]) - 1] = False    # last boundary of a segment -> first of the next
    return T, frames, cuts


@dataclass
class FrameDeltas(ParamsView):
    """Preintegrated deltas of consecutive frames (output of :func:`~imu_ground.imu.preint_batch.preintegrate`).

    Attributes
    ----------
    t_start, t_end : ndarray, shape (F,)
        Frame boundary times, s.
    delta_t : ndarray, shape (F,)
        Integrated time per frame, s (sum of the interval lengths).
    delta_R : ndarray, shape (F, 3, 3)
        ``R_{start<-end}``: body frame at ``t_end`` -> body frame at ``t_start``.
    delta_v : ndarray, shape (F, 3)
        Velocity increment without gravity, m/s, body frame at ``t_start``.
    delta_p : ndarray, shape (F, 3)
        Position increment without gravity, m, body frame at ``t_start``.
    covariance : ndarray, shape (F, 9, 9), or None
        Order [rotation (right error, rad), velocity (m/s), position (m)]
        (None when computed with ``uncertainty=False``).
    d_R_d_bg, d_v_d_bg, d_p_d_bg, d_v_d_ba, d_p_d_ba : ndarray, shape (F, 3, 3), or None
        First-order bias Jacobians (see :class:`~imu_ground.imu.preint_measurement.PreintegratedImu`).
    valid : ndarray of bool, shape (F,)
        False for frames that overlap a timestamp gap longer than ``max_gap``.
    n_intervals : ndarray of int, shape (F,)
        Number of integration intervals (sample pieces) in each frame.
    params : PreintegrationParams
        All the settings the deltas were computed with (the one owner of the
        biases, noise densities and hold, also readable as properties).
    """

    t_start: np.ndarray
    t_end: np.ndarray
    delta_t: np.ndarray
    delta_R: np.ndarray
    delta_v: np.ndarray
    delta_p: np.ndarray
    covariance: np.ndarray | None
    d_R_d_bg: np.ndarray | None
    d_v_d_bg: np.ndarray | None
    d_p_d_bg: np.ndarray | None
    d_v_d_ba: np.ndarray | None
    d_p_d_ba: np.ndarray | None
    valid: np.ndarray
    n_intervals: np.ndarray
    params: PreintegrationParams = field(default_factory=PreintegrationParams)

    def __len__(self) -> int:
        return int(self.t_start.shape[0])

    def _need_uncertainty(self) -> None:
        if self.covariance is None or self.d_R_d_bg is None:
            raise ValueError("these deltas were computed with uncertainty=False (no covariance or "
                             "bias Jacobians)")

    @property
    def bias_jacobian(self) -> np.ndarray:
        """All bias Jacobians, shape (F, 9, 6): rows [rotation, velocity, position], columns [bg, ba]."""
        self._need_uncertainty()
        J = np.zeros((len(self), 9, 6))
        J[:, 0:3, 0:3] = self.d_R_d_bg
        J[:, 3:6, 0:3] = self.d_v_d_bg
        J[:, 6:9, 0:3] = self.d_p_d_bg
        J[:, 3:6, 3:6] = self.d_v_d_ba
        J[:, 6:9, 3:6] = self.d_p_d_ba
        return J

    def corrected(self, bias_gyro: npt.ArrayLike, bias_accel: npt.ArrayLike
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First-order bias update of every frame's deltas, without re-integration.

        Parameters
        ----------
        bias_gyro, bias_accel : array_like, shape (3,) or (F, 3)
            New bias estimates, rad/s and m/s^2, body frame.

        Returns
        -------
        delta_R : ndarray (F, 3, 3)
            ``delta_R Exp(d_R_d_bg dbg)``: ``R_{start<-end}``.
        delta_v : ndarray (F, 3)
            m/s, body frame at the start.
        delta_p : ndarray (F, 3)
            m, body frame at the start.
        """
        self._need_uncertainty()
        dbg = np.broadcast_to(np.asarray(bias_gyro, dtype=float) - self.bias_gyro, (len(self), 3))
        dba = np.broadcast_to(np.asarray(bias_accel, dtype=float) - self.bias_accel, (len(self), 3))

        def mv(M, x):
            return np.einsum("fij,fj->fi", M, x)
        R = self.delta_R @ so3.exp(mv(self.d_R_d_bg, dbg))
        v = self.delta_v + mv(self.d_v_d_bg, dbg) + mv(self.d_v_d_ba, dba)
        p = self.delta_p + mv(self.d_p_d_bg, dbg) + mv(self.d_p_d_ba, dba)
        return project_if_needed(R), v, p

    def frame(self, i: int) -> PreintegratedImu:
        """Frame ``i`` as a :class:`~imu_ground.imu.preint_measurement.PreintegratedImu` (e.g. to combine frames)."""
        self._need_uncertainty()
        assert self.covariance is not None
        J, S = right_to_left(self.delta_R[i], self.bias_jacobian[i], self.covariance[i])
        return PreintegratedImu.from_arrays(
            self.params, self.delta_t[i], self.delta_R[i], self.delta_v[i], self.delta_p[i], J, S,
            t_start=float(self.t_start[i]), t_end=float(self.t_end[i]), valid=bool(self.valid[i]),
            n_intervals=int(self.n_intervals[i]))
