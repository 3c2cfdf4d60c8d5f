"""The InvariantEKF's predict/update kernels in pure Python, on the filter's flat state buffer.

:class:`~imu_ground.filters.invariant_ekf.InvariantEKF` keeps its whole state in
one flat sequence of floats (layout: the ``B_*`` offsets below) and runs
:func:`predict` and :func:`update` on it: these pure-Python functions, or their
C twins in ``imu_ground/filters/_ekf_native.c`` (the same formulas term for term,
same calling convention, equal under the twin rule of :mod:`imu_ground._native`) when that extension is built. Here the
buffer is a ``list`` (slice reads and writes are the cheapest in Python); the C
kernels take an ``array('d')``. The equations are in the module notes of
:mod:`imu_ground.filters.invariant_ekf`; matrices are row-major 9-sequences
(:func:`imu_ground.so3.mul_flat` and friends), rotations unit quaternions
``(w, x, y, z)``.
"""
from __future__ import annotations

import math

import numpy as np

from imu_ground.so3 import (
    exp_flat,
    flat_from_quat,
    hat_flat,
    log_flat,
    mul_flat,
    mul_nt_flat,
    quat_exp,
    quat_from_flat,
    quat_mul,
    quat_normalise,
    transpose_flat,
)

__all__ = [
    "B_B",
    "B_DET",
    "B_HB",
    "B_K",
    "B_LEFT",
    "B_NUP",
    "B_P",
    "B_PPO",
    "B_PPR",
    "B_Q",
    "B_QN",
    "B_RENORM",
    "B_RN",
    "B_S",
    "B_SI",
    "B_X",
    "B_XPO",
    "B_XPR",
    "B_XV",
    "B_Y",
    "B_Z",
    "B_ZN",
    "STATE_SIZE",
    "check_cov",
    "flat_rotation",
    "new_state",
    "predict",
    "state_x",
    "update",
]

# State buffer layout (offsets in floats; the E_* enum of _ekf_native.c). The Python kernels write
# neighbours in one slice: q and P, x_prior and P_prior, x_post and P_post, and y .. det S are adjacent.
B_Q, B_P, B_QN, B_RN = 0, 4, 13, 22           # quaternion of x (4), P, Q, R (9 each)
B_X, B_XV = 31, 40                             # x as a matrix (cache) and its validity flag
B_XPR, B_PPR, B_XPO, B_PPO = 41, 45, 54, 58    # x_prior (quaternion), P_prior, x_post, P_post
B_Y, B_K, B_S, B_SI = 67, 70, 79, 88           # y (3), K, S, S^-1
B_DET, B_NUP = 97, 98                          # det S (nan before any update), number of updates
B_B, B_HB, B_LEFT, B_RENORM = 99, 102, 111, 112  # b (3), -[b]x, 1.0 for the left error, renormalise period
B_Z, B_ZN = 113, 122                           # last z (up to 9), its size (0: none)
STATE_SIZE = 123

_I3 = np.eye(3)
_I9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
_ZERO9 = (0.0,) * 9
_ZERO3 = (0.0, 0.0, 0.0)


def new_state(q, P, Q, R, b, left: bool, renorm_every: int) -> list:
    """A state buffer (list of STATE_SIZE floats): quaternion ``q`` (4), ``P``, ``Q``, ``R`` (row-major 9),
    body axis ``b`` (3), error kind and renormalisation period; no update yet (``det S`` nan)."""
    s = [0.0] * STATE_SIZE
    s[B_Q:B_Q + 4] = q
    s[B_P:B_P + 9] = P
    s[B_QN:B_QN + 9] = Q
    s[B_RN:B_RN + 9] = R
    s[B_XPR:B_XPR + 4] = s[B_XPO:B_XPO + 4] = q
    s[B_PPR:B_PPR + 9] = s[B_PPO:B_PPO + 9] = P
    s[B_DET] = math.nan
    s[B_B:B_B + 3] = b
    s[B_HB:B_HB + 9] = [-v for v in hat_flat(*b)]     # H = -[b]x of the left direction update
    s[B_LEFT] = 1.0 if left else 0.0
    s[B_RENORM] = float(renorm_every)
    return s


def flat_rotation(u) -> list | None:
    """Row-major 9 floats of a 3x3 matrix or a rotation vector (rad); None stays None."""
    if u is None:
        return None
    u = np.asarray(u, dtype=float)
    if u.shape == (3, 3):
        return u.ravel().tolist()
    if u.shape == (3,):
        return list(exp_flat(*u.tolist()))
    raise ValueError(f"rotation increment must be a 3x3 matrix or a rotation vector of shape (3,), got {u.shape}")


def check_cov(name: str, m) -> np.ndarray:
    """A covariance argument as a C-contiguous float (3, 3) array (a scalar ``s`` means ``s I``)."""
    m = np.asarray(m, dtype=float)
    if m.ndim == 0:
        return float(m) * _I3
    if m.shape != (3, 3):
        raise ValueError(f"{name} must be a scalar or a 3x3 matrix, got shape {m.shape}")
    return np.ascontiguousarray(m)


def _congruence(a, p, q=_ZERO9) -> tuple:
    """``A P A^T + Q`` for symmetric ``P`` and ``Q`` (upper triangle computed, lower mirrored), 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    m0, m1, m2, m3, m4, m5, m6, m7, m8 = mul_flat(a, p)
    c00 = m0 * a0 + m1 * a1 + m2 * a2 + q[0]
    c01 = m0 * a3 + m1 * a4 + m2 * a5 + q[1]
    c02 = m0 * a6 + m1 * a7 + m2 * a8 + q[2]
    c11 = m3 * a3 + m4 * a4 + m5 * a5 + q[4]
    c12 = m3 * a6 + m4 * a7 + m5 * a8 + q[5]
    c22 = m6 * a6 + m7 * a7 + m8 * a8 + q[8]
    return c00, c01, c02, c01, c11, c12, c02, c12, c22


def _sym_upper(m) -> tuple:
    """The symmetric matrix of the upper triangle of ``m`` (row-major 9-tuple)."""
    return m[0], m[1], m[2], m[1], m[4], m[5], m[2], m[5], m[8]


def _singular(det: float) -> np.linalg.LinAlgError:
    return np.linalg.LinAlgError(f"innovation covariance is singular (det = {det})")


def _inv_flat(m):
    """Inverse (row-major 9-tuple) and determinant of a 3x3 matrix by cofactors."""
    a, b, c, d, e, f, g, h, i = m
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    if det == 0.0 or not math.isfinite(det):
        raise _singular(det)
    r = 1.0 / det
    return (A * r, (c * h - b * i) * r, (b * f - c * e) * r,
            B * r, (a * i - c * g) * r, (c * d - a * f) * r,
            C * r, (b * g - a * h) * r, (a * e - b * d) * r), det


def _update_rotation_left(q, P, z, r):
    """Left-error update with a rotation measurement, unrolled (H = I; the state a unit quaternion).

    Unrolls ``y = Log(x^T z)`` (as ``2 atan2(|v|, w) v / |v|`` of the quaternion
    ``conj(q) q_z``, accurate up to pi), ``S = P + R``, ``S^-1`` by symmetric
    cofactors, ``K = P S^-1``, ``q <- q Exp(K y)`` and ``P <- K R`` (upper
    triangle, mirrored); matrices are row-major 9-tuples. Returns ``q, P, y, K,
    S, SI, det S``.
    """
    qw, qx, qy, qz = q
    zw, zx, zy, zz = quat_from_flat(z)
    aw, ax, ay, az = (qw * zw + qx * zx + qy * zy + qz * zz, qw * zx - qx * zw - qy * zz + qz * zy,
                      qw * zy + qx * zz - qy * zw - qz * zx, qw * zz - qx * zy + qy * zx - qz * zw)
    if aw < 0.0:
        aw, ax, ay, az = -aw, -ax, -ay, -az
    vn = math.sqrt(ax * ax + ay * ay + az * az)
    f = 2.0 * math.atan2(vn, aw) / vn if vn > 0.0 else 2.0
    y0, y1, y2 = ax * f, ay * f, az * f
    p0, p1, p2, _, p4, p5, _, _, p8 = P
    r0, r1, r2, _, r4, r5, _, _, r8 = r
    s0, s1, s2, s4, s5, s8 = p0 + r0, p1 + r1, p2 + r2, p4 + r4, p5 + r5, p8 + r8
    i00, i01, i02 = s4 * s8 - s5 * s5, s2 * s5 - s1 * s8, s1 * s5 - s2 * s4
    det = s0 * i00 + s1 * i01 + s2 * i02
    if det == 0.0 or not math.isfinite(det):
        raise _singular(det)
    d = 1.0 / det
    i00, i01, i02 = i00 * d, i01 * d, i02 * d
    i11, i12, i22 = (s0 * s8 - s2 * s2) * d, (s1 * s2 - s0 * s5) * d, (s0 * s4 - s1 * s1) * d
    SI = (i00, i01, i02, i01, i11, i12, i02, i12, i22)
    K = k0, k1, k2, k3, k4, k5, k6, k7, k8 = mul_flat(P, SI)
    if r1 == 0.0 and r2 == 0.0 and r5 == 0.0:   # diagonal R (the same numbers, without the zero terms)
        n01, n02, n12 = k1 * r4, k2 * r8, k5 * r8
        Pn = (k0 * r0, n01, n02, n01, k4 * r4, n12, n02, n12, k8 * r8)
    else:
        n01 = k0 * r1 + k1 * r4 + k2 * r5
        n02 = k0 * r2 + k1 * r5 + k2 * r8
        n12 = k3 * r2 + k4 * r5 + k5 * r8
        Pn = (k0 * r0 + k1 * r1 + k2 * r2, n01, n02, n01, k3 * r1 + k4 * r4 + k5 * r5, n12,
              n02, n12, k6 * r2 + k7 * r5 + k8 * r8)
    e = quat_exp(k0 * y0 + k1 * y1 + k2 * y2, k3 * y0 + k4 * y1 + k5 * y2, k6 * y0 + k7 * y1 + k8 * y2)
    return (quat_mul(q, e),
            Pn, (y0, y1, y2), K, (s0, s1, s2, s1, s4, s5, s2, s5, s8), SI, det)


def state_x(s: list) -> list:
    """The state's rotation as a row-major 9-list: the cached matrix, else built from the quaternion (and cached)."""
    if not s[B_XV]:
        s[B_X:B_X + 9] = flat_from_quat(s[B_Q:B_Q + 4])
        s[B_XV] = 1.0
    return s[B_X:B_X + 9]


def predict(s: list, u, Q: np.ndarray | None) -> bool:
    """``InvariantEKF.predict`` on the state ``s``: increment ``u`` (None, (3, 3) or a rotation vector (3,),
    rad), process noise ``Q`` ((3, 3) array; None: the state's). Returns True (the C twin's "done")."""
    P = s[B_P:B_P + 9]
    q: list | tuple = s[B_Q:B_Q + 4]
    qn: list | tuple = s[B_QN:B_QN + 9] if Q is None else Q.ravel().tolist()
    if u is None:
        U = None
    elif type(u) is np.ndarray and u.shape == (3, 3):
        U = u.ravel().tolist()
    else:
        U = flat_rotation(u)
    x: list | tuple | None = None
    if U is not None:
        q = quat_mul(q, quat_from_flat(U))
        if s[B_LEFT]:                   # P <- U^T P U + Q
            s[B_Q:B_P + 9] = s[B_XPR:B_PPR + 9] = q + _congruence(transpose_flat(U), P, qn)   # q, P adjacent
            s[B_XV] = 0.0
            return True
    elif s[B_XV]:
        x = s[B_X:B_X + 9]
    if not s[B_LEFT]:                   # P <- P + A Q A^T, A = x U
        x = flat_from_quat(q) if x is None else x
        qn = _congruence(x, qn)
    p0, p1, p2, _, p4, p5, _, _, p8 = P
    q0, q1, q2, _, q4, q5, _, _, q8 = qn
    a, b, c = p1 + q1, p2 + q2, p5 + q5
    s[B_Q:B_P + 9] = s[B_XPR:B_PPR + 9] = (*q, p0 + q0, a, b, a, p4 + q4, c, b, c, p8 + q8)
    if x is not None:
        s[B_X:B_X + 9] = x
        s[B_XV] = 1.0
    elif U is not None:
        s[B_XV] = 0.0
    return True


def _update_general(s: list, shape, zl, r):
    """The right-error rotation update and both direction updates (matrices as 9-tuples)."""
    x = state_x(s)
    P = s[B_P:B_P + 9]
    left = s[B_LEFT]
    if shape == (3, 3):                 # H = I: K = P S^-1, P <- (I - K) P = K Rn (information form)
        y = log_flat(mul_nt_flat(zl, x))
        Rn = _congruence(x, r)
        p0, p1, p2, _, p4, p5, _, _, p8 = P
        r0, r1, r2, _, r4, r5, _, _, r8 = Rn
        a, b, c = p1 + r1, p2 + r2, p5 + r5
        S = (p0 + r0, a, b, a, p4 + r4, c, b, c, p8 + r8)
        SI, detS = _inv_flat(S)
        K = mul_flat(P, SI)
        Pn = _sym_upper(mul_flat(K, Rn))
    elif shape == (3,):
        z0, z1, z2 = zl
        b0, b1, b2 = s[B_B:B_B + 3]
        if left:
            x0, x1, x2, x3, x4, x5, x6, x7, x8 = x
            y = (x0 * z0 + x3 * z1 + x6 * z2 - b0, x1 * z0 + x4 * z1 + x7 * z2 - b1,
                 x2 * z0 + x5 * z1 + x8 * z2 - b2)
            H: list | tuple = s[B_HB:B_HB + 9]
            Rn = _congruence((x0, x3, x6, x1, x4, x7, x2, x5, x8), r)
        else:
            xb = (x[0] * b0 + x[1] * b1 + x[2] * b2, x[3] * b0 + x[4] * b1 + x[5] * b2,
                  x[6] * b0 + x[7] * b1 + x[8] * b2)
            y = (z0 - xb[0], z1 - xb[1], z2 - xb[2])
            H = tuple(-v for v in hat_flat(*xb))
            Rn = r
        PHT = mul_nt_flat(P, H)
        S = tuple(m + n for m, n in zip(_sym_upper(mul_flat(H, PHT)), _sym_upper(Rn), strict=True))
        SI, detS = _inv_flat(S)
        K = mul_flat(PHT, SI)
        KH = mul_flat(K, H)
        IKH = tuple(i - kh for i, kh in zip(_I9, KH, strict=True))           # Joseph form
        Pn = tuple(m + n for m, n in zip(_congruence(IKH, P), _congruence(K, Rn), strict=True))
    else:
        raise ValueError(f"z must be a 3x3 rotation or a unit vector of shape (3,), got {shape}")
    y0, y1, y2 = y
    k0, k1, k2, k3, k4, k5, k6, k7, k8 = K
    e = quat_exp(k0 * y0 + k1 * y1 + k2 * y2, k3 * y0 + k4 * y1 + k5 * y2, k6 * y0 + k7 * y1 + k8 * y2)
    q = s[B_Q:B_Q + 4]
    return quat_mul(q, e) if left else quat_mul(e, q), Pn, y, K, S, SI, detS


def update(s: list, z, R: np.ndarray | None) -> bool:
    """``InvariantEKF.update`` on the state ``s``: ``z`` None (skip), a (3, 3) rotation or a (3,) direction;
    noise ``R`` ((3, 3) array; None: the state's). Returns True; raises LinAlgError for a singular ``S``
    (the C twin returns ``det S`` instead) and ValueError naming a bad ``z``; the state is then unchanged."""
    if z is None:
        s[B_ZN] = 0.0
        s[B_XPO:B_XPO + 4] = s[B_Q:B_Q + 4]
        s[B_PPO:B_PPO + 9] = s[B_P:B_P + 9]
        s[B_Y:B_Y + 3] = _ZERO3
        return True
    r = s[B_RN:B_RN + 9] if R is None else R.ravel().tolist()
    if type(z) is not np.ndarray:
        z = np.asarray(z, dtype=float)
    shape = z.shape
    zl = z.ravel().tolist()
    if shape == (3, 3) and s[B_LEFT]:           # the usual case
        q, Pn, y, K, S, SI, detS = _update_rotation_left(s[B_Q:B_Q + 4], s[B_P:B_P + 9], zl, r)
    else:
        q, Pn, y, K, S, SI, detS = _update_general(s, shape, zl, r)
    n = s[B_NUP] + 1.0
    s[B_NUP] = n
    if n % s[B_RENORM] == 0.0:
        q = quat_normalise(q)
    s[B_Q:B_P + 9] = s[B_XPO:B_PPO + 9] = (*q, *Pn)        # adjacent in the layout
    s[B_XV] = 0.0
    s[B_Z:B_Z + len(zl)] = zl
    s[B_ZN] = float(len(zl))
    s[B_Y:B_DET + 1] = (*y, *K, *S, *SI, detS)            # y, K, S, SI, det S adjacent
    return True
