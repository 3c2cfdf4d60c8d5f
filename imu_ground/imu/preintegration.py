r"""On-manifold IMU preintegration (Forster, Carlone, Dellaert, Scaramuzza, IEEE T-RO 2017).

Between two frame times ``t_i < t_j`` the samples are summarised, independently of the unknown attitude,
velocity and gravity, by

.. math::

    \Delta R_{ij} = \prod_k \operatorname{Exp}((\tilde\omega_k - b_g)\,\delta t_k), \quad
    \Delta v_{ij} = \sum_k \Delta R_{ik} (\tilde a_k - b_a)\,\delta t_k, \quad
    \Delta p_{ij} = \sum_k \Delta v_{ik}\,\delta t_k + \tfrac12 \Delta R_{ik}(\tilde a_k - b_a)\,\delta t_k^2

(Sec. VI; gravity is *not* included). With ``R = R_{world<-body}``, velocity, position and gravity ``g`` in the
world frame:

.. math::

    R_j = R_i \Delta R_{ij}, \quad
    v_j = v_i + g\,\Delta t_{ij} + R_i \Delta v_{ij}, \quad
    p_j = p_i + v_i \Delta t_{ij} + \tfrac12 g \Delta t_{ij}^2 + R_i \Delta p_{ij}.

Frames
------
``delta_R`` is ``R_{start<-end}`` (glossary: :mod:`imu_ground.so3`): body frame at the frame's end -> body
frame at its start, so ``R_k = R_{k-1} @ delta_R_k`` for ``R_{world<-body}`` attitudes; ``delta_v`` (m/s) and
``delta_p`` (m) are in the body frame at the start.

Signal model
------------
The signal is piecewise linear between samples; each interval between consecutive *knots* (the samples and
the frame boundaries between them) is integrated with one held rate and specific force:
``hold="midpoint"`` (default) the mean of the interval's two ends (a boundary gets the interpolated signal;
second order for the rotation), ``hold="left"`` the left sample's value (zero-order hold, as Forster and
GTSAM). Two frames that meet between samples compose (:meth:`PreintegratedImu.combine`) exactly to the
integration with the boundary as a knot. Within an interval the specific force is rotated with the attitude at
its start (Forster's discretisation): exact rotation, velocity and position first order in ``|omega| dt``.

Noise and bias Jacobians
------------------------
``gyro_noise_density`` (rad/s/sqrt(Hz)) and ``accel_noise_density`` (m/s^2/sqrt(Hz)) are white-noise
densities, equal on the three axes; an interval of length ``dt`` gets discrete noise of variance
``sigma^2 / dt`` on its held value. The 9x9 covariance is ordered ``[rotation, velocity, position]`` with the
rotation error on the right, ``delta_R_measured = delta_R_true @ Exp(dphi)`` (Forster, Sec. VI-B). The bias
Jacobians are the exact derivatives of the discrete deltas at the bias they were integrated with (Sec. VI-C);
``corrected`` gives the first-order update ``delta_R Exp(dR_dbg dbg)``, ``delta_v + dv_dbg dbg + dv_dba dba``, ...

Where it lives
--------------
This module: frame boundaries, :func:`preintegrate` (the step over a whole log, compiled) and
:class:`FrameDeltas`; :mod:`~imu_ground.imu.preint_kernel` the one body (an interval, a sample into frames);
:mod:`~imu_ground.imu.preint_params` :class:`PreintegrationParams`; :mod:`~imu_ground.imu.preint_measurement`
:class:`PreintegratedImu`;
:mod:`~imu_ground.imu.live.preint_stream` :class:`StreamingPreintegrator` (the step per sample).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from imu_ground.errors import ImuGroundError
from imu_ground.imu.data import ImuData
from imu_ground.imu.live.preint_stream import StreamingPreintegrator
from imu_ground.imu.preint_kernel import first_rate_boundary, run_log, state_buffer
from imu_ground.imu.preint_measurement import JACOBIAN_BLOCKS, PreintegratedImu, bias_corrected, right_form, right_to_left
from imu_ground.imu.preint_params import ParamsView, PreintegrationParams, gap_message
from imu_ground.so3.conversions import matrix_from_quat

__all__ = ["FrameDeltas", "PreintegratedImu", "PreintegrationParams", "StreamingPreintegrator", "first_rate_boundary",
           "make_frame_times", "preintegrate", "segment_frame_times"]


def make_frame_times(t: np.ndarray, *, rate: float | None = None, every: int | None = None,
                     t_origin: float | None = None, snap_tol: float = 1e-9) -> np.ndarray:
    """Frame boundary times for a log: a frame rate or every N samples.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    rate : float, optional
        Frames per second: boundaries ``t_origin + k / rate`` (``t_origin`` s, default ``t[0]``) inside the log.
    every : int, optional
        Boundaries at every ``every``-th sample, starting with the first.
    snap_tol : float
        Boundaries within this of the log's ends still count as inside, s.

    Returns
    -------
    ndarray, shape (F + 1,)
        Boundaries; frame ``i`` spans ``[T[i], T[i+1]]`` (a tail after the last belongs to no frame).
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

    Each segment gets the boundaries :func:`make_frame_times` gives it alone; the span between two segments
    belongs to no frame.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    rate, segment_gap, snap_tol : float
        Frames per second; a step longer than ``segment_gap`` s starts a segment; as :func:`make_frame_times`.

    Returns
    -------
    (T, frames, cuts) or None
        None when no step is longer than ``segment_gap``; else the boundaries ``T`` (F + 1,), which of the ``F``
        intervals between them are frames (bool, False across a cut), and the sample index before each cut.
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
        Times (s, strictly increasing), angular rate (rad/s) and specific force (m/s^2), body frame.
    frame_times : array_like, shape (F + 1,), optional
        Frame boundaries, s, strictly increasing and inside ``[t[0], t[-1]]``.
    rate, every, t_origin :
        Instead of ``frame_times``, as :func:`make_frame_times`.
    params : PreintegrationParams, optional
        ``uncertainty=False``: the covariance and bias Jacobians are None.
    **options
        Fields of :class:`PreintegrationParams` overriding ``params`` (``bias_gyro=..., on_gap="flag"``).

    Returns
    -------
    FrameDeltas

    Raises
    ------
    ValueError
        Non-increasing timestamps, frame boundaries outside the log or not increasing, or a gap inside a frame
        with ``on_gap="raise"``.
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
    t_start, t_end, delta_t : ndarray, shape (F,)
        Frame boundary times and integrated time per frame, s.
    delta_R : ndarray, shape (F, 3, 3)
        ``R_{start<-end}``: body frame at ``t_end`` -> body frame at ``t_start``.
    delta_v, delta_p : ndarray, shape (F, 3)
        Velocity (m/s) and position (m) increments without gravity, body frame at ``t_start``.
    covariance : ndarray, shape (F, 9, 9), or None
        [rotation (right error, rad), velocity (m/s), position (m)]; None with ``uncertainty=False``.
    d_R_d_bg, d_v_d_bg, d_p_d_bg, d_v_d_ba, d_p_d_ba : ndarray, shape (F, 3, 3), or None
        Bias Jacobians (as :class:`PreintegratedImu`'s).
    valid : ndarray of bool, shape (F,)
        False for frames that overlap a timestamp gap longer than ``max_gap``.
    n_intervals : ndarray of int, shape (F,)
        Integration intervals (sample pieces) per frame.
    params : PreintegrationParams
        The settings the deltas were computed with (also readable as properties).
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
        delta_R, delta_v, delta_p : ndarray (F, 3, 3), (F, 3), (F, 3)
            As :meth:`PreintegratedImu.corrected`, per frame.
        """
        shape = (len(self), 3)
        return bias_corrected(self.delta_R, self.delta_v, self.delta_p, self.bias_jacobian,
                              np.broadcast_to(np.asarray(bias_gyro, dtype=float) - self.bias_gyro, shape),
                              np.broadcast_to(np.asarray(bias_accel, dtype=float) - self.bias_accel, shape))

    def frame(self, i: int) -> PreintegratedImu:
        """Frame ``i`` as a :class:`PreintegratedImu` (e.g. to combine frames)."""
        self._need_uncertainty()
        assert self.covariance is not None
        J, S = right_to_left(self.delta_R[i], self.bias_jacobian[i], self.covariance[i])
        return PreintegratedImu.from_arrays(
            self.params, self.delta_t[i], self.delta_R[i], self.delta_v[i], self.delta_p[i], J, S,
            t_start=float(self.t_start[i]), t_end=float(self.t_end[i]), valid=bool(self.valid[i]),
            n_intervals=int(self.n_intervals[i]))
