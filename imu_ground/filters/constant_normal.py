r"""The constant normal: the static extrinsic alone (the paper's "naive" baseline), an estimator like the others.

:class:`ConstantNormal` follows :class:`~imu_ground.filters.estimator.GroundEstimator`; its residual road <- body is
the identity on every frame, so the normal is the static extrinsic's, ``n_s = R_gs^T e_z`` (sensor frame), and pitch
and roll relative to the road are 0; it still integrates ``cumulative`` (world <- body). :class:`BaselineEstimator`
is the plumbing it shares with the evaluation's research baselines (:class:`~imu_ground.evaluation.baselines.EulerEKF`).
A bad frame (not a rotation, non-finite, ``delta_t <= 0``) raises ``ValueError``, the state unchanged.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from imu_ground.filters.estimator import GroundEstimate, GroundTrack, as_egomotion, pitch_roll_from_normal
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.frame_checks import bad_frame_error, frame_problem, frame_problems, frame_where, static_rotation
from imu_ground.imu.egomotion import EgoMotion
from imu_ground.so3 import cumulative_rotations
from imu_ground.units import RENORM_EVERY

__all__ = ["BaselineEstimator", "ConstantNormal"]


class BaselineEstimator:
    """The protocol's plumbing of the simple baselines: static extrinsic, frame checks, ``run`` over ``_run``.

    Subclasses define ``reset``, ``step`` and ``_run(egomotion) -> GroundTrack``.
    """

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
    #: The whole drive at once (each estimator's own; :meth:`run` checks the input first).
    _run: Callable[[EgoMotion], GroundTrack]

    def run(self, egomotion, smooth: bool = False) -> GroundTrack:
        """Process a drive (continuing from the current state, as ``step`` would).

        Parameters
        ----------
        egomotion : EgoMotion, ImuData or ndarray (F, 3, 3) / (F, 3)
            Frames, sensor frame (:func:`~imu_ground.filters.estimator.as_egomotion`).
        smooth : bool
            The baselines have no smoother (:class:`ConstantNormal` accepts it and changes nothing).
        """
        if smooth and not self._smooth_ok:
            raise ValueError(f"{type(self).__name__} has no offline smoother: run it with smooth=False")
        return self._run(as_egomotion(egomotion))


class ConstantNormal(BaselineEstimator):
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
        cum = np.zeros((0, 3, 3))
        if n:
            cum = cumulative_rotations(body, self.cumulative, self._count, renorm_every=RENORM_EVERY)
            self.cumulative = cum[-1].copy()
            self._count += n
        E = np.tile(np.eye(3), (n, 1, 1))
        return GroundTrack.from_residuals(E, cum, np.zeros((n, 3, 3)), cum, self._Rgs,
                                          self.extrinsic.translation, t=em.t, valid=em.valid)
