r"""Baselines to compare the ground normal filters against, on the estimator protocol.

- :class:`ConstantNormal`: the static extrinsic alone (the paper's "naive").
- :class:`EulerEKF`: a standard EKF on filterpy's
  :class:`~filterpy.kalman.ExtendedKalmanFilter` whose state is the ZYX Euler
  angles ``(roll, pitch, yaw)`` of the slow road attitude ``X`` (world <- road,
  ``X = Rz(yaw) Ry(pitch) Rx(roll)``). It gets the same ego-motion, the same
  prediction (``X <- X T_k``, the heading twist of each increment, or a pure
  random walk) and the same Q and R as :class:`~imu_ground.filters.GroundNormalFilter`
  and measures the Euler angles of the cumulative rotation (``H = I``, angle
  differences wrapped to (-pi, pi]). What it lacks is invariance: its
  covariance lives in Euler coordinates, whose Jacobians depend on the state
  and whose axes do not turn with the vehicle, so large turns and poor
  initial estimates are where it differs.

Both follow :class:`~imu_ground.filters.estimator.GroundEstimator`: ``reset()``,
``step(frame) -> GroundEstimate`` and ``run(egomotion, smooth=False) -> GroundTrack``
(frames and signs as documented in :mod:`imu_ground.filters.estimator`). A bad
frame (not a rotation, non-finite, ``delta_t <= 0``) raises ``ValueError`` and
leaves the state as it was.
"""
from __future__ import annotations

import numpy as np

from imu_ground import so3
from imu_ground.filters.estimator import GroundEstimate, GroundTrack, as_egomotion, pitch_roll_from_normal
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.frame_checks import (
    bad_frame_error,
    frame_problem,
    frame_problems,
    frame_where,
    static_rotation,
)
from imu_ground.so3 import cumulative_rotations, euler_zyx, twist_angle
from imu_ground.units import RENORM_EVERY

__all__ = ["ConstantNormal", "EulerEKF", "euler_zyx", "from_euler_zyx"]


def from_euler_zyx(e: np.ndarray) -> np.ndarray:
    """Inverse of :func:`euler_zyx`: ``Rz(yaw) Ry(pitch) Rx(roll)``, batch (..., 3) -> (..., 3, 3)."""
    e = np.asarray(e, dtype=float)
    return so3.rotz(e[..., 2]) @ so3.roty(e[..., 1]) @ so3.rotx(e[..., 0])


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


class _Baseline:
    """The protocol's plumbing both baselines share: extrinsic, frame checks, ``run`` over ``step``."""

    def __init__(self, extrinsic: Extrinsic | np.ndarray | None) -> None:
        self.extrinsic = Extrinsic.coerce(extrinsic)
        self._Rgs = static_rotation(self.extrinsic)
        self._count = 0
        self.cumulative = np.eye(3)

    def _body_increment(self, frame) -> np.ndarray:
        """``R_gs delta_R R_gs^T`` of a frame (an EgoFrame or a bare 3x3 rotation), checked."""
        d = np.asarray(getattr(frame, "delta_R", frame), dtype=float)
        dt = float(getattr(frame, "delta_t", 1.0))
        problem = frame_problem(d.ravel().tolist(), None, dt) if d.shape == (3, 3) else \
            f"delta_R must be 3x3, got shape {d.shape}"
        if problem:
            raise bad_frame_error(problem, frame_where(self._count, float(getattr(frame, "t", np.nan))))
        self._count += 1
        return d if self._Rgs is None else self._Rgs @ d @ self._Rgs.T

    def _estimate(self, E: np.ndarray, P: np.ndarray) -> GroundEstimate:
        pitch, roll = pitch_roll_from_normal(E[2])
        return GroundEstimate(float(pitch), float(roll), True, residual=E, Rgs=self._Rgs, P=P)

    #: Whether ``run(..., smooth=True)`` is allowed (it changes nothing for a constant estimate).
    _smooth_ok = False

    def run(self, egomotion, smooth: bool = False) -> GroundTrack:
        """Process a drive (continuing from the current state, as ``step`` would).

        Parameters
        ----------
        egomotion : EgoMotion, ImuData or ndarray (F, 3, 3) / (F, 3)
            Frames in the sensor frame (see :func:`~imu_ground.filters.estimator.as_egomotion`).
        smooth : bool
            Offline smoothing: the baselines have none (:class:`ConstantNormal` accepts
            it and changes nothing, :class:`EulerEKF` refuses it).
        """
        if smooth and not self._smooth_ok:
            raise ValueError(f"{type(self).__name__} has no offline smoother: run it with smooth=False")
        return self._run(as_egomotion(egomotion))


class ConstantNormal(_Baseline):
    """The static extrinsic alone: the normal never moves (the paper's "naive").

    Parameters
    ----------
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static sensor-to-ground extrinsic (ground <- sensor); identity by default.
    """

    def __init__(self, extrinsic: Extrinsic | np.ndarray | None = None) -> None:
        super().__init__(extrinsic)

    def reset(self) -> None:
        """Back to the start (cumulative rotation the identity)."""
        self.cumulative = np.eye(3)
        self._count = 0

    def step(self, frame) -> GroundEstimate:
        """One frame: the residual is the identity (normal = static normal).

        Parameters
        ----------
        frame : EgoFrame or ndarray (3, 3)
            ``delta_R`` sensor_{k-1} <- sensor_k (only the cumulative rotation uses it).
        """
        self.cumulative = self.cumulative @ self._body_increment(frame)
        return self._estimate(np.eye(3), np.zeros((3, 3)))

    _smooth_ok = True

    def _run(self, em) -> GroundTrack:
        """The whole drive at once (vectorised)."""
        d = np.asarray(em.delta_R, dtype=float)
        for k, problem in enumerate(frame_problems(d, None, np.asarray(em.delta_t, dtype=float))):
            if problem:
                raise bad_frame_error(problem, frame_where(self._count + k, float(em.t[k])))
        body = d if self._Rgs is None else self._Rgs @ d @ self._Rgs.T
        n = len(body)
        cum = (cumulative_rotations(body, self.cumulative, self._count, renorm_every=RENORM_EVERY) if n
               else np.zeros((0, 3, 3)))
        if n:
            self.cumulative = cum[-1].copy()
            self._count += n
        E = np.tile(np.eye(3), (n, 1, 1))
        return GroundTrack.from_residuals(E, cum, np.zeros((n, 3, 3)), cum, self._Rgs,
                                          self.extrinsic.translation, t=em.t, valid=em.valid)


class EulerEKF(_Baseline):
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
        :class:`~imu_ground.filters.GroundNormalFilter` does by default).
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
        ekf.P = np.eye(3) * P if np.ndim(P) == 0 else np.asarray(P, dtype=float).copy()
        ekf.Q = np.eye(3) * Q if np.ndim(Q) == 0 else np.asarray(Q, dtype=float).copy()
        ekf.R = np.eye(3) * R if np.ndim(R) == 0 else np.asarray(R, dtype=float).copy()
        self.ekf = ekf
        self.cumulative = np.eye(3)
        self._count = 0

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
                   residual=lambda a, b: _wrap(np.asarray(a) - np.asarray(b)))
        ekf.x = np.asarray(ekf.x, dtype=float).ravel()
        ekf.x[2] = _wrap(ekf.x[2])
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
