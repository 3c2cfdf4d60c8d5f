r"""Suspension-aware ground normal: the road's slow attitude plus the body's load-transfer tilt.

The paper's filter (:class:`~imu_ground.filters.ground.GroundNormalFilter`) splits the attitude into
road and body by frequency alone, so body tilt that lasts (a braking's nose dive, the roll through a
long bend) leaks into the "road". The body's tilt relative to the road follows the load on the
suspension, which the accelerometer measures. Frames and signs as in :mod:`imu_ground.filters.estimator`;
forces in the body frame (FLU), m/s^2.

Pipeline, per frame k
---------------------
1. **Gravity and velocity** (:class:`~imu_ground.filters.gravity_velocity.GravityVelocityFilter`):
   the speed, the gravity-compensated acceleration ``a`` and the specific force ``f`` (frame means).
2. **Suspension model** (:mod:`~imu_ground.filters.suspension_model`): the load
   ``u = a + s (f - a)`` (``s = load``; ``a_y`` from speed times yaw rate per ``lateral``), optionally
   through a second-order ``response``; the body tilt relative to the road
   ``b_k = [k_roll u_y, k_pitch u_x + k_cross u_y, 0]`` (rotation vector); gains fixed or online.
3. **Invariant EKF on SO(3)** (left error, the scalar :class:`~imu_ground.filters.residual.ResidualKernel`)
   on the road attitude ``X``: predict ``X <- X Rz(psi_k)`` with noise ``diag(q_k, q_k, q_yaw)``,
   ``q_k = ((q_time + q_dist |v_k|) dt_k + q_turn |psi_k|) sigma_e^2``; update with
   ``Z_k = R_k Exp(-b_k)``, noise ``diag(sigma_e^2, sigma_e^2, r_yaw sigma_e^2)``.
4. **Output** ``E_k = X_k^T R_k``: the modelled tilt plus the unmodelled fast body motion, with the
   1-sigma and status (:mod:`~imu_ground.filters.status`), the road's grade and bank
   (:mod:`~imu_ground.filters.road`) and the mount monitor (:mod:`~imu_ground.filters.mount_monitor`).

Speed-aided (``speed=``): a measured forward speed (m/s, NaN where unknown) is a velocity measurement
of the gravity/velocity filter and the speed in ``q_k``. Online gains: causal recursive least squares
of the band-passed gyro tilt on the band-passed acceleration, the prior weighted like ``gain_prior_seconds``
of typical driving. Offline (``run(..., smooth=True)``): gravity and speed from the linear RTS smoother, then
the forward attitude filter and its RTS smoother on the group, blended ``X = X_f Exp(w Log(X_f^T X_s))``,
``w = smoother_weight``.

:meth:`~SuspensionAwareFilter.step` and :meth:`~SuspensionAwareFilter.run` drive the same component
bodies (a frame, or a compiled loop over the batch); the components keep and save their own state.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from typing import Optional, Sequence, Union

import numpy as np

from imu_ground import so3
from imu_ground.filters.estimator import GroundEstimate, SuspensionTrack, as_egomotion
from imu_ground.filters.extrinsics import resolve_platform
from imu_ground.filters.frame_checks import (
    check_on_invalid,
    checked_frame,
    checked_frames,
    frames_of,
    hold_skipped,
    static_rotation,
)
from imu_ground.filters.gains import DEFAULT_CROSS_GAIN, DEFAULT_GAINS, GAIN_BAND, bandpass_gain_regression
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.invariant_ekf import InvariantEKF
from imu_ground.filters.mount_monitor import WINDOW as MONITOR_WINDOW
from imu_ground.filters.mount_monitor import MountMonitor
from imu_ground.filters.recalibration import MountRecalibrator
from imu_ground.filters.residual import ResidualKernel
from imu_ground.filters.residual import frame as residual_frame
from imu_ground.filters.road import NO_SPEED_REASON, RoadFilter, road_one
from imu_ground.filters.status import (CONVERGED_MOVING_SECONDS, CONVERGED_STD, DEGRADED, OK, SLOW_SPEED, SUSPENSION_STD, SigmaModel,
                                       frame_status_code, ok_note, track_reasons)
from imu_ground.filters.suspension_model import SuspensionModel, load_share
from imu_ground.imu.egomotion import EgoFrame
from imu_ground.imu.warm_start import STATE_VERSION, StateError, StateReader, pack_state, unpack_state
from imu_ground.so3 import heading_change, matrix_from_quat, quat_from_matrix, twist_angle
from imu_ground.units import DEG

__all__ = [
    "DEFAULT_CROSS_GAIN",
    "DEFAULT_GAINS",
    "GAIN_BAND",
    "MAX_MEASURED_SPEED",
    "ROAD_THREAD_FRAMES",
    "SuspensionAwareFilter",
    "SuspensionTrack",
    "bandpass_gain_regression",
]

_I3 = np.eye(3)
#: A measured speed beyond this, m/s (or not finite), is no measurement: the frame runs on the IMU alone.
MAX_MEASURED_SPEED = 1e3
#: Frames of a batch from which :meth:`SuspensionAwareFilter.run` runs the road's gravity pass in a second thread.
ROAD_THREAD_FRAMES = 2000
_LATERAL = ("auto", "kinematic", "accelerometer")


class SuspensionAwareFilter:
    r"""Ground normal with a suspension model: an invariant EKF on the road attitude, filterpy style.

    The model is in the module docstring; the defaults are the KITTI car's (OXTS RT3003, FLU, identity extrinsic).

    Parameters
    ----------
    gains : (float, float)
        ``(k_pitch, k_roll)``, rad per m/s^2 (:data:`~imu_ground.filters.gains.DEFAULT_GAINS`); with
        ``online_gains`` the prior.
    sigma_e : float
        Std of the unmodelled body motion per frame, rad (0.2 deg).
    q_time, q_dist, q_turn : float
        Road process noise, units of ``sigma_e^2`` per second, per metre and per radian of heading change.
    q_yaw : float
        Process noise about up per frame, rad^2.
    r_yaw, P0 : float
        Measurement noise about up and initial variance of the road attitude, units of ``sigma_e^2``.
    load : {"specific_force", "acceleration"} or float
        Share ``s`` (0 to 1) of gravity's road-plane component in the load (``"specific_force"``: 1, the default).
    response : (float, float), optional
        Second-order response ``(freq_hz, damping)`` (unit static gain) of the load; None: quasi-static.
    online_gains, gain_prior_seconds, gain_band : bool, float, (float, float)
        Estimate the gains online; the prior's weight (s of typical driving); the regression's band, Hz.
    frame_rate : float, optional
        Hz, of the discrete-time design and of the preintegration of an ImuData given to :meth:`run`. Default:
        the ego-motion's rate (or ``1 / delta_t`` of the first frame given to :meth:`step`).
    smoother_weight : float
        Offline mode: weight of the RTS smoother against the forward filter (1 = pure smoother).
    extrinsic : Extrinsic, ndarray (3, 3), str or Path, optional
        Static ground <- sensor extrinsic (identity), a shipped name or a calibration file
        (:func:`~imu_ground.filters.extrinsics.resolve_platform`; its gains are used unless ``gains`` is given).
    lever_arm : array_like (3,), optional
        Sensor position relative to the body's pitch/roll centre, ground frame, m.
    gravity, R0 : dict, ndarray (3, 3), optional
        Options of the :class:`~imu_ground.filters.gravity_velocity.GravityVelocityFilter`; initial attitude
        world <- body.
    on_invalid : {"raise", "skip"}
        A bad frame raises ``ValueError`` (state unchanged) or is skipped (the previous estimate, ``valid=False``).
    cross_gain : float
        ``k_cross``, rad per m/s^2 (:data:`~imu_ground.filters.gains.DEFAULT_CROSS_GAIN`; 0 disables).
    lateral : {"auto", "kinematic", "accelerometer"}
        The lateral acceleration in the load ``u_y``: ``"kinematic"`` is ``v psi_k / dt`` (the
        measured speed where given, else the estimated), ``"accelerometer"`` the gravity-compensated
        ``a_y``; ``"auto"``: kinematic on frames with a measured speed, accelerometer elsewhere.
    recalibrate_online : bool
        Re-estimate the mount after the mount monitor's alarm (:mod:`imu_ground.filters.recalibration`);
        ``run`` then steps frame by frame (no ``smooth``).

    Attributes
    ----------
    x, P, Q, R, K, y, S, x_prior, P_prior, x_post, P_post : ndarray
        filterpy-style; ``Q`` and ``R`` the configured noises, ``Q_last`` the last frame's process noise.
    gains : ndarray (2,)
        Current ``(k_pitch, k_roll)``, rad per m/s^2 (the model's).
    model, sigma, road_filter, mount_monitor, recalibrator, gravity_filter
        The components: SuspensionModel, SigmaModel, RoadFilter, MountMonitor, MountRecalibrator (None
        without ``recalibrate_online``), GravityVelocityFilter (module docstring).
    cumulative, last_load, speed
        ``R_k`` (world <- body); the last frame's load (m/s^2) and speed (m/s).
    """

    def __init__(self, gains: Optional[Sequence[float]] = None, sigma_e: float = 0.2 * DEG,
                 q_time: float = 0.1, q_dist: float = 0.1, q_yaw: float = 1.0, r_yaw: float = 1e-6,
                 P0: float = 1.0, load: Union[str, float] = 1.0, response: Optional[Sequence[float]] = None,
                 online_gains: bool = False, gain_prior_seconds: float = 60.0,
                 gain_band: Sequence[float] = GAIN_BAND, frame_rate: Optional[float] = None,
                 smoother_weight: float = 0.25, extrinsic=None,
                 lever_arm: Optional[Sequence[float]] = None, gravity: Optional[dict] = None,
                 R0: Optional[np.ndarray] = None, on_invalid: str = "raise",
                 cross_gain: float = DEFAULT_CROSS_GAIN, lateral: str = "auto", q_turn: float = 10.0,
                 recalibrate_online: bool = False) -> None:
        self.recalibrate_online = bool(recalibrate_online)
        self.cross_gain = float(cross_gain)
        if lateral not in _LATERAL:
            raise ValueError(f"lateral must be one of {', '.join(_LATERAL)}, got {lateral!r}")
        self.lateral = lateral
        self.extrinsic, file_gains = resolve_platform(extrinsic)
        if gains is None:
            gains = DEFAULT_GAINS if file_gains is None else file_gains
        self.gains0 = np.array(gains, dtype=float).reshape(2)
        self.sigma_e = float(sigma_e)
        self.q_time, self.q_dist, self.q_turn = float(q_time), float(q_dist), float(q_turn)
        self.q_yaw, self.r_yaw, self.P0 = float(q_yaw), float(r_yaw), float(P0)
        if not (min(self.sigma_e, self.q_yaw, self.r_yaw, self.P0) > 0
                and min(self.q_time, self.q_dist, self.q_turn) >= 0):
            raise ValueError("sigma_e, q_yaw, r_yaw and P0 must be positive; q_time, q_dist and q_turn non-negative")
        self.load = load
        self.load_share = load_share(load)
        self.response = None if response is None else (float(response[0]), float(response[1]))
        self.online_gains = bool(online_gains)
        self.gain_prior_seconds = float(gain_prior_seconds)
        self.gain_band = (float(gain_band[0]), float(gain_band[1]))
        self.frame_rate = None if frame_rate is None else float(frame_rate)
        if not 0.0 <= smoother_weight <= 1.0:
            raise ValueError(f"smoother_weight must be in [0, 1], got {smoother_weight!r}")
        self.smoother_weight = float(smoother_weight)
        self.on_invalid = check_on_invalid(on_invalid)
        self._Rgs = static_rotation(self.extrinsic)
        self.lever_arm = None if lever_arm is None else np.asarray(lever_arm, dtype=float).reshape(3)
        self._gravity_kw = dict(gravity or {})
        self.R0 = _I3.copy() if R0 is None else np.array(R0, dtype=float)
        self._r = self.sigma_e ** 2
        self.reset()

    @classmethod
    def from_calibration(cls, calibration, **kwargs) -> "SuspensionAwareFilter":
        """A filter with the extrinsic and fixed gains of a calibration (keyword arguments override)."""
        kw = calibration.filter_kwargs()
        kw.update(kwargs)
        return cls(**kw)

    def reset(self) -> None:
        """Back to the initial state (attitude R0, prior gains, fresh gravity filter)."""
        r = self._r
        self._Rgs = static_rotation(self.extrinsic)
        self._kernel = k = ResidualKernel(self.P0 * r, self.P0 * r, r, self.r_yaw * r, Rgs=self._Rgs)
        self._kbuf, self._kcheck = k.buf, k.check
        self.gravity_filter = GravityVelocityFilter(R0=self.R0, extrinsic=self.extrinsic,
                                                    lever_arm=self.lever_arm, **self._gravity_kw)
        self.model = SuspensionModel(self.gains0, self.load_share, self.response, self.cross_gain,
                                     self.online_gains, self.gain_prior_seconds, self.gain_band, self._Rgs)
        self.sigma = SigmaModel(SUSPENSION_STD, CONVERGED_STD, self.load_share, self.cross_gain,
                                CONVERGED_MOVING_SECONDS)
        self.speed = 0.0
        self._q_last = 0.0
        self._frames = 0
        self.road_filter = RoadFilter(self.extrinsic, self.lever_arm, self._gravity_kw)
        self.mount_monitor = MountMonitor()
        self.recalibrator = MountRecalibrator(self.extrinsic.translation) if self.recalibrate_online else None
        self._time = 0.0                            # s since the start or a reset
        if self.frame_rate is not None:
            self.model.design(self.frame_rate)

    cumulative = property(lambda self: self.gravity_filter.cumulative,
                          doc="Cumulative body attitude R_k, world <- body (3x3).")
    Q = property(lambda self: np.diag([self.q_time * self._r, self.q_time * self._r, self.q_yaw]),
                 doc="Configured process noise (horizontal rad^2/s at standstill, up rad^2 per frame).")
    R = property(lambda self: np.diag([self._r, self._r, self.r_yaw * self._r]),
                 doc="Configured measurement noise (rad^2).")
    last_load = property(lambda self: np.array(self.model.load), doc="Load of the last frame (u_x, u_y), m/s^2.")
    gains = property(lambda self: self.model.gains, doc="Current (k_pitch, k_roll), rad per m/s^2.")
    Q_last = property(lambda self: np.diag([self._q_last, self._q_last, self.q_yaw]),
                      doc="Process noise of the last frame's predict (rad^2).")

    residual = property(lambda self: self._kernel.residual_matrix(), doc="``E_k``, road <- body (3x3).")
    x = property(lambda self: self.cumulative @ self.residual.T, doc="Slow road attitude X_k, world <- road (3x3).")
    P = property(lambda self: self._kernel.covariance(), doc="Covariance of X, body tangent space (rad^2).")

    x_post = x
    P_post = P

    def _last(self, i: int | slice, default):
        last = self._kernel.last
        return default if last is None else last[i]

    K = property(lambda self: np.diag([self._last(0, 0.0)] * 2 + [self._last(1, 0.0)]), doc="Last Kalman gain.")
    y = property(lambda self: np.array(self._last(slice(4, 7), (0.0, 0.0, 0.0))), doc="Last innovation (rad).")
    S = property(lambda self: np.diag([self._last(2, 0.0)] * 2 + [self._last(3, 0.0)]) + self.R,
                 doc="Last innovation covariance (rad^2).")
    P_prior = property(lambda self: np.diag([self._last(2, self._kernel.a)] * 2 + [self._last(3, self._kernel.c)]),
                       doc="P after the last predict.")

    @property
    def x_prior(self) -> np.ndarray:
        """X after the last predict."""
        m = self._last(slice(7, 11), None)
        return self.x if m is None else self.cumulative @ matrix_from_quat(np.array(m)).T

    def _settings(self) -> dict:
        return dict(gains=self.gains0, sigma_e=self.sigma_e, q_time=self.q_time, q_dist=self.q_dist,
                    q_yaw=self.q_yaw, r_yaw=self.r_yaw, P0=self.P0, load=self.load_share, response=self.response,
                    online_gains=self.online_gains, gain_prior_seconds=self.gain_prior_seconds,
                    gain_band=self.gain_band, frame_rate=self.frame_rate, smoother_weight=self.smoother_weight,
                    extrinsic=self.extrinsic.settings(), lever_arm=self.lever_arm, gravity=dict(self._gravity_kw),
                    R0=self.R0, on_invalid=self.on_invalid, cross_gain=self.cross_gain, lateral=self.lateral,
                    q_turn=self.q_turn, **({"recalibrate_online": True} if self.recalibrate_online else {}))

    def state_dict(self) -> dict:
        """The state as a JSON-serialisable dict (:mod:`imu_ground.imu.warm_start`), for :meth:`load_state_dict`
        with the same settings: the kernels' buffers whole (a resumed run continues bit for bit) and the
        components' states."""
        st = {"frames": self._frames, **self.sigma.state_dict(), "kernel": list(self._kernel.buf),
              "gravity": self.gravity_filter.kernel_state(), **self.model.state_dict(), "speed": self.speed,
              "q_last": self._q_last, **self.road_filter.state_dict(), "monitor": self.mount_monitor.state_dict(),
              "time": self._time}
        if self.recalibrator is not None:
            st["recalibrator"] = self.recalibrator.state_dict()
            st["mount"] = None if self._Rgs is None else self._Rgs.ravel().tolist()
        return pack_state("SuspensionAwareFilter", STATE_VERSION, self._settings(), st)

    def load_state_dict(self, state: dict) -> None:
        """Resume from a :meth:`state_dict`.

        Raises
        ------
        StateError
            (a ValueError) A state of another estimator, layout or settings (each differing setting named), or
            a corrupt one (the entry named); the filter is then as after :meth:`reset`.
        """
        st = StateReader("SuspensionAwareFilter",
                         unpack_state(state, "SuspensionAwareFilter", STATE_VERSION, self._settings()))
        frames, kernel = st.int("frames"), self._kernel.read_state(st, "kernel")
        gravity = self.gravity_filter.read_kernel_state(st, "gravity")
        assert gravity is not None
        speed, q_last, time = st.float("speed"), st.float("q_last"), st.float("time")
        mount = None if self.recalibrator is None else st.floats("mount", (9,), optional=True)
        mount = None if mount is None else mount.reshape(3, 3)
        if mount is not None and not (np.abs(mount.T @ mount - _I3).max() < 1e-9 and np.linalg.det(mount) > 0):
            raise st.error("mount", "is not a rotation matrix")
        self.reset()
        try:
            self.model.load_state_dict(st)
            self.sigma.load_state_dict(st)
            self.road_filter.load_state_dict(st)
            self.mount_monitor.load_state_dict(st.part("monitor"))
            if self.recalibrator is not None:
                self.recalibrator.load_state_dict(st.part("recalibrator"))
        except StateError:
            self.reset()
            raise
        self._kernel.load(kernel)
        self._kbuf = self._kernel.buf
        self.gravity_filter.load_kernel_state(gravity)
        self._frames, self.speed, self._q_last, self._time = frames, speed, q_last, time
        if mount is not None:
            self._set_mount(mount)

    def _road_noise(self, speed, dt, psi):
        """``q_k`` of the module docstring (rad^2), floats or arrays alike."""
        return ((self.q_time + self.q_dist * abs(speed)) * dt + self.q_turn * abs(psi)) * self._r

    @staticmethod
    def _checked_speed(speed, n: int) -> Optional[np.ndarray]:
        """``speed`` as floats, one per frame (else ValueError), or None."""
        if speed is None:
            return None
        speed = np.asarray(speed, dtype=float)
        if speed.shape != (n,):
            raise ValueError(f"speed must have one value per frame ({n}), got shape {speed.shape}")
        return speed

    def step(self, frame, delta_v=None, delta_t: Optional[float] = None, stationary: bool = False,
             valid: bool = True, speed: Optional[float] = None) -> GroundEstimate:
        """Process one frame of ego-motion.

        Parameters
        ----------
        frame : EgoFrame, PreintegratedImu or ndarray (3, 3)
            An :class:`~imu_ground.imu.egomotion.EgoFrame` (or a frame of the
            :class:`~imu_ground.imu.preintegration.StreamingPreintegrator`), or its ``delta_R``
            (sensor_{k-1} <- sensor_k) followed by the other fields:
        delta_v, delta_t, stationary, valid
            As in :meth:`~imu_ground.filters.gravity_velocity.GravityVelocityFilter.step`.
        speed : float, optional
            Measured forward speed over the frame (wheel / CAN), m/s; None, NaN, infinite or beyond
            :data:`MAX_MEASURED_SPEED`: IMU only.

        Returns
        -------
        GroundEstimate
            The residual road <- body after this frame; a skipped bad frame gives the previous one, ``valid=False``.

        Raises
        ------
        ValueError
            A bad frame with ``on_invalid="raise"`` (the state is unchanged).
        """
        if delta_v is None:
            if type(frame) is not EgoFrame:         # (an EgoFrame has the five fields)
                if not isinstance(frame, (tuple, list, np.ndarray)) and hasattr(frame, "delta_v"):
                    frame = EgoFrame.of(frame)      # a PreintegratedImu
                elif isinstance(frame, np.ndarray) or not isinstance(frame, (tuple, list)) or len(frame) < 5:
                    shape = getattr(np.asarray(frame, dtype=object), "shape", ())
                    raise ValueError("SuspensionAwareFilter.step needs an EgoFrame (delta_R, delta_v, delta_t, "
                                     "stationary, valid) with accelerometer data, or step(delta_R, delta_v, "
                                     f"delta_t): got {type(frame).__name__} of shape {shape} alone; a rotation "
                                     "alone has no accelerometer data (use GroundNormalFilter for rotations only)")
            d, delta_v, delta_t, stationary, valid = frame[:5]
        else:
            d = frame
        if delta_t is None:
            raise ValueError("SuspensionAwareFilter.step needs the frame duration delta_t, s")
        checked = checked_frame(self._kcheck, frame, d, delta_v, delta_t, self.on_invalid, self._frames)
        if checked is None:
            return GroundEstimate.of_residual(self.residual, self.P, self._Rgs, valid=False)
        d, dv = checked
        dt = float(delta_t)
        model = self.model
        if model.rate is None:
            model.design(1.0 / dt)
        self._frames += 1
        gf = self.gravity_filter
        sp = math.nan if speed is None else float(speed)
        if not abs(sp) <= MAX_MEASURED_SPEED:
            sp = math.nan                           # infinite or absurd: no measurement (NaN stays NaN)
        stationary, valid = bool(stationary), bool(valid)
        force, (ax, ay, _), v = gf.step_sensor(d, dv, dt, stationary, valid, sp)
        fx, fy = force[0], force[1]
        road = None
        if sp == sp or self.road_filter.gravity_filter is not None:
            road = self.road_filter.step(d, dv, dt, stationary, valid, sp)
        self._time += dt
        mm = self.mount_monitor
        alarm = mm.alarm
        if alarm is None and (road is not None or mm.engaged):
            alarm = mm.update(self._time, None if road is None else road[0], valid and sp == sp)
        self.speed = speed = v if math.isnan(sp) else sp
        psi = heading_change(d, self._Rgs)
        if self.recalibrator is not None:
            alarm = self._recalibrate(dt, force, sp, psi, road, valid, alarm)
        lateral = self.lateral
        kinematic = lateral == "kinematic" or (lateral == "auto" and sp == sp)
        weights = model.tilt_weights                # (the gains used at this frame)
        tilt_x, tilt_y = model.step(d, fx, fy, ax, ay, speed * psi / dt if kinematic else None)
        ux, uy = model.load
        q = self._road_noise(speed, dt, psi)
        self._q_last = q
        o = residual_frame(self._kbuf, d, q, self.q_yaw, True, tilt_x, tilt_y, True)   # d checked above
        if road is not None:
            road = road_one(o, *road)
        recal = None if self.recalibrator is None else self.recalibrator.note
        note = alarm if alarm is not None else ok_note(abs(speed) < SLOW_SPEED,
                                                        recal if road is not None else NO_SPEED_REASON)
        Rgs, sigma = self._Rgs, self.sigma
        sigma.drive.update(d, dt, speed, stationary, valid, ux, uy, Rgs)
        info = sigma.frame(o[4], ux, uy, gf.horizontal_gravity_variance(), weights, dt, note, abs(psi) / dt)
        code = frame_status_code(sigma.converged, stationary, valid, alarm is not None)
        return GroundEstimate(o[6], o[7], True, o, None, Rgs, o, code, info, road)

    def run(self, egomotion, smooth: bool = False, speed: Optional[np.ndarray] = None) -> SuspensionTrack:
        """Process a whole drive, continuing from the current state as :meth:`step` would (the same kernel).

        Parameters
        ----------
        egomotion : EgoMotion or ImuData
            Per-frame ego-motion, sensor frame (an ImuData is preintegrated at ``frame_rate``, default 10 Hz).
        smooth : bool
            Offline mode (module docstring); the streaming state is left at the end of the forward pass.
        speed : ndarray (N,), optional
            Measured forward speed per frame (e.g. :func:`imu_ground.datasets.speed.frame_speed`), m/s; NaN: none.

        Returns
        -------
        SuspensionTrack
            With the ego-motion's times and validity (False also on skipped frames).

        Raises
        ------
        ValueError
            A bad frame with ``on_invalid="raise"`` (nothing processed), or another frame rate than the design's.
        """
        em = as_egomotion(egomotion, rate=self.frame_rate)
        if self.recalibrator is not None:
            if smooth:
                raise ValueError("online mount re-estimation (recalibrate_online) runs frame by frame: it cannot "
                                 "be combined with the offline smoother (smooth=True)")
            return self._run_by_steps(em, speed)
        n = len(em)
        good = checked_frames(em.delta_R, em.delta_v, em.delta_t, em.t, self.on_invalid)
        self.model.design(float(em.rate))
        start = dict(E=self.residual, P=self.P, cum=self.cumulative.copy(), load=self.last_load,
                     speed=self.speed, gains=self.gains.copy(), gravity=self.gravity_filter.x[3:].copy())
        sub = em if good.all() else frames_of(em, good)
        m = len(sub)
        speed = self._checked_speed(speed, n)
        if speed is not None:
            speed = speed[good]
            speed = np.where(np.abs(speed) <= MAX_MEASURED_SPEED, speed, np.nan)
        self._frames += m
        # the road's gravity pass depends on nothing below: on a long batch it runs in a second thread
        road = speed is not None or self.road_filter.gravity_filter is not None
        sp = np.full(m, np.nan) if speed is None else speed
        with ThreadPoolExecutor(1) if road and m >= ROAD_THREAD_FRAMES else nullcontext() as pool:
            road_pass = pool.submit(self.road_filter.gravity_pass, sub, sp).result if pool else None
            return self._run_filters(em, sub, good, start, speed, smooth, road, road_pass)

    def _run_filters(self, em, sub, good: np.ndarray, start: dict, speed: Optional[np.ndarray], smooth: bool,
                     road: bool, road_pass) -> SuspensionTrack:
        """The rest of :meth:`run` on the good frames ``sub`` (``road_pass``: the road's gravity pass or None)."""
        m = len(sub)
        gt = self.gravity_filter.run(sub, smooth=smooth, speed=speed)
        if speed is not None:
            gt.speed = np.where(np.isfinite(speed), speed, gt.speed)
        psi = twist_angle(gt.body_increments)
        lateral = None
        if self.lateral != "accelerometer" and m:
            use = np.full(m, self.lateral == "kinematic") if speed is None else \
                (self.lateral == "kinematic") | np.isfinite(speed)
            lateral = np.where(use, gt.speed * psi / np.asarray(sub.delta_t, dtype=float), np.nan)
        u, ks, susp = self.model.run(gt, lateral)
        if m:
            self.speed = float(gt.speed[-1])
        dt = np.asarray(sub.delta_t, dtype=float)
        q = self._road_noise(gt.speed, dt, psi)
        o = self._kernel.run(sub.delta_R, q, self.q_yaw, susp[:, 1], susp[:, 0])
        if m:
            self._q_last = float(q[-1])
        E = matrix_from_quat(o[:, :4])
        Ps = np.zeros((m, 3, 3))
        Ps[:, 0, 0] = Ps[:, 1, 1] = o[:, 4]
        Ps[:, 2, 2] = o[:, 5]
        cum = gt.cumulative
        qE = o[:, :4]
        if smooth and m:
            Xs = self._smooth(gt.body_increments, cum @ np.swapaxes(E, 1, 2), Ps, q)
            E = np.swapaxes(Xs, 1, 2) @ cum
            qE = quat_from_matrix(E)
        held = {name: hold_skipped(v, good, start[name]) for name, v in
                dict(E=E, P=Ps, cum=cum, load=u, speed=gt.speed, gains=ks, gravity=gt.gravity).items()}
        extra = self._track_confidence(em, sub, good, Ps[:, 0, 0], u, ks, gt.P, qE, speed, psi / dt, gt.speed, road,
                                       road_pass)
        susp_all = self.model.tilt(held["gains"], held["load"])
        cum_all = held["cum"]
        return SuspensionTrack.from_residuals(
            held["E"], cum_all @ np.swapaxes(held["E"], 1, 2), held["P"], cum_all, self._Rgs,
            self.extrinsic.translation, em.t, np.asarray(em.valid, dtype=bool) & good,
            load=held["load"], speed=held["speed"], gains=held["gains"], suspension=susp_all,
            gravity=held["gravity"], **extra)

    def _smooth(self, db: np.ndarray, Xs: np.ndarray, Ps: np.ndarray, q: np.ndarray) -> np.ndarray:
        """RTS smoother on the group over the forward pass, blended with ``smoother_weight``."""
        n = len(Xs)
        Qs = np.zeros((n, 3, 3))
        Qs[:, 0, 0] = Qs[:, 1, 1] = q
        Qs[:, 2, 2] = self.q_yaw
        smoother = InvariantEKF(Q=self.Q_last, R=self.R, error="left")
        Xsm, Psm, _, _ = smoother.rts_smoother(Xs, Ps, us=so3.rotz(twist_angle(db)), Qs=Qs)
        w = self.smoother_weight
        if w == 1.0:
            Ps[:] = Psm
            return Xsm
        if w > 0.0:
            Ps[:] = (1.0 - w) * Ps + w * Psm
            return Xs @ so3.exp(w * so3.log(np.swapaxes(Xs, 1, 2) @ Xsm))
        return Xs

    def _track_confidence(self, em, sub, good: np.ndarray, a: np.ndarray, load: np.ndarray, gains: np.ndarray,
                          gravity_cov: np.ndarray, q: np.ndarray, speed: Optional[np.ndarray], yaw_rate: np.ndarray,
                          speed_used: np.ndarray, road_on: bool, road_pass=None) -> dict:
        """A batch's 1-sigma, road and status fields; the components advance as the frames would."""
        n, m = len(good), len(sub)
        drive = self.sigma.drive.run(sub.delta_R, sub.delta_t, speed_used, sub.stationary, sub.valid, load, self._Rgs)
        var = self.sigma.track(a, load, gains, gravity_cov, yaw_rate, drive)
        var_max = np.full(n, np.inf)
        std = np.full((n, 2), np.nan)
        var_max[good], std[good] = var.max(axis=1), np.sqrt(var)
        road = np.full((n, 4), np.nan)
        sp = np.full(m, np.nan) if speed is None else speed
        rg = np.full((m, 3), np.nan)
        if road_on:
            road[good], rg = self.road_filter.run(sub, sp, q, np.sqrt(var[:, 0]), np.sqrt(var[:, 1]), road_pass)
        times = np.cumsum(np.concatenate([[self._time], np.asarray(sub.delta_t, dtype=float)]))[1:]
        if m:
            self._time = float(times[-1])
        mm = self.mount_monitor
        degraded = np.zeros(n, dtype=bool)
        degraded[good] = mm.run(times, rg, np.asarray(sub.valid, dtype=bool) & np.isfinite(sp))
        latch = np.full(n, np.inf)
        latch[good] = self.sigma.latch_variance(a, load, gains, gravity_cov, yaw_rate, drive[:, 0])
        codes = self.sigma.statuses(latch, em.stationary, em.valid, good, degraded)
        slow = np.zeros(n, dtype=bool)
        slow[good] = np.abs(speed_used) < SLOW_SPEED
        no_road = np.isnan(road[:, 0])
        notes = np.array([ok_note(s_, r_) for s_ in (False, True) for r_ in (None, NO_SPEED_REASON)], dtype=object)
        details = np.where(degraded, mm.alarm, notes[2 * slow + no_road])
        reasons = track_reasons(codes, np.sqrt(var_max), em.delta_t,
                                np.where((codes == OK) | (codes == DEGRADED), details, np.array(None, dtype=object)),
                                moving_seconds=self.sigma.min_moving_seconds)
        return dict(pitch_std=std[:, 0], roll_std=std[:, 1], status=codes, status_reason=reasons,
                    road_grade=road[:, 0], road_bank=road[:, 1], road_grade_std=road[:, 2], road_bank_std=road[:, 3])

    def _recalibrate(self, dt: float, force, speed: float, psi: float, road, valid: bool, alarm):
        """One frame of the online re-estimation (:mod:`imu_ground.filters.recalibration`); returns the alarm
        still standing (None once re-estimated)."""
        r = self.recalibrator
        assert r is not None
        r.record(self._time, dt, force, speed, psi, road, valid)
        if alarm is None:
            return None
        mm = self.mount_monitor
        if not r.ready(mm.alarm_t, dt, valid and road is not None):
            return alarm
        est = r.estimate(mm.reference, mm.alarm_t - MONITOR_WINDOW)
        if est is None:
            return alarm
        delta, w = est
        self._apply_mount_change(delta, w, mm.reference)
        mm.reset()
        r.accept(delta, self._time)
        return None

    def _apply_mount_change(self, delta: np.ndarray, w: np.ndarray, reference) -> None:
        """``R_gs <- Exp(delta) R_gs`` in every component; ``w`` the world tilt and ``reference`` the gravity
        before the change (:mod:`imu_ground.filters.recalibration`)."""
        D = so3.exp(np.asarray(delta, dtype=float))
        Rgs = D @ (_I3 if self._Rgs is None else self._Rgs)
        gf = self.road_filter.gravity_filter
        assert gf is not None
        Rr = np.array(gf.gravity_snapshot()[1], dtype=float).reshape(3, 3)
        Rm = self.gravity_filter.cumulative.copy()
        up = so3.exp(np.asarray(w, dtype=float)) @ (np.asarray(reference, dtype=float) / np.linalg.norm(reference))
        self.road_filter.set_mount(Rgs, D, up)
        self.gravity_filter.set_mount(Rgs, D, Rm @ Rr.T @ up)    # (its world: Rm Rr^T <- the road filter's)
        self._kernel.set_mount(Rgs)
        self._Rgs = Rgs
        self.model.set_mount(Rgs)

    def _set_mount(self, Rgs: np.ndarray) -> None:
        """The static rotation in the Python objects (a warm start)."""
        self._Rgs = Rgs
        self.model.set_mount(Rgs)
        self.gravity_filter.set_mount(Rgs)
        self.road_filter.set_mount(Rgs)

    def _run_by_steps(self, em, speed: Optional[np.ndarray]) -> SuspensionTrack:
        """:meth:`run` frame by frame through :meth:`step` (online re-estimation), the same track fields."""
        n = len(em)
        checked_frames(em.delta_R, em.delta_v, em.delta_t, em.t, self.on_invalid)
        self.model.design(float(em.rate))
        speed = self._checked_speed(speed, n)
        E, P, cum, Rgs = (np.zeros((n, 3, 3)) for _ in range(4))
        load, gains, grav = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 3))
        sp, valid = np.zeros(n), np.zeros(n, dtype=bool)
        extra = {k: np.full(n, np.nan) for k in ("pitch_std", "roll_std", "road_grade", "road_bank",
                                                   "road_grade_std", "road_bank_std")}
        status, reasons = np.zeros(n, dtype=np.uint8), np.full(n, "", dtype=object)
        d, dv, dts = (np.asarray(a, dtype=float) for a in (em.delta_R, em.delta_v, em.delta_t))
        st, ok = np.asarray(em.stationary, dtype=bool), np.asarray(em.valid, dtype=bool)
        for k in range(n):
            gains[k] = self.gains
            est = self.step(d[k], dv[k], float(dts[k]), bool(st[k]), bool(ok[k]),
                            speed=None if speed is None else float(speed[k]))
            E[k], P[k], cum[k] = self.residual, self.P, self.cumulative
            Rgs[k] = _I3 if self._Rgs is None else self._Rgs
            load[k], sp[k], grav[k] = self.last_load, self.speed, self.gravity_filter.x[3:]
            valid[k] = est.valid and ok[k]
            status[k], reasons[k] = est.status_code, est.status_reason
            for key, v in extra.items():
                v[k] = getattr(est, key)
        return SuspensionTrack.from_residuals(
            E, cum @ np.swapaxes(E, 1, 2), P, cum, Rgs, self.extrinsic.translation, em.t, valid, load=load,
            speed=sp, gains=gains, suspension=self.model.tilt(gains, load), gravity=grav, status=status,
            status_reason=reasons, **extra)
