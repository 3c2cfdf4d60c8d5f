"""Gravity and velocity from an IMU alone, with vehicle constraints: a linear Kalman filter on frames.

Frames and signs follow :mod:`imu_ground.so3`: world ``w`` is the gyro-integrated
body frame at the start (``R0``, world <- body), body ``b`` FLU (x forward,
y left, z up), gravity stored as its reaction (+9.81 m/s^2 up at rest).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np

from imu_ground import so3
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.ground import _increment_matrix
from imu_ground.filters.invariant_ekf import _renormalise
from imu_ground.imu.data import ImuData
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion
from imu_ground.units import RENORM_EVERY as _RENORM_EVERY

__all__ = ["GravityEstimate", "GravityTrack", "GravityVelocityFilter"]

_I3 = np.eye(3)
_DIAG = (np.arange(6), np.arange(6))
_UPPER = np.eye(6, k=3)

def _egomotion_arrays(ego: Union[EgoMotion, ImuData]):
    """``(delta_R, delta_v, delta_t, stationary, valid)`` of an EgoMotion (an ImuData is preintegrated)."""
    if isinstance(ego, ImuData):
        ego = imu_to_egomotion(ego)
    if not isinstance(ego, EgoMotion):
        raise TypeError(f"expected an EgoMotion (or ImuData), got {type(ego).__name__}")
    d = np.asarray(ego.delta_R, dtype=float)
    n = len(d)
    dv = np.asarray(ego.delta_v, dtype=float)
    dt = np.asarray(ego.delta_t, dtype=float)
    st = np.asarray(ego.stationary, dtype=bool)
    valid = np.asarray(ego.valid, dtype=bool)
    if d.shape != (n, 3, 3) or dv.shape != (n, 3) or dt.shape != (n,) or st.shape != (n,) or valid.shape != (n,):
        raise ValueError("EgoMotion arrays have inconsistent shapes")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(dv)) and np.all(dt > 0)):
        raise ValueError("EgoMotion has non-finite increments or non-positive frame durations")
    return d, dv, dt, st, valid


class GravityEstimate(NamedTuple):
    """One frame of :meth:`GravityVelocityFilter.step`.

    Attributes
    ----------
    velocity : ndarray (3,)
        Velocity, world frame (gyro-integrated body frame at the start), m/s.
    gravity : ndarray (3,)
        Reaction to gravity (+9.81 m/s^2 up at rest), world frame, m/s^2.
    acceleration : ndarray (3,)
        Gravity-compensated acceleration, frame mean, body frame at mid-frame, m/s^2.
    specific_force : ndarray (3,)
        Specific force (what an accelerometer reads), frame mean, body frame at
        mid-frame, m/s^2.
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
    velocity : ndarray (N, 3)        m/s, world frame.
    gravity : ndarray (N, 3)         reaction to gravity, m/s^2, world frame.
    acceleration : ndarray (N, 3)    gravity-compensated, m/s^2, body frame at mid-frame.
    specific_force : ndarray (N, 3)  m/s^2, body frame at mid-frame.
    speed : ndarray (N,)             m/s.
    P : ndarray (N, 6, 6)            covariance of ``[v, g]``.
    cumulative : ndarray (N, 3, 3)   body attitude, world <- body (frame end).
    body_increments : ndarray (N, 3, 3) body_{k-1} <- body_k (extrinsic applied).
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

    observed by the non-holonomic constraint ``[e_y, e_z]^T R_k^T v_k = 0 + n``
    (a car neither slides sideways nor moves vertically in its own frame) while
    moving and by ``v_k = 0 + n`` at standstill frames. The constraint needs the
    body frame to be the vehicle's (FLU): give the ``extrinsic`` when the IMU is
    mounted otherwise.

    Parameters
    ----------
    sigma_nhc : float
        Std of the body lateral and vertical velocity, m/s (0.3).
    sigma_zupt : float
        Std of the velocity at standstill, m/s (0.05).
    q_v : float
        Velocity random walk, m/s/sqrt(s) (0.05).
    q_g : float
        Gravity random walk, m/s^2/sqrt(s) (1e-6).
    q_gap : float
        Extra velocity random walk on frames integrated through a timestamp gap
        (``valid`` False), m/s/sqrt(s) (1.0).
    zupt_gate : float
        A standstill flag is ignored (the constraint used instead) when the
        predicted velocity is this far from zero, squared Mahalanobis distance
        (100: ten sigma). Standstill detectors flag smooth cruising too.
    sigma_v0, sigma_g0 : float
        Initial std of velocity (m/s, 30) and gravity (m/s^2, 1).
    v0, g0 : array_like (3,), optional
        Initial velocity and gravity reaction, world frame. Default zero velocity
        and the first frame's mean specific force.
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static ground <- sensor rotation (inputs are sensor-frame increments).
    lever_arm : array_like (3,), optional
        Sensor position relative to the body's pitch/roll centre, ground frame,
        m. When given, the accelerations are moved to that point,
        ``f_0 = f_s - alpha x r - w x (w x r)`` (``w`` the frame's mean rate,
        ``alpha`` its backward difference: half a frame late). Default: none.
    R0 : ndarray (3, 3), optional
        Initial attitude, world <- body (identity).

    Attributes
    ----------
    x, P : ndarray (6,), (6, 6)
        State and covariance; ``x_prior``, ``P_prior``, ``x_post``, ``P_post``,
        ``F``, ``Q``, ``H``, ``R``, ``K``, ``y``, ``S`` of the last step
        (filterpy's names).
    cumulative : ndarray (3, 3)
        ``R_k``, world <- body.
    """

    def __init__(self, sigma_nhc: float = 0.3, sigma_zupt: float = 0.05, q_v: float = 0.05,
                 q_g: float = 1e-6, q_gap: float = 1.0, sigma_v0: float = 30.0, sigma_g0: float = 1.0,
                 zupt_gate: float = 100.0, v0: Optional[Sequence[float]] = None,
                 g0: Optional[Sequence[float]] = None, extrinsic: Union[Extrinsic, np.ndarray, None] = None,
                 lever_arm: Optional[Sequence[float]] = None, R0: Optional[np.ndarray] = None) -> None:
        self.sigma_nhc, self.sigma_zupt = float(sigma_nhc), float(sigma_zupt)
        self.q_v, self.q_g, self.q_gap = float(q_v), float(q_g), float(q_gap)
        self.sigma_v0, self.sigma_g0 = float(sigma_v0), float(sigma_g0)
        self.zupt_gate = float(zupt_gate)
        self.extrinsic = Extrinsic.coerce(extrinsic)
        self._Rgs = self.extrinsic.rotation
        self._identity_extrinsic = bool(np.array_equal(self._Rgs, _I3))
        self.lever_arm = None if lever_arm is None else np.asarray(lever_arm, dtype=float).reshape(3)
        self.R0 = _I3.copy() if R0 is None else np.array(R0, dtype=float)
        self._v0 = None if v0 is None else np.asarray(v0, dtype=float).reshape(3)
        self._g0 = None if g0 is None else np.asarray(g0, dtype=float).reshape(3)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state."""
        self.x = np.zeros(6)
        if self._v0 is not None:
            self.x[:3] = self._v0
        if self._g0 is not None:
            self.x[3:] = self._g0
        self._initialised = self._g0 is not None
        self.P = np.diag([self.sigma_v0 ** 2] * 3 + [self.sigma_g0 ** 2] * 3)
        self.cumulative = self.R0.copy()
        self._count = 0
        self._w_prev = np.zeros(3)             # mean body rate of the previous frame (rad/s)
        self._has_w_prev = False
        self.zupt_rejected = 0
        self._F = np.eye(6)
        self._Rzupt = self.sigma_zupt ** 2 * _I3
        self._Rnhc = self.sigma_nhc ** 2 * _I3
        self._Rnhc[0, 0] = 0.0
        self._dt, self._qv, self._qg, self._zupt = 0.0, 0.0, 0.0, False
        self._Rk = self.cumulative.copy()
        self.K = np.zeros((6, 3))
        self.y = np.zeros(3)
        self.S = np.zeros((3, 3))
        self.x_prior, self.P_prior = self.x.copy(), self.P.copy()
        self.x_post, self.P_post = self.x.copy(), self.P.copy()

    # filterpy-style matrices of the last step, built on demand
    @property
    def F(self) -> np.ndarray:
        """State transition of the last predict (6x6)."""
        F = np.eye(6)
        F[:3, 3:] = -self._dt * _I3
        return F

    @property
    def Q(self) -> np.ndarray:
        """Process noise of the last predict (6x6)."""
        return np.diag([self._qv] * 3 + [self._qg] * 3)

    @property
    def H(self) -> np.ndarray:
        """Measurement matrix of the last update (3x6): body-frame velocity ``R_k^T v``; the forward
        row is zero for the non-holonomic update (forward speed unobserved)."""
        H = np.zeros((3, 6))
        H[:, :3] = self._Rk.T
        if not self._zupt:
            H[0] = 0.0
        return H

    @property
    def R(self) -> np.ndarray:
        """Measurement noise of the last update, (m/s)^2 (3x3, forward entry zero for the NHC)."""
        return self._Rzupt if self._zupt else self._Rnhc

    # -- internals (shared with SuspensionAwareFilter) -------------------------------------
    def _to_body(self, d: np.ndarray, dv: np.ndarray):
        """Sensor-frame increments (one or a batch) to the body frame: ``R_gs d R_gs^T``, ``R_gs dv``."""
        if self._identity_extrinsic:
            return d, dv
        R = self._Rgs
        return R @ d @ R.T, dv @ R.T

    def _step_body(self, d: np.ndarray, dv: np.ndarray, dt: float, stationary: bool, valid: bool) -> np.ndarray:
        """Predict and update with one body-frame frame; returns ``R_{k-1}``."""
        Rprev = self.cumulative
        self._count += 1
        Rk = Rprev @ d
        if self._count % _RENORM_EVERY == 0:
            Rk = _renormalise(Rk)
        self.cumulative = Rk
        x = self.x
        if not self._initialised:
            x = x.copy()
            x[3:] = Rprev @ dv / dt
            self._initialised = True
        # predict: v <- v + R_{k-1} dv - dt g; P <- F P F^T + Q, F = [[I, -dt I], [0, I]]
        g = x[3:]
        x = np.concatenate([x[:3] + Rprev @ dv - dt * g, g])
        qv = (self.q_v ** 2 + (0.0 if valid else self.q_gap ** 2)) * dt
        qg = self.q_g ** 2 * dt
        F = self._F
        if F[0, 3] != -dt:
            F = self._F = np.eye(6) - dt * _UPPER
        P = F @ self.P @ F.T
        P[_DIAG] += (qv, qv, qv, qg, qg, qg)
        self.x_prior, self.P_prior = x, P
        self._dt, self._qv, self._qg, self._Rk = dt, qv, qg, Rk
        # update with the body-frame velocity R_k^T v: all of it at a standstill (zero-velocity
        # update), its lateral and vertical components while moving (non-holonomic constraint)
        if stationary:
            h, Rm = Rk.T, self._Rzupt
            PHT = P[:, :3] @ Rk
            S = h @ PHT[:3] + Rm
            Si = np.linalg.inv(S)
            y = -(h @ x[:3])
            if y @ Si @ y > self.zupt_gate:
                stationary = False          # a smooth cruise flagged as standstill: constraint instead
                self.zupt_rejected += 1
        if not stationary:
            h, Rm = Rk.T[1:3], self._Rnhc[1:, 1:]
            PHT = P[:, :3] @ h.T
            S = h @ PHT[:3] + Rm
            (s00, s01), (s10, s11) = S.tolist()
            det = s00 * s11 - s01 * s10
            Si = np.array([[s11 / det, -s01 / det], [-s10 / det, s00 / det]])
            y = -(h @ x[:3])
        self._zupt = stationary
        K = PHT @ Si
        x = x + K @ y
        KPt = K @ PHT.T                          # Joseph form: P - K H P - P H^T K^T + K S K^T
        P = P - KPt - KPt.T + K @ S @ K.T
        P = 0.5 * (P + P.T)
        self.x = self.x_post = x
        self.P = self.P_post = P
        if stationary:
            self.K, self.y, self.S = K, y, S
        else:                                    # padded to the 3 body axes (forward: unobserved)
            self.K = np.zeros((6, 3))
            self.K[:, 1:] = K
            self.y = np.array([0.0, y[0], y[1]])
            self.S = np.zeros((3, 3))
            self.S[1:, 1:] = S
        return Rprev

    def _forces(self, Rprev, d, dv, dt, g, w_prev):
        """Specific force and gravity-compensated acceleration, frame means in the body frame at
        mid-frame (one frame or a batch), and the frames' mean body rates (rad/s)."""
        dt = np.asarray(dt, dtype=float)[..., None]
        phi = so3.log(d)
        w = phi / dt
        half = so3.exp(0.5 * phi)                  # body_{k-1} <- body at mid-frame
        f = np.einsum("...ji,...j->...i", half, dv / dt)
        if self.lever_arm is not None:
            r = self.lever_arm
            alpha = (w - w_prev) / dt
            f = f - np.cross(alpha, r) - np.cross(w, np.cross(w, r))
        g_mid = np.einsum("...ji,...j->...i", half, np.einsum("...ji,...j->...i", Rprev, g))
        return f, f - g_mid, w

    def _frame(self, d: np.ndarray, dv: np.ndarray, dt: float, stationary: bool, valid: bool):
        """One body-frame frame: filter step, then the forces with the posterior gravity (as ``_forces``)."""
        Rprev = self._step_body(d, dv, dt, stationary, valid)
        phi = so3.log_one(d)
        w = phi / dt
        half = so3.exp_one(0.5 * phi)
        f = (dv / dt) @ half
        if self.lever_arm is not None:
            r = self.lever_arm
            alpha = (w - (self._w_prev if self._has_w_prev else w)) / dt
            f = f - np.cross(alpha, r) - np.cross(w, np.cross(w, r))
        self._w_prev, self._has_w_prev = w, True
        return f, f - (self.x[3:] @ Rprev) @ half

    # -- streaming ----------------------------------------------------------------------------
    def step(self, delta_R: np.ndarray, delta_v: np.ndarray, delta_t: float, stationary: bool = False,
             valid: bool = True) -> GravityEstimate:
        """Process one frame.

        Parameters
        ----------
        delta_R : ndarray (3, 3), (4, 4) or (3,)
            Sensor rotation increment, sensor_{k-1} <- sensor_k.
        delta_v : ndarray (3,)
            Gravity-free velocity increment, sensor frame at the frame's start, m/s.
        delta_t : float
            Frame duration, s.
        stationary : bool
            The frame ends at a standstill (zero-velocity update).
        valid : bool
            False for a frame integrated through a timestamp gap.

        Returns
        -------
        GravityEstimate
        """
        d, dv = self._to_body(_increment_matrix(delta_R), np.asarray(delta_v, dtype=float).reshape(3))
        f, a = self._frame(d, dv, float(delta_t), bool(stationary), bool(valid))
        v = self.x[:3].copy()
        return GravityEstimate(v, self.x[3:].copy(), a, f, float(np.linalg.norm(v)))

    # -- batch -------------------------------------------------------------------------------
    def run(self, egomotion: Union[EgoMotion, ImuData], smooth: bool = False) -> GravityTrack:
        """Process a whole drive, continuing from the current state as :meth:`step` would.

        Parameters
        ----------
        egomotion : EgoMotion or ImuData
            Per-frame increments (an ImuData is preintegrated at 10 Hz).
        smooth : bool
            Rauch-Tung-Striebel smoother over the drive (offline).

        Returns
        -------
        GravityTrack
        """
        d, dv, dt, st, valid = _egomotion_arrays(egomotion)
        return self._run_body(*self._to_body(d, dv), dt, st, valid, smooth)

    def _run_body(self, d, dv, dt, st, valid, smooth) -> GravityTrack:
        n = len(dt)
        xs = np.empty((n, 6))
        Ps = np.empty((n, 6, 6))
        cum = np.empty((n, 3, 3))
        Rprev = np.empty((n, 3, 3))
        if smooth:
            xps, Pps = np.empty((n, 6)), np.empty((n, 6, 6))
        for k in range(n):
            Rprev[k] = self._step_body(d[k], dv[k], float(dt[k]), bool(st[k]), bool(valid[k]))
            xs[k], Ps[k], cum[k] = self.x, self.P, self.cumulative
            if smooth:
                xps[k], Pps[k] = self.x_prior, self.P_prior
        if smooth:
            F = np.eye(6)
            for k in range(n - 2, -1, -1):
                F[:3, 3:] = -dt[k + 1] * _I3
                C = np.linalg.solve(Pps[k + 1], F @ Ps[k]).T
                xs[k] = xs[k] + C @ (xs[k + 1] - xps[k + 1])
                P = Ps[k] + C @ (Ps[k + 1] - Pps[k + 1]) @ C.T
                Ps[k] = 0.5 * (P + P.T)
        if n:
            w_prev = np.empty((n, 3))
            w_prev[1:] = so3.log(d[:-1]) / dt[:-1, None]
            w_prev[0] = self._w_prev if self._has_w_prev else so3.log_one(d[0]) / dt[0]
            f, acc, w = self._forces(Rprev, d, dv, dt, xs[:, 3:], w_prev)
            self._w_prev, self._has_w_prev = w[-1].copy(), True
        else:
            f = acc = np.zeros((0, 3))
        return GravityTrack(xs[:, :3].copy(), xs[:, 3:].copy(), acc, f, np.linalg.norm(xs[:, :3], axis=1),
                            Ps, cum, d)

