"""Gravity and velocity from an IMU alone, with vehicle constraints: a linear Kalman filter on frames.

Frames and signs follow the glossary of :mod:`imu_ground.so3`: world ``w`` is the
gyro-integrated body frame at the start (``R0 = R_{w<-body_0}``), body ``b`` FLU
(x forward, y left, z up), gravity stored as its reaction (+9.81 m/s^2 up at rest).

:meth:`GravityVelocityFilter.step` and ``run`` drive one compiled per-frame body
(:mod:`imu_ground.filters.gravity_kernel`), whose flat buffer is the filter's whole state.
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np

from imu_ground.filters import gravity_kernel
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.frame_checks import frame_problem
from imu_ground.filters.gravity_kernel import (
    _UPPER21,
    I_EXTR,
    I_LAST,
    I_QGAPG,
    I_REJECTED,
    I_WPREV,
    body_forces,
    body_increments,
    new_state,
)
from imu_ground.filters.gravity_kernel import full_cov as _full_cov
from imu_ground.imu.data import ImuData
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion
from imu_ground.imu.warm_start import STATE_VERSION, StateReader, buffer_like, pack_state, unpack_state
from imu_ground.so3 import as_rotations

__all__ = ["GravityEstimate", "GravityTrack", "GravityVelocityFilter", "egomotion_arrays"]

_I3 = np.eye(3)
_I_GXX, _I_GYY = 21, 24                 # the kernel's state: P[3, 3] and P[4, 4] (gravity_kernel's layout)


def egomotion_arrays(ego: Union[EgoMotion, ImuData]):
    """``(delta_R, delta_v, delta_t, stationary, valid)`` of an EgoMotion (an ImuData is preintegrated).

    Raises
    ------
    TypeError, ValueError
        Not an EgoMotion; inconsistent shapes; non-finite increments or non-positive durations.
    """
    if isinstance(ego, ImuData):
        ego = imu_to_egomotion(ego)
    if not isinstance(ego, EgoMotion):
        raise TypeError(f"expected an EgoMotion (or ImuData), got {type(ego).__name__}")
    d, dv, dt = (np.asarray(a, dtype=float) for a in (ego.delta_R, ego.delta_v, ego.delta_t))
    st, valid = (np.asarray(a, dtype=bool) for a in (ego.stationary, ego.valid))
    n = len(d)
    if d.shape != (n, 3, 3) or dv.shape != (n, 3) or dt.shape != (n,) or st.shape != (n,) or valid.shape != (n,):
        raise ValueError("EgoMotion arrays have inconsistent shapes")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(dv)) and np.all(dt > 0)):
        raise ValueError("EgoMotion has non-finite increments or non-positive frame durations")
    return d, dv, dt, st, valid


class GravityEstimate(NamedTuple):
    """One frame of :meth:`GravityVelocityFilter.step`.

    Attributes
    ----------
    velocity, gravity : ndarray (3,)
        m/s and the reaction to gravity (m/s^2), world frame.
    acceleration, specific_force : ndarray (3,)
        Gravity-compensated and as an accelerometer reads it: frame means, m/s^2, body frame at mid-frame.
    speed : float
        ``|velocity|``, m/s.
    """
    velocity: np.ndarray
    gravity: np.ndarray
    acceleration: np.ndarray
    specific_force: np.ndarray
    speed: float


@dataclass
class GravityTrack:
    """Per-frame results of :meth:`GravityVelocityFilter.run` (N frames).

    Attributes
    ----------
    velocity, gravity, acceleration, specific_force, speed : ndarray (N, 3) / (N,)
        As in :class:`GravityEstimate`, per frame.
    P : ndarray (N, 6, 6)
        Covariance of ``[v, g]``.
    cumulative, body_increments : ndarray (N, 3, 3)
        World <- body at the frame end; body_{k-1} <- body_k (extrinsic applied).
    """
    velocity: np.ndarray
    gravity: np.ndarray
    acceleration: np.ndarray
    specific_force: np.ndarray
    speed: np.ndarray
    P: np.ndarray
    cumulative: np.ndarray
    body_increments: np.ndarray


class GravityVelocityFilter:
    r"""IMU-only gravity and velocity with vehicle constraints (linear Kalman filter on frames).

    State ``x = [v_w, g_w]`` (velocity and reaction to gravity in the world
    frame, i.e. the body frame at the start ``R0``, carried by the
    gyro-integrated attitude ``R_k``, world <- body)::

        v_k = v_{k-1} + R_{k-1} dv_k - dt_k g_w      (dv_k: gravity-free velocity increment, body_{k-1})
        g_k = g_{k-1} + w_g                           (earth rate and gyro drift: a tiny random walk)

    observed by the non-holonomic constraint ``[e_y, e_z]^T R_k^T v_k = 0 + n`` (a car
    neither slides sideways nor moves vertically in its own frame) while moving, by ``v_k = 0 +
    n`` at standstill frames, or by a measured speed (``sigma_speed``). The constraint needs the
    body frame to be the vehicle's (FLU): give the ``extrinsic`` when it is mounted otherwise.

    Parameters
    ----------
    sigma_nhc, sigma_zupt : float
        Std of the body lateral and vertical velocity and of the velocity at standstill, m/s.
    q_v, q_g, q_gap, q_gap_g : float
        Velocity (m/s/sqrt(s)) and gravity (m/s^2/sqrt(s)) random walks, and the extra ones through a
        timestamp gap (``valid`` False).
    zupt_gate : float
        A standstill flag is ignored (the constraint used instead) beyond this squared Mahalanobis distance
        of the predicted velocity from zero.
    sigma_v0, sigma_g0, v0, g0
        Initial std of velocity (m/s) and gravity (m/s^2); initial velocity and gravity reaction
        (array_like (3,), world frame; default zero and the first frame's specific force).
    extrinsic, R0 : Extrinsic or ndarray (3, 3), optional
        Static ground <- sensor rotation (inputs are sensor-frame increments); initial attitude world <- body.
    lever_arm : array_like (3,), optional
        Sensor position relative to the body's pitch/roll centre, ground frame, m: the accelerations are moved
        there, ``f_0 = f_s - alpha x r - w x (w x r)`` (``w`` the frame's mean rate, ``alpha`` its backward
        difference).
    sigma_speed : float
        Std of a measured forward speed (``speed`` of :meth:`step` / :meth:`run`), m/s (at most 1000): the
        update is then ``R_k^T v = (speed, 0, 0)``, noise ``diag(sigma_speed^2, sigma_nhc^2, sigma_nhc^2)``.

    Attributes
    ----------
    x, P, cumulative : ndarray (6,), (6, 6), (3, 3)
        State, covariance, ``R_k`` (world <- body); ``x_prior``, ``P_prior``, ``x_post``, ``P_post``, ``F``,
        ``Q``, ``H``, ``R``, ``K``, ``y``, ``S`` of the last step (filterpy's names).
    zupt_rejected : int
        Standstill flags overruled by the gate so far.
    kernel : module
        :mod:`~imu_ground.filters.gravity_kernel` (class attribute).
    """

    kernel = gravity_kernel

    def __init__(self, sigma_nhc: float = 0.3, sigma_zupt: float = 0.05, q_v: float = 0.05,
                 q_g: float = 1e-6, q_gap: float = 1.0, q_gap_g: float = 0.1, sigma_v0: float = 30.0,
                 sigma_g0: float = 1.0,
                 zupt_gate: float = 100.0, v0: Optional[Sequence[float]] = None,
                 g0: Optional[Sequence[float]] = None, extrinsic: Union[Extrinsic, np.ndarray, None] = None,
                 lever_arm: Optional[Union[Sequence[float], np.ndarray]] = None, R0: Optional[np.ndarray] = None,
                 sigma_speed: float = 0.1) -> None:
        if not 0 < float(sigma_speed) <= 1e3:     # (larger: no information, and S ill-conditioned)
            raise ValueError(f"sigma_speed must be in (0, 1000] m/s (no speed: leave it out), got {sigma_speed!r}")
        self.sigma_speed, self.sigma_nhc, self.sigma_zupt = float(sigma_speed), float(sigma_nhc), float(sigma_zupt)
        self.q_v, self.q_g, self.q_gap, self.q_gap_g = float(q_v), float(q_g), float(q_gap), float(q_gap_g)
        self.sigma_v0, self.sigma_g0 = float(sigma_v0), float(sigma_g0)
        self.zupt_gate = float(zupt_gate)
        self.extrinsic = Extrinsic.coerce(extrinsic)
        self._Rgs = self.extrinsic.rotation
        self._identity_extrinsic = bool(np.array_equal(self._Rgs, _I3))
        self._rgs9 = self._Rgs.ravel().tolist()
        self.lever_arm = None if lever_arm is None else np.asarray(lever_arm, dtype=float).reshape(3)
        self._lever = None if self.lever_arm is None else tuple(self.lever_arm.tolist())
        self.R0 = _I3.copy() if R0 is None else np.array(R0, dtype=float)
        self._v0 = None if v0 is None else np.asarray(v0, dtype=float).reshape(3)
        self._g0 = None if g0 is None else np.asarray(g0, dtype=float).reshape(3)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state."""
        v = [0.0] * 3 if self._v0 is None else self._v0.tolist()
        g = [0.0] * 3 if self._g0 is None else self._g0.tolist()
        sv, sg = self.sigma_v0 ** 2, self.sigma_g0 ** 2
        p = [sv, 0.0, 0.0, sv, 0.0, sv] + [0.0] * 9 + [sg, 0.0, 0.0, sg, 0.0, sg]
        prm = (self.q_v ** 2, self.q_gap ** 2, self.q_g ** 2, self.sigma_zupt ** 2, self.sigma_nhc ** 2,
               self.zupt_gate, self.sigma_speed ** 2)
        s = new_state(v + g, p, self.R0.ravel().tolist(), prm, self._g0 is not None, self._lever,
                      None if self._identity_extrinsic else self._rgs9, self.q_gap_g ** 2)
        k = self.kernel
        self._s = np.array(s)
        self._step_frame, self._step_sensor, self._run_frames = k.step_frame, k.step_sensor, k.run_frames
        self._to_body = k.to_body
        self._w = SimpleNamespace(sync=None)

    @property
    def zupt_rejected(self) -> int:
        """Standstill flags overruled by the gate so far."""
        return int(self._s[I_REJECTED])

    # -- state as numpy arrays (built on access; in-place changes are seen by the next frame)
    def _pull(self) -> None:
        """Arrays handed out by ``x``, ``P`` or ``cumulative`` back into the buffer."""
        x, P, R = self._w.sync
        self._s[0:36] = x.tolist() + [float(P[i, j]) for i, j in _UPPER21] + R.ravel().tolist()
        self._w.sync = None

    def _arrays(self):
        if self._w.sync is None:
            s = self._s
            self._w.sync = (np.array(s[0:6]), _full_cov(np.array(s[6:27])), np.array(s[27:36]).reshape(3, 3))
        return self._w.sync

    def _set_array(self, i: int, value) -> None:
        a = self._arrays()[i]
        a[...] = np.asarray(value, dtype=float).reshape(a.shape)

    x = property(lambda self: self._arrays()[0], lambda self, v: self._set_array(0, v),
                 doc="State ``[v_w, g_w]`` (6,): velocity (m/s) and gravity reaction (m/s^2), world frame.")
    P = property(lambda self: self._arrays()[1], lambda self, v: self._set_array(1, v),
                 doc="Covariance of ``[v, g]`` (6, 6).")
    cumulative = property(lambda self: self._arrays()[2], lambda self, v: self._set_array(2, v),
                          doc="``R_k = R_{w<-body_k}`` (3, 3), the gyro-integrated attitude at the last frame's end.")
    x_prior = property(lambda self: np.array(self._last_step()[7][:6]), doc="State after the last predict (6,).")
    P_prior = property(lambda self: _full_cov(np.array(self._last_step()[7][6:27])), doc="P after the last predict.")
    x_post = property(lambda self: self.x.copy(), doc="State after the last update (6,).")
    P_post = property(lambda self: self.P.copy(), doc="P after the last update (6, 6).")

    def _last_step(self):
        """``(kind, K, y, S, dt, qv, qg, prior)`` of the last frame (kind 0 constraint, 1 ZUPT, 2 speed)."""
        s = self._s
        if s[I_LAST]:
            last = s[I_LAST:I_LAST + 59].tolist()
            kind = int(last[1])
            nk, ny, ns = (18, 3, 6) if kind else (12, 2, 3)
            return (kind, tuple(last[2:2 + nk]), tuple(last[20:20 + ny]), tuple(last[23:23 + ns]), *last[29:32],
                    tuple(last[32:59]))
        return (0, (0.0,) * 12, (0.0, 0.0), (0.0,) * 3, 0.0, 0.0, 0.0, tuple(s[:27].tolist()))

    def _update_matrices(self):
        """``H, R, K, y, S`` of the last update in body axes (forward row/column zero for the NHC)."""
        zupt, K, y, S, _, _, _, _ = self._last_step()
        Rk = self.cumulative
        H = np.zeros((3, 6))
        H[:, :3] = Rk.T
        sn = self.sigma_nhc ** 2
        if zupt:                                # kept in world axes by the kernel: rotate to the body
            s0, s1, s2, s4, s5, s8 = S
            return (H, self.sigma_zupt ** 2 * _I3 if zupt == 1 else np.diag([self.sigma_speed ** 2, sn, sn]),
                    np.array(K).reshape(6, 3) @ Rk, Rk.T @ np.array(y),
                    Rk.T @ np.array([[s0, s1, s2], [s1, s4, s5], [s2, s5, s8]]) @ Rk)
        H[0] = 0.0
        Kb, Sb = np.zeros((6, 3)), np.zeros((3, 3))
        Kb[:, 1:] = np.array(K).reshape(6, 2)
        Sb[1:, 1:] = [[S[0], S[1]], [S[1], S[2]]]
        return H, np.diag([0.0, sn, sn]), Kb, np.array([0.0, y[0], y[1]]), Sb

    F = property(lambda self: np.eye(6) - self._last_step()[4] * np.eye(6, k=3),
                 doc="State transition of the last predict (6x6), ``[[I, -dt I], [0, I]]``.")
    Q = property(lambda self: np.diag([self._last_step()[5]] * 3 + [self._last_step()[6]] * 3),
                 doc="Process noise of the last predict (6x6).")
    H = property(lambda self: self._update_matrices()[0],
                 doc="Measurement matrix of the last update (3x6): body-frame velocity ``R_k^T v``.")
    R = property(lambda self: self._update_matrices()[1], doc="Measurement noise of the last update, (m/s)^2.")
    K = property(lambda self: self._update_matrices()[2], doc="Gain of the last update (6x3, body axes).")
    y = property(lambda self: self._update_matrices()[3], doc="Innovation of the last update (3,), body axes.")
    S = property(lambda self: self._update_matrices()[4], doc="Innovation covariance of the last update (3x3).")

    def to_body(self, d: np.ndarray, dv: np.ndarray):
        """Sensor-frame increments ``d`` (..., 3, 3) and ``dv`` (..., 3, m/s) to the body frame."""
        return (d, dv) if self._identity_extrinsic else body_increments(self._Rgs, d, dv)

    def to_body_flat(self, d9, dv3):
        """:meth:`to_body` of one frame as plain floats (9 row-major, 3)."""
        return (d9, dv3) if self._identity_extrinsic else self._to_body(self._s, d9, dv3)

    def step_body(self, d9, dv3, dt: float, stationary: bool = False, valid: bool = True,
                  speed: Optional[float] = None):
        """One unchecked frame already in the body frame, as plain floats: the fast path of :meth:`step`.

        Parameters
        ----------
        d9, dv3 : sequences of 9 and 3 floats
            ``R_{body_{k-1}<-body_k}`` row-major; gravity-free velocity increment (body_{k-1}, m/s).
        dt, stationary, valid, speed
            As in :meth:`step`.

        Returns
        -------
        specific_force, acceleration : tuple of 3 floats
            As in :class:`GravityEstimate`.
        speed : float
            ``|v|`` after the update, m/s.
        """
        if self._w.sync is not None:
            self._pull()
        return self._step_frame(self._s, d9, dv3, dt, stationary, valid, speed)

    def step_sensor(self, d9, dv3, dt: float, stationary: bool = False, valid: bool = True,
                    speed: Optional[float] = None):
        """``step_body(*to_body_flat(d9, dv3), ...)`` in one call (sensor-frame increments)."""
        if self._w.sync is not None:
            self._pull()
        return self._step_sensor(self._s, d9, dv3, dt, stationary, valid, speed)

    def _settings(self) -> dict:
        return dict(sigma_speed=self.sigma_speed, sigma_nhc=self.sigma_nhc, sigma_zupt=self.sigma_zupt, q_v=self.q_v,
                    q_g=self.q_g, q_gap=self.q_gap, sigma_v0=self.sigma_v0, sigma_g0=self.sigma_g0,
                    zupt_gate=self.zupt_gate, extrinsic=self.extrinsic.settings(), lever_arm=self.lever_arm,
                    R0=self.R0, v0=self._v0, g0=self._g0)

    def kernel_state(self) -> list:
        """The kernel's state buffer as plain floats."""
        if self._w.sync is not None:
            self._pull()
        return [float(v) for v in self._s]

    def read_kernel_state(self, reader: StateReader, name: str, optional: bool = False) -> Optional[list]:
        """The entry ``name`` of a saved state, checked to be a buffer of this layout (None if ``optional`` and
        null)."""
        a = reader.floats(name, (len(self._s),), nan=slice(I_LAST, I_QGAPG), optional=optional)
        return None if a is None else a.tolist()

    def load_kernel_state(self, values: list) -> None:
        """Back to a :meth:`kernel_state` (checked by :meth:`read_kernel_state`)."""
        self._w.sync = None
        self._s = buffer_like(self._s, values)

    def state_dict(self) -> dict:
        """The state as a JSON-serialisable dict, for :meth:`load_state_dict` with the same settings."""
        return pack_state("GravityVelocityFilter", STATE_VERSION, self._settings(), {"buffer": self.kernel_state()})

    def load_state_dict(self, state: dict) -> None:
        """Resume from a :meth:`state_dict`.

        Raises
        ------
        StateError
            A state of another estimator, layout or settings, or a corrupt one (named).
        """
        st = StateReader("GravityVelocityFilter", unpack_state(state, "GravityVelocityFilter", STATE_VERSION,
                                                               self._settings()))
        buffer = self.read_kernel_state(st, "buffer")
        assert buffer is not None                   # not optional
        self.load_kernel_state(buffer)

    def horizontal_gravity_variance(self) -> float:
        """``P[3, 3] + P[4, 4]``, (m/s^2)^2."""
        s = self._s
        return s.item(_I_GXX) + s.item(_I_GYY)

    def gravity_snapshot(self) -> tuple:
        """``(g, R, p6)`` of :func:`~imu_ground.filters.road.road_one` as plain floats."""
        if self._w.sync is not None:
            self._pull()
        s = self._s[3:36].tolist()
        return tuple(s[0:3]), tuple(s[24:33]), tuple(s[18:24])

    def set_mount(self, Rgs: np.ndarray, turn: Optional[np.ndarray] = None,
                  direction: Optional[np.ndarray] = None) -> None:
        """A new static rotation ground <- sensor ``Rgs``; with ``turn`` (the change ``D``, body frame) also the
        state: ``R <- R D^T``, gravity along the unit ``direction`` (world frame), the buffer's extrinsic.
        Without ``turn`` only the Python side (a warm start)."""
        Rgs = np.asarray(Rgs, dtype=float)
        if turn is not None:
            if self._w.sync is not None:
                self._pull()
            s = self._s
            R = np.array(s[27:36], dtype=float).reshape(3, 3) @ np.asarray(turn, dtype=float).T
            g = np.array(s[3:6], dtype=float)
            s[3:6] = (np.linalg.norm(g) * np.asarray(direction, dtype=float)).tolist()
            s[27:36] = R.ravel().tolist()
            s[I_EXTR] = 1.0
            s[I_EXTR + 1:I_EXTR + 10] = Rgs.ravel().tolist()
        self._Rgs, self._identity_extrinsic, self._rgs9 = Rgs, False, Rgs.ravel().tolist()

    def step(self, delta_R, delta_v=None, delta_t=None, stationary: bool = False,
             valid: bool = True, speed: Optional[float] = None) -> GravityEstimate:
        """Process one frame.

        Parameters
        ----------
        delta_R : ndarray (3, 3), (4, 4) or (3,), or EgoFrame
            Sensor rotation increment, sensor_{k-1} <- sensor_k; or an EgoFrame carrying every field.
        delta_v, delta_t : ndarray (3,), float
            Gravity-free velocity increment (sensor frame at the frame's start, m/s); frame duration, s.
        stationary, valid : bool
            The frame ends at a standstill (zero-velocity update); False through a timestamp gap.
        speed : float, optional
            Measured forward speed at the frame's end (wheel / CAN), m/s; None or NaN: none.

        Returns
        -------
        GravityEstimate

        Raises
        ------
        ValueError
            Not one rotation, or a bad frame (:func:`~imu_ground.filters.frame_checks.frame_problem`); the state
            is unchanged.
        """
        if delta_v is None:
            delta_R, delta_v, delta_t, stationary, valid = delta_R[:5]
        if type(delta_R) is not np.ndarray or delta_R.shape != (3, 3):
            delta_R = as_rotations(delta_R)
            if delta_R.shape != (3, 3):
                raise ValueError(f"delta_R must be one rotation, got shape {delta_R.shape}")
        d9 = delta_R.ravel().tolist()
        dva = np.asarray(delta_v, dtype=float).reshape(3)
        dv = dva.tolist()
        dt = float(delta_t)
        problem = frame_problem(d9, dv, dt)
        if problem is not None:
            raise ValueError(f"bad frame: {problem}; the filter's state is unchanged")
        if self._w.sync is not None:
            self._pull()
        e = np.empty(12)                                    # [v, g, acceleration, specific force]
        speed = self._step_sensor(self._s, delta_R, dva, dt, stationary, valid, speed, e)
        return GravityEstimate(e[0:3], e[3:6], e[6:9], e[9:12], speed)

    def run(self, egomotion: Union[EgoMotion, ImuData], smooth: bool = False,
            speed: Optional[np.ndarray] = None) -> GravityTrack:
        """Process a whole drive, continuing from the current state as :meth:`step` would.

        Parameters
        ----------
        egomotion : EgoMotion or ImuData
            Per-frame increments (an ImuData is preintegrated at 10 Hz).
        smooth : bool
            Rauch-Tung-Striebel smoother over the drive (offline).
        speed : ndarray (N,), optional
            Measured forward speed per frame, m/s (NaN: none).

        Returns
        -------
        GravityTrack
        """
        d, dv, dt, st, valid = egomotion_arrays(egomotion)
        return self._run(d, dv, dt, st, valid, smooth, speed, sensor=True)

    def run_body(self, d, dv, dt, stationary, valid, smooth: bool = False, speed=None) -> GravityTrack:
        """:meth:`run` on checked body-frame arrays (:func:`egomotion_arrays`; ``speed`` (N,) or None)."""
        return self._run(d, dv, dt, stationary, valid, smooth, speed, sensor=False)

    def _run(self, d, dv, dt, stationary, valid, smooth, speed, sensor: bool) -> GravityTrack:
        """The kernel's ``run_frames`` on checked arrays, then the smoother."""
        n = len(dt)
        d = np.ascontiguousarray(d, dtype=float).reshape(n, 3, 3)
        dv, dt = np.ascontiguousarray(dv, dtype=float).reshape(n, 3), np.ascontiguousarray(dt, dtype=float)
        st, va = (np.ascontiguousarray(a, dtype=bool).reshape(n) for a in (stationary, valid))
        if speed is not None:
            speed = np.ascontiguousarray(speed, dtype=float).reshape(n)
        if self._w.sync is not None:
            self._pull()
        s = self._s
        r_start, w_prev = np.array(s[27:36]).reshape(3, 3), list(s[I_WPREV:I_WPREV + 4])
        v, g, f, acc = (np.empty((n, 3)) for _ in range(4))
        P, cum, sp = np.empty((n, 6, 6)), np.empty((n, 3, 3)), np.empty(n)
        priors = np.empty((n, 27)) if smooth else None
        body = np.empty((n, 3, 3)) if sensor else None
        self._run_frames(s, d, dv, dt, st, va, speed, v, g, P, cum, f, acc, sp, priors, body)
        if sensor:
            d, dv = body, (self.to_body(d, dv)[1] if smooth else None)
        if smooth and n:
            assert priors is not None
            xs, P = _rts(np.hstack([v, g]), P, priors[:, :6], _full_cov(priors[:, 6:27]), dt)
            v, g = xs[:, :3].copy(), xs[:, 3:].copy()
            f, acc, _ = body_forces(d, dv, dt, g, r_start, cum, self._lever, w_prev[1:] if w_prev[0] else None)
            sp = np.linalg.norm(v, axis=1)
        return GravityTrack(v, g, acc, f, sp, P, cum, d)


def _rts(xs, Ps, xps, Pps, dt):
    """RTS smoother of the forward pass (F = [[I, -dt I], [0, I]])."""
    xs, Ps = xs.copy(), Ps.copy()
    F = np.eye(6)
    for k in range(len(dt) - 2, -1, -1):
        F[:3, 3:] = -dt[k + 1] * _I3
        C = np.linalg.solve(Pps[k + 1], F @ Ps[k]).T
        xs[k] = xs[k] + C @ (xs[k + 1] - xps[k + 1])
        P = Ps[k] + C @ (Ps[k + 1] - Pps[k + 1]) @ C.T
        Ps[k] = 0.5 * (P + P.T)
    return xs, Ps
