r"""On-manifold IMU preintegration (Forster, Carlone, Dellaert, Scaramuzza, IEEE T-RO 2017).

Between two frame times ``t_i < t_j`` the gyro and accelerometer samples are
summarised, independently of the unknown attitude, velocity and gravity, by

.. math::

    \Delta R_{ij} = \prod_k \operatorname{Exp}((\tilde\omega_k - b_g)\,\delta t_k), \quad
    \Delta v_{ij} = \sum_k \Delta R_{ik} (\tilde a_k - b_a)\,\delta t_k, \quad
    \Delta p_{ij} = \sum_k \Delta v_{ik}\,\delta t_k + \tfrac12 \Delta R_{ik}(\tilde a_k - b_a)\,\delta t_k^2

(Forster et al. 2017, Sec. VI; gravity is *not* included). With the state ``R`` = world
from body, velocity and position in the world frame and gravity ``g`` (world):

.. math::

    R_j = R_i \Delta R_{ij}, \quad
    v_j = v_i + g\,\Delta t_{ij} + R_i \Delta v_{ij}, \quad
    p_j = p_i + v_i \Delta t_{ij} + \tfrac12 g \Delta t_{ij}^2 + R_i \Delta p_{ij}.

Frames
------
- ``delta_R`` maps vectors from the body frame at the frame's *end* into the
  body frame at the frame's *start* ("start from end"): ``R_k = R_{k-1} @ delta_R_k``
  for world-from-body attitudes ``R``.
- ``delta_v`` and ``delta_p`` are expressed in the body frame at the frame's start
  (m/s and m).

Signal model (how a sample is held over its interval)
-----------------------------------------------------
The IMU signal is taken as piecewise linear between samples. Each interval
between consecutive *knots* (the samples, plus the frame boundaries that fall
between samples) is integrated with one constant rate and specific force:

- ``hold="midpoint"`` (default): the mean of the signal at the interval's two
  ends (trapezoid / midpoint rule; second order for the rotation). A frame boundary between two
  samples gets the linearly interpolated signal, so the two pieces of a split
  interval use ``(y_k + y_b)/2`` and ``(y_b + y_{k+1})/2``.
- ``hold="left"``: the value of the left sample, held until the next sample
  (zero-order hold, first order; what Forster's discrete model and GTSAM assume).
  A boundary between samples gets the left sample's value, so the rotation of
  the two pieces composes exactly to that of the unsplit interval.

In both cases two frames that meet between samples compose (:meth:`PreintegratedImu.combine`)
exactly to the integration over the samples with the boundary inserted as a
knot. Within an interval the specific force is rotated with the attitude at the
interval's start (Forster's discretisation): rotation is exact for the held
rate, velocity and position are first order in ``|omega| dt`` (an error of
about ``|omega| dt / 2`` of each interval's velocity change).

The streaming and batch paths use the same knots, the same held values and the
same ``delta_t`` per interval.

Noise and bias Jacobians
------------------------
``gyro_noise_density`` (rad/s/sqrt(Hz)) and ``accel_noise_density``
(m/s^2/sqrt(Hz)) are continuous-time white-noise densities, equal on the three
axes; an interval of length ``dt`` receives discrete noise of variance
``sigma^2 / dt`` on its held value (Forster's discrete noise). The 9x9 covariance is in
the order ``[rotation, velocity, position]`` with the rotation error on the
right, ``delta_R_measured = delta_R_true @ Exp(dphi)`` (as in Forster, Sec. VI-B).
The bias Jacobians are the exact derivatives of the discrete deltas at the
bias they were integrated with (Forster, Sec. VI-C and appendix); use
:meth:`PreintegratedImu.corrected` / :meth:`FrameDeltas.corrected` for the
first-order update ``delta_R Exp(dR_dbg dbg)``, ``delta_v + dv_dbg dbg + dv_dba dba``, ...

Implementation
--------------
The streaming value type :class:`PreintegratedImu` runs Forster's recursion in
scalar Python floats (no numpy inside :meth:`~PreintegratedImu.integrate`).
Internally it keeps the rotation error and the rotation rows of the bias
Jacobian on the *left* (``delta_R_measured = Exp(dtheta) delta_R_true``, in the
frame-start body frame), which turns the state matrix into a unit lower
block-triangular one; the public properties convert to Forster's right-error
form.

The batch path :func:`preintegrate` is vectorised over all intervals of a log
without a Python loop over samples: fused batched ``Exp`` and left Jacobians,
a log-depth (Hillis-Steele) product scan for ``delta_R`` within each frame,
cumulative sums for ``delta_v``/``delta_p``, and the closed-form solution of the
covariance and Jacobian recursions, ``sum_k G_k Q_k G_k^T`` and ``sum_k G_k``,
where ``G_k`` is the sensitivity of the frame's deltas to the noise of interval
``k`` (it only needs the frame's prefix products and sums; see
``_blocks_kernel``). The only Python loop runs over chunks of about 32k
intervals, to keep the temporaries in cache. Frames with many more intervals than
the others are cut into blocks that are merged with the associative
composition of preintegrated measurements (a log-depth tree), which is also
available as :meth:`PreintegratedImu.combine`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Literal, Sequence

import numpy as np

from imu_ground import so3
from imu_ground.imu.data import ImuData

__all__ = [
    "PreintegratedImu",
    "FrameDeltas",
    "StreamingPreintegrator",
    "preintegrate",
    "make_frame_times",
]

Hold = Literal["midpoint", "left"]
OnGap = Literal["raise", "flag"]

_SMALL2 = 1e-8          # theta^2 below which the Taylor series are used (theta < 1e-4 rad)
_ORTHO_TOL = 1e-12      # project delta_R onto SO(3) when |R^T R - I| exceeds this
_CHUNK = 1 << 15         # intervals per vectorised chunk in preintegrate (cache-sized temporaries)
_N_STATE = 107          # length of PreintegratedImu's scalar state list

# Layout of PreintegratedImu._s (a tuple of floats: immutable, so copies share it
# and the garbage collector stops tracking it). Position rows are kept in the
# "q form" q = p - T v (T = time integrated so far): the recursion
# p' = p + dt (v + v') / 2 becomes q' = q - (T + dt/2) (v' - v), which makes every
# position row a scaled copy of the velocity increment (fewer operations).
#   0          T      sum of dt, s
#   1:10       R      delta_R, row-major
#   10:13      v      delta_v
#   13:16      p      delta_p
#   16:25      Th     left rotation-error Jacobian w.r.t. b_g (= delta_R @ dR_dbg)
#   25:34      Vg     dv_dbg
#   34:43      Mg     dp_dbg - T dv_dbg
#   43:52      Va     dv_dba
#   52:61      Ma     dp_dba - T dv_dba
#   61:67      rr     left rotation-error covariance, symmetric (00 01 02 11 12 22)
#   67:76      rv     E[dtheta dv^T], row-major
#   76:85      rq     E[dtheta dq^T]
#   85:91      vv     symmetric
#   91:100     vq     E[dv dq^T]
#   100:106    qq     symmetric
#   106        n      number of intervals integrated (int)
_SYM = ((0, 1, 2), (1, 3, 4), (2, 4, 5))
_I9 = np.eye(9)
_ndarray = np.ndarray


def _identity_state() -> tuple:
    s = [0.0] * _N_STATE
    s[1] = s[5] = s[9] = 1.0
    s[106] = 0
    return tuple(s)


def _check_hold(hold: str) -> None:
    if hold not in ("midpoint", "left"):
        raise ValueError(f"hold must be 'midpoint' or 'left', got {hold!r}")


def _check_on_gap(on_gap: str) -> None:
    if on_gap not in ("raise", "flag"):
        raise ValueError(f"on_gap must be 'raise' or 'flag', got {on_gap!r}")


def _vec3(x, name: str) -> tuple[float, float, float]:
    a = np.asarray(x, dtype=float).reshape(-1)
    if a.shape != (3,):
        raise ValueError(f"{name} must have 3 elements, got shape {np.shape(x)}")
    return float(a[0]), float(a[1]), float(a[2])


def _gap_message(t0: float, length: float, max_gap: float) -> str:
    return (f"IMU timestamp gap of {length:.6g} s at t = {t0:.6f} s (from {t0:.6f} s to "
            f"{t0 + length:.6f} s) exceeds max_gap = {max_gap:g} s; refusing to preintegrate "
            f"across it (pass on_gap='flag' to mark the affected frames invalid instead)")


# ---------------------------------------------------------------------------
# Left-form <-> right-form conversion and composition (vectorised)
# ---------------------------------------------------------------------------
def _left_to_right(R: np.ndarray, J: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Left rotation error (start frame) to Forster's right error: D = diag(R^T, I, I)."""
    Rt = np.swapaxes(R, -1, -2)
    J = J.copy()
    J[..., 0:3, :] = Rt @ J[..., 0:3, :]
    S = S.copy()
    S[..., 0:3, :] = Rt @ S[..., 0:3, :]
    S[..., :, 0:3] = S[..., :, 0:3] @ R
    return J, 0.5 * (S + np.swapaxes(S, -1, -2))


def _right_to_left(R: np.ndarray, J: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    J = J.copy()
    J[..., 0:3, :] = R @ J[..., 0:3, :]
    S = S.copy()
    S[..., 0:3, :] = R @ S[..., 0:3, :]
    S[..., :, 0:3] = S[..., :, 0:3] @ np.swapaxes(R, -1, -2)
    return J, 0.5 * (S + np.swapaxes(S, -1, -2))


def _compose_left(a: tuple, b: tuple) -> tuple:
    """Compose two consecutive preintegrated measurements (left-error form), batched.

    ``a`` and ``b`` are tuples ``(T, R, v, p, J, S)`` with shapes (...), (...,3,3),
    (...,3), (...,3), (...,9,6), (...,9,9); ``a`` comes first. Exact for the deltas,
    exact linear-error propagation for ``J`` (bias Jacobian) and ``S`` (covariance).
    """
    Ta, Ra, va, pa, Ja, Sa = a
    Tb, Rb, vb, pb, Jb, Sb = b
    R = Ra @ Rb
    Rvb = np.einsum("...ij,...j->...i", Ra, vb)
    Rpb = np.einsum("...ij,...j->...i", Ra, pb)
    v = va + Rvb
    p = pa + va * Tb[..., None] + Rpb
    T = Ta + Tb
    if Ja is None:
        return T, R, v, p, None, None
    shape = Ta.shape
    Fa = np.broadcast_to(_I9, shape + (9, 9)).copy()
    Fa[..., 3:6, 0:3] = -so3.hat(Rvb)
    Fa[..., 6:9, 0:3] = -so3.hat(Rpb)
    Fa[..., 6:9, 3:6] = Tb[..., None, None] * np.eye(3)
    Fb = np.zeros(shape + (9, 9))
    for k in range(3):
        Fb[..., 3 * k:3 * k + 3, 3 * k:3 * k + 3] = Ra
    J = Fa @ Ja + Fb @ Jb
    S = Fa @ Sa @ np.swapaxes(Fa, -1, -2) + Fb @ Sb @ np.swapaxes(Fb, -1, -2)
    return T, R, v, p, J, 0.5 * (S + np.swapaxes(S, -1, -2))


def _project_if_needed(R: np.ndarray) -> np.ndarray:
    """Project the rotations whose orthonormality defect exceeds _ORTHO_TOL (rare)."""
    R = np.asarray(R, dtype=float)
    E = np.swapaxes(R, -1, -2) @ R - np.eye(3)
    bad = np.max(np.abs(E), axis=(-2, -1)) > _ORTHO_TOL
    if np.any(bad):
        R = R.copy()
        R[bad] = so3.project(R[bad])
    return R


# ---------------------------------------------------------------------------
# Streaming value type
# ---------------------------------------------------------------------------
class PreintegratedImu:
    """Preintegrated IMU measurements between two times (streaming value type).

    Like GTSAM's ``PreintegratedImuMeasurements``: call :meth:`integrate` with each
    interval's duration and held measurements, read the deltas, covariance and
    bias Jacobians, :meth:`reset` to start a new frame.

    Parameters
    ----------
    bias_gyro : array_like, shape (3,)
        Gyro bias subtracted from every rate (the linearisation point), rad/s,
        body frame.
    bias_accel : array_like, shape (3,)
        Accelerometer bias subtracted from every specific force, m/s^2, body frame.
    gyro_noise_density : float
        Gyro white noise, rad/s/sqrt(Hz) (= rad/sqrt(s)), same on all axes.
    accel_noise_density : float
        Accelerometer white noise, m/s^2/sqrt(Hz), same on all axes.
    uncertainty : bool
        Propagate the covariance and the bias Jacobians (default). False keeps
        only ``delta_R``, ``delta_v`` and ``delta_p`` (the same formulas, about
        a quarter of the work: what a filter that needs only the deltas wants);
        the covariance and Jacobian properties then raise ``ValueError``.

    Attributes
    ----------
    t_start, t_end : float
        Times of the frame this object summarises, s (``nan`` unless set by
        :class:`StreamingPreintegrator` or :meth:`FrameDeltas.frame`).
    valid : bool
        False when the frame spans a timestamp gap longer than ``max_gap``
        (set by the front-ends).
    n_intervals : int
        Number of :meth:`integrate` calls since the last reset.

    Notes
    -----
    ``delta_R`` maps the body frame at the end into the body frame at the start
    (start from end). ``delta_v`` / ``delta_p`` are in the body frame at the start.
    """

    __slots__ = ("_s", "_bias", "_qg", "_qa", "_par", "gyro_noise_density", "accel_noise_density",
                 "t_start", "t_end", "valid", "uncertainty")

    def __init__(self, bias_gyro: Sequence[float] = (0.0, 0.0, 0.0),
                 bias_accel: Sequence[float] = (0.0, 0.0, 0.0),
                 gyro_noise_density: float = 0.0, accel_noise_density: float = 0.0,
                 uncertainty: bool = True) -> None:
        self.uncertainty = bool(uncertainty)
        self._bias = _vec3(bias_gyro, "bias_gyro") + _vec3(bias_accel, "bias_accel")
        self.gyro_noise_density = float(gyro_noise_density)
        self.accel_noise_density = float(accel_noise_density)
        if self.gyro_noise_density < 0 or self.accel_noise_density < 0:
            raise ValueError("noise densities must be >= 0")
        self._qg = self.gyro_noise_density ** 2
        self._qa = self.accel_noise_density ** 2
        self.reset()

    # -- state -------------------------------------------------------------
    def reset(self, bias_gyro: Sequence[float] | None = None,
              bias_accel: Sequence[float] | None = None) -> None:
        """Start over: identity deltas, zero covariance and Jacobians.

        Parameters
        ----------
        bias_gyro, bias_accel : array_like, shape (3,), optional
            New linearisation biases (rad/s, m/s^2, body frame); unchanged if None.
        """
        bg = self._bias[:3] if bias_gyro is None else _vec3(bias_gyro, "bias_gyro")
        ba = self._bias[3:] if bias_accel is None else _vec3(bias_accel, "bias_accel")
        self._bias = bg + ba
        self._par = self._bias + (self._qa, self._qg)
        self._s = _identity_state()
        self.t_start = math.nan
        self.t_end = math.nan
        self.valid = True

    @property
    def n_intervals(self) -> int:
        """Number of :meth:`integrate` calls (intervals) since the last reset."""
        return int(self._s[106])

    @n_intervals.setter
    def n_intervals(self, value: int) -> None:
        self._s = self._s[:106] + (int(value),)

    def copy(self) -> "PreintegratedImu":
        """An independent copy (the state is an immutable tuple of floats, shared)."""
        out = PreintegratedImu.__new__(PreintegratedImu)
        out._s = self._s
        out._bias = self._bias
        out._qg, out._qa = self._qg, self._qa
        out._par = self._par
        out.gyro_noise_density = self.gyro_noise_density
        out.accel_noise_density = self.accel_noise_density
        out.t_start, out.t_end, out.valid = self.t_start, self.t_end, self.valid
        out.uncertainty = self.uncertainty
        return out

    def integrate(self, dt: float, gyro: Sequence[float], accel: Sequence[float]) -> None:
        """Add one interval with constant measurements.

        Parameters
        ----------
        dt : float
            Interval length, s (> 0).
        gyro : sequence of 3 floats
            Angular rate held over the interval, rad/s, body frame (bias not removed).
        accel : sequence of 3 floats
            Specific force held over the interval, m/s^2, body frame (bias not removed).
        """
        if not dt > 0.0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        if type(gyro) is np.ndarray:
            gyro = gyro.tolist()
        if type(accel) is np.ndarray:
            accel = accel.tolist()
        wx, wy, wz = gyro
        ax, ay, az = accel
        self._integrate(float(dt), float(wx), float(wy), float(wz),
                        float(ax), float(ay), float(az))

    def _integrate_deltas(self, dt: float, wx: float, wy: float, wz: float,
                          ax: float, ay: float, az: float) -> None:
        # uncertainty=False: delta_R, delta_v, delta_p only, the formulas of _integrate
        bgx, bgy, bgz, bax, bay, baz, _, _ = self._par
        s = self._s
        T, r00, r01, r02, r10, r11, r12, r20, r21, r22, v0, v1, v2, p0, p1, p2 = s[:16]
        x = (wx - bgx) * dt
        y = (wy - bgy) * dt
        z = (wz - bgz) * dt
        fx = (ax - bax) * dt
        fy = (ay - bay) * dt
        fz = (az - baz) * dt
        xx = x * x
        yy = y * y
        zz = z * z
        t2 = xx + yy + zz
        if t2 < _SMALL2:
            A = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
            B = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
        else:
            th = math.sqrt(t2)
            hs = math.sin(0.5 * th)
            A = math.sin(th) / th
            B = 2.0 * hs * hs / t2
        c0 = r00 * fx + r01 * fy + r02 * fz
        c1 = r10 * fx + r11 * fy + r12 * fz
        c2 = r20 * fx + r21 * fy + r22 * fz
        Bxy = B * x * y
        Bxz = B * x * z
        Byz = B * y * z
        Ax = A * x
        Ay = A * y
        Az = A * z
        e00 = 1.0 - B * (yy + zz)
        e11 = 1.0 - B * (xx + zz)
        e22 = 1.0 - B * (xx + yy)
        e01 = Bxy - Az
        e10 = Bxy + Az
        e02 = Bxz + Ay
        e20 = Bxz - Ay
        e12 = Byz - Ax
        e21 = Byz + Ax
        self._s = (
            T + dt,
            r00 * e00 + r01 * e10 + r02 * e20, r00 * e01 + r01 * e11 + r02 * e21,
            r00 * e02 + r01 * e12 + r02 * e22,
            r10 * e00 + r11 * e10 + r12 * e20, r10 * e01 + r11 * e11 + r12 * e21,
            r10 * e02 + r11 * e12 + r12 * e22,
            r20 * e00 + r21 * e10 + r22 * e20, r20 * e01 + r21 * e11 + r22 * e21,
            r20 * e02 + r21 * e12 + r22 * e22,
            v0 + c0, v1 + c1, v2 + c2,
            p0 + dt * (v0 + 0.5 * c0), p1 + dt * (v1 + 0.5 * c1), p2 + dt * (v2 + 0.5 * c2),
        ) + s[16:106] + (s[106] + 1,)

    def _integrate(self, dt: float, wx: float, wy: float, wz: float,
                   ax: float, ay: float, az: float) -> None:
        # Hot path: scalar floats only (see the module docstring and the state layout).
        if not self.uncertainty:
            return self._integrate_deltas(dt, wx, wy, wz, ax, ay, az)
        bgx, bgy, bgz, bax, bay, baz, qa, qg = self._par
        (T, r00, r01, r02, r10, r11, r12, r20, r21, r22, v0, v1, v2, p0, p1, p2,
         h00, h01, h02, h10, h11, h12, h20, h21, h22,
         g00, g01, g02, g10, g11, g12, g20, g21, g22,
         m00, m01, m02, m10, m11, m12, m20, m21, m22,
         a00, a01, a02, a10, a11, a12, a20, a21, a22,
         b00, b01, b02, b10, b11, b12, b20, b21, b22,
         rr00, rr01, rr02, rr11, rr12, rr22,
         rv00, rv01, rv02, rv10, rv11, rv12, rv20, rv21, rv22,
         rq00, rq01, rq02, rq10, rq11, rq12, rq20, rq21, rq22,
         vv00, vv01, vv02, vv11, vv12, vv22,
         vq00, vq01, vq02, vq10, vq11, vq12, vq20, vq21, vq22,
         qq00, qq01, qq02, qq11, qq12, qq22, n) = self._s
        mid = T + 0.5 * dt
        x = (wx - bgx) * dt
        y = (wy - bgy) * dt
        z = (wz - bgz) * dt
        fx = (ax - bax) * dt
        fy = (ay - bay) * dt
        fz = (az - baz) * dt
        xx = x * x
        yy = y * y
        zz = z * z
        t2 = xx + yy + zz
        if t2 < _SMALL2:
            A = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
            B = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
            C = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
        else:
            th = math.sqrt(t2)
            sn = math.sin(th)
            hs = math.sin(0.5 * th)
            A = sn / th
            B = 2.0 * hs * hs / t2
            C = (th - sn) / (t2 * th)
        xy = x * y
        xz = x * z
        yz = y * z
        # c = delta_R_k f dt: rotated velocity increment (start-body frame)
        c0 = r00 * fx + r01 * fy + r02 * fz
        c1 = r10 * fx + r11 * fy + r12 * fz
        c2 = r20 * fx + r21 * fy + r22 * fz
        # --- gyro-bias Jacobians: H = hat(c) Th; Vg -= H; Mg += mid H; Th -= delta_R_k Jl dt
        H0 = c1 * h20 - c2 * h10
        H1 = c1 * h21 - c2 * h11
        H2 = c1 * h22 - c2 * h12
        g00 -= H0
        g01 -= H1
        g02 -= H2
        m00 += mid * H0
        m01 += mid * H1
        m02 += mid * H2
        H0 = c2 * h00 - c0 * h20
        H1 = c2 * h01 - c0 * h21
        H2 = c2 * h02 - c0 * h22
        g10 -= H0
        g11 -= H1
        g12 -= H2
        m10 += mid * H0
        m11 += mid * H1
        m12 += mid * H2
        H0 = c0 * h10 - c1 * h00
        H1 = c0 * h11 - c1 * h01
        H2 = c0 * h12 - c1 * h02
        g20 -= H0
        g21 -= H1
        g22 -= H2
        m20 += mid * H0
        m21 += mid * H1
        m22 += mid * H2
        # j = Jl(phi) dt = (I + B K + C K^2) dt
        Cd = C * dt
        Bd = B * dt
        Cxy = Cd * xy
        Cxz = Cd * xz
        Cyz = Cd * yz
        Bx = Bd * x
        By = Bd * y
        Bz = Bd * z
        j00 = dt - Cd * (yy + zz)
        j11 = dt - Cd * (xx + zz)
        j22 = dt - Cd * (xx + yy)
        j01 = Cxy - Bz
        j10 = Cxy + Bz
        j02 = Cxz + By
        j20 = Cxz - By
        j12 = Cyz - Bx
        j21 = Cyz + Bx
        # Th -= U, U = delta_R_k Jl dt
        h00 -= (r00 * j00 + r01 * j10 + r02 * j20)
        h01 -= (r00 * j01 + r01 * j11 + r02 * j21)
        h02 -= (r00 * j02 + r01 * j12 + r02 * j22)
        h10 -= (r10 * j00 + r11 * j10 + r12 * j20)
        h11 -= (r10 * j01 + r11 * j11 + r12 * j21)
        h12 -= (r10 * j02 + r11 * j12 + r12 * j22)
        h20 -= (r20 * j00 + r21 * j10 + r22 * j20)
        h21 -= (r20 * j01 + r21 * j11 + r22 * j21)
        h22 -= (r20 * j02 + r21 * j12 + r22 * j22)
        # --- accelerometer-bias Jacobians: d = delta_R_k dt; Va -= d; Ma += mid d
        d = r00 * dt
        a00 -= d
        b00 += mid * d
        d = r01 * dt
        a01 -= d
        b01 += mid * d
        d = r02 * dt
        a02 -= d
        b02 += mid * d
        d = r10 * dt
        a10 -= d
        b10 += mid * d
        d = r11 * dt
        a11 -= d
        b11 += mid * d
        d = r12 * dt
        a12 -= d
        b12 += mid * d
        d = r20 * dt
        a20 -= d
        b20 += mid * d
        d = r21 * dt
        a21 -= d
        b21 += mid * d
        d = r22 * dt
        a22 -= d
        b22 += mid * d
        # --- covariance (left form, q rows). u = hat(c) theta is the velocity error
        # increment (plus accelerometer noise n): v' = v - u + n, q' = q + mid (u - n).
        # X = hat(c) rr, XH = hat(c) rr hat(c)^T (+ noise N = qa dt I), Y = hat(c) rv, Yq = hat(c) rq.
        X00 = c1 * rr02 - c2 * rr01
        X01 = c1 * rr12 - c2 * rr11
        X02 = c1 * rr22 - c2 * rr12
        X10 = c2 * rr00 - c0 * rr02
        X11 = c2 * rr01 - c0 * rr12
        X12 = c2 * rr02 - c0 * rr22
        X20 = c0 * rr01 - c1 * rr00
        X21 = c0 * rr11 - c1 * rr01
        X22 = c0 * rr12 - c1 * rr02
        na = qa * dt
        N00 = c1 * X02 - c2 * X01 + na
        N01 = c2 * X00 - c0 * X02
        N02 = c0 * X01 - c1 * X00
        N11 = c2 * X10 - c0 * X12 + na
        N12 = c0 * X11 - c1 * X10
        N22 = c0 * X21 - c1 * X20 + na
        Y00 = c1 * rv20 - c2 * rv10
        Y01 = c1 * rv21 - c2 * rv11
        Y02 = c1 * rv22 - c2 * rv12
        Y10 = c2 * rv00 - c0 * rv20
        Y11 = c2 * rv01 - c0 * rv21
        Y12 = c2 * rv02 - c0 * rv22
        Y20 = c0 * rv10 - c1 * rv00
        Y21 = c0 * rv11 - c1 * rv01
        Y22 = c0 * rv12 - c1 * rv02
        Z00 = c1 * rq20 - c2 * rq10
        Z01 = c1 * rq21 - c2 * rq11
        Z02 = c1 * rq22 - c2 * rq12
        Z10 = c2 * rq00 - c0 * rq20
        Z11 = c2 * rq01 - c0 * rq21
        Z12 = c2 * rq02 - c0 * rq22
        Z20 = c0 * rq10 - c1 * rq00
        Z21 = c0 * rq11 - c1 * rq01
        Z22 = c0 * rq12 - c1 * rq02
        # qq' = qq + mid (Z + Z^T) + mid^2 (XH + N)
        mid2 = mid * mid
        qq00 += mid * 2.0 * Z00 + mid2 * N00
        qq01 += mid * (Z01 + Z10) + mid2 * N01
        qq02 += mid * (Z02 + Z20) + mid2 * N02
        qq11 += mid * 2.0 * Z11 + mid2 * N11
        qq12 += mid * (Z12 + Z21) + mid2 * N12
        qq22 += mid * 2.0 * Z22 + mid2 * N22
        # vq' = vq + mid (Y^T - XH - N) - Z
        vq00 += mid * (Y00 - N00) - Z00
        vq01 += mid * (Y10 - N01) - Z01
        vq02 += mid * (Y20 - N02) - Z02
        vq10 += mid * (Y01 - N01) - Z10
        vq11 += mid * (Y11 - N11) - Z11
        vq12 += mid * (Y21 - N12) - Z12
        vq20 += mid * (Y02 - N02) - Z20
        vq21 += mid * (Y12 - N12) - Z21
        vq22 += mid * (Y22 - N22) - Z22
        # vv' = vv - (Y + Y^T) + XH + N
        vv00 += N00 - 2.0 * Y00
        vv01 += N01 - Y01 - Y10
        vv02 += N02 - Y02 - Y20
        vv11 += N11 - 2.0 * Y11
        vv12 += N12 - Y12 - Y21
        vv22 += N22 - 2.0 * Y22
        # rq' = rq + mid X^T, rv' = rv - X^T
        rq00 += mid * X00
        rq01 += mid * X10
        rq02 += mid * X20
        rq10 += mid * X01
        rq11 += mid * X11
        rq12 += mid * X21
        rq20 += mid * X02
        rq21 += mid * X12
        rq22 += mid * X22
        rv00 -= X00
        rv01 -= X10
        rv02 -= X20
        rv10 -= X01
        rv11 -= X11
        rv12 -= X21
        rv20 -= X02
        rv21 -= X12
        rv22 -= X22
        # gyro noise: U Q U^T / dt = qg dt [(1 - k t2) I + k psi psi^T], psi = delta_R_k phi,
        # since Jl Jl^T = I + k K^2 with k = 2C - B^2 - C^2 t2
        if qg != 0.0:
            kap = 2.0 * C - B * B - C * C * t2
            w1 = qg * dt * kap
            w0 = qg * dt - w1 * t2
            s0 = r00 * x + r01 * y + r02 * z
            s1 = r10 * x + r11 * y + r12 * z
            s2 = r20 * x + r21 * y + r22 * z
            ws0 = w1 * s0
            ws1 = w1 * s1
            rr00 += w0 + ws0 * s0
            rr11 += w0 + ws1 * s1
            rr22 += w0 + w1 * s2 * s2
            rr01 += ws0 * s1
            rr02 += ws0 * s2
            rr12 += ws1 * s2
        # --- deltas: p += dt (v + c/2), v += c, R = R Exp(phi), Exp = I + A K + B K^2
        p0 += dt * (v0 + 0.5 * c0)
        p1 += dt * (v1 + 0.5 * c1)
        p2 += dt * (v2 + 0.5 * c2)
        Bxy = B * xy
        Bxz = B * xz
        Byz = B * yz
        Ax = A * x
        Ay = A * y
        Az = A * z
        e00 = 1.0 - B * (yy + zz)
        e11 = 1.0 - B * (xx + zz)
        e22 = 1.0 - B * (xx + yy)
        e01 = Bxy - Az
        e10 = Bxy + Az
        e02 = Bxz + Ay
        e20 = Bxz - Ay
        e12 = Byz - Ax
        e21 = Byz + Ax
        self._s = (
            T + dt,
            r00 * e00 + r01 * e10 + r02 * e20, r00 * e01 + r01 * e11 + r02 * e21,
            r00 * e02 + r01 * e12 + r02 * e22,
            r10 * e00 + r11 * e10 + r12 * e20, r10 * e01 + r11 * e11 + r12 * e21,
            r10 * e02 + r11 * e12 + r12 * e22,
            r20 * e00 + r21 * e10 + r22 * e20, r20 * e01 + r21 * e11 + r22 * e21,
            r20 * e02 + r21 * e12 + r22 * e22,
            v0 + c0, v1 + c1, v2 + c2, p0, p1, p2,
            h00, h01, h02, h10, h11, h12, h20, h21, h22,
            g00, g01, g02, g10, g11, g12, g20, g21, g22,
            m00, m01, m02, m10, m11, m12, m20, m21, m22,
            a00, a01, a02, a10, a11, a12, a20, a21, a22,
            b00, b01, b02, b10, b11, b12, b20, b21, b22,
            rr00, rr01, rr02, rr11, rr12, rr22,
            rv00, rv01, rv02, rv10, rv11, rv12, rv20, rv21, rv22,
            rq00, rq01, rq02, rq10, rq11, rq12, rq20, rq21, rq22,
            vv00, vv01, vv02, vv11, vv12, vv22,
            vq00, vq01, vq02, vq10, vq11, vq12, vq20, vq21, vq22,
            qq00, qq01, qq02, qq11, qq12, qq22, n + 1)

    def _require_uncertainty(self) -> None:
        if not self.uncertainty:
            raise ValueError("this preintegration was made with uncertainty=False: it has no covariance "
                             "or bias Jacobians (use uncertainty=True)")

    # -- array views ---------------------------------------------------------
    def _left_arrays(self) -> tuple:
        s = np.asarray(self._s)
        R = s[1:10].reshape(3, 3)
        J = np.zeros((9, 6))
        J[0:3, 0:3] = s[16:25].reshape(3, 3)
        J[3:6, 0:3] = s[25:34].reshape(3, 3)
        J[6:9, 0:3] = s[34:43].reshape(3, 3)
        J[3:6, 3:6] = s[43:52].reshape(3, 3)
        J[6:9, 3:6] = s[52:61].reshape(3, 3)
        S = np.zeros((9, 9))
        sym = np.array(_SYM)
        S[0:3, 0:3] = s[61:67][sym]
        S[0:3, 3:6] = s[67:76].reshape(3, 3)
        S[0:3, 6:9] = s[76:85].reshape(3, 3)
        S[3:6, 3:6] = s[85:91][sym]
        S[3:6, 6:9] = s[91:100].reshape(3, 3)
        S[6:9, 6:9] = s[100:106][sym]
        S = np.triu(S) + np.triu(S, 1).T
        # q form -> p form: p = q + T v (rows 6:9 += T * rows 3:6, same for columns)
        T = float(s[0])
        J[6:9] += T * J[3:6]
        S[6:9] += T * S[3:6]
        S[:, 6:9] += T * S[:, 3:6]
        return np.float64(T), R.copy(), s[10:13].copy(), s[13:16].copy(), J, S

    @classmethod
    def _from_left_arrays(cls, T, R, v, p, J, S, bias: tuple, qg: float, qa: float) -> "PreintegratedImu":
        out = cls.__new__(cls)
        out._bias = bias
        out._qg, out._qa = float(qg), float(qa)
        out._par = bias + (out._qa, out._qg)
        out.uncertainty = True
        out.gyro_noise_density = math.sqrt(out._qg)
        out.accel_noise_density = math.sqrt(out._qa)
        iu = np.triu_indices(3)
        # p form -> q form: q = p - T v
        T = float(T)
        J = np.array(J, dtype=float)
        S = np.array(S, dtype=float)
        J[6:9] -= T * J[3:6]
        S[6:9] -= T * S[3:6]
        S[:, 6:9] -= T * S[:, 3:6]
        s = np.empty(_N_STATE)
        s[0] = T
        s[1:10] = np.asarray(R).reshape(9)
        s[10:13] = v
        s[13:16] = p
        s[16:25] = J[0:3, 0:3].reshape(9)
        s[25:34] = J[3:6, 0:3].reshape(9)
        s[34:43] = J[6:9, 0:3].reshape(9)
        s[43:52] = J[3:6, 3:6].reshape(9)
        s[52:61] = J[6:9, 3:6].reshape(9)
        s[61:67] = S[0:3, 0:3][iu]
        s[67:76] = S[0:3, 3:6].reshape(9)
        s[76:85] = S[0:3, 6:9].reshape(9)
        s[85:91] = S[3:6, 3:6][iu]
        s[91:100] = S[3:6, 6:9].reshape(9)
        s[100:106] = S[6:9, 6:9][iu]
        out._s = tuple(s.tolist())
        out.t_start = math.nan
        out.t_end = math.nan
        out.valid = True
        out.n_intervals = 0
        return out

    # -- public read-outs ----------------------------------------------------
    @property
    def bias_gyro(self) -> np.ndarray:
        """Gyro bias the deltas were integrated with, rad/s, body frame, shape (3,)."""
        return np.array(self._bias[:3])

    @property
    def bias_accel(self) -> np.ndarray:
        """Accelerometer bias the deltas were integrated with, m/s^2, body frame, shape (3,)."""
        return np.array(self._bias[3:])

    @property
    def delta_t(self) -> float:
        """Integrated time, s (sum of the ``dt`` passed to :meth:`integrate`)."""
        return self._s[0]

    @property
    def delta_R(self) -> np.ndarray:
        """Rotation, shape (3, 3): body frame at the end -> body frame at the start."""
        return _project_if_needed(np.array(self._s[1:10]).reshape(3, 3))

    @property
    def delta_v(self) -> np.ndarray:
        """Velocity increment without gravity, m/s, body frame at the start, shape (3,)."""
        return np.array(self._s[10:13])

    @property
    def delta_p(self) -> np.ndarray:
        """Position increment without gravity, m, body frame at the start, shape (3,)."""
        return np.array(self._s[13:16])

    @property
    def d_R_d_bg(self) -> np.ndarray:
        """dR/dbg (3, 3), rad per rad/s: ``delta_R(bg + d) ~= delta_R Exp(d_R_d_bg @ d)`` (right, end-body frame)."""
        self._require_uncertainty()
        R = np.array(self._s[1:10]).reshape(3, 3)
        return R.T @ np.array(self._s[16:25]).reshape(3, 3)

    @property
    def d_v_d_bg(self) -> np.ndarray:
        """d delta_v / d bg, shape (3, 3), m/s per rad/s (start-body frame)."""
        self._require_uncertainty()
        return np.array(self._s[25:34]).reshape(3, 3)

    @property
    def d_p_d_bg(self) -> np.ndarray:
        """d delta_p / d bg, shape (3, 3), m per rad/s (start-body frame)."""
        self._require_uncertainty()
        s = self._s
        return (s[0] * np.array(s[25:34]) + np.array(s[34:43])).reshape(3, 3)

    @property
    def d_v_d_ba(self) -> np.ndarray:
        """d delta_v / d ba, shape (3, 3), s (start-body frame)."""
        self._require_uncertainty()
        return np.array(self._s[43:52]).reshape(3, 3)

    @property
    def d_p_d_ba(self) -> np.ndarray:
        """d delta_p / d ba, shape (3, 3), s^2 (start-body frame)."""
        self._require_uncertainty()
        s = self._s
        return (s[0] * np.array(s[43:52]) + np.array(s[52:61])).reshape(3, 3)

    @property
    def bias_jacobian(self) -> np.ndarray:
        """All bias Jacobians as one (9, 6) matrix: rows [rotation, velocity, position], columns [bg, ba]."""
        self._require_uncertainty()
        T, R, v, p, J, S = self._left_arrays()
        return _left_to_right(R, J, S)[0]

    @property
    def covariance(self) -> np.ndarray:
        """Noise covariance (9, 9): [rotation (right error, end-body frame, rad), velocity (m/s), position (m)]."""
        self._require_uncertainty()
        T, R, v, p, J, S = self._left_arrays()
        return _left_to_right(R, J, S)[1]

    def corrected(self, bias_gyro: Sequence[float], bias_accel: Sequence[float]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First-order bias update of the deltas without re-integration (Forster, Sec. VI-C).

        Parameters
        ----------
        bias_gyro, bias_accel : array_like, shape (3,)
            New bias estimates, rad/s and m/s^2, body frame.

        Returns
        -------
        delta_R : ndarray (3, 3)
            ``delta_R Exp(d_R_d_bg @ dbg)``, end-body -> start-body frame.
        delta_v : ndarray (3,)
            ``delta_v + d_v_d_bg @ dbg + d_v_d_ba @ dba``, m/s, start-body frame.
        delta_p : ndarray (3,)
            ``delta_p + d_p_d_bg @ dbg + d_p_d_ba @ dba``, m, start-body frame.
        """
        self._require_uncertainty()
        dbg = np.asarray(bias_gyro, dtype=float) - self.bias_gyro
        dba = np.asarray(bias_accel, dtype=float) - self.bias_accel
        R = self.delta_R @ so3.exp(self.d_R_d_bg @ dbg)
        v = self.delta_v + self.d_v_d_bg @ dbg + self.d_v_d_ba @ dba
        p = self.delta_p + self.d_p_d_bg @ dbg + self.d_p_d_ba @ dba
        return so3.project(R), v, p

    def combine(self, other: "PreintegratedImu") -> "PreintegratedImu":
        """Preintegration of this interval followed by ``other`` (exact composition).

        Both must share biases and noise densities. The result's ``delta_R`` is
        ``self.delta_R @ other.delta_R`` (end of ``other`` -> start of ``self``);
        covariance and bias Jacobians are propagated exactly (linear errors).

        Parameters
        ----------
        other : PreintegratedImu
            The interval that starts where this one ends.

        Returns
        -------
        PreintegratedImu
        """
        if other._bias != self._bias or (other._qg, other._qa) != (self._qg, self._qa):
            raise ValueError("combine needs equal biases and noise densities")
        a = tuple(np.asarray(x) for x in self._left_arrays())
        b = tuple(np.asarray(x) for x in other._left_arrays())
        T, R, v, p, J, S = _compose_left(a, b)
        out = PreintegratedImu._from_left_arrays(T, R, v, p, J, S, self._bias, self._qg, self._qa)
        out.uncertainty = self.uncertainty and other.uncertainty
        out.t_start, out.t_end = self.t_start, other.t_end
        out.valid = bool(self.valid and other.valid)
        out.n_intervals = self.n_intervals + other.n_intervals
        return out

    def __repr__(self) -> str:
        phi = so3.log(self.delta_R)
        return (f"PreintegratedImu(delta_t={self.delta_t:.6g} s, n_intervals={self.n_intervals}, "
                f"rotvec={np.array2string(phi, precision=5)}, delta_v={np.array2string(self.delta_v, precision=5)}, "
                f"delta_p={np.array2string(self.delta_p, precision=5)}, valid={self.valid})")


# ---------------------------------------------------------------------------
# Frame times
# ---------------------------------------------------------------------------
def make_frame_times(t: np.ndarray, *, rate: float | None = None, every: int | None = None,
                     t_origin: float | None = None, snap_tol: float = 1e-9) -> np.ndarray:
    """Frame boundary times for a log: a frame rate or every N samples.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, s, strictly increasing.
    rate : float, optional
        Frames per second: boundaries ``t_origin + k / rate`` inside the log.
    every : int, optional
        Boundaries at every ``every``-th sample, starting with the first.
    t_origin : float, optional
        First boundary for ``rate``, s (default ``t[0]``).
    snap_tol : float
        Boundaries within this of the log's ends still count as inside, s.

    Returns
    -------
    ndarray, shape (F + 1,)
        Boundaries; frame ``i`` spans ``[T[i], T[i+1]]``. A trailing part of the
        log after the last boundary belongs to no frame.
    """
    t = np.asarray(t, dtype=float)
    if (rate is None) == (every is None):
        raise ValueError("give exactly one of rate= and every=")
    if every is not None:
        if int(every) < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        return t[::int(every)].copy()
    if not rate > 0:
        raise ValueError(f"rate must be > 0, got {rate}")
    origin = float(t[0]) if t_origin is None else float(t_origin)
    kmin = max(0, math.ceil((t[0] - snap_tol - origin) * rate) - 1)
    kmax = math.floor((t[-1] + snap_tol - origin) * rate) + 1
    T = origin + np.arange(kmin, kmax + 1) / rate
    return T[(T >= t[0] - snap_tol) & (T <= t[-1] + snap_tol)]


# ---------------------------------------------------------------------------
# Batch results
# ---------------------------------------------------------------------------
@dataclass
class FrameDeltas:
    """Preintegrated deltas of consecutive frames (output of :func:`preintegrate`).

    Attributes
    ----------
    t_start, t_end : ndarray, shape (F,)
        Frame boundary times, s.
    delta_t : ndarray, shape (F,)
        Integrated time per frame, s (sum of the interval lengths).
    delta_R : ndarray, shape (F, 3, 3)
        Body frame at ``t_end`` -> body frame at ``t_start``.
    delta_v : ndarray, shape (F, 3)
        Velocity increment without gravity, m/s, body frame at ``t_start``.
    delta_p : ndarray, shape (F, 3)
        Position increment without gravity, m, body frame at ``t_start``.
    covariance : ndarray, shape (F, 9, 9), or None
        Order [rotation (right error, rad), velocity (m/s), position (m)]
        (None when computed with ``uncertainty=False``).
    d_R_d_bg, d_v_d_bg, d_p_d_bg, d_v_d_ba, d_p_d_ba : ndarray, shape (F, 3, 3), or None
        First-order bias Jacobians (see :class:`PreintegratedImu`).
    valid : ndarray of bool, shape (F,)
        False for frames that overlap a timestamp gap longer than ``max_gap``.
    n_intervals : ndarray of int, shape (F,)
        Number of integration intervals (sample pieces) in each frame.
    bias_gyro, bias_accel : ndarray, shape (3,)
        Biases the deltas were integrated with (rad/s, m/s^2, body frame).
    gyro_noise_density, accel_noise_density : float
        Noise densities used for ``covariance``.
    hold : str
        ``"midpoint"`` or ``"left"`` (see the module docstring).
    """

    t_start: np.ndarray
    t_end: np.ndarray
    delta_t: np.ndarray
    delta_R: np.ndarray
    delta_v: np.ndarray
    delta_p: np.ndarray
    covariance: np.ndarray | None
    d_R_d_bg: np.ndarray | None
    d_v_d_bg: np.ndarray | None
    d_p_d_bg: np.ndarray | None
    d_v_d_ba: np.ndarray | None
    d_p_d_ba: np.ndarray | None
    valid: np.ndarray
    n_intervals: np.ndarray
    bias_gyro: np.ndarray
    bias_accel: np.ndarray
    gyro_noise_density: float
    accel_noise_density: float
    hold: str

    def __len__(self) -> int:
        return int(self.t_start.shape[0])

    def _need_uncertainty(self) -> None:
        if self.covariance is None or self.d_R_d_bg is None:
            raise ValueError("these deltas were computed with uncertainty=False (no covariance or "
                             "bias Jacobians)")

    @property
    def bias_jacobian(self) -> np.ndarray:
        """All bias Jacobians, shape (F, 9, 6): rows [rotation, velocity, position], columns [bg, ba]."""
        self._need_uncertainty()
        J = np.zeros((len(self), 9, 6))
        J[:, 0:3, 0:3] = self.d_R_d_bg
        J[:, 3:6, 0:3] = self.d_v_d_bg
        J[:, 6:9, 0:3] = self.d_p_d_bg
        J[:, 3:6, 3:6] = self.d_v_d_ba
        J[:, 6:9, 3:6] = self.d_p_d_ba
        return J

    def corrected(self, bias_gyro: np.ndarray, bias_accel: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First-order bias update of every frame's deltas, without re-integration.

        Parameters
        ----------
        bias_gyro, bias_accel : array_like, shape (3,) or (F, 3)
            New bias estimates, rad/s and m/s^2, body frame.

        Returns
        -------
        delta_R : ndarray (F, 3, 3)
            ``delta_R Exp(d_R_d_bg dbg)``: end-body -> start-body frame.
        delta_v : ndarray (F, 3)
            m/s, start-body frame.
        delta_p : ndarray (F, 3)
            m, start-body frame.
        """
        self._need_uncertainty()
        dbg = np.broadcast_to(np.asarray(bias_gyro, dtype=float) - self.bias_gyro, (len(self), 3))
        dba = np.broadcast_to(np.asarray(bias_accel, dtype=float) - self.bias_accel, (len(self), 3))
        mv = lambda M, x: np.einsum("fij,fj->fi", M, x)  # noqa: E731
        R = self.delta_R @ so3.exp(mv(self.d_R_d_bg, dbg))
        v = self.delta_v + mv(self.d_v_d_bg, dbg) + mv(self.d_v_d_ba, dba)
        p = self.delta_p + mv(self.d_p_d_bg, dbg) + mv(self.d_p_d_ba, dba)
        return _project_if_needed(R), v, p

    def frame(self, i: int) -> PreintegratedImu:
        """Frame ``i`` as a :class:`PreintegratedImu` (e.g. to :meth:`~PreintegratedImu.combine` frames)."""
        self._need_uncertainty()
        J, S = _right_to_left(self.delta_R[i], self.bias_jacobian[i], self.covariance[i])
        out = PreintegratedImu._from_left_arrays(
            self.delta_t[i], self.delta_R[i], self.delta_v[i], self.delta_p[i], J, S,
            tuple(float(b) for b in self.bias_gyro) + tuple(float(b) for b in self.bias_accel),
            self.gyro_noise_density ** 2, self.accel_noise_density ** 2)
        out.t_start, out.t_end = float(self.t_start[i]), float(self.t_end[i])
        out.valid = bool(self.valid[i])
        out.n_intervals = int(self.n_intervals[i])
        return out


# ---------------------------------------------------------------------------
# Batch kernel
# ---------------------------------------------------------------------------
def _exp_and_left_jacobian(x: np.ndarray, y: np.ndarray, z: np.ndarray):
    """Exp(phi) and Jl(phi) for component arrays x, y, z of shape S (fused, contiguous).

    Returns two component-major arrays of shape (3, 3) + S.
    """
    xx, yy, zz = x * x, y * y, z * z
    t2 = xx + yy + zz
    small = t2 < _SMALL2
    any_small = bool(small.any())
    ts2 = np.where(small, 1.0, t2) if any_small else t2
    th = np.sqrt(ts2)
    sn = np.sin(th)
    hs = np.sin(0.5 * th)
    A = sn / th
    B = 2.0 * hs * hs / ts2
    C = (th - sn) / (ts2 * th)
    if any_small:
        t2s = t2[small]
        tts = t2s * t2s
        A[small] = 1.0 - t2s / 6.0 + tts / 120.0
        B[small] = 0.5 - t2s / 24.0 + tts / 720.0
        C[small] = 1.0 / 6.0 - t2s / 120.0 + tts / 5040.0
    xy, xz, yz = x * y, x * z, y * z
    E = np.empty((3, 3) + x.shape)
    E[0, 0] = 1.0 - B * (yy + zz)
    E[1, 1] = 1.0 - B * (xx + zz)
    E[2, 2] = 1.0 - B * (xx + yy)
    Bxy, Bxz, Byz = B * xy, B * xz, B * yz
    Ax, Ay, Az = A * x, A * y, A * z
    E[0, 1] = Bxy - Az
    E[1, 0] = Bxy + Az
    E[0, 2] = Bxz + Ay
    E[2, 0] = Bxz - Ay
    E[1, 2] = Byz - Ax
    E[2, 1] = Byz + Ax
    Jl = np.empty((3, 3) + x.shape)
    Jl[0, 0] = 1.0 - C * (yy + zz)
    Jl[1, 1] = 1.0 - C * (xx + zz)
    Jl[2, 2] = 1.0 - C * (xx + yy)
    Cxy, Cxz, Cyz = C * xy, C * xz, C * yz
    Bx, By, Bz = B * x, B * y, B * z
    Jl[0, 1] = Cxy - Bz
    Jl[1, 0] = Cxy + Bz
    Jl[0, 2] = Cxz + By
    Jl[2, 0] = Cxz - By
    Jl[1, 2] = Cyz - Bx
    Jl[2, 1] = Cyz + Bx
    return E, Jl


def _mm(A: np.ndarray, B: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Matrix product of component-major 3x3 arrays, shapes (3, 3, ...)."""
    if out is None:
        out = np.empty(np.broadcast_shapes(A.shape, B.shape))
    for i in range(3):
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        for j in range(3):
            o = out[i, j]
            np.multiply(a0, B[0, j], out=o)
            o += a1 * B[1, j]
            o += a2 * B[2, j]
    return out


def _scan_products(M: np.ndarray) -> np.ndarray:
    """Inclusive product scan along axis 2 of component-major matrices (3, 3, L, B).

    ``out[:, :, k] = M[:, :, 0] @ M[:, :, 1] @ ... @ M[:, :, k]`` by Hillis-Steele
    doubling: ceil(log2 L) rounds of batched 3x3 products.
    """
    P = M.copy()
    n = P.shape[2]
    d = 1
    while d < n:
        Q = P.copy()
        _mm(P[:, :, :-d], P[:, :, d:], out=Q[:, :, d:])
        P = Q
        d *= 2
    return P


def _cross_rows(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Component-major ``M @ hat(x)``: row i of the result is ``M[i] x x`` (cross product)."""
    out = np.empty(np.broadcast_shapes(M.shape, (3, 3) + x.shape[1:]))
    x0, x1, x2 = x[0], x[1], x[2]
    for i in range(3):
        m0, m1, m2 = M[i, 0], M[i, 1], M[i, 2]
        out[i, 0] = m1 * x2 - m2 * x1
        out[i, 1] = m2 * x0 - m0 * x2
        out[i, 2] = m0 * x1 - m1 * x0
    return out


def _hat_times(x: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Component-major ``hat(x) @ M``: column j of the result is ``x x M[:, j]``."""
    out = np.empty(np.broadcast_shapes(M.shape, (3, 3) + x.shape[1:]))
    x0, x1, x2 = x[0], x[1], x[2]
    for j in range(3):
        m0, m1, m2 = M[0, j], M[1, j], M[2, j]
        out[0, j] = x1 * m2 - x2 * m1
        out[1, j] = x2 * m0 - x0 * m2
        out[2, j] = x0 * m1 - x1 * m0
    return out


def _blocks_kernel(dt: np.ndarray, w: np.ndarray, f: np.ndarray, qg: float, qa: float,
                   uncertainty: bool = True) -> tuple:
    """Preintegrate padded blocks of intervals in closed form, left-error form.

    Parameters are component-major, interval index before block index (so that
    every elementwise operation runs over long contiguous rows): ``dt`` (L, B)
    with zeros as padding, ``w`` and ``f`` (3, L, B) bias-corrected held rate and
    specific force. Interval ``k``
    of a block has rotation ``Rk`` before it, rotated velocity increment ``c_k``,
    deltas ``V_k``/``P_k`` after it and ends at ``e_k``; with ``xv_k = v_n - V_k`` and
    ``xp_k = p_n - P_k - V_k (T - e_k)`` a left rotation perturbation ``u`` at the end
    of interval ``k`` moves ``(dtheta, dv, dp)`` by ``(u, -hat(xv_k) u, -hat(xp_k) u)``.
    Hence, with ``U_k = Rk Jl(phi_k) dt_k``:

    - Jacobians: ``Th = -sum U_k``, ``Vg = sum hat(xv_k) U_k``, ``Pg = sum hat(xp_k) U_k``,
      ``Va = -sum Rk dt_k``, ``Pa = -sum Rk dt_k (T - e_k + dt_k / 2)``;
    - covariance: ``sum_k G_k Q_k G_k^T`` with ``W_k = q_g U_k U_k^T / dt_k``
      (rotation rows) and the isotropic accelerometer terms.

    Returns (T, R, v, p, J, S) with shapes (B,), (B,3,3), (B,3), (B,3), (B,9,6), (B,9,9);
    J and S are None when ``uncertainty`` is False.
    """
    L, nb = dt.shape
    phi = w * dt
    E, Jl = _exp_and_left_jacobian(phi[0], phi[1], phi[2])
    del phi
    P = _scan_products(E)                                   # delta_R after interval k
    del E
    Rk = np.empty_like(P)                                   # delta_R before interval k
    Rk[:, :, 0] = np.eye(3)[:, :, None]
    Rk[:, :, 1:] = P[:, :, :-1]
    fd = f * dt
    c = np.empty_like(fd)
    for i in range(3):
        c[i] = Rk[i, 0] * fd[0] + Rk[i, 1] * fd[1] + Rk[i, 2] * fd[2]
    del fd
    V = np.cumsum(c, axis=1)                                # delta_v after interval k
    Vb = np.empty_like(V)                                   # ... and before
    Vb[:, 0] = 0.0
    Vb[:, 1:] = V[:, :-1]
    Pp = np.cumsum(dt * (Vb + 0.5 * c), axis=1)             # delta_p after interval k
    del Vb, c
    e = np.cumsum(dt, axis=0)                               # end time of interval k
    T = e[-1].copy()
    Rn = np.ascontiguousarray(P[:, :, -1].transpose(2, 0, 1))
    vn = np.ascontiguousarray(V[:, -1].T)
    pn = np.ascontiguousarray(Pp[:, -1].T)
    if not uncertainty:
        return T, Rn, vn, pn, None, None
    Uo = _mm(Rk, Jl)                                        # U / dt
    del Jl, P
    U = Uo * dt
    xv = vn.T[:, None, :] - V
    rem = T[None, :] - e                                    # time left after interval k
    xp = pn.T[:, None, :] - Pp - V * rem
    del V, Pp
    wa = dt * (rem + 0.5 * dt)                              # dt (T - midpoint of interval k)
    J = np.zeros((nb, 9, 6))
    J[:, 0:3, 0:3] = -U.sum(axis=2).transpose(2, 0, 1)
    J[:, 3:6, 0:3] = _hat_times(xv, U).sum(axis=2).transpose(2, 0, 1)
    J[:, 6:9, 0:3] = _hat_times(xp, U).sum(axis=2).transpose(2, 0, 1)
    J[:, 3:6, 3:6] = -(Rk * dt).sum(axis=2).transpose(2, 0, 1)
    J[:, 6:9, 3:6] = -(Rk * wa).sum(axis=2).transpose(2, 0, 1)
    S = np.zeros((nb, 9, 9))
    if qg != 0.0:
        # W = q_g dt Uo Uo^T (symmetric); rv = sum W hat(xv), rp = sum W hat(xp),
        # vv = sum hat(xv) W hat(xv)^T = -sum hat(xv) (W hat(xv)), vp, pp alike.
        W = np.empty((3, 3, L, nb))
        qdt = qg * dt
        for i in range(3):
            for j in range(i, 3):
                W[i, j] = (Uo[i, 0] * Uo[j, 0] + Uo[i, 1] * Uo[j, 1] + Uo[i, 2] * Uo[j, 2]) * qdt
                if j != i:
                    W[j, i] = W[i, j]
        M1 = _cross_rows(W, xv)
        M2 = _cross_rows(W, xp)
        S[:, 0:3, 0:3] = W.sum(axis=2).transpose(2, 0, 1)
        S[:, 0:3, 3:6] = M1.sum(axis=2).transpose(2, 0, 1)
        S[:, 0:3, 6:9] = M2.sum(axis=2).transpose(2, 0, 1)
        S[:, 3:6, 3:6] = -_hat_times(xv, M1).sum(axis=2).transpose(2, 0, 1)
        S[:, 3:6, 6:9] = -_hat_times(xv, M2).sum(axis=2).transpose(2, 0, 1)
        S[:, 6:9, 6:9] = -_hat_times(xp, M2).sum(axis=2).transpose(2, 0, 1)
        S[:, 3:6, 0:3] = S[:, 0:3, 3:6].transpose(0, 2, 1)
        S[:, 6:9, 0:3] = S[:, 0:3, 6:9].transpose(0, 2, 1)
        S[:, 6:9, 3:6] = S[:, 3:6, 6:9].transpose(0, 2, 1)
    if qa != 0.0:
        s0 = qa * T
        s1 = qa * wa.sum(axis=0)
        s2 = qa * (wa * (rem + 0.5 * dt)).sum(axis=0)
        i3 = np.arange(3)
        S[:, 3 + i3, 3 + i3] += s0[:, None]
        S[:, 3 + i3, 6 + i3] += s1[:, None]
        S[:, 6 + i3, 3 + i3] += s1[:, None]
        S[:, 6 + i3, 6 + i3] += s2[:, None]
    return T, Rn, vn, pn, J, 0.5 * (S + S.transpose(0, 2, 1))


def _merge_blocks(res: tuple, block_frame: np.ndarray, n_frames: int) -> tuple:
    """Merge consecutive blocks of the same frame with a log-depth tree of compositions."""
    counts = np.bincount(block_frame, minlength=n_frames)
    if np.all(counts == 1):
        return res
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    multi = np.flatnonzero(counts > 1)
    width = int(counts.max())
    pos = np.arange(block_frame.size) - first[block_frame]
    # padded (n_multi, width) table of blocks with identity padding
    sel = np.isin(block_frame, multi)
    row = np.searchsorted(multi, block_frame[sel])
    col = pos[sel]

    def pad(x, ident):
        out = np.broadcast_to(ident, (multi.size, width) + ident.shape).copy()
        out[row, col] = x[sel]
        return out

    ident = (np.float64(0.0), np.eye(3), np.zeros(3), np.zeros(3), np.zeros((9, 6)), np.zeros((9, 9)))
    m = 6 if res[4] is not None else 4          # without covariance and Jacobians: 4 entries
    cur = [pad(x, i) for x, i in zip(res[:m], ident)]
    while cur[0].shape[1] > 1:
        if cur[0].shape[1] % 2:
            cur = [np.concatenate([x, np.broadcast_to(i, (x.shape[0], 1) + i.shape)], axis=1)
                   for x, i in zip(cur, ident)]
        a = tuple(x[:, 0::2] for x in cur) + (None, None) * (m == 4)
        b = tuple(x[:, 1::2] for x in cur) + (None, None) * (m == 4)
        cur = list(_compose_left(a, b))[:m]
    out = []
    single = counts == 1
    for x, c in zip(res[:m], cur):
        o = np.empty((n_frames,) + x.shape[1:])
        o[single] = x[first[single]]
        o[multi] = c[:, 0]
        out.append(o)
    return tuple(out) + (None, None) * (m == 4)


def _validate_times(t: np.ndarray) -> None:
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"need at least 2 samples, got t of shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("IMU timestamps contain NaN or inf")
    d = np.diff(t)
    bad = np.flatnonzero(~(d > 0))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"IMU timestamps must be strictly increasing: t[{i + 1}] = {t[i + 1]!r} s comes after "
            f"t[{i}] = {t[i]!r} s ({bad.size} non-increasing step(s)); drop non-increasing samples "
            f"upstream (validation) before preintegrating")


def preintegrate(imu: ImuData | tuple[np.ndarray, np.ndarray, np.ndarray],
                 frame_times: np.ndarray | None = None, *,
                 rate: float | None = None, every: int | None = None,
                 t_origin: float | None = None,
                 bias_gyro: Sequence[float] = (0.0, 0.0, 0.0),
                 bias_accel: Sequence[float] = (0.0, 0.0, 0.0),
                 gyro_noise_density: float = 0.0, accel_noise_density: float = 0.0,
                 hold: Hold = "midpoint", max_gap: float = 0.1, on_gap: OnGap = "raise",
                 snap_tol: float = 1e-9, uncertainty: bool = True) -> FrameDeltas:
    """Preintegrate a whole log into frames, vectorised (no Python loop over samples).

    Parameters
    ----------
    imu : ImuData or (t, gyro, accel)
        Times (s, strictly increasing), angular rate (rad/s) and specific force
        (m/s^2), both in the body frame.
    frame_times : array_like, shape (F + 1,), optional
        Frame boundaries, s, strictly increasing and inside ``[t[0], t[-1]]``;
        frame ``i`` spans ``[frame_times[i], frame_times[i+1]]``.
    rate, every, t_origin :
        Instead of ``frame_times``: frames at ``rate`` Hz from ``t_origin``
        (default ``t[0]``), or every ``every`` samples (see :func:`make_frame_times`).
    bias_gyro, bias_accel : array_like, shape (3,)
        Biases subtracted before integration (rad/s, m/s^2, body frame).
    gyro_noise_density : float
        rad/s/sqrt(Hz).
    accel_noise_density : float
        m/s^2/sqrt(Hz).
    hold : {"midpoint", "left"}
        How a sample's value is held over its interval (module docstring).
    max_gap : float
        Sample intervals longer than this (s) are timestamp gaps.
    on_gap : {"raise", "flag"}
        ``"raise"``: ValueError naming the gap's time and length if a gap lies
        inside any frame. ``"flag"``: integrate through it (held signal) and set
        ``valid = False`` for the frames it overlaps.
    snap_tol : float
        A boundary within this of a sample (s) is placed on the sample instead of
        splitting the interval. Must be below half the sample spacing.
    uncertainty : bool
        Compute the covariance and the bias Jacobians (default). False skips
        them (the fields are None), e.g. for per-sample dead reckoning.

    Returns
    -------
    FrameDeltas
        Per frame: ``delta_R`` (end-body -> start-body frame), ``delta_v``,
        ``delta_p`` (start-body frame), 9x9 covariance, bias Jacobians, validity.

    Raises
    ------
    ValueError
        Non-increasing timestamps, frame boundaries outside the log or not
        increasing, or a gap inside a frame with ``on_gap="raise"``.
    """
    _check_hold(hold)
    _check_on_gap(on_gap)
    if isinstance(imu, ImuData):
        t, gyro, accel = imu.t, imu.gyro, imu.accel
    else:
        t, gyro, accel = imu
    t = np.ascontiguousarray(t, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    accel = np.asarray(accel, dtype=float)
    if gyro.shape != (t.size, 3) or accel.shape != (t.size, 3):
        raise ValueError(f"gyro and accel must have shape ({t.size}, 3), got {gyro.shape}, {accel.shape}")
    _validate_times(t)
    if frame_times is None:
        T = make_frame_times(t, rate=rate, every=every, t_origin=t_origin, snap_tol=snap_tol)
    else:
        if rate is not None or every is not None:
            raise ValueError("give frame_times or rate/every, not both")
        T = np.asarray(frame_times, dtype=float).reshape(-1)
    if T.size < 2:
        raise ValueError(f"need at least 2 frame boundaries inside the log, got {T.size}")
    if not np.all(np.diff(T) > 2 * snap_tol):
        raise ValueError("frame_times must be strictly increasing (by more than 2 * snap_tol)")
    if T[0] < t[0] - snap_tol or T[-1] > t[-1] + snap_tol:
        raise ValueError(f"frame boundaries [{T[0]!r}, {T[-1]!r}] s are not inside the log "
                         f"[{t[0]!r}, {t[-1]!r}] s")
    bg = np.array(_vec3(bias_gyro, "bias_gyro"))
    ba = np.array(_vec3(bias_accel, "bias_accel"))
    if not (gyro_noise_density >= 0 and accel_noise_density >= 0):
        raise ValueError("noise densities must be >= 0")
    qg = float(gyro_noise_density) ** 2
    qa = float(accel_noise_density) ** 2
    y = np.concatenate([gyro, accel], axis=1)
    n = t.size

    # --- knots: samples plus boundaries that fall between samples --------------
    k = np.searchsorted(t, T)                       # t[k-1] < T <= t[k]
    hi = np.minimum(k, n - 1)
    lo = np.maximum(k - 1, 0)
    d_hi = np.abs(t[hi] - T)
    d_lo = np.abs(T - t[lo])
    near = np.where(d_hi <= d_lo, hi, lo)
    snapped = np.minimum(d_hi, d_lo) <= snap_tol
    ins = ~snapped
    ki = k[ins]
    Ti = T[ins]
    if hold == "midpoint":
        wgt = (Ti - t[ki - 1]) / (t[ki] - t[ki - 1])
        yb = y[ki - 1] + (y[ki] - y[ki - 1]) * wgt[:, None]
    else:
        yb = y[ki - 1]
    kt = np.insert(t, ki, Ti)
    ky = np.insert(y, ki, yb, axis=0)
    Teff = np.where(snapped, t[near], T)
    b = np.searchsorted(kt, Teff)                   # knot index of each boundary
    if np.any(np.diff(b) <= 0):
        raise ValueError("two frame boundaries fall on the same sample; frames must be longer "
                         "than the snapping tolerance")
    j0, j1 = int(b[0]), int(b[-1])
    dt_all = np.diff(kt[j0:j1 + 1])
    if hold == "midpoint":
        held = (ky[j0:j1] + ky[j0 + 1:j1 + 1]) * 0.5
    else:
        held = ky[j0:j1]
    nfr = T.size - 1
    nint = np.diff(b)

    # --- gaps (on the original sample intervals) -------------------------------
    orig = np.searchsorted(t, kt[j0:j1], side="right") - 1   # sample interval of each knot interval
    gap_orig = np.diff(t) > max_gap
    is_gap = gap_orig[orig]
    valid = np.ones(nfr, dtype=bool)
    if np.any(is_gap):
        if on_gap == "raise":
            g = int(orig[np.flatnonzero(is_gap)[0]])
            raise ValueError(_gap_message(float(t[g]), float(t[g + 1] - t[g]), max_gap))
        frame_of = np.repeat(np.arange(nfr), nint)
        valid[np.unique(frame_of[is_gap])] = False

    # --- blocks: frames cut into pieces of at most Lb intervals ----------------
    mean_len = dt_all.size / nfr
    Lb = int(min(nint.max(), max(16, 2 * math.ceil(mean_len))))
    nblk = -(-nint // Lb)
    block_frame = np.repeat(np.arange(nfr), nblk)
    nbt = int(nblk.sum())
    first_blk = np.cumsum(nblk) - nblk
    blk_in_frame = np.arange(nbt) - np.repeat(first_blk, nblk)
    start = (b[:-1] - j0)[block_frame] + Lb * blk_in_frame
    stop = np.minimum(start + Lb, (b[1:] - j0)[block_frame])
    idx = start[None, :] + np.arange(Lb)[:, None]            # (Lb, blocks)
    pad = idx >= stop[None, :]
    idx[pad] = 0
    dtp = dt_all[idx]
    dtp[pad] = 0.0
    hp = np.ascontiguousarray(held.T)[:, idx]                # component-major (6, Lb, blocks)
    hp[:, pad] = 0.0
    hp[0:3] -= bg[:, None, None]
    hp[3:6] -= ba[:, None, None]
    # Work through the blocks in chunks of about _CHUNK intervals: the temporaries
    # then stay in cache (a loop over groups of frames, not over samples).
    step = max(1, _CHUNK // Lb)
    parts = [_blocks_kernel(dtp[:, i:i + step], hp[0:3, :, i:i + step], hp[3:6, :, i:i + step], qg, qa,
                            uncertainty) for i in range(0, nbt, step)]
    res = tuple(np.concatenate([r[j] for r in parts]) if uncertainty or j < 4 else None for j in range(6))
    Tn, Rn, vn, pn, Jn, Sn = _merge_blocks(res, block_frame, nfr)
    Rn = _project_if_needed(Rn)
    if uncertainty:
        Jr, Sr = _left_to_right(Rn, Jn, Sn)
        jac = dict(d_R_d_bg=Jr[:, 0:3, 0:3].copy(), d_v_d_bg=Jr[:, 3:6, 0:3].copy(),
                   d_p_d_bg=Jr[:, 6:9, 0:3].copy(), d_v_d_ba=Jr[:, 3:6, 3:6].copy(),
                   d_p_d_ba=Jr[:, 6:9, 3:6].copy())
    else:
        Sr = None
        jac = dict.fromkeys(("d_R_d_bg", "d_v_d_bg", "d_p_d_bg", "d_v_d_ba", "d_p_d_ba"))
    return FrameDeltas(
        t_start=T[:-1].copy(), t_end=T[1:].copy(), delta_t=np.asarray(Tn, dtype=float),
        delta_R=Rn, delta_v=vn, delta_p=pn, covariance=Sr, **jac,
        valid=valid, n_intervals=nint.astype(int),
        bias_gyro=bg, bias_accel=ba, gyro_noise_density=float(gyro_noise_density),
        accel_noise_density=float(accel_noise_density), hold=hold)


# ---------------------------------------------------------------------------
# Streaming front-end
# ---------------------------------------------------------------------------
class StreamingPreintegrator:
    """Sample-by-sample front-end: emits a finished :class:`PreintegratedImu` per frame.

    Frames are given by explicit boundary times, a frame rate, or a sample
    count, exactly as in :func:`preintegrate`, and the results are the same
    (same knots, held values, boundary splitting and gap handling).

    Parameters
    ----------
    frame_times : iterable of float, optional
        Boundaries, s, strictly increasing; samples before the first are ignored.
    rate : float, optional
        Frame rate, Hz: boundaries ``t_origin + k / rate``, unbounded.
    every : int, optional
        A boundary at every ``every``-th sample, starting with the first.
    t_origin : float, optional
        First boundary for ``rate`` (default: the first sample's time), s.
    bias_gyro, bias_accel, gyro_noise_density, accel_noise_density :
        As in :class:`PreintegratedImu`.
    hold, max_gap, on_gap, snap_tol, uncertainty :
        As in :func:`preintegrate` (``uncertainty=False``: deltas only, no
        covariance or bias Jacobians; the fast choice for a filter that needs
        just ``delta_R``/``delta_v``).

    Notes
    -----
    A frame is emitted by the first sample at or after its end boundary (less
    ``snap_tol``), since the interval that straddles the boundary is needed.
    For speed pass Python floats (tuples or lists); numpy rows are converted
    with ``tolist()``. Each emitted frame has ``t_start``, ``t_end`` and
    ``valid`` set; its ``delta_R`` maps the body frame at ``t_end`` into the
    body frame at ``t_start``. A sample rejected with ValueError (non-increasing
    time, gap with ``on_gap="raise"``) leaves the state unchanged.
    """

    def __init__(self, frame_times: Iterable[float] | None = None, *,
                 rate: float | None = None, every: int | None = None,
                 t_origin: float | None = None,
                 bias_gyro: Sequence[float] = (0.0, 0.0, 0.0),
                 bias_accel: Sequence[float] = (0.0, 0.0, 0.0),
                 gyro_noise_density: float = 0.0, accel_noise_density: float = 0.0,
                 hold: Hold = "midpoint", max_gap: float = 0.1, on_gap: OnGap = "raise",
                 snap_tol: float = 1e-9, uncertainty: bool = True) -> None:
        _check_hold(hold)
        _check_on_gap(on_gap)
        if sum(x is not None for x in (frame_times, rate, every)) != 1:
            raise ValueError("give exactly one of frame_times, rate and every")
        self._times = None
        if frame_times is not None:
            self._times = [float(x) for x in np.asarray(list(frame_times), dtype=float).reshape(-1)]
            if any(not (b - a > 2 * snap_tol) for a, b in zip(self._times, self._times[1:])):
                raise ValueError("frame_times must be strictly increasing (by more than 2 * snap_tol)")
        if rate is not None and not rate > 0:
            raise ValueError(f"rate must be > 0, got {rate}")
        if every is not None and int(every) < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        self._rate = None if rate is None else float(rate)
        self._every = None if every is None else int(every)
        self._origin = None if t_origin is None else float(t_origin)
        self._midpoint = hold == "midpoint"
        self.hold = hold
        self.max_gap = float(max_gap)
        self.on_gap = on_gap
        self.snap_tol = float(snap_tol)
        self._pim = PreintegratedImu(bias_gyro, bias_accel, gyro_noise_density, accel_noise_density,
                                     uncertainty=uncertainty)
        self._integ = self._pim._integrate if uncertainty else self._pim._integrate_deltas
        self._prev: tuple | None = None     # (t, wx, wy, wz, ax, ay, az) of the last sample
        self._cd = 1 << 62                  # samples until the next every-N boundary
        self._k = 0                         # index of the next boundary
        self._next = math.inf               # time of the next boundary
        self._lim = -math.inf               # fast path while t < _lim (= _next - snap_tol)
        self._active = False                # inside a frame

    @property
    def current(self) -> PreintegratedImu:
        """The frame being integrated (a live object; copy it to keep it)."""
        return self._pim

    def _boundary(self, k: int) -> float:
        if self._times is not None:
            return self._times[k] if k < len(self._times) else math.inf
        if self._rate is not None:
            return self._origin + k / self._rate
        return math.inf     # every-N boundaries are counted in samples

    def _cross(self, tb: float, out: list) -> None:
        """A boundary at tb: emit the running frame, start the next if there is one."""
        pim = self._pim
        if self._active:
            pim.t_end = tb
            out.append(pim.copy())
        self._k += 1
        self._next = self._boundary(self._k)
        self._lim = self._next - self.snap_tol
        more = self._every is not None or self._next != math.inf
        pim.reset()
        pim.t_start = tb
        self._active = more

    def push(self, t: float, gyro: Sequence[float], accel: Sequence[float]) -> tuple[PreintegratedImu, ...]:
        """Add one sample; return the frames finished by it (usually none, or one).

        Parameters
        ----------
        t : float
            Sample time, s (strictly increasing).
        gyro : sequence of 3 floats
            Angular rate, rad/s, body frame.
        accel : sequence of 3 floats
            Specific force, m/s^2, body frame.

        Returns
        -------
        tuple of PreintegratedImu
            Finished frames (usually an empty tuple), each with ``t_start``, ``t_end``, ``valid``; the
            ``delta_R`` of each maps the body frame at ``t_end`` into the body
            frame at ``t_start``.
        """
        if type(t) is not float:
            t = float(t)
        if type(gyro) is _ndarray:
            gyro = gyro.tolist()
        if type(accel) is _ndarray:
            accel = accel.tolist()
        prev = self._prev
        if prev is not None:
            # fast path: no boundary, no gap, not an every-N boundary sample
            h = t - prev[0]
            if 0.0 < h <= self.max_gap and t < self._lim:
                cd = self._cd - 1
                if cd:
                    self._cd = cd
                    wx, wy, wz = gyro
                    ax, ay, az = accel
                    self._prev = (t, wx, wy, wz, ax, ay, az)
                    if self._active:
                        if self._midpoint:
                            _, gx0, gy0, gz0, fx0, fy0, fz0 = prev
                            self._integ(h, (gx0 + wx) * 0.5, (gy0 + wy) * 0.5, (gz0 + wz) * 0.5,
                                                 (fx0 + ax) * 0.5, (fy0 + ay) * 0.5, (fz0 + az) * 0.5)
                        else:
                            self._integ(h, prev[1], prev[2], prev[3], prev[4], prev[5], prev[6])
                    return ()
        return self._push_slow(t, gyro, accel)

    def _push_slow(self, t: float, gyro: Sequence[float], accel: Sequence[float]) -> tuple[PreintegratedImu, ...]:
        wx, wy, wz = gyro
        ax, ay, az = accel
        out: list[PreintegratedImu] = []
        prev = self._prev
        tol = self.snap_tol
        if prev is None:
            self._prev = (t, wx, wy, wz, ax, ay, az)
            if self._every is not None:
                self._cross(t, out)
                self._cd = self._every
                return tuple(out)
            if self._rate is not None:
                if self._origin is None:
                    self._origin = t
                # skip boundaries before the first sample (as make_frame_times does)
                k = max(0, math.ceil((t - tol - self._origin) * self._rate) - 1)
                while self._boundary(k) < t - tol:
                    k += 1
                self._k = k
            self._next = self._boundary(self._k)
            self._lim = self._next - tol
            if self._next < t - tol:
                raise ValueError(f"frame boundary {self._next!r} s is before the first sample at {t!r} s")
            if abs(self._next - t) <= tol:
                self._cross(self._next, out)
            return tuple(out)
        t0, gx0, gy0, gz0, fx0, fy0, fz0 = prev
        h = t - t0
        if not h > 0.0:
            raise ValueError(f"IMU timestamps must be strictly increasing: got t = {t!r} s after "
                             f"{t0!r} s; drop non-increasing samples upstream (validation)")
        gap = h > self.max_gap
        if gap and self.on_gap == "raise" and (self._active or self._next < t - tol):
            raise ValueError(_gap_message(t0, h, self.max_gap))
        self._prev = (t, wx, wy, wz, ax, ay, az)
        # boundaries strictly inside (t0, t - tol): split the interval there
        tk, k0 = t0, (gx0, gy0, gz0, fx0, fy0, fz0)
        while self._next < t - tol:
            tb = self._next
            if self._midpoint:
                wgt = (tb - t0) / h
                kb = (gx0 + (wx - gx0) * wgt, gy0 + (wy - gy0) * wgt, gz0 + (wz - gz0) * wgt,
                      fx0 + (ax - fx0) * wgt, fy0 + (ay - fy0) * wgt, fz0 + (az - fz0) * wgt)
            else:
                kb = k0
            if self._active:
                self._piece(tb - tk, k0, kb, gap)
            self._cross(tb, out)
            tk, k0 = tb, kb
        if self._active:
            self._piece(t - tk, k0, (wx, wy, wz, ax, ay, az), gap)
        if self._every is not None:
            self._cd -= 1
            if self._cd == 0:
                self._cross(t, out)
                self._cd = self._every
        elif abs(self._next - t) <= tol:
            self._cross(self._next, out)
        return tuple(out)

    def _piece(self, dt: float, ka: tuple, kb: tuple, gap: bool) -> None:
        """Integrate a piece of length dt between knots with values ka and kb."""
        if gap:
            self._pim.valid = False
        if self._midpoint:
            self._pim._integrate(dt, (ka[0] + kb[0]) * 0.5, (ka[1] + kb[1]) * 0.5, (ka[2] + kb[2]) * 0.5,
                                 (ka[3] + kb[3]) * 0.5, (ka[4] + kb[4]) * 0.5, (ka[5] + kb[5]) * 0.5)
        else:
            self._pim._integrate(dt, ka[0], ka[1], ka[2], ka[3], ka[4], ka[5])
