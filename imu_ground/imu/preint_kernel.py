"""The one body of preintegration: the kinematics of one interval, and the step of one sample into frames.

:func:`integrate` is Forster's recursion (Sec. VI and appendix; :mod:`imu_ground.imu.preintegration`) on
scalar floats: the deltas and, optionally, their bias Jacobians and covariance. :func:`push_step` takes one
sample into the frame being integrated (splitting the interval at frame boundaries, flagging gaps, finishing
frames): per sample live, over a whole log in :func:`run_log`. Compiled through :mod:`imu_ground._jit`.

State layouts
-------------
``deltas`` (11 floats): ``T`` (integrated time, s), ``delta_R`` as the unit quaternion
``(w, x, y, z)`` of ``R_{start<-now}`` (body frame now -> body frame at the start),
``delta_v`` (m/s) and ``delta_p`` (m) in the start body frame.

``uncertainty`` (90 floats), left-error form in the start body frame
(``delta_R_measured = Exp(dtheta) delta_R_true``), position rows in the "q form" ``q = p - T v``::

    0:9    Th   left rotation-error Jacobian w.r.t. b_g (= delta_R @ dR_dbg)
    9:18   Vg   d delta_v / d b_g
    18:27  Mg   d delta_p / d b_g - T Vg
    27:36  Va   d delta_v / d b_a
    36:45  Ma   d delta_p / d b_a - T Va
    45:51  rr   covariance of dtheta, symmetric (00 01 02 11 12 22)
    51:60  rv   E[dtheta dv^T], row-major
    60:69  rq   E[dtheta dq^T]
    69:75  vv   symmetric
    75:84  vq   E[dv dq^T]
    84:90  qq   symmetric

:mod:`imu_ground.imu.preint_measurement` reads them out in Forster's right-error, p-form.

The step's state buffer (offsets ``_S_*``) holds the deltas and uncertainty, then the last sample
(bias removed; its time NaN before the first sample) and the frame bookkeeping; a finished frame
is a row of the frames buffer: deltas, uncertainty, then ``_O_*``.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from math import cos, sin, sqrt

import numpy as np

from imu_ground import so3
from imu_ground._jit import jitable, njit
from imu_ground.imu.preint_params import PreintegrationParams

__all__ = [
    "DELTAS_IDENTITY",
    "UNCERTAINTY_ZERO",
    "first_rate_boundary",
    "integrate",
    "integrate_interval",
    "push_step",
    "quaternion_from_rotation",
    "rotation_from_quaternion",
    "run_log",
    "state_buffer",
]

#: Deltas of an empty interval: T = 0, delta_R = I (quaternion 1), delta_v = delta_p = 0.
DELTAS_IDENTITY: tuple = (0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
#: Bias Jacobians and covariance of an empty interval (all zero).
UNCERTAINTY_ZERO: tuple = (0.0,) * 90
_NO_UNCERTAINTY = np.zeros(0)
#: theta^2 (rad^2) below which the Taylor series of the SO(3) coefficients are used (so3.SMALL_ANGLE, as exp_flat).
_SMALL_ANGLE2 = so3.SMALL_ANGLE ** 2

# The step's state buffer (offsets in floats): deltas (11) and uncertainty (90), then the bookkeeping
_S_UNC, _S_PREV, _S_LIM, _S_MAXGAP, _S_CD, _S_BIAS, _S_NOISE, _S_MIDPOINT, _S_UNCERTAINTY = (
    11, 101, 108, 109, 110, 111, 117, 119, 120)
_S_K, _S_NEXT, _S_ACTIVE, _S_N, _S_MARK, _S_TSTART, _S_VALID = 121, 122, 123, 124, 125, 126, 127
_S_TOL, _S_MODE, _S_RATE, _S_ORIGIN, _S_RAISE, _S_EVERY, _S_KNOTS, _S_SIZE = 128, 129, 130, 131, 132, 133, 134, 152
# (_S_PREV: t, gyro (3), accel (3) of the last sample, bias removed; _S_LIM: the fast path runs while t < it;
# _S_MODE: boundaries every-N 0, rate 1, frame_times 2; _S_K: index of the next boundary, at _S_NEXT (s);
# _S_CD: samples until the next every-N boundary; _S_N: intervals integrated off the fast path in this frame,
# _S_MARK: _S_CD at its start, so that the frame has _S_N + _S_MARK - _S_CD intervals; _S_KNOTS: scratch)
# A finished frame's row of the frames buffer: deltas, uncertainty, then these
_O_N, _O_TSTART, _O_TEND, _O_VALID, _O_SIZE = 101, 102, 103, 104, 105


@njit
def integrate(s: np.ndarray, u: np.ndarray, dt: float, x: float, y: float, z: float,
              fx: float, fy: float, fz: float, qg: float, qa: float) -> None:
    """Add one interval of held rate and specific force to the deltas ``s`` and, unless ``u`` is empty,
    to their bias Jacobians and covariance ``u`` (in place; layouts in the module docstring).

    Unrolled entry by entry on float locals. With ``R_k`` the rotation before the interval,
    ``c = R_k f dt`` and ``mid = T + dt/2``:

    - deltas: ``p += dt (v + c/2)``, ``v += c``, ``R = R_k Exp(phi)`` as the quaternion product
      ``q_k (x) (cos(th/2), sin(th/2) phi / th)``;
    - bias Jacobians: ``Vg -= hat(c) Th``, ``Mg += mid hat(c) Th``, ``Th -= R_k Jl(phi) dt``,
      ``Va -= R_k dt``, ``Ma += mid R_k dt``;
    - covariance: with ``u_k = hat(c) dtheta - n_a`` the errors move as ``dv' = dv - u_k``,
      ``dq' = dq + mid u_k``; the gyro noise adds ``q_g dt [(1 - kappa t^2) I + kappa psi psi^T]``
      to ``rr`` (``psi = R_k phi``, ``Jl Jl^T = I + kappa K^2``).

    Parameters
    ----------
    s, u : ndarray, shape (11,) and (90,) or (0,)
        Deltas, bias Jacobians and covariance so far (``u`` empty: the deltas only).
    dt : float
        Interval length, s (> 0).
    x, y, z, fx, fy, fz : float
        Rotation increment ``phi = (w - b_g) dt`` (rad) and velocity increment ``(a - b_a) dt`` before
        rotation (m/s), body frame.
    qg, qa : float
        Squared gyro and accelerometer noise densities (``PreintegrationParams.noise``).
    """
    T, qw, qx, qy, qz, v0, v1, v2, p0, p1, p2 = s
    xx, yy, zz = x * x, y * y, z * z
    t2 = xx + yy + zz
    # Exp(phi) as the unit quaternion (cos(th/2), k phi), k = sin(th/2) / th
    if t2 < _SMALL_ANGLE2:
        ch = 1.0 - t2 / 8.0 + t2 * t2 / 384.0
        k = 0.5 - t2 / 48.0 + t2 * t2 / 3840.0
    else:
        th = sqrt(t2)
        ch = cos(0.5 * th)
        k = sin(0.5 * th) / th
    # c = R_k f dt, the rotated velocity increment (start body frame), by the quaternion:
    # c = f + qw t + q_v x t with t = 2 q_v x f
    tx, ty, tz = 2.0 * (qy * fz - qz * fy), 2.0 * (qz * fx - qx * fz), 2.0 * (qx * fy - qy * fx)
    c0 = fx + qw * tx + qy * tz - qz * ty
    c1 = fy + qw * ty + qz * tx - qx * tz
    c2 = fz + qw * tz + qx * ty - qy * tx
    if u.size:
        # the 90 floats (layout in the module docstring), entry by entry
        h00, h01, h02, h10, h11, h12 = u[0], u[1], u[2], u[3], u[4], u[5]
        h20, h21, h22, g00, g01, g02 = u[6], u[7], u[8], u[9], u[10], u[11]
        g10, g11, g12, g20, g21, g22 = u[12], u[13], u[14], u[15], u[16], u[17]
        m00, m01, m02, m10, m11, m12 = u[18], u[19], u[20], u[21], u[22], u[23]
        m20, m21, m22, a00, a01, a02 = u[24], u[25], u[26], u[27], u[28], u[29]
        a10, a11, a12, a20, a21, a22 = u[30], u[31], u[32], u[33], u[34], u[35]
        b00, b01, b02, b10, b11, b12 = u[36], u[37], u[38], u[39], u[40], u[41]
        b20, b21, b22, rr00, rr01, rr02 = u[42], u[43], u[44], u[45], u[46], u[47]
        rr11, rr12, rr22, rv00, rv01, rv02 = u[48], u[49], u[50], u[51], u[52], u[53]
        rv10, rv11, rv12, rv20, rv21, rv22 = u[54], u[55], u[56], u[57], u[58], u[59]
        rq00, rq01, rq02, rq10, rq11, rq12 = u[60], u[61], u[62], u[63], u[64], u[65]
        rq20, rq21, rq22, vv00, vv01, vv02 = u[66], u[67], u[68], u[69], u[70], u[71]
        vv11, vv12, vv22, vq00, vq01, vq02 = u[72], u[73], u[74], u[75], u[76], u[77]
        vq10, vq11, vq12, vq20, vq21, vq22 = u[78], u[79], u[80], u[81], u[82], u[83]
        qq00, qq01, qq02, qq11, qq12, qq22 = u[84], u[85], u[86], u[87], u[88], u[89]
        if t2 < _SMALL_ANGLE2:
            B = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
            C = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
        else:
            B = 2.0 * k * k                         # (1 - cos th) / th^2 = 2 sin^2(th/2) / th^2
            C = (th - sin(th)) / (t2 * th)
        # R_k = delta_R before the interval, from the quaternion
        x2, y2, z2 = qx + qx, qy + qy, qz + qz
        wx2, wy2, wz2 = qw * x2, qw * y2, qw * z2
        xx2, yy2, zz2 = qx * x2, qy * y2, qz * z2
        xy2, xz2, yz2 = qx * y2, qx * z2, qy * z2
        r00, r01, r02 = 1.0 - yy2 - zz2, xy2 - wz2, xz2 + wy2
        r10, r11, r12 = xy2 + wz2, 1.0 - xx2 - zz2, yz2 - wx2
        r20, r21, r22 = xz2 - wy2, yz2 + wx2, 1.0 - xx2 - yy2
        mid = T + 0.5 * dt
        # --- gyro-bias Jacobians: H = hat(c) Th; Vg -= H; Mg += mid H; Th -= delta_R_k Jl dt.
        # Row by row, H (and D below) reused so that each row's floats are freed at once (faster).
        H0, H1, H2 = c1 * h20 - c2 * h10, c1 * h21 - c2 * h11, c1 * h22 - c2 * h12
        g00, g01, g02 = g00 - H0, g01 - H1, g02 - H2
        m00, m01, m02 = m00 + mid * H0, m01 + mid * H1, m02 + mid * H2
        H0, H1, H2 = c2 * h00 - c0 * h20, c2 * h01 - c0 * h21, c2 * h02 - c0 * h22
        m10, m11, m12 = m10 + mid * H0, m11 + mid * H1, m12 + mid * H2
        g10, g11, g12 = g10 - H0, g11 - H1, g12 - H2
        H0, H1, H2 = c0 * h10 - c1 * h00, c0 * h11 - c1 * h01, c0 * h12 - c1 * h02
        g20, g21, g22 = g20 - H0, g21 - H1, g22 - H2
        m20, m21, m22 = m20 + mid * H0, m21 + mid * H1, m22 + mid * H2
        # j = Jl(phi) dt = (I + B K + C K^2) dt
        Cd, Bd = C * dt, B * dt
        Cxy, Cxz, Cyz = Cd * (x * y), Cd * (x * z), Cd * (y * z)
        Bx, By, Bz = Bd * x, Bd * y, Bd * z
        j00, j11, j22 = dt - Cd * (yy + zz), dt - Cd * (xx + zz), dt - Cd * (xx + yy)
        j01, j10, j02 = Cxy - Bz, Cxy + Bz, Cxz + By
        j20, j12, j21 = Cxz - By, Cyz - Bx, Cyz + Bx
        # Th -= U, U = delta_R_k Jl dt, by rows
        h00, h01, h02 = (h00 - (r00 * j00 + r01 * j10 + r02 * j20), h01 - (r00 * j01 + r01 * j11 + r02 * j21),
                         h02 - (r00 * j02 + r01 * j12 + r02 * j22))
        h10, h11, h12 = (h10 - (r10 * j00 + r11 * j10 + r12 * j20), h11 - (r10 * j01 + r11 * j11 + r12 * j21),
                         h12 - (r10 * j02 + r11 * j12 + r12 * j22))
        h20, h21, h22 = (h20 - (r20 * j00 + r21 * j10 + r22 * j20), h21 - (r20 * j01 + r21 * j11 + r22 * j21),
                         h22 - (r20 * j02 + r21 * j12 + r22 * j22))
        # --- accelerometer-bias Jacobians: D = delta_R_k dt; Va -= D; Ma += mid D
        D0, D1, D2 = r00 * dt, r01 * dt, r02 * dt
        a00, a01, a02 = a00 - D0, a01 - D1, a02 - D2
        b00, b01, b02 = b00 + mid * D0, b01 + mid * D1, b02 + mid * D2
        D0, D1, D2 = r10 * dt, r11 * dt, r12 * dt
        b10, b11, b12 = b10 + mid * D0, b11 + mid * D1, b12 + mid * D2
        a10, a11, a12 = a10 - D0, a11 - D1, a12 - D2
        D0, D1, D2 = r20 * dt, r21 * dt, r22 * dt
        a20, a21, a22 = a20 - D0, a21 - D1, a22 - D2
        b20, b21, b22 = b20 + mid * D0, b21 + mid * D1, b22 + mid * D2
        # --- covariance (left form, q rows). u = hat(c) theta is the velocity error
        # increment (plus accelerometer noise n): v' = v - u + n, q' = q + mid (u - n).
        # X = hat(c) rr, XH = hat(c) rr hat(c)^T (+ noise N = qa dt I), Y = hat(c) rv, Yq = hat(c) rq.
        X00, X01, X02 = c1 * rr02 - c2 * rr01, c1 * rr12 - c2 * rr11, c1 * rr22 - c2 * rr12
        X10, X11, X12 = c2 * rr00 - c0 * rr02, c2 * rr01 - c0 * rr12, c2 * rr02 - c0 * rr22
        X20, X21, X22 = c0 * rr01 - c1 * rr00, c0 * rr11 - c1 * rr01, c0 * rr12 - c1 * rr02
        na = qa * dt
        N00, N01, N02 = c1 * X02 - c2 * X01 + na, c2 * X00 - c0 * X02, c0 * X01 - c1 * X00
        N11, N12, N22 = c2 * X10 - c0 * X12 + na, c0 * X11 - c1 * X10, c0 * X21 - c1 * X20 + na
        Y00, Y01, Y02 = c1 * rv20 - c2 * rv10, c1 * rv21 - c2 * rv11, c1 * rv22 - c2 * rv12
        Y10, Y11, Y12 = c2 * rv00 - c0 * rv20, c2 * rv01 - c0 * rv21, c2 * rv02 - c0 * rv22
        Y20, Y21, Y22 = c0 * rv10 - c1 * rv00, c0 * rv11 - c1 * rv01, c0 * rv12 - c1 * rv02
        Z00, Z01, Z02 = c1 * rq20 - c2 * rq10, c1 * rq21 - c2 * rq11, c1 * rq22 - c2 * rq12
        Z10, Z11, Z12 = c2 * rq00 - c0 * rq20, c2 * rq01 - c0 * rq21, c2 * rq02 - c0 * rq22
        Z20, Z21, Z22 = c0 * rq10 - c1 * rq00, c0 * rq11 - c1 * rq01, c0 * rq12 - c1 * rq02
        # qq' = qq + mid (Z + Z^T) + mid^2 (XH + N)
        mid2, midx2 = mid * mid, mid * 2.0
        qq00, qq01, qq02 = (qq00 + (midx2 * Z00 + mid2 * N00), qq01 + (mid * (Z01 + Z10) + mid2 * N01),
                            qq02 + (mid * (Z02 + Z20) + mid2 * N02))
        qq11, qq12, qq22 = (qq11 + (midx2 * Z11 + mid2 * N11), qq12 + (mid * (Z12 + Z21) + mid2 * N12),
                            qq22 + (midx2 * Z22 + mid2 * N22))
        # vq' = vq + mid (Y^T - XH - N) - Z
        vq00, vq01, vq02 = (vq00 + (mid * (Y00 - N00) - Z00), vq01 + (mid * (Y10 - N01) - Z01),
                            vq02 + (mid * (Y20 - N02) - Z02))
        vq10, vq11, vq12 = (vq10 + (mid * (Y01 - N01) - Z10), vq11 + (mid * (Y11 - N11) - Z11),
                            vq12 + (mid * (Y21 - N12) - Z12))
        vq20, vq21, vq22 = (vq20 + (mid * (Y02 - N02) - Z20), vq21 + (mid * (Y12 - N12) - Z21),
                            vq22 + (mid * (Y22 - N22) - Z22))
        # vv' = vv - (Y + Y^T) + XH + N
        vv00, vv01, vv02 = vv00 + (N00 - 2.0 * Y00), vv01 + (N01 - Y01 - Y10), vv02 + (N02 - Y02 - Y20)
        vv11, vv12, vv22 = vv11 + (N11 - 2.0 * Y11), vv12 + (N12 - Y12 - Y21), vv22 + (N22 - 2.0 * Y22)
        # rq' = rq + mid X^T, rv' = rv - X^T
        rq00, rq01, rq02 = rq00 + mid * X00, rq01 + mid * X10, rq02 + mid * X20
        rq10, rq11, rq12 = rq10 + mid * X01, rq11 + mid * X11, rq12 + mid * X21
        rq20, rq21, rq22 = rq20 + mid * X02, rq21 + mid * X12, rq22 + mid * X22
        rv00, rv01, rv02 = rv00 - X00, rv01 - X10, rv02 - X20
        rv10, rv11, rv12 = rv10 - X01, rv11 - X11, rv12 - X21
        rv20, rv21, rv22 = rv20 - X02, rv21 - X12, rv22 - X22
        # gyro noise: U Q U^T / dt = qg dt [(1 - k t2) I + k psi psi^T], psi = delta_R_k phi,
        # since Jl Jl^T = I + k K^2 with k = 2C - B^2 - C^2 t2
        if qg != 0.0:
            kap = 2.0 * C - B * B - C * C * t2
            qgd = qg * dt
            w1 = qgd * kap
            w0 = qgd - w1 * t2
            s0 = r00 * x + r01 * y + r02 * z
            s1 = r10 * x + r11 * y + r12 * z
            s2 = r20 * x + r21 * y + r22 * z
            ws0, ws1 = w1 * s0, w1 * s1
            rr00, rr11, rr22 = rr00 + (w0 + ws0 * s0), rr11 + (w0 + ws1 * s1), rr22 + (w0 + w1 * s2 * s2)
            rr01, rr02, rr12 = rr01 + ws0 * s1, rr02 + ws0 * s2, rr12 + ws1 * s2
        # write back (entry by entry: no tuple of 90 floats in the compiled code)
        u[0], u[1], u[2], u[3], u[4], u[5] = h00, h01, h02, h10, h11, h12
        u[6], u[7], u[8], u[9], u[10], u[11] = h20, h21, h22, g00, g01, g02
        u[12], u[13], u[14], u[15], u[16], u[17] = g10, g11, g12, g20, g21, g22
        u[18], u[19], u[20], u[21], u[22], u[23] = m00, m01, m02, m10, m11, m12
        u[24], u[25], u[26], u[27], u[28], u[29] = m20, m21, m22, a00, a01, a02
        u[30], u[31], u[32], u[33], u[34], u[35] = a10, a11, a12, a20, a21, a22
        u[36], u[37], u[38], u[39], u[40], u[41] = b00, b01, b02, b10, b11, b12
        u[42], u[43], u[44], u[45], u[46], u[47] = b20, b21, b22, rr00, rr01, rr02
        u[48], u[49], u[50], u[51], u[52], u[53] = rr11, rr12, rr22, rv00, rv01, rv02
        u[54], u[55], u[56], u[57], u[58], u[59] = rv10, rv11, rv12, rv20, rv21, rv22
        u[60], u[61], u[62], u[63], u[64], u[65] = rq00, rq01, rq02, rq10, rq11, rq12
        u[66], u[67], u[68], u[69], u[70], u[71] = rq20, rq21, rq22, vv00, vv01, vv02
        u[72], u[73], u[74], u[75], u[76], u[77] = vv11, vv12, vv22, vq00, vq01, vq02
        u[78], u[79], u[80], u[81], u[82], u[83] = vq10, vq11, vq12, vq20, vq21, vq22
        u[84], u[85], u[86], u[87], u[88], u[89] = qq00, qq01, qq02, qq11, qq12, qq22
    # --- deltas: p += dt (v + c/2), v += c, q = q_k (x) (ch, k phi)
    dx, dy, dz = k * x, k * y, k * z
    s[0] = T + dt
    s[1] = qw * ch - qx * dx - qy * dy - qz * dz
    s[2] = qw * dx + qx * ch + qy * dz - qz * dy
    s[3] = qw * dy - qx * dz + qy * ch + qz * dx
    s[4] = qw * dz + qx * dy - qy * dx + qz * ch
    s[5], s[6], s[7] = v0 + c0, v1 + c1, v2 + c2
    s[8], s[9], s[10] = p0 + dt * (v0 + 0.5 * c0), p1 + dt * (v1 + 0.5 * c1), p2 + dt * (v2 + 0.5 * c2)



def integrate_interval(s: tuple, u: tuple | None, dt: float, x: float, y: float, z: float,
                       fx: float, fy: float, fz: float, noise: tuple[float, float]) -> tuple[tuple, tuple | None]:
    """:func:`integrate` on tuples: the new ``(deltas, uncertainty)`` (``uncertainty`` None when ``u`` is)."""
    sa = np.array(s, dtype=float)
    ua = _NO_UNCERTAINTY if u is None else np.array(u, dtype=float)
    integrate(sa, ua, float(dt), float(x), float(y), float(z), float(fx), float(fy), float(fz),
              float(noise[0]), float(noise[1]))
    return tuple(sa.tolist()), (None if u is None else tuple(ua.tolist()))


def rotation_from_quaternion(q: Sequence[float]) -> tuple:
    """Row-major rotation matrix (9 floats) of a quaternion ``(w, x, y, z)``, normalised first."""
    return so3.flat_from_quat(so3.quat_normalise(q))


def quaternion_from_rotation(r: tuple) -> tuple:
    """Unit quaternion ``(w, x, y, z)`` of a row-major rotation matrix (9 floats) (Shepperd's method)."""
    return so3.quat_normalise(so3.quat_from_flat(r))


@jitable
def first_rate_boundary(t_first: float, rate: float, origin: float, snap_tol: float) -> int:
    """Index of the first boundary ``origin + k / rate`` (k >= 0) at or after ``t_first - snap_tol``."""
    k = max(0, math.ceil((t_first - snap_tol - origin) * rate) - 1)
    while origin + k / rate < t_first - snap_tol:
        k += 1
    return k


@jitable
def _copy(dst: np.ndarray, src: np.ndarray) -> None:
    """``dst[:] = src`` for 1-d arrays of one length, as a loop (an array slice assignment compiles numba's
    shape-check and error code at every use, much of this module's first compile)."""
    for i in range(src.size):
        dst[i] = src[i]


@njit
def _integrate(b: np.ndarray, dt: float, x: float, y: float, z: float, fx: float, fy: float, fz: float) -> None:
    """:func:`integrate` on the state buffer."""
    u = b[_S_UNC:_S_PREV] if b[_S_UNCERTAINTY] != 0.0 else b[_S_UNC:_S_UNC]
    integrate(b[0:_S_UNC], u, dt, x, y, z, fx, fy, fz, b[_S_NOISE], b[_S_NOISE + 1])


@njit
def _integrate_piece(b: np.ndarray, dt: float, ka: np.ndarray, kb: np.ndarray, gap: bool) -> None:
    """One piece of ``dt`` s between knots with bias-free values ``ka``, ``kb`` (6); a piece of a gap flags the frame."""
    if gap:
        b[_S_VALID] = 0.0
    if b[_S_MIDPOINT] != 0.0:
        hh = 0.5 * dt
        _integrate(b, dt, (ka[0] + kb[0]) * hh, (ka[1] + kb[1]) * hh, (ka[2] + kb[2]) * hh,
                   (ka[3] + kb[3]) * hh, (ka[4] + kb[4]) * hh, (ka[5] + kb[5]) * hh)
    else:
        _integrate(b, dt, ka[0] * dt, ka[1] * dt, ka[2] * dt, ka[3] * dt, ka[4] * dt, ka[5] * dt)
    b[_S_N] += 1.0


@njit
def _boundary_after(b: np.ndarray, times: np.ndarray, k: float) -> float:
    """Time of boundary ``k``, s: a frame time (inf past the last), on the rate's grid, or inf (every-N)."""
    if b[_S_MODE] == 2.0:
        return times[int(k)] if k < times.size else math.inf
    if b[_S_MODE] == 1.0:
        return b[_S_ORIGIN] + k / b[_S_RATE]
    return math.inf


@njit
def _cross_boundary(b: np.ndarray, times: np.ndarray, out: np.ndarray, nout: int, tb: float) -> int:
    """A boundary at ``tb``: the frame into row ``nout`` of ``out``, the next started; returns the rows written."""
    if b[_S_ACTIVE] != 0.0:
        _copy(out[nout, 0:_S_PREV], b[0:_S_PREV])
        out[nout, _O_N] = b[_S_N] + b[_S_MARK] - b[_S_CD]
        out[nout, _O_TSTART] = b[_S_TSTART]
        out[nout, _O_TEND] = tb
        out[nout, _O_VALID] = b[_S_VALID]
        nout += 1
    k = b[_S_K] + 1.0
    nxt = _boundary_after(b, times, k)
    active = b[_S_MODE] == 0.0 or nxt != math.inf
    b[_S_K] = k
    b[_S_NEXT] = nxt
    b[_S_ACTIVE] = 1.0 if active else 0.0
    b[_S_LIM] = nxt - b[_S_TOL] if active else -math.inf
    b[0:_S_PREV] = 0.0
    b[1] = 1.0                                  # identity quaternion
    b[_S_N] = 0.0
    b[_S_MARK] = b[_S_CD]
    b[_S_TSTART] = tb
    b[_S_VALID] = 1.0
    return nout


@njit
def _first_sample(b: np.ndarray, times: np.ndarray, out: np.ndarray, t: float) -> int:
    """The first sample: place the first boundary (-1: a frame time before it)."""
    tol = b[_S_TOL]
    if b[_S_MODE] == 0.0:
        _cross_boundary(b, times, out, 0, t)
        b[_S_CD] = b[_S_MARK] = b[_S_EVERY]
        return 0
    k = b[_S_K]
    if b[_S_MODE] == 1.0:
        origin = t if math.isnan(b[_S_ORIGIN]) else b[_S_ORIGIN]
        k = float(first_rate_boundary(t, b[_S_RATE], origin, tol))
        b[_S_ORIGIN] = origin
    nxt = _boundary_after(b, times, k)
    if nxt < t - tol:
        return -1
    b[_S_K], b[_S_NEXT], b[_S_LIM] = k, nxt, -math.inf
    if abs(nxt - t) <= tol:
        _cross_boundary(b, times, out, 0, nxt)
    return 0


@njit
def push_step(b: np.ndarray, times: np.ndarray, out: np.ndarray, t: float, wx: float, wy: float, wz: float,
              ax: float, ay: float, az: float) -> int:
    """Take one sample (time s; gyro rad/s, specific force m/s^2, body frame, bias not removed) into the state
    buffer ``b`` (``times``: the frame times, in that mode); an interval that crosses boundaries is split there,
    each finished frame written to a row of ``out``.

    Returns
    -------
    int
        Frames finished (usually 0); -1, the buffer untouched, for a sample refused (non-increasing time, a gap
        with ``on_gap="raise"``, a frame time before the first sample) or finishing more frames than ``out`` holds.
    """
    h = t - b[_S_PREV]
    # inside a frame (_S_LIM is -inf before the first sample), no gap, not an every-N boundary
    if t < b[_S_LIM] and 0.0 < h <= b[_S_MAXGAP] and b[_S_CD] != 1.0:
        b[_S_CD] -= 1.0
        wx, wy, wz = wx - b[_S_BIAS], wy - b[_S_BIAS + 1], wz - b[_S_BIAS + 2]
        ax, ay, az = ax - b[_S_BIAS + 3], ay - b[_S_BIAS + 4], az - b[_S_BIAS + 5]
        gx, gy, gz, fx, fy, fz = b[_S_PREV + 1], b[_S_PREV + 2], b[_S_PREV + 3], b[_S_PREV + 4], b[_S_PREV + 5], \
            b[_S_PREV + 6]
        b[_S_PREV], b[_S_PREV + 1], b[_S_PREV + 2], b[_S_PREV + 3] = t, wx, wy, wz
        b[_S_PREV + 4], b[_S_PREV + 5], b[_S_PREV + 6] = ax, ay, az
        if b[_S_MIDPOINT] != 0.0:               # mean of the two samples, the 1/2 folded into dt
            hh = 0.5 * h
            _integrate(b, h, (gx + wx) * hh, (gy + wy) * hh, (gz + wz) * hh, (fx + ax) * hh, (fy + ay) * hh,
                       (fz + az) * hh)
        else:                                   # the left sample's value
            _integrate(b, h, gx * h, gy * h, gz * h, fx * h, fy * h, fz * h)
        return 0
    return _push_boundary(b, times, out, t, wx, wy, wz, ax, ay, az)


@njit
def _push_boundary(b: np.ndarray, times: np.ndarray, out: np.ndarray, t: float, wx: float, wy: float, wz: float,
                   ax: float, ay: float, az: float) -> int:
    """:func:`push_step` off its fast path: the first sample, boundaries, gaps, refusals."""
    t0 = b[_S_PREV]
    if math.isnan(t0):
        nout = _first_sample(b, times, out, t)
        if nout >= 0:
            b[_S_PREV], b[_S_PREV + 1], b[_S_PREV + 2], b[_S_PREV + 3] = t, wx - b[_S_BIAS], wy - b[_S_BIAS + 1], \
                wz - b[_S_BIAS + 2]
            b[_S_PREV + 4], b[_S_PREV + 5], b[_S_PREV + 6] = ax - b[_S_BIAS + 3], ay - b[_S_BIAS + 4], \
                az - b[_S_BIAS + 5]
        return nout
    h = t - t0
    tol = b[_S_TOL]
    gap = h > b[_S_MAXGAP]
    if not h > 0.0 or (gap and b[_S_RAISE] != 0.0 and (b[_S_ACTIVE] != 0.0 or b[_S_NEXT] < t - tol)):
        return -1
    # the frames this sample finishes: more than out holds is refused (the caller grows out)
    nxt, k, rows = b[_S_NEXT], b[_S_K], 0
    while nxt < t - tol:
        rows += 1
        k += 1.0
        nxt = _boundary_after(b, times, k)
    if abs(nxt - t) <= tol or (b[_S_MODE] == 0.0 and b[_S_CD] == 1.0):
        rows += 1
    if rows > out.shape[0]:
        return -1
    # knots in the scratch (no allocation): the last sample pv, this one k1, a piece's ends k0 and kb
    pv, k1 = b[_S_PREV + 1:_S_PREV + 7], b[_S_KNOTS:_S_KNOTS + 6]
    k0, kb = b[_S_KNOTS + 6:_S_KNOTS + 12], b[_S_KNOTS + 12:_S_KNOTS + 18]
    k1[0], k1[1], k1[2] = wx - b[_S_BIAS], wy - b[_S_BIAS + 1], wz - b[_S_BIAS + 2]
    k1[3], k1[4], k1[5] = ax - b[_S_BIAS + 3], ay - b[_S_BIAS + 4], az - b[_S_BIAS + 5]
    _copy(k0, pv)
    tk, nout = t0, 0
    while b[_S_NEXT] < t - tol:                 # boundaries strictly inside (t0, t - tol): split there
        tb = b[_S_NEXT]
        if b[_S_MIDPOINT] != 0.0:
            wgt = (tb - t0) / h
            for i in range(6):
                kb[i] = pv[i] + (k1[i] - pv[i]) * wgt
        else:
            _copy(kb, k0)
        if b[_S_ACTIVE] != 0.0:
            _integrate_piece(b, tb - tk, k0, kb, gap)
        nout = _cross_boundary(b, times, out, nout, tb)
        tk = tb
        _copy(k0, kb)
    if b[_S_ACTIVE] != 0.0:
        _integrate_piece(b, t - tk, k0, k1, gap)
    if b[_S_MODE] == 0.0:
        b[_S_CD] -= 1.0
        b[_S_MARK] -= 1.0                       # (an interval counted in _S_N)
        if b[_S_CD] == 0.0:
            nout = _cross_boundary(b, times, out, nout, t)
            b[_S_CD] = b[_S_MARK] = b[_S_EVERY]
    elif abs(b[_S_NEXT] - t) <= tol:
        nout = _cross_boundary(b, times, out, nout, b[_S_NEXT])
    b[_S_PREV] = t
    _copy(pv, k1)
    return nout


def state_buffer(par: PreintegrationParams, rate: float | None, every: int | None,
                   origin: float | None) -> np.ndarray:
    """A fresh state buffer of :func:`push_step`: frames every ``every`` samples, at ``rate`` Hz from ``origin``
    (s; None: the first sample), or (both None) at the frame times passed to it."""
    b = np.zeros(_S_SIZE)
    b[0:11] = DELTAS_IDENTITY
    b[_S_PREV] = b[_S_TSTART] = math.nan
    b[_S_LIM], b[_S_NEXT], b[_S_VALID] = -math.inf, math.inf, 1.0
    b[_S_CD] = b[_S_MARK] = float(1 << 52)      # (exact as a float)
    b[_S_MAXGAP], b[_S_TOL] = par.max_gap, par.snap_tol
    b[_S_BIAS:_S_BIAS + 6] = par.bias
    b[_S_NOISE:_S_NOISE + 2] = par.noise
    b[_S_MIDPOINT] = 1.0 if par.hold == "midpoint" else 0.0
    b[_S_UNCERTAINTY] = 1.0 if par.uncertainty else 0.0
    b[_S_RAISE] = 1.0 if par.on_gap == "raise" else 0.0
    b[_S_MODE] = 0.0 if every is not None else (1.0 if rate is not None else 2.0)
    b[_S_RATE], b[_S_EVERY] = rate or 0.0, every or 0
    b[_S_ORIGIN] = math.nan if origin is None else origin
    return b


@njit
def run_log(b: np.ndarray, times: np.ndarray, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
            deltas: np.ndarray, unc: np.ndarray, meta: np.ndarray) -> tuple[int, int]:
    """:func:`push_step` over a whole log (t (N,), s; gyro, accel (N, 3)): frame ``f``'s deltas into ``deltas[f]``,
    its uncertainty into ``unc[f]`` (``unc`` may have no rows), interval count and validity into ``meta[f]``.
    Returns ``(frames written, first sample refused or -1)``."""
    rows = np.empty((16, _O_SIZE))
    nf, i = 0, 0
    while i < t.size:
        r = push_step(b, times, rows, t[i], gyro[i, 0], gyro[i, 1], gyro[i, 2], accel[i, 0], accel[i, 1],
                      accel[i, 2])
        if r < 0:
            if rows.shape[0] > times.size:      # (room for every frame: refused)
                return nf, i
            rows = np.empty((2 * rows.shape[0], _O_SIZE))
            continue
        for j in range(r):
            _copy(deltas[nf], rows[j, 0:_S_UNC])
            if unc.shape[0]:
                _copy(unc[nf], rows[j, _S_UNC:_S_PREV])
            meta[nf, 0], meta[nf, 1] = rows[j, _O_N], rows[j, _O_VALID]
            nf += 1
        i += 1
    return nf, -1
