r"""The evaluation's research baselines, on the estimator protocol.

- :class:`ConstantNormal`: the static extrinsic alone (the paper's "naive", ``--method naive``),
  re-exported from :mod:`imu_ground.filters.constant_normal`.
- :class:`EulerEKF`: a standard EKF (filterpy) whose state is the ZYX Euler angles ``(roll, pitch,
  yaw)`` of the slow road attitude ``X = Rz(yaw) Ry(pitch) Rx(roll)`` (world <- road), with the
  ego-motion, prediction (``X <- X T_k``, the heading twist, or a random walk) and Q, R of
  :class:`~imu_ground.filters.GroundNormalFilter`, measuring the Euler angles of the cumulative
  rotation (``H = I``, differences wrapped). It lacks invariance: its covariance lives in Euler
  coordinates, whose axes do not turn with the vehicle.

Both follow :class:`~imu_ground.filters.estimator.GroundEstimator` (frames and signs there); a bad
frame raises ``ValueError`` and leaves the state as it was.
"""
from __future__ import annotations

import numpy as np

from imu_ground import so3
from imu_ground.evaluation.metrics import wrap_pi
from imu_ground.filters.constant_normal import BaselineEstimator, ConstantNormal
from imu_ground.filters.estimator import GroundEstimate, GroundTrack
from imu_ground.so3 import euler_zyx, twist_angle

__all__ = ["ConstantNormal", "EulerEKF", "euler_zyx", "from_euler_zyx"]


def from_euler_zyx(e: np.ndarray) -> np.ndarray:
    """Inverse of :func:`euler_zyx`: ``Rz(yaw) Ry(pitch) Rx(roll)``, batch (..., 3) -> (..., 3, 3)."""
    e = np.asarray(e, dtype=float)
    return so3.rotz(e[..., 2]) @ so3.roty(e[..., 1]) @ so3.rotx(e[..., 0])


class EulerEKF(BaselineEstimator):
    """Standard EKF baseline with an Euler-angle state, on filterpy.

    Parameters
    ----------
    Q, R, P : float or ndarray (3, 3)
        Process noise per frame, measurement noise and initial covariance, Euler coordinates (rad^2).
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static extrinsic, ground <- sensor.
    follow_heading : bool
        Predict with the heading twist of each body increment.
    x0 : array_like (3,), optional
        Initial (roll, pitch, yaw) of the slow state, rad; default zeros.

    Attributes
    ----------
    ekf : filterpy.kalman.ExtendedKalmanFilter
        The underlying filter (``ekf.x`` is ``(roll, pitch, yaw)``).
    """

    def __init__(self, Q=1e-2, R=1.0, P=1.0, extrinsic=None, follow_heading: bool = True,
                 x0: np.ndarray | None = None) -> None:
        super().__init__(extrinsic)
        self.follow_heading = follow_heading
        self._init = (Q, R, P, None if x0 is None else np.asarray(x0, dtype=float).copy())
        self.reset()

    def reset(self) -> None:
        """Back to the initial state and covariance."""
        from filterpy.kalman import ExtendedKalmanFilter
        Q, R, P, x0 = self._init
        ekf = ExtendedKalmanFilter(dim_x=3, dim_z=3)
        ekf.x = np.zeros(3) if x0 is None else x0.copy()
        ekf.P, ekf.Q, ekf.R = (np.eye(3) * v if np.ndim(v) == 0 else np.asarray(v, dtype=float).copy()
                               for v in (P, Q, R))
        self.ekf = ekf
        self.cumulative = np.eye(3)
        self._count = 0

    @staticmethod
    def _predict_jacobian(x: np.ndarray, T: np.ndarray) -> np.ndarray:
        """d euler(X(x) T) / dx by central differences (3x3)."""
        F = np.empty((3, 3))
        h = 1e-6
        for i, dx in enumerate(np.eye(3) * h):
            F[:, i] = wrap_pi(euler_zyx(from_euler_zyx(x + dx) @ T) - euler_zyx(from_euler_zyx(x - dx) @ T)) / (2 * h)
        return F

    def step(self, frame) -> GroundEstimate:
        """One frame: predict with the heading twist (or a random walk), update with the Euler angles.

        Parameters
        ----------
        frame : EgoFrame or ndarray (3, 3)
            ``delta_R`` sensor_{k-1} <- sensor_k.

        Returns
        -------
        GroundEstimate
            Residual ``E = X^T R_k`` (road <- body), ``P`` in Euler coordinates (rad^2).
        """
        d = self._body_increment(frame)
        self.cumulative = self.cumulative @ d
        ekf = self.ekf
        if self.follow_heading:
            T = so3.rotz(float(twist_angle(d)))
            F = self._predict_jacobian(ekf.x, T)
            ekf.x = euler_zyx(from_euler_zyx(ekf.x) @ T)
        else:
            F = np.eye(3)
        ekf.F = F
        ekf.P = F @ ekf.P @ F.T + ekf.Q
        ekf.x_prior, ekf.P_prior = ekf.x.copy(), ekf.P.copy()
        z = euler_zyx(self.cumulative)
        ekf.update(z, HJacobian=lambda x: np.eye(3), Hx=lambda x: x,
                   residual=lambda a, b: wrap_pi(np.asarray(a) - np.asarray(b)))
        ekf.x = np.asarray(ekf.x, dtype=float).ravel()
        ekf.x[2] = wrap_pi(ekf.x[2])
        return self._estimate(from_euler_zyx(ekf.x).T @ self.cumulative, ekf.P.copy())

    def _run(self, em) -> GroundTrack:
        """The drive frame by frame."""
        n = len(em)
        E, P, X, cum = (np.empty((n, 3, 3)) for _ in range(4))
        for k, frame in enumerate(em.frames()):
            est = self.step(frame)
            E[k], P[k] = est.residual, est.P
            X[k] = from_euler_zyx(self.ekf.x)
            cum[k] = self.cumulative
        return GroundTrack.from_residuals(E, X, P, cum, self._Rgs, self.extrinsic.translation,
                                          t=em.t, valid=em.valid)
