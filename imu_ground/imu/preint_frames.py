"""Frames: their boundaries, the batch preintegration of a whole log into them, and the result.

:func:`make_frame_times` turns a frame rate or a sample count into boundary times;
:func:`preintegrate` runs the streaming step (:func:`~imu_ground.imu.preint_kernel.push_step`)
over a whole log in one compiled loop, so its frames are those of
:class:`~imu_ground.imu.live.preint_stream.StreamingPreintegrator`; :class:`FrameDeltas` holds
the deltas, covariance and bias Jacobians of consecutive frames. Frames: ``delta_R`` is
``R_{start<-end}`` (glossary in :mod:`imu_ground.so3`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from imu_ground.errors import ImuGroundError
from imu_ground.imu.data import ImuData
from imu_ground.imu.preint_kernel import run_log, state_buffer
from imu_ground.imu.preint_kernel import first_rate_boundary as first_rate_boundary
from imu_ground.imu.preint_measurement import JACOBIAN_BLOCKS, PreintegratedImu, bias_corrected, right_form, right_to_left
from imu_ground.imu.preint_params import ParamsView, PreintegrationParams, gap_message
from imu_ground.so3.conversions import matrix_from_quat

__all__ = ["FrameDeltas", "first_rate_boundary", "make_frame_times", "preintegrate", "segment_frame_times"]


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


def _inputs(imu: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, gyro, accel) as float arrays from an ImuData or a tuple, checked."""
    if isinstance(imu, ImuData):
        t, gyro, accel = imu.t, imu.gyro, imu.accel
    else:
        t, gyro, accel = imu
    t = np.ascontiguousarray(t, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    accel = np.asarray(accel, dtype=float)
    if gyro.shape != (t.size, 3) or accel.shape != (t.size, 3):
        raise ValueError(f"gyro and accel must have shape ({t.size}, 3), got {gyro.shape}, {accel.shape}")
    if t.ndim != 1 or t.size < 2:
        raise ImuGroundError(f"need at least 2 samples, got t of shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("IMU timestamps contain NaN or inf")
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"IMU timestamps must be strictly increasing: t[{i + 1}] = {t[i + 1]!r} s comes after "
            f"t[{i}] = {t[i]!r} s ({bad.size} non-increasing step(s)); drop non-increasing samples "
            f"upstream (validation) before preintegrating")
    return t, gyro, accel


def _boundaries(t: np.ndarray, frame_times: Any, rate: float | None, every: int | None,
                t_origin: float | None, snap_tol: float) -> np.ndarray:
    """Frame boundaries (F + 1,) inside the log, checked."""
    if frame_times is None:
        T = make_frame_times(t, rate=rate, every=every, t_origin=t_origin, snap_tol=snap_tol)
    else:
        if rate is not None or every is not None:
            raise ValueError("give frame_times or rate/every, not both")
        T = np.asarray(frame_times, dtype=float).reshape(-1)
    if T.size < 2:
        raise ImuGroundError(f"need at least 2 frame boundaries inside the log, got {T.size}")
    if not np.all(np.diff(T) > 2 * snap_tol):
        raise ValueError("frame_times must be strictly increasing (by more than 2 * snap_tol)")
    if T[0] < t[0] - snap_tol or T[-1] > t[-1] + snap_tol:
        raise ValueError(f"frame boundaries [{T[0]!r}, {T[-1]!r}] s are not inside the log "
                         f"[{t[0]!r}, {t[-1]!r}] s")
    return T


def preintegrate(imu: ImuData | tuple[np.ndarray, np.ndarray, np.ndarray],
                 frame_times: np.ndarray | None = None, *,
                 rate: float | None = None, every: int | None = None,
                 t_origin: float | None = None, params: PreintegrationParams | None = None,
                 **options: Any) -> FrameDeltas:
    """Preintegrate a whole log into frames (the streaming step over every sample, compiled).

    Parameters
    ----------
    imu : ImuData or (t, gyro, accel)
        Times (s, strictly increasing), angular rate (rad/s) and specific force
        (m/s^2), both in the body frame.
    frame_times : array_like, shape (F + 1,), optional
        Frame boundaries, s, strictly increasing and inside ``[t[0], t[-1]]``;
        frame ``i`` spans ``[frame_times[i], frame_times[i+1]]``.
    rate, every, t_origin :
        Instead of ``frame_times``: frames at ``rate`` Hz from ``t_origin``
        (default ``t[0]``), or every ``every`` samples (see :func:`make_frame_times`).
    params : PreintegrationParams, optional
        Biases, noise densities, hold, gap rule, snapping, ``uncertainty``
        (False: no covariance or bias Jacobians; those fields are None).
    **options
        Fields of :class:`~imu_ground.imu.preint_params.PreintegrationParams`
        overriding ``params`` (``bias_gyro=..., on_gap="flag"``).

    Returns
    -------
    FrameDeltas
        Per frame: ``delta_R`` (``R_{start<-end}``), ``delta_v``, ``delta_p``
        (start body frame), 9x9 covariance, bias Jacobians, validity.

    Raises
    ------
    ValueError
        Non-increasing timestamps, frame boundaries outside the log or not
        increasing, or a gap inside a frame with ``on_gap="raise"``.
    """
    par = PreintegrationParams.coerce(params, **options)
    t, gyro, accel = _inputs(imu)
    T = _boundaries(t, frame_times, rate, every, t_origin, par.snap_tol)
    F = T.size - 1
    deltas, unc, meta = np.empty((F, 11)), np.empty((F if par.uncertainty else 0, 90)), np.empty((F, 2))
    n, refused = run_log(state_buffer(par, None, None, None), T, t, np.ascontiguousarray(gyro),
                         np.ascontiguousarray(accel), deltas, unc, meta)
    if refused >= 0:                    # (the times are checked above: a gap inside a frame)
        raise ValueError(gap_message(float(t[refused - 1]), float(t[refused] - t[refused - 1]), par.max_gap))
    assert n == F                       # every boundary is inside the log
    R = matrix_from_quat(deltas[:, 1:5])
    jac: dict[str, np.ndarray | None]
    if par.uncertainty:
        J, S = right_form(deltas[:, 0], R, unc)
        jac = {k: J[:, r:r + 3, c:c + 3].copy() for k, (r, c) in JACOBIAN_BLOCKS.items()}
    else:
        S, jac = None, dict.fromkeys(JACOBIAN_BLOCKS)
    return FrameDeltas(
        t_start=T[:-1].copy(), t_end=T[1:].copy(), delta_t=deltas[:, 0].copy(), delta_R=R,
        delta_v=deltas[:, 5:8].copy(), delta_p=deltas[:, 8:11].copy(), covariance=S, **jac, valid=meta[:, 1] != 0.0,
        n_intervals=meta[:, 0].astype(int), params=par)


@dataclass
class FrameDeltas(ParamsView):
    """Preintegrated deltas of consecutive frames (output of :func:`preintegrate`).

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
        for name, (r, c) in JACOBIAN_BLOCKS.items():
            J[:, r:r + 3, c:c + 3] = getattr(self, name)
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
        shape = (len(self), 3)
        return bias_corrected(self.delta_R, self.delta_v, self.delta_p, self.bias_jacobian,
                              np.broadcast_to(np.asarray(bias_gyro, dtype=float) - self.bias_gyro, shape),
                              np.broadcast_to(np.asarray(bias_accel, dtype=float) - self.bias_accel, shape))

    def frame(self, i: int) -> PreintegratedImu:
        """Frame ``i`` as a :class:`~imu_ground.imu.preint_measurement.PreintegratedImu` (e.g. to combine frames)."""
        self._need_uncertainty()
        assert self.covariance is not None
        J, S = right_to_left(self.delta_R[i], self.bias_jacobian[i], self.covariance[i])
        return PreintegratedImu.from_arrays(
            self.params, self.delta_t[i], self.delta_R[i], self.delta_v[i], self.delta_p[i], J, S,
            t_start=float(self.t_start[i]), t_end=float(self.t_end[i]), valid=bool(self.valid[i]),
            n_intervals=int(self.n_intervals[i]))
