r"""Strapdown dead reckoning in a gravity-aligned world frame from preintegrated deltas.

World frame: local level, z up, gravity ``g_world = [0, 0, -g]``, the heading of the initial attitude.
Attitudes are ``R_{world<-body}`` (glossary: :mod:`imu_ground.so3`). The states at frame boundaries follow
the prediction of :mod:`imu_ground.imu.preintegration` frame after frame (cumulative rotations and sums).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from imu_ground import so3
from imu_ground.imu.data import ImuData
from imu_ground.imu.preintegration import FrameDeltas, preintegrate
from imu_ground.imu.standstill import estimate_gyro_bias
from imu_ground.units import GRAVITY, RENORM_EVERY

__all__ = ["NavSolution", "attitude_from_accel", "dead_reckon", "dead_reckon_imu"]


@dataclass
class NavSolution:
    """Dead-reckoned states at the frame boundaries.

    Attributes
    ----------
    t : ndarray, shape (F + 1,)
        Boundary times, s.
    R : ndarray, shape (F + 1, 3, 3)
        Attitude ``R_{world<-body}`` (world: level, z up).
    v, p : ndarray, shape (F + 1, 3)
        Velocity (m/s) and position (m), world frame.
    valid : ndarray of bool, shape (F + 1,)
        False from the first frame that crossed a timestamp gap onwards.
    gravity : float
        Magnitude of gravity used, m/s^2.
    """

    t: np.ndarray
    R: np.ndarray
    v: np.ndarray
    p: np.ndarray
    valid: np.ndarray
    gravity: float

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def roll_pitch_yaw(self) -> np.ndarray:
        """(F + 1, 3) roll, pitch, yaw in rad with ``R_{world<-body} = Rz(yaw) Ry(pitch) Rx(roll)``."""
        return so3.euler_zyx(self.R)


def attitude_from_accel(accel_mean: Sequence[float], yaw: float = 0.0) -> np.ndarray:
    """Attitude of a body at rest from its mean specific force (which points up; yaw is free).

    Parameters
    ----------
    accel_mean : array_like, shape (3,)
        Mean specific force at rest, body frame, m/s^2 (any positive scale).
    yaw : float
        Heading to use, rad.

    Returns
    -------
    ndarray, shape (3, 3)
        ``R_{world<-body} = Rz(yaw) Ry(pitch) Rx(roll)`` (world: level, z up), with
        ``roll = atan2(f_y, f_z)``, ``pitch = atan2(-f_x, hypot(f_y, f_z))``, so that
        ``R @ f / |f| = [0, 0, 1]``.
    """
    f = np.asarray(accel_mean, dtype=float).reshape(3)
    if not np.all(np.isfinite(f)) or np.linalg.norm(f) == 0:
        raise ValueError(f"need a finite non-zero specific force, got {f}")
    roll = np.arctan2(f[1], f[2])
    pitch = np.arctan2(-f[0], np.hypot(f[1], f[2]))
    return so3.rotz(yaw) @ so3.roty(pitch) @ so3.rotx(roll)


def dead_reckon(deltas: FrameDeltas, R0: np.ndarray, v0: Sequence[float] = (0.0, 0.0, 0.0),
                p0: Sequence[float] = (0.0, 0.0, 0.0), *, gravity: float = GRAVITY,
                bias_gyro: Sequence[float] | None = None,
                bias_accel: Sequence[float] | None = None) -> NavSolution:
    """Propagate attitude, velocity and position through consecutive frames.

    Parameters
    ----------
    deltas : FrameDeltas
        Consecutive frames (``t_end[k] == t_start[k+1]``).
    R0 : array_like, shape (3, 3)
        ``R_{world<-body}`` at ``deltas.t_start[0]``.
    v0, p0 : array_like, shape (3,)
        Initial velocity (m/s) and position (m), world frame.
    gravity : float
        Magnitude of gravity, m/s^2.
    bias_gyro, bias_accel : array_like, shape (3,), optional
        Biases (rad/s, m/s^2, body) to correct the deltas to, first order (:meth:`FrameDeltas.corrected`).

    Returns
    -------
    NavSolution
        States at ``[t_start[0], t_end[0], t_end[1], ...]``; ``R`` is ``R_{world<-body}``.
    """
    F = len(deltas)
    if F > 1 and not np.allclose(deltas.t_end[:-1], deltas.t_start[1:], rtol=0, atol=1e-9):
        raise ValueError("frames must be consecutive (t_end[k] == t_start[k+1])")
    R0 = np.asarray(R0, dtype=float).reshape(3, 3)
    if bias_gyro is not None or bias_accel is not None:
        bg = deltas.bias_gyro if bias_gyro is None else bias_gyro
        ba = deltas.bias_accel if bias_accel is None else bias_accel
        dR, dv, dp = deltas.corrected(bg, ba)
    else:
        dR, dv, dp = deltas.delta_R, deltas.delta_v, deltas.delta_p
    T = np.asarray(deltas.delta_t, dtype=float)
    R = np.empty((F + 1, 3, 3))
    R[0] = so3.project(R0)
    R[1:] = so3.cumulative_rotations(dR, R[0], renorm_every=RENORM_EVERY)
    g_world = np.array([0.0, 0.0, -float(gravity)])
    Rdv = np.einsum("fij,fj->fi", R[:-1], dv)
    Rdp = np.einsum("fij,fj->fi", R[:-1], dp)
    v = np.empty((F + 1, 3))
    v[0] = v0
    np.cumsum(g_world * T[:, None] + Rdv, axis=0, out=v[1:])
    v[1:] += v[0]
    p = np.empty((F + 1, 3))
    p[0] = p0
    np.cumsum(v[:-1] * T[:, None] + 0.5 * g_world * (T * T)[:, None] + Rdp, axis=0, out=p[1:])
    p[1:] += p[0]
    t = np.concatenate([deltas.t_start[:1], deltas.t_end])
    valid = np.concatenate([[True], np.cumprod(deltas.valid).astype(bool)])
    return NavSolution(t=t, R=R, v=v, p=p, valid=valid, gravity=float(gravity))


def dead_reckon_imu(imu: ImuData, *, rate: float | None = None, every: int | None = None,
                    R0: np.ndarray | None = None, v0: Sequence[float] = (0.0, 0.0, 0.0),
                    p0: Sequence[float] = (0.0, 0.0, 0.0),
                    bias_gyro: Sequence[float] | Literal["standstill"] | None = "standstill",
                    bias_accel: Sequence[float] = (0.0, 0.0, 0.0), gravity: float = GRAVITY,
                    hold: Literal["midpoint", "left"] = "midpoint", max_gap: float = 0.1,
                    on_gap: Literal["raise", "flag"] = "raise",
                    standstill: dict | None = None) -> NavSolution:
    """Dead-reckon a whole log: bias and initial attitude from standstill, then propagate.

    Parameters
    ----------
    imu : ImuData
    rate, every : optional
        Output frames: ``rate`` Hz, or every ``every`` samples (default: every sample).
    R0 : array_like (3, 3), optional
        Initial ``R_{world<-body}``. Default: from the mean specific force of the first standstill, which must
        begin within 1 s of the log's start (yaw 0); ValueError otherwise.
    v0, p0, gravity :
        As :func:`dead_reckon`.
    bias_gyro : array_like (3,), "standstill" or None
        Gyro bias, rad/s (``"standstill"``: :func:`~imu_ground.imu.standstill.estimate_gyro_bias`; None: zeros).
    bias_accel : array_like, shape (3,)
        Accelerometer bias, m/s^2.
    hold, max_gap, on_gap :
        See :class:`~imu_ground.imu.preint_params.PreintegrationParams`.
    standstill : dict, optional
        Keyword arguments for the standstill detection.

    Returns
    -------
    NavSolution
    """
    kw = dict(standstill or {})
    kw.setdefault("gravity", gravity)
    need_est = R0 is None or (isinstance(bias_gyro, str) and bias_gyro == "standstill")
    est = estimate_gyro_bias(imu, **kw) if need_est else None
    if isinstance(bias_gyro, str):
        if bias_gyro != "standstill":
            raise ValueError(f"bias_gyro must be an array, 'standstill' or None, got {bias_gyro!r}")
        assert est is not None              # need_est
        bg = est.bias
    else:
        bg = np.zeros(3) if bias_gyro is None else np.asarray(bias_gyro, dtype=float)
    if R0 is None:
        assert est is not None              # need_est
        if not est.found or est.intervals[0, 0] > imu.t[0] + 1.0:
            raise ValueError("the log does not start at rest (no standstill within 1 s of its "
                             "start); give the initial attitude R0")
        R0 = attitude_from_accel(est.accel_mean[0])
    deltas = preintegrate(imu, rate=rate, every=1 if rate is None and every is None else every, bias_gyro=bg,
                          bias_accel=bias_accel, hold=hold, max_gap=max_gap, on_gap=on_gap, uncertainty=False)
    return dead_reckon(deltas, R0, v0, p0, gravity=gravity)
