r"""Ground plane normal from ego-motion: the paper's pipeline, done right.

Frames
------
- sensor frame ``s``: the frame the ego-motion is given in (IMU, camera, ...).
- body/ground frame ``g``: the vehicle frame that, at rest on flat ground,
  has x forward, y left and z along the ground normal (FLU). The static
  extrinsic ``R_gs`` (ground <- sensor) relates the two.
- world frame ``w``: the body frame at the first frame (or ``R0``).
- road frame ``r``: the slow part of the body attitude: ``X_k`` (world <- road).

Pipeline, per frame k
---------------------
1. body increment ``dR_b = R_gs dR_s R_gs^T`` (``dR_s``: sensor_{k-1} <- sensor_k);
2. cumulative body rotation ``R_k = R_{k-1} dR_b`` (world <- body), right-multiplied
   because the increments are expressed in the moving body frame;
3. invariant EKF (:class:`~imu_ground.filters.invariant_ekf.InvariantEKF`, left error)
   on ``X_k``: predict ``X <- X T_k`` where ``T_k = Rz(psi_k)`` is the twist of
   ``dR_b`` about the body up axis (the road frame turns with the vehicle's
   heading; ``follow_heading=False`` gives the paper's pure random walk),
   then update with ``R_k`` (full rotation) or with its up axis ``R_k e_z``;
4. residual ``E_k = X_k^T R_k`` (road <- body): the fast body motion;
5. dynamic extrinsic ``R_gs(k) = E_k R_gs`` (road-ground <- sensor) and the
   ground normal in the sensor frame ``n_s = R_gs(k)^T e_z``.

Signs (KITTI OXTS convention): with ``E = Rz(yaw) Ry(pitch) Rx(roll)``, pitch
is positive nose *down* (right-handed about y-left), roll positive left side
*up* (right-handed about x-forward). They are read off the body-frame normal
``n_b = E^T e_z = [-sin(pitch), sin(roll) cos(pitch), cos(pitch) cos(roll)]``,
so they do not depend on any yaw left in ``E``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple, Optional, Union

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from imu_ground import so3
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.invariant_ekf import InvariantEKF, _renormalise

__all__ = ["GroundNormalFilter", "GroundEstimate", "GroundTrack", "pitch_roll_from_normal"]

_EZ = np.array([0.0, 0.0, 1.0])
_EX = np.array([1.0, 0.0, 0.0])
_RENORM_EVERY = 64      # frames between re-orthonormalisations of the cumulative rotation


def pitch_roll_from_normal(n_body: np.ndarray):
    """Pitch and roll of the body relative to the road from the normal in the body frame.

    Parameters
    ----------
    n_body : array_like, shape (..., 3)
        Unit road normal in the body (FLU) frame.

    Returns
    -------
    pitch, roll : ndarray, shape (...)
        Radians; pitch positive nose down, roll positive left side up
        (``n_b = [-sin p, sin r cos p, cos p cos r]``).
    """
    n = np.asarray(n_body, dtype=float)
    pitch = np.arctan2(-n[..., 0], np.hypot(n[..., 1], n[..., 2]))
    roll = np.arctan2(n[..., 1], n[..., 2])
    return pitch, roll


class GroundEstimate(NamedTuple):
    """One frame's result of :meth:`GroundNormalFilter.step`.

    Attributes
    ----------
    normal : ndarray (3,)
        Unit ground normal in the sensor frame.
    pitch, roll : float
        Body attitude relative to the road, rad (pitch + nose down, roll + left up).
    residual : ndarray (3, 3)
        ``E = X^T R`` (road <- body), the fast body motion.
    extrinsic : ndarray (3, 3)
        Dynamic extrinsic rotation ``E R_gs`` (road-ground <- sensor).
    P : ndarray (3, 3)
        Covariance of the slow state, body tangent space (rad^2).
    """
    normal: np.ndarray
    pitch: float
    roll: float
    residual: np.ndarray
    extrinsic: np.ndarray
    P: np.ndarray


@dataclass
class GroundTrack:
    """Per-frame results of :meth:`GroundNormalFilter.run` (batch first, N frames).

    Attributes
    ----------
    normal : ndarray (N, 3)      unit ground normal, sensor frame.
    pitch, roll : ndarray (N,)   rad, body relative to road (signs as in :class:`GroundEstimate`).
    residual : ndarray (N, 3, 3) road <- body.
    extrinsic : ndarray (N, 3, 3) dynamic extrinsic, road-ground <- sensor.
    P : ndarray (N, 3, 3)        covariance of the slow state (rad^2).
    x : ndarray (N, 3, 3)        slow state, world <- road.
    cumulative : ndarray (N, 3, 3) cumulative body rotation, world <- body.
    translation : ndarray (3,)   static sensor position in the ground frame (m).
    """
    normal: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    residual: np.ndarray
    extrinsic: np.ndarray
    P: np.ndarray
    x: np.ndarray
    cumulative: np.ndarray
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __len__(self) -> int:
        return len(self.pitch)

    def to_dataframe(self, t: Optional[np.ndarray] = None) -> pd.DataFrame:
        """Table with t, normal_x/y/z, pitch, roll (rad) and the residual as a quaternion (x, y, z, w)."""
        q = Rotation.from_matrix(self.residual).as_quat()
        df = pd.DataFrame({
            "t": np.arange(len(self), dtype=float) if t is None else np.asarray(t, dtype=float),
            "normal_x": self.normal[:, 0], "normal_y": self.normal[:, 1], "normal_z": self.normal[:, 2],
            "pitch": self.pitch, "roll": self.roll,
            "qx": q[:, 0], "qy": q[:, 1], "qz": q[:, 2], "qw": q[:, 3]})
        return df


def _increment_matrix(delta_R) -> np.ndarray:
    """3x3 rotation from a 3x3 rotation, a 4x4 relative pose or a rotation vector (rad)."""
    d = np.asarray(delta_R, dtype=float)
    if d.shape == (3,):
        return so3.exp_one(d)
    if d.shape == (4, 4):
        return d[:3, :3]
    if d.shape != (3, 3):
        raise ValueError(f"delta_R must be a 3x3 rotation, a 4x4 pose or a rotation vector, got shape {d.shape}")
    return d


def _rotz_one(psi: float) -> np.ndarray:
    """Rotation about z by ``psi`` rad, one 3x3 matrix (scalar fast path of :func:`so3.rotz`)."""
    c, s = math.cos(psi), math.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _twist_angle(d: np.ndarray) -> np.ndarray:
    """Angle of the twist of ``d`` about z (swing-twist), ``2 atan2(q_z, q_w)``, batch."""
    return np.arctan2(d[..., 1, 0] - d[..., 0, 1], d[..., 0, 0] + d[..., 1, 1])


def _is_axisymmetric(m: np.ndarray) -> bool:
    """True for diag(a, a, c): commutes with every rotation about z."""
    return bool(np.all(m == np.diag(np.diag(m))) and m[0, 0] == m[1, 1])


class GroundNormalFilter:
    """Ground normal, pitch and roll from ego-motion (Zhang et al. 2022, improved).

    Parameters
    ----------
    Q : float or ndarray (3, 3)
        Process noise of the slow road attitude per frame, body tangent space,
        rad^2. Default ``1e-2 I`` (the paper).
    R : float or ndarray (3, 3)
        Measurement noise of the cumulative rotation (rad^2) or of its up axis.
        Default ``I`` (the paper).
    P : float or ndarray (3, 3)
        Initial covariance (rad^2). Default ``I`` (the paper's code).
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static sensor-to-ground extrinsic (``R_gs``: ground <- sensor, and the
        sensor position in the ground frame). Default identity.
    measurement : {"rotation", "up", "forward"}
        What the filter observes of ``R_k``: the full rotation, its up axis
        ``R_k e_z`` (tilt only) or its forward axis ``R_k e_x`` (the paper's
        code, which observes the camera's optical axis).
    follow_heading : bool
        Predict the road frame with the twist of each body increment about the
        up axis (default). False is the paper's random walk, which lags in
        turns (about 9 deg in a 9 deg/s turn at 10 Hz with the paper's noise,
        the whole turn when only the up axis is observed).
    R0 : ndarray (3, 3), optional
        Initial cumulative rotation, world <- body (default identity).

    Attributes
    ----------
    ekf : InvariantEKF
        The filter on the slow state; ``x``, ``P``, ``Q``, ``R``, ``K``, ``y``,
        ``S`` ... are forwarded from it.
    cumulative : ndarray (3, 3)
        ``R_k``, world <- body.

    Examples
    --------
    >>> import numpy as np
    >>> from imu_ground.filters.ground import GroundNormalFilter
    >>> f = GroundNormalFilter()
    >>> est = f.step(np.eye(3))
    >>> est.normal
    array([0., 0., 1.])
    """

    def __init__(self, Q: Union[float, np.ndarray] = 1e-2, R: Union[float, np.ndarray] = 1.0,
                 P: Union[float, np.ndarray] = 1.0, extrinsic: Union[Extrinsic, np.ndarray, None] = None,
                 measurement: str = "rotation", follow_heading: bool = True,
                 R0: Optional[np.ndarray] = None) -> None:
        if measurement not in ("rotation", "up", "forward"):
            raise ValueError(f"measurement must be 'rotation', 'up' or 'forward', got {measurement!r}")
        extrinsic = Extrinsic.coerce(extrinsic)
        self.extrinsic = extrinsic
        self.measurement = measurement
        self.follow_heading = bool(follow_heading)
        self.R0 = np.eye(3) if R0 is None else np.array(R0, dtype=float)
        b = _EX if measurement == "forward" else _EZ
        self.ekf = InvariantEKF(x=self.R0, P=P, Q=Q, R=R, error="left", b=b)
        self._P0 = self.ekf.P.copy()
        self.cumulative = self.R0.copy()
        self._Rgs = extrinsic.rotation
        self._identity_extrinsic = bool(np.array_equal(self._Rgs, np.eye(3)))
        self._count = 0

    @classmethod
    def paper(cls, **kwargs) -> "GroundNormalFilter":
        """The paper's method with its published parameters (Zhang et al. 2022).

        A random-walk slow state observed through the full cumulative rotation,
        ``Q = 1e-2 I``, ``R = I``, ``P0 = I``, one predict and update a frame;
        rotations accumulated in the correct order. Keyword arguments override.
        """
        kw = dict(Q=1e-2, R=1.0, P=1.0, measurement="rotation", follow_heading=False)
        kw.update(kwargs)
        return cls(**kw)

    @classmethod
    def reference_code(cls, **kwargs) -> "GroundNormalFilter":
        """The configuration of the paper's reference code (manymuch/ground_normal_filter).

        As :meth:`paper`, but only the forward axis of the cumulative rotation
        is observed (the code measures the camera's optical axis, ``R_k e_z``
        in camera axes, the body's x axis), so roll about it is never
        corrected. Its accumulation-order error is not reproduced.
        """
        kw = dict(Q=1e-2, R=1.0, P=1.0, measurement="forward", follow_heading=False)
        kw.update(kwargs)
        return cls(**kw)

    # filterpy-style attributes forwarded from the EKF
    x = property(lambda self: self.ekf.x, doc="Slow state X_k, world <- road (3x3).")
    P = property(lambda self: self.ekf.P, doc="Covariance of the slow state, body tangent space (rad^2).")
    Q = property(lambda self: self.ekf.Q, doc="Process noise per frame (rad^2).")
    R = property(lambda self: self.ekf.R, doc="Measurement noise.")
    K = property(lambda self: self.ekf.K, doc="Last Kalman gain.")
    y = property(lambda self: self.ekf.y, doc="Last innovation.")
    S = property(lambda self: self.ekf.S, doc="Last innovation covariance.")

    def reset(self) -> None:
        """Back to the initial state (cumulative rotation R0, slow state R0, covariance P0)."""
        self.__init__(Q=self.ekf.Q, R=self.ekf.R, P=self._P0, extrinsic=self.extrinsic,
                      measurement=self.measurement, follow_heading=self.follow_heading, R0=self.R0)

    # -- streaming -------------------------------------------------------------
    def _body_increment(self, delta_R: np.ndarray) -> np.ndarray:
        d = _increment_matrix(delta_R)
        if not self._identity_extrinsic:
            d = self._Rgs @ d @ self._Rgs.T
        return d

    def step(self, delta_R: np.ndarray) -> GroundEstimate:
        """Process one frame's ego-motion.

        Parameters
        ----------
        delta_R : ndarray (3, 3), (4, 4) or (3,)
            Relative rotation of the sensor from the previous frame to this one,
            sensor_{k-1} <- sensor_k (a rotation matrix, a 4x4 relative pose,
            or a rotation vector in rad).

        Returns
        -------
        GroundEstimate
        """
        d = self._body_increment(delta_R)
        self._count += 1
        Rk = self.cumulative @ d
        if self._count % _RENORM_EVERY == 0:
            Rk = _renormalise(Rk)
        self.cumulative = Rk
        ekf = self.ekf
        if self.follow_heading:
            ekf.predict(_rotz_one(math.atan2(d[1, 0] - d[0, 1], d[0, 0] + d[1, 1])))
        else:
            ekf.predict()
        if self.measurement == "rotation":
            ekf.update(Rk)
        else:
            ekf.update(Rk @ ekf.b)
        E = ekf.x.T @ Rk
        return self._estimate(E, ekf.P)

    def _estimate(self, E: np.ndarray, P: np.ndarray) -> GroundEstimate:
        nb = E[2]                           # E^T e_z: third row of E
        pitch = math.atan2(-nb[0], math.hypot(nb[1], nb[2]))
        roll = math.atan2(nb[1], nb[2])
        if self._identity_extrinsic:
            dyn = E
            ns = nb.copy()
        else:
            dyn = E @ self._Rgs
            ns = dyn[2].copy()
        return GroundEstimate(ns, pitch, roll, E, dyn, P)

    # -- batch -------------------------------------------------------------------
    def run(self, delta_Rs: np.ndarray, smooth: bool = False, progress: bool = False) -> GroundTrack:
        """Process a whole sequence of relative rotations.

        Continues from the filter's current state, exactly as calling
        :meth:`step` once per frame would (same numbers to rounding).

        Parameters
        ----------
        delta_Rs : ndarray (N, 3, 3), (N, 4, 4) or (N, 3)
            Relative rotations sensor_{k-1} <- sensor_k.
        smooth : bool
            Offline mode: forward filter plus Rauch-Tung-Striebel smoother on
            the group, zero lag (uses every frame, so results at frame k depend
            on the future).
        progress : bool
            Show a progress bar (used by the slow, general path only).

        Returns
        -------
        GroundTrack
        """
        d = np.asarray(delta_Rs, dtype=float)
        if d.ndim == 2 and d.shape[1] == 3:
            d = so3.exp(d)
        elif d.ndim == 3 and d.shape[1:] == (4, 4):
            d = d[:, :3, :3]
        if d.ndim != 3 or d.shape[1:] != (3, 3):
            raise ValueError(f"delta_Rs must have shape (N, 3, 3), (N, 4, 4) or (N, 3), got {np.shape(delta_Rs)}")
        if not np.all(np.isfinite(d)):
            bad = np.flatnonzero(~np.all(np.isfinite(d), axis=(1, 2)))
            raise ValueError(f"delta_Rs has non-finite values in {bad.size} frames, first at index {bad[0]}")
        n = len(d)
        if not self._identity_extrinsic:
            d = self._Rgs @ d @ self._Rgs.T
        psi = _twist_angle(d) if self.follow_heading else np.zeros(n)
        if self._fast_path_ok():
            Xs, Ps, cum = self._run_fast(d, psi)
        else:
            Xs, Ps, cum = self._run_loop(d, psi, progress)
        if smooth and n:
            T = so3.rotz(psi)
            Xs, Ps, _, _ = self.ekf.rts_smoother(Xs, Ps, us=T)
        E = np.swapaxes(Xs, 1, 2) @ cum
        nb = E[:, 2, :]
        pitch, roll = pitch_roll_from_normal(nb)
        dyn = E if self._identity_extrinsic else E @ self._Rgs
        normal = dyn[:, 2, :].copy()
        return GroundTrack(normal, pitch, roll, E, dyn, Ps, Xs, cum, self.extrinsic.translation.copy())

    def _fast_path_ok(self) -> bool:
        e = self.ekf
        if self.measurement == "forward":
            return False
        if not (_is_axisymmetric(e.P) and _is_axisymmetric(e.Q)):
            return False
        if self.measurement == "rotation":
            return _is_axisymmetric(e.R)
        return bool(np.array_equal(e.R, e.R[0, 0] * np.eye(3)))

    def _run_loop(self, d, psi, progress):
        from tqdm.auto import tqdm
        n = len(d)
        Xs = np.empty((n, 3, 3))
        Ps = np.empty((n, 3, 3))
        cum = np.empty((n, 3, 3))
        ekf = self.ekf
        it = tqdm(range(n), disable=not progress, desc="ground filter", unit="frame")
        for k in it:
            self._count += 1
            Rk = self.cumulative @ d[k]
            if self._count % _RENORM_EVERY == 0:
                Rk = _renormalise(Rk)
            self.cumulative = Rk
            ekf.predict(_rotz_one(psi[k]) if self.follow_heading else None)
            ekf.update(Rk if self.measurement == "rotation" else Rk @ ekf.b)
            Xs[k], Ps[k], cum[k] = ekf.x, ekf.P, Rk
        return Xs, Ps, cum

    def _run_fast(self, d, psi):
        """Scalar recursion on the residual when P stays diag(a, a, c).

        With Q, R, P0 symmetric about the up axis and the prediction a rotation
        about it, every P is diag(a, a, c) whatever the data, so the gains are a
        precomputed scalar sequence and only the residual E_k = X_k^T R_k needs
        a (cheap, quaternion) recursion:
        ``E_k^- = T_k^T E_{k-1} dR_k``, ``E_k = Exp(-K_k y_k) E_k^-``.
        Cumulative rotations and slow states follow vectorised.
        """
        n = len(d)
        ekf = self.ekf
        q1, q3 = ekf.Q[0, 0], ekf.Q[2, 2]
        r1, r3 = ekf.R[0, 0], ekf.R[2, 2]
        a, c = ekf.P[0, 0], ekf.P[2, 2]
        up = self.measurement == "up"
        # gains and covariances: scalar recursions (cheap, data independent)
        ka = np.empty(n)
        kc = np.empty(n)
        pa = np.empty(n)
        pc = np.empty(n)
        for k in range(n):
            a += q1
            c += q3
            if up:
                g = a / (a + r1)
                a = a * r1 / (a + r1)
                ka[k], kc[k] = g, 0.0
            else:
                g, h = a / (a + r1), c / (c + r3)
                a, c = g * r1, h * r3
                ka[k], kc[k] = g, h
            pa[k], pc[k] = a, c
        # cumulative rotations, sequential as in step() (same rounding)
        cum = np.empty((n, 3, 3))
        Rk = self.cumulative
        count = self._count
        for k in range(n):
            count += 1
            Rk = Rk @ d[k]
            if count % _RENORM_EVERY == 0:
                Rk = _renormalise(Rk)
            cum[k] = Rk
        # residual recursion in quaternions (w, x, y, z)
        E0 = ekf.x.T @ self.cumulative
        qs = Rotation.from_matrix(np.concatenate([E0[None], d])).as_quat(scalar_first=True)
        cps, sps = np.cos(0.5 * psi), np.sin(0.5 * psi)
        qE = _residual_recursion(qs[0].tolist(), qs[1:].tolist(), cps.tolist(), sps.tolist(),
                                 ka.tolist(), kc.tolist(), up)
        E = Rotation.from_quat(qE, scalar_first=True).as_matrix()
        Xs = cum @ np.swapaxes(E, 1, 2)
        Ps = np.zeros((n, 3, 3))
        Ps[:, 0, 0] = pa
        Ps[:, 1, 1] = pa
        Ps[:, 2, 2] = pc
        # leave the streaming state exactly where step() would have left it
        if n:
            self._count = count
            self.cumulative = cum[-1]
            ekf.x = Xs[-1].copy()
            ekf.P = Ps[-1].copy()
            ekf.x_post, ekf.P_post = ekf.x.copy(), ekf.P.copy()
        return Xs, Ps, cum


def _residual_recursion(qe, qd, cps, sps, ka, kc, up, bx=None, by=None):
    """Scalar loop of the residual quaternion (see ``GroundNormalFilter._run_fast``).

    ``qe``: initial residual (w, x, y, z); ``qd``: body increments; ``cps``,
    ``sps``: cos and sin of half the twist angles; ``ka``, ``kc``: gains about
    the horizontal axes and the up axis. ``bx``, ``by`` (optional, rad): a
    modelled body tilt ``b = (bx, by, 0)`` per frame, so that the rotation
    measurement's innovation is ``Log(E^- Exp(-b))`` (the suspension-aware
    filter); not used with ``up``. Returns a list of residual quaternions.
    """
    sqrt, atan2, sin, cos = math.sqrt, math.atan2, math.sin, math.cos
    ew, ex, ey, ez = qe
    out = [None] * len(qd)
    for k in range(len(qd)):
        # conjugate by the twist: vector part rotated by Rz(-psi)
        ch, sh = cps[k], sps[k]
        c2 = ch * ch - sh * sh          # cos(psi)
        s2 = 2.0 * ch * sh              # sin(psi)
        vx = c2 * ex + s2 * ey
        vy = -s2 * ex + c2 * ey
        # E^- = (T^T E T) (T^T dR) = T^T E dR: left-multiply by the conjugate
        # twist quaternion, then right by dR:  q = conj(t) * e * t * (conj(t) * d)
        dw, dx, dy, dz = qd[k]
        # s = conj(t) * d with t = (ch, 0, 0, sh)
        sw = ch * dw + sh * dz
        sx = ch * dx + sh * dy
        sy = ch * dy - sh * dx
        sz = ch * dz - sh * dw
        # m = (ew, vx, vy, ez) * s
        mw = ew * sw - vx * sx - vy * sy - ez * sz
        mx = ew * sx + vx * sw + vy * sz - ez * sy
        my = ew * sy - vx * sz + vy * sw + ez * sx
        mz = ew * sz + vx * sy - vy * sx + ez * sw
        if mw < 0.0:
            mw, mx, my, mz = -mw, -mx, -my, -mz
        if up:
            # y = E^- e_z - e_z (third column of E^-); dx = k (e_z x y) = k (-y_y, y_x, 0)
            yx = 2.0 * (mx * mz + mw * my)
            yy = 2.0 * (my * mz - mw * mx)
            gx, gy, gz = -ka[k] * yy, ka[k] * yx, 0.0
        else:
            if bx is None:
                Mw, Mx, My, Mz = mw, mx, my, mz
            else:
                # M = m Exp(-b), b = (bx, by, 0)
                bn = sqrt(bx[k] * bx[k] + by[k] * by[k])
                hb = 0.5 - bn * bn / 48.0 if bn < 1e-4 else sin(0.5 * bn) / bn
                cw, cx, cy = cos(0.5 * bn), -hb * bx[k], -hb * by[k]
                Mw = mw * cw - mx * cx - my * cy
                Mx = mw * cx + mx * cw - mz * cy
                My = mw * cy + my * cw + mz * cx
                Mz = mz * cw + mx * cy - my * cx
                if Mw < 0.0:
                    Mw, Mx, My, Mz = -Mw, -Mx, -My, -Mz
            vn = sqrt(Mx * Mx + My * My + Mz * Mz)
            if vn < 1e-300:
                f = 0.0
            else:
                f = 2.0 * atan2(vn, Mw) / vn
            gx, gy, gz = ka[k] * f * Mx, ka[k] * f * My, kc[k] * f * Mz
        # E = Exp(-g) E^-
        th = sqrt(gx * gx + gy * gy + gz * gz)
        if th < 1e-4:
            hs = 0.5 - th * th / 48.0
        else:
            hs = sin(0.5 * th) / th
        aw = cos(0.5 * th)
        ax, ay, az = -hs * gx, -hs * gy, -hs * gz
        ew = aw * mw - ax * mx - ay * my - az * mz
        ex = aw * mx + ax * mw + ay * mz - az * my
        ey = aw * my - ax * mz + ay * mw + az * mx
        ez = aw * mz + ax * my - ay * mx + az * mw
        nrm = 1.0 / sqrt(ew * ew + ex * ex + ey * ey + ez * ez)
        ew, ex, ey, ez = ew * nrm, ex * nrm, ey * nrm, ez * nrm
        out[k] = (ew, ex, ey, ez)
    return out
