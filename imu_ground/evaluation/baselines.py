r"""Baselines to compare the ground normal filter against.

- :class:`ConstantNormal`: the static extrinsic alone (the paper's "naive").
- :class:`EulerEKF`: a standard EKF on filterpy's
  :class:`~filterpy.kalman.ExtendedKalmanFilter` whose state is the ZYX Euler
  angles ``(roll, pitch, yaw)`` of the slow road attitude ``X`` (world <- road,
  ``X = Rz(yaw) Ry(pitch) Rx(roll)``). It gets the same ego-motion, the same
  prediction (``X <- X T_k``, the heading twist of each increment, or a pure
  random walk) and the same Q and R as :class:`~imu_ground.filters.ground.GroundNormalFilter`
  and measures the Euler angles of the cumulative rotation (``H = I``, angle
  differences wrapped to (-pi, pi]). What it lacks is invariance: its
  covariance lives in Euler coordinates, whose Jacobians depend on the state
  and whose axes do not turn with the vehicle, so large turns and poor
  initial estimates are where it differs.

Both return a :class:`~imu_ground.filters.ground.GroundTrack`, frames as documented there.
"""
from __future__ import annotations

import math
from typing import Optional, Union

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter
from scipy.spatial.transform import Rotation

from imu_ground import so3
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.ground import GroundTrack, _twist_angle, pitch_roll_from_normal

__all__ = ["ConstantNormal", "EulerEKF", "euler_zyx", "from_euler_zyx"]


def _body_increments(delta_Rs: np.ndarray, ext: Extrinsic) -> np.ndarray:
    d = np.asarray(delta_Rs, dtype=float)
    if d.ndim == 2 and d.shape[1] == 3:
        d = so3.exp(d)
    if d.ndim != 3 or d.shape[1:] != (3, 3):
        raise ValueError(f"delta_Rs must have shape (N, 3, 3) or (N, 3), got {np.shape(delta_Rs)}")
    return ext.rotation @ d @ ext.rotation.T


def _cumulative(d: np.ndarray, R0: np.ndarray) -> np.ndarray:
    out = np.empty_like(d)
    R = R0
    for k in range(len(d)):          # per frame (10 Hz), not per IMU sample
        R = R @ d[k]
        out[k] = R
    return so3.project(out)


def _track(E: np.ndarray, X: np.ndarray, P: np.ndarray, cum: np.ndarray, ext: Extrinsic) -> GroundTrack:
    pitch, roll = pitch_roll_from_normal(E[:, 2, :])
    dyn = E @ ext.rotation
    return GroundTrack(dyn[:, 2, :].copy(), pitch, roll, E, dyn, P, X, cum, ext.translation.copy())


def euler_zyx(R: np.ndarray) -> np.ndarray:
    """``(roll, pitch, yaw)`` with ``R = Rz(yaw) Ry(pitch) Rx(roll)``, rad, batch (..., 3, 3) -> (..., 3)."""
    R = np.asarray(R, dtype=float)
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    pitch = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 2, 1], R[..., 2, 2]))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    return np.stack([roll, pitch, yaw], axis=-1)


def from_euler_zyx(e: np.ndarray) -> np.ndarray:
    """Inverse of :func:`euler_zyx`: ``Rz(yaw) Ry(pitch) Rx(roll)``, batch (..., 3) -> (..., 3, 3)."""
    e = np.asarray(e, dtype=float)
    return so3.rotz(e[..., 2]) @ so3.roty(e[..., 1]) @ so3.rotx(e[..., 0])


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


class ConstantNormal:
    """The static extrinsic alone: the normal never moves (the paper's "naive").

    Parameters
    ----------
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static sensor-to-ground extrinsic (ground <- sensor); identity by default.
    """

    def __init__(self, extrinsic: Union[Extrinsic, np.ndarray, None] = None) -> None:
        self.extrinsic = Extrinsic.coerce(extrinsic)

    def run(self, delta_Rs: np.ndarray, R0: Optional[np.ndarray] = None) -> GroundTrack:
        """Per-frame track whose residual is the identity (normal = static normal).

        Parameters
        ----------
        delta_Rs : ndarray (N, 3, 3) or (N, 3)
            Relative sensor rotations, sensor_{k-1} <- sensor_k (only their count
            and the cumulative rotation, for completeness, are used).
        R0 : ndarray (3, 3), optional
            Initial cumulative rotation, world <- body.
        """
        d = _body_increments(delta_Rs, self.extrinsic)
        n = len(d)
        cum = _cumulative(d, np.eye(3) if R0 is None else np.asarray(R0, dtype=float))
        E = np.tile(np.eye(3), (n, 1, 1))
        return _track(E, cum, np.zeros((n, 3, 3)), cum, self.extrinsic)


class EulerEKF:
    """Standard EKF baseline with an Euler-angle state, on filterpy.

    Parameters
    ----------
    Q, R, P : float or ndarray (3, 3)
        Process noise per frame, measurement noise and initial covariance in
        Euler-angle coordinates (rad^2); defaults as the paper: 1e-2 I, I, I.
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static sensor-to-ground extrinsic (ground <- sensor).
    follow_heading : bool
        Predict with the heading twist of each body increment (as
        :class:`~imu_ground.filters.ground.GroundNormalFilter` does by default).
    x0 : array_like (3,), optional
        Initial (roll, pitch, yaw) of the slow state, rad; default zeros.

    Attributes
    ----------
    ekf : filterpy.kalman.ExtendedKalmanFilter
        The underlying filter (``ekf.x`` is ``(roll, pitch, yaw)``).
    """

    def __init__(self, Q=1e-2, R=1.0, P=1.0, extrinsic=None, follow_heading: bool = True,
                 x0: Optional[np.ndarray] = None) -> None:
        self.extrinsic = Extrinsic.coerce(extrinsic)
        self.follow_heading = follow_heading
        ekf = ExtendedKalmanFilter(dim_x=3, dim_z=3)
        ekf.x = np.zeros(3) if x0 is None else np.asarray(x0, dtype=float).copy()
        ekf.P = np.eye(3) * P if np.ndim(P) == 0 else np.asarray(P, dtype=float).copy()
        ekf.Q = np.eye(3) * Q if np.ndim(Q) == 0 else np.asarray(Q, dtype=float).copy()
        ekf.R = np.eye(3) * R if np.ndim(R) == 0 else np.asarray(R, dtype=float).copy()
        self.ekf = ekf
        self.cumulative = np.eye(3)

    @staticmethod
    def _predict_jacobian(x: np.ndarray, T: np.ndarray) -> np.ndarray:
        """d euler(X(x) T) / dx by central differences (3x3)."""
        F = np.empty((3, 3))
        h = 1e-6
        for i in range(3):
            dx = np.zeros(3)
            dx[i] = h
            F[:, i] = _wrap(euler_zyx(from_euler_zyx(x + dx) @ T) - euler_zyx(from_euler_zyx(x - dx) @ T)) / (2 * h)
        return F

    def step(self, delta_R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One frame: returns the residual ``E = X^T R_k`` (road <- body) and ``P``.

        Parameters
        ----------
        delta_R : ndarray (3, 3)
            sensor_{k-1} <- sensor_k.
        """
        d = self.extrinsic.rotation @ np.asarray(delta_R, dtype=float) @ self.extrinsic.rotation.T
        self.cumulative = self.cumulative @ d
        ekf = self.ekf
        if self.follow_heading:
            T = so3.rotz(float(_twist_angle(d)))
            F = self._predict_jacobian(ekf.x, T)
            ekf.x = euler_zyx(from_euler_zyx(ekf.x) @ T)
        else:
            F = np.eye(3)
        ekf.F = F
        ekf.P = F @ ekf.P @ F.T + ekf.Q
        ekf.x_prior, ekf.P_prior = ekf.x.copy(), ekf.P.copy()
        z = euler_zyx(self.cumulative)
        ekf.update(z, HJacobian=lambda x: np.eye(3), Hx=lambda x: x,
                   residual=lambda a, b: _wrap(np.asarray(a) - np.asarray(b)))
        ekf.x = np.asarray(ekf.x, dtype=float).ravel()
        ekf.x[2] = _wrap(ekf.x[2])
        E = from_euler_zyx(ekf.x).T @ self.cumulative
        return E, ekf.P

    def run(self, delta_Rs: np.ndarray) -> GroundTrack:
        """Process a sequence of relative rotations (sensor_{k-1} <- sensor_k), (N, 3, 3)."""
        d = np.asarray(delta_Rs, dtype=float)
        if d.ndim == 2 and d.shape[1] == 3:
            d = so3.exp(d)
        n = len(d)
        E = np.empty((n, 3, 3))
        P = np.empty((n, 3, 3))
        X = np.empty((n, 3, 3))
        cum = np.empty((n, 3, 3))
        for k in range(n):
            E[k], P[k] = self.step(d[k])
            X[k] = from_euler_zyx(self.ekf.x)
            cum[k] = self.cumulative
        return _track(E, X, P, cum, self.extrinsic)
