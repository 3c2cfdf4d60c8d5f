r"""Ground plane normal from ego-motion: the paper's pipeline, done right.

Frames and signs: :mod:`imu_ground.filters.estimator`. Per frame k:

1. body increment ``dR_b = R_gs dR_s R_gs^T`` (``dR_s``: sensor_{k-1} <- sensor_k);
2. cumulative rotation ``R_k = R_{k-1} dR_b`` (world <- body; right-multiplied, the increments are body-frame);
3. invariant EKF (left error) on ``X_k``: predict ``X <- X T_k``, ``T_k = Rz(psi_k)`` the twist of ``dR_b`` about
   the body up axis (``follow_heading=False``: the paper's random walk), update with ``R_k`` or one of its axes;
4. residual ``E_k = X_k^T R_k`` (road <- body), dynamic extrinsic ``E_k R_gs`` (road-ground <- sensor) and the
   normal in the sensor frame ``n_s = (E_k R_gs)^T e_z``.

Steps 2-4 are :mod:`imu_ground.filters.residual` (``step`` one frame of it, ``run`` the same over a drive, the
smoother a post-pass, :meth:`~imu_ground.filters.invariant_ekf.InvariantEKF.rts_smoother`).
"""
from __future__ import annotations

from math import isnan
from typing import Any, Optional, Union

import numpy as np

from imu_ground import so3
from imu_ground.filters.estimator import GroundEstimate, GroundTrack, as_egomotion, pitch_roll_from_normal
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.frame_checks import (check_on_invalid, checked_frame, checked_frames, hold_skipped,
                                             static_rotation)
from imu_ground.filters.invariant_ekf import InvariantEKF
from imu_ground.filters.invariant_ekf_kernel import check_cov
from imu_ground.filters.residual import NO_DV, ResidualKernel, check, frame_checked
from imu_ground.filters.road import NO_ROAD_REASON
from imu_ground.filters.status import FILTER_CONVERGED_STD, FILTER_STD, OK, SigmaModel, frame_status_code, track_reasons
from imu_ground.imu.egomotion import EgoFrame
from imu_ground.imu.warm_start import STATE_VERSION, StateReader, pack_state, unpack_state
from imu_ground.so3 import matrix_from_quat, twist_angle

__all__ = ["GroundNormalFilter", "GroundEstimate", "GroundTrack", "pitch_roll_from_normal"]

_I3 = np.eye(3)
_F64 = np.dtype(np.float64)
_AXES = {"rotation": None, "up": (0.0, 0.0, 1.0), "forward": (1.0, 0.0, 0.0)}
_PAPER: dict[str, Any] = dict(Q=1e-2, R=1.0, P=1.0, follow_heading=False)


def _cov(name: str, value) -> np.ndarray:
    m = check_cov(name, value)
    if not (np.all(np.isfinite(m)) and np.allclose(m, m.T) and np.all(np.linalg.eigvalsh(m) > 0)):
        shown = value if np.ndim(value) == 0 else m.tolist()
        raise ValueError(f"{name} must be a positive (co)variance, rad^2 (a positive number or a positive "
                         f"definite 3x3 matrix), got {shown}")
    return m


def _is_axisymmetric(m: np.ndarray) -> bool:
    """True for diag(a, a, c): commutes with every rotation about z."""
    return bool(np.all(m == np.diag(np.diag(m))) and m[0, 0] == m[1, 1])


class GroundNormalFilter:
    """Ground normal, pitch and roll from ego-motion (Zhang et al. 2022, improved).

    Parameters
    ----------
    Q, R, P : float or ndarray (3, 3)
        Process noise per frame (body tangent space), measurement noise of ``R_k`` or of its observed axis, and
        initial covariance, rad^2. Defaults ``1e-2 I``, ``I``, ``I`` (the paper's, per 10 Hz frame).
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static extrinsic ``R_gs`` (ground <- sensor) and sensor position. Default identity.
    measurement : {"rotation", "up", "forward"}
        What is observed of ``R_k``: the full rotation, its up axis ``R_k e_z`` or its forward axis ``R_k e_x``
        (the paper's code, which observes the camera's optical axis).
    follow_heading : bool
        Predict with the heading twist of each increment (default); False: the paper's random walk (lags in turns).
    R0 : ndarray (3, 3), optional
        Initial cumulative rotation, world <- body (default identity).
    on_invalid : {"raise", "skip"}
        A bad frame (non-finite, not a rotation, ``delta_t <= 0``) raises ``ValueError`` with the state unchanged,
        or is skipped: ``step`` returns the previous estimate flagged ``valid=False``, ``run`` holds the values.

    Attributes
    ----------
    x, P, Q, R, K, y, S : ndarray
        filterpy-style: slow state (world <- road), its covariance, the noises, the last gain, innovation and
        innovation covariance.
    cumulative : ndarray (3, 3)
        ``R_k``, world <- body.
    ekf : None
        Kept for compatibility (there is no separate filter object).
    """

    def __init__(self, Q: Union[float, np.ndarray] = 1e-2, R: Union[float, np.ndarray] = 1.0,
                 P: Union[float, np.ndarray] = 1.0, extrinsic: Union[Extrinsic, np.ndarray, None] = None,
                 measurement: str = "rotation", follow_heading: bool = True,
                 R0: Optional[np.ndarray] = None, on_invalid: str = "raise") -> None:
        if measurement not in _AXES:
            raise ValueError(f"measurement must be 'rotation', 'up' or 'forward', got {measurement!r}")
        self.extrinsic = Extrinsic.coerce(extrinsic)
        self.measurement = measurement
        self.follow_heading = bool(follow_heading)
        self.on_invalid = check_on_invalid(on_invalid)
        self.R0 = _I3.copy() if R0 is None else np.array(R0, dtype=float)
        self._Q, self._R, self._P0 = _cov("Q", Q), _cov("R", R), _cov("P", P)
        self._Rgs = static_rotation(self.extrinsic)
        # P stays diag(a, a, c) (an estimate's P is then that of its row, see residual.frame)
        self._diag = (_is_axisymmetric(self._P0) and _is_axisymmetric(self._Q) and _is_axisymmetric(self._R)
                      and (measurement == "rotation" or measurement == "up" and self._R[0, 0] == self._R[2, 2]))
        self.reset()

    @classmethod
    def paper(cls, **kwargs) -> "GroundNormalFilter":
        """The paper's method (Zhang et al. 2022): random walk, full rotation, ``Q = 1e-2 I``, ``R = P0 = I``,
        rotations accumulated in the correct order; keyword arguments override."""
        return cls(**{**_PAPER, "measurement": "rotation", **kwargs})

    @classmethod
    def reference_code(cls, **kwargs) -> "GroundNormalFilter":
        """The paper's reference code (manymuch/ground_normal_filter): as :meth:`paper` observing only the forward
        axis (roll about it never corrected); its accumulation-order error is not reproduced."""
        return cls(**{**_PAPER, "measurement": "forward", **kwargs})

    def reset(self) -> None:
        """Back to the initial state (cumulative rotation R0, slow state R0, covariance P0)."""
        self._frames = 0
        self.sigma = SigmaModel(FILTER_STD, FILTER_CONVERGED_STD)      # the 1-sigma and its convergence latch
        axis = _AXES[self.measurement]
        R = self._R if axis is None else self.R0.T @ self._R @ self.R0      # (a direction's noise: world axes)
        self._kernel = ResidualKernel(0.0, 0.0, 0.0, 0.0, follow_heading=self.follow_heading, Rgs=self._Rgs,
                                      cumulative=True, P=self._P0, Q=self._Q, R=R, axis=axis)
        self._buf = self._kernel.buf

    ekf = None

    # -- filterpy-style attributes ------------------------------------------------------------
    cumulative = property(lambda self: self.R0 @ matrix_from_quat(np.array(self._kernel.R)),
                          doc="``R_k``, world <- body (3x3).")
    residual = property(lambda self: self._kernel.residual_matrix(), doc="``E_k = X_k^T R_k``, road <- body (3x3).")
    x = property(lambda self: self.cumulative @ self.residual.T, doc="Slow state X_k, world <- road (3x3).")
    P = property(lambda self: self._kernel.covariance(), doc="Covariance of the slow state, body tangent space (rad^2).")
    Q = property(lambda self: self._Q, doc="Process noise per frame (rad^2), as configured.")
    R = property(lambda self: self._R, doc="Measurement noise, as configured.")

    def _last(self, i: int) -> np.ndarray:
        last = self._kernel.last_matrices()
        return np.zeros((3, 3) if i < 3 else 3) if last is None else last[i]

    K = property(lambda self: self._last(0), doc="Last Kalman gain (3x3).")
    y = property(lambda self: self._last(3), doc="Last innovation (rad, or the up-axis residual).")
    S = property(lambda self: self._last(1), doc="Last innovation covariance.")

    # -- warm start ------------------------------------------------------------------------------
    def _settings(self) -> dict:
        return dict(Q=self._Q, R=self._R, P=self._P0, extrinsic=self.extrinsic.settings(),
                    measurement=self.measurement, follow_heading=self.follow_heading, R0=self.R0,
                    on_invalid=self.on_invalid)

    def state_dict(self) -> dict:
        """The state as a JSON-serialisable dict (:mod:`imu_ground.imu.warm_start`), for :meth:`load_state_dict`."""
        st = {"frames": self._frames, **self.sigma.state_dict(), "kernel": list(self._kernel.buf)}
        return pack_state("GroundNormalFilter", STATE_VERSION, self._settings(), st)

    def load_state_dict(self, state: dict) -> None:
        """Resume from a :meth:`state_dict` of the same settings; another estimator's, layout, settings or a corrupt
        one raises :class:`~imu_ground.imu.warm_start.StateError` naming what is wrong (the filter unchanged)."""
        st = StateReader("GroundNormalFilter", unpack_state(state, "GroundNormalFilter", STATE_VERSION,
                                                            self._settings()))
        frames = st.int("frames")
        sigma = SigmaModel(FILTER_STD, FILTER_CONVERGED_STD)           # (read before anything changes)
        sigma.load_state_dict(st)
        kernel = self._kernel.read_state(st, "kernel")
        self.reset()
        self._frames, self.sigma = frames, sigma
        self._kernel.load(kernel)
        self._buf = self._kernel.buf

    # -- streaming -----------------------------------------------------------------------------
    def step(self, frame) -> GroundEstimate:
        """Process one frame's ego-motion.

        Parameters
        ----------
        frame : EgoFrame or ndarray (3, 3), (4, 4) or (3,)
            An :class:`~imu_ground.imu.egomotion.EgoFrame`, or its ``delta_R`` alone (sensor_{k-1} <- sensor_k:
            a rotation matrix, a 4x4 relative pose or a rotation vector, rad).

        Returns
        -------
        GroundEstimate
            After this frame; a skipped bad frame gives the previous state flagged ``valid=False``.

        Raises
        ------
        ValueError
            A bad frame with ``on_invalid="raise"`` (the state is unchanged).
        """
        if type(frame) is EgoFrame:
            d, dv, dt, stationary, valid, _ = frame
            dt = float(dt)
        elif type(frame) is np.ndarray or not hasattr(frame, "delta_R"):
            d, dv, dt, stationary, valid = frame, None, 1.0, False, True
        else:
            d, dv, dt = frame.delta_R, frame.delta_v, float(frame.delta_t)
            stationary, valid = getattr(frame, "stationary", False), getattr(frame, "valid", True)
        o = None
        if (type(d) is np.ndarray and d.shape == (3, 3) and d.dtype is _F64
                and (dv is None or type(dv) is np.ndarray and dv.shape == (3,) and dv.dtype is _F64)):
            try:
                o = frame_checked(self._buf, d, NO_DV if dv is None else dv, dt)
            except TypeError:                           # not C-contiguous
                pass
        if o is None or isnan(o[0]):               # checked again (coerced if need be), to name a bad frame
            checked = checked_frame(check, frame, d, dv, dt, self.on_invalid, self._frames)
            if checked is None:
                return GroundEstimate.of_residual(self.residual, self.P, self._Rgs, valid=False)
            d, dv = checked
            o = frame_checked(self._buf, d, NO_DV if dv is None else dv, dt)
        self._frames += 1
        info = self.sigma.frame(o[4], dt=dt, note=NO_ROAD_REASON)
        code = frame_status_code(self.sigma.converged, bool(stationary), bool(valid))
        return GroundEstimate(o[6], o[7], True, o, None, self._Rgs, o if self._diag else self.P, code, info)

    # -- batch -----------------------------------------------------------------------------------
    def run(self, egomotion, smooth: bool = False) -> GroundTrack:
        """Process a whole drive, continuing from the current state exactly as :meth:`step` per frame would.

        Parameters
        ----------
        egomotion : EgoMotion, ImuData or ndarray (F, 3, 3), (F, 4, 4) or (F, 3)
            Ego-motion, sensor frame (:func:`~imu_ground.filters.estimator.as_egomotion`).
        smooth : bool
            Offline: forward filter plus Rauch-Tung-Striebel smoother on the group (zero lag, uses the future).

        Returns
        -------
        GroundTrack
            With the ego-motion's times and validity (False also on skipped frames).

        Raises
        ------
        ValueError
            A bad frame with ``on_invalid="raise"`` (named by index and time; nothing is processed).
        """
        em = as_egomotion(egomotion)
        d = np.asarray(em.delta_R, dtype=float)
        good = checked_frames(d, em.delta_v, em.delta_t, em.t, self.on_invalid)
        start = (self.residual, self.P, self.cumulative)
        dg = d[good]
        Ps = np.empty((len(dg), 3, 3))
        o = self._kernel.run(dg, 0.0, 0.0, P_out=Ps)
        self._frames += len(dg)
        E, cum = matrix_from_quat(o[:, :4]), self.R0 @ matrix_from_quat(o[:, 8:])
        Xs = cum @ np.swapaxes(E, 1, 2)
        if smooth and len(dg):
            Xs, Ps = self._smooth(dg, Xs, Ps)
            E = np.swapaxes(Xs, 1, 2) @ cum
        a = 0.5 * (Ps[:, 0, 0] + Ps[:, 1, 1])
        E, Ps, cum = (hold_skipped(v, good, s) for v, s in zip((E, Ps, cum), start, strict=True))
        n = len(good)
        var_max = np.full(n, np.inf)
        stds = np.full((n, 2), np.nan)                  # (a skipped frame has none, as in step)
        var = self.sigma.track(a)
        var_max[good], stds[good] = var.max(axis=1), np.sqrt(var)
        codes = self.sigma.statuses(var_max, em.stationary, em.valid, good)
        return GroundTrack.from_residuals(E, cum @ np.swapaxes(E, 1, 2), Ps, cum, self._Rgs,
                                          self.extrinsic.translation, em.t, np.asarray(em.valid, bool) & good,
                                          pitch_std=stds[:, 0], roll_std=stds[:, 1], status=codes,
                                          status_reason=track_reasons(
                                              codes, np.sqrt(var_max), em.delta_t,
                                              np.where(codes == OK, NO_ROAD_REASON, np.array(None, dtype=object)),
                                              converged_std=FILTER_CONVERGED_STD))

    def _smooth(self, d: np.ndarray, Xs: np.ndarray, Ps: np.ndarray):
        """Rauch-Tung-Striebel smoother on the group over the forward pass (sensor increments ``d``)."""
        db = d if self._Rgs is None else self._Rgs @ d @ self._Rgs.T
        T = so3.rotz(twist_angle(db)) if self.follow_heading else np.broadcast_to(_I3, db.shape)
        smoother = InvariantEKF(Q=self._Q, R=self._R, error="left")
        Xsm, Psm, _, _ = smoother.rts_smoother(Xs, Ps, us=T)
        return Xsm, Psm
