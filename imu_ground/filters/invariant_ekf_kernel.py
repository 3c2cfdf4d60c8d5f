"""The invariant EKF on SO(3), written once: its predict and updates on tuples, and the state buffer of InvariantEKF.

:func:`predict_left`, :func:`update_rotation_left` and :func:`update_direction_left` are the filter's one definition
(left error; equations: :mod:`imu_ground.filters.invariant_ekf`) on a unit quaternion ``q`` ``(w, x, y, z)`` and
row-major 9-tuples (:func:`imu_ground.so3.mul_flat`), compiled into every body that calls them
(:func:`imu_ground._jit.jitable`): :func:`predict` and :func:`update` below (which add the right error) on the
InvariantEKF's state array (layout: the ``B_*`` offsets), and :func:`imu_ground.filters.residual.frame`. An update
returns ``(q, P, y, K, S, S^-1, det S, ok)``; ``ok`` False for a singular ``S`` (the caller keeps its state).
"""
from __future__ import annotations

import math

import numpy as np

from imu_ground._jit import jitable, njit
from imu_ground.so3 import (
    exp_flat, flat_from_quat, hat_flat, log_flat, mul_flat, mul_nt_flat, quat_exp, quat_from_flat, quat_mul,
    quat_normalise, transpose_flat
)

__all__ = [
    "B_B", "B_DET", "B_HB", "B_K", "B_LEFT", "B_NUP", "B_P", "B_PPO", "B_PPR", "B_Q", "B_QN", "B_RENORM", "B_RN",
    "B_S", "B_SI", "B_X", "B_XPO", "B_XPR", "B_XV", "B_Y", "B_Z", "B_ZN", "STATE_SIZE", "check_cov", "fill_x",
    "flat_rotation", "new_state", "predict", "update", "predict_left", "update_rotation_left",
    "update_direction_left", "congruence",
]

# State buffer layout (offsets in floats).
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
_ZERO9 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_ZERO3 = (0.0, 0.0, 0.0)
_NONE = np.zeros(0)                            # the array argument of a kind "none" (no increment, the state's noise)
_F64 = np.dtype(np.float64)
_BAD_INCREMENT = "rotation increment must be a 3x3 matrix or a rotation vector of shape (3,)"
for _helper in (exp_flat, flat_from_quat, hat_flat, log_flat, mul_flat, mul_nt_flat, quat_exp, quat_from_flat,
                quat_mul, quat_normalise, transpose_flat):
    jitable(_helper)                    # so3's scalar kernels, compiled into the bodies below that call them


def new_state(q, P, Q, R, b, left: bool, renorm_every: int) -> np.ndarray:
    """A state buffer (STATE_SIZE float64): quaternion ``q``, ``P``, ``Q``, ``R`` (row-major), body axis ``b``,
    error kind and renormalisation period; no update yet (``det S`` nan)."""
    s = np.zeros(STATE_SIZE)
    s[B_Q:B_Q + 4] = s[B_XPR:B_XPR + 4] = s[B_XPO:B_XPO + 4] = q
    s[B_P:B_P + 9] = s[B_PPR:B_PPR + 9] = s[B_PPO:B_PPO + 9] = P
    s[B_QN:B_QN + 9] = Q
    s[B_RN:B_RN + 9] = R
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
    a, kind = _argument(u, _BAD_INCREMENT)
    return a.ravel().tolist() if kind == 9 else list(exp_flat(*a.tolist()))


def check_cov(name: str, m) -> np.ndarray:
    """A covariance argument as a C-contiguous float (3, 3) array (a scalar ``s`` means ``s I``)."""
    m = np.asarray(m, dtype=float)
    if m.ndim == 0:
        return float(m) * _I3
    if m.shape != (3, 3):
        raise ValueError(f"{name} must be a scalar or a 3x3 matrix, got shape {m.shape}")
    return np.ascontiguousarray(m)


@jitable
def _get9(a, i):
    """``a[i:i + 9]`` as a tuple."""
    return a[i], a[i + 1], a[i + 2], a[i + 3], a[i + 4], a[i + 5], a[i + 6], a[i + 7], a[i + 8]


@jitable
def _get4(a, i):
    """``a[i:i + 4]`` as a tuple."""
    return a[i], a[i + 1], a[i + 2], a[i + 3]


@jitable
def _put(s, i, t):
    """``s[i:i + len(t)] = t``."""
    for k in range(len(t)):
        s[i + k] = t[k]


@jitable
def _add9(a, b):
    """Sum of two 9-tuples."""
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3], a[4] + b[4], a[5] + b[5], a[6] + b[6],
            a[7] + b[7], a[8] + b[8])


@jitable
def congruence(a, p, q):
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


@jitable
def _sym_upper(m):
    """The symmetric matrix of the upper triangle of ``m`` (row-major 9-tuple)."""
    return m[0], m[1], m[2], m[1], m[4], m[5], m[2], m[5], m[8]


@jitable
def _inv_flat(m):
    """Inverse (row-major 9-tuple) and determinant of a 3x3 matrix by cofactors, and whether it is regular."""
    a, b, c, d, e, f, g, h, i = m
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    if det == 0.0 or not math.isfinite(det):
        return _ZERO9, det, False
    r = 1.0 / det
    return (A * r, (c * h - b * i) * r, (b * f - c * e) * r,
            B * r, (a * i - c * g) * r, (c * d - a * f) * r,
            C * r, (b * g - a * h) * r, (a * e - b * d) * r), det, True


@jitable
def _correct(q, K, y, left):
    """``q Exp(K y)`` (left error) or ``Exp(K y) q`` (right)."""
    y0, y1, y2 = y
    k0, k1, k2, k3, k4, k5, k6, k7, k8 = K
    e = quat_exp(k0 * y0 + k1 * y1 + k2 * y2, k3 * y0 + k4 * y1 + k5 * y2, k6 * y0 + k7 * y1 + k8 * y2)
    return quat_mul(q, e) if left else quat_mul(e, q)


@jitable
def _identity_gain(P, r):
    """Gain of an update with ``H = I`` (upper triangles of ``P`` and ``r``): ``S = P + R``, ``K = P S^-1`` and
    ``P <- K R`` (the information form of ``(I - K) P``), as ``(K, P, S, S^-1, det S, ok)``; ``K`` zero if not ok."""
    R = _sym_upper(r)
    S = _add9(_sym_upper(P), R)
    SI, det, ok = _inv_flat(S)
    if not ok:
        return _ZERO9, P, S, SI, det, False
    K = mul_flat(P, SI)
    return K, _sym_upper(mul_flat(K, R)), S, SI, det, True


@jitable
def predict_left(q, P, U, u, Qn):
    """Left-error predict ``x <- x U``, ``P <- U^T P U + Q``: ``U`` a 9-tuple, ``u`` its quaternion."""
    return quat_mul(q, u), congruence(transpose_flat(U), P, Qn)


@jitable
def update_rotation_left(q, P, qz, r):
    """Left-error update with a rotation ``qz`` (quaternion), ``H = I``: ``y = Log(x^T z)`` (``2 atan2(|v|, w) v / |v|``
    of ``conj(q) qz``, accurate up to pi), ``S = P + R``, ``K = P S^-1``, ``q <- q Exp(K y)``, ``P <- K R``."""
    qw, qx, qy, qz_ = q
    zw, zx, zy, zz = qz
    aw, ax, ay, az = (qw * zw + qx * zx + qy * zy + qz_ * zz, qw * zx - qx * zw - qy * zz + qz_ * zy,
                      qw * zy + qx * zz - qy * zw - qz_ * zx, qw * zz - qx * zy + qy * zx - qz_ * zw)
    if aw < 0.0:
        aw, ax, ay, az = -aw, -ax, -ay, -az
    vn = math.sqrt(ax * ax + ay * ay + az * az)
    f = 2.0 * math.atan2(vn, aw) / vn if vn > 0.0 else 2.0
    y = (ax * f, ay * f, az * f)
    K, Pn, S, SI, det, ok = _identity_gain(P, r)
    if not ok:
        return q, P, y, K, S, SI, det, False
    return _correct(q, K, y, True), Pn, y, K, S, SI, det, True


@jitable
def _joseph(P, H, y, Rn):
    """Gain and Joseph-form covariance of a linear update: ``(K, P, S, S^-1, det S, ok)``."""
    PHT = mul_nt_flat(P, H)
    S = _add9(_sym_upper(mul_flat(H, PHT)), _sym_upper(Rn))
    SI, det, ok = _inv_flat(S)
    K = mul_flat(PHT, SI)
    kh = mul_flat(K, H)
    IKH = (1.0 - kh[0], 0.0 - kh[1], 0.0 - kh[2], 0.0 - kh[3], 1.0 - kh[4], 0.0 - kh[5],
           0.0 - kh[6], 0.0 - kh[7], 1.0 - kh[8])
    return K, _add9(congruence(IKH, P, _ZERO9), congruence(K, Rn, _ZERO9)), S, SI, det, ok


@jitable
def update_direction_left(q, P, x, z, b, r):
    """Left-error update with a direction ``z = x b + v`` (world axes, noise ``r`` world, 9-tuple), ``x`` the
    matrix of ``q``: ``y = x^T z - b``, ``H = -[b]x``, noise ``x^T r x``, Joseph form, ``q <- q Exp(K y)``."""
    x0, x1, x2, x3, x4, x5, x6, x7, x8 = x
    z0, z1, z2 = z
    y = (x0 * z0 + x3 * z1 + x6 * z2 - b[0], x1 * z0 + x4 * z1 + x7 * z2 - b[1],
         x2 * z0 + x5 * z1 + x8 * z2 - b[2])
    h = hat_flat(b[0], b[1], b[2])
    H = (-h[0], -h[1], -h[2], -h[3], -h[4], -h[5], -h[6], -h[7], -h[8])
    K, Pn, S, SI, det, ok = _joseph(P, H, y, congruence(transpose_flat(x), r, _ZERO9))
    return _correct(q, K, y, True), Pn, y, K, S, SI, det, ok


@njit
def fill_x(s):
    """Fill the state's cached rotation matrix (row-major at ``B_X``) from its quaternion, unless valid."""
    if s[B_XV] == 0.0:
        _put(s, B_X, flat_from_quat(_get4(s, B_Q)))
        s[B_XV] = 1.0


@njit
def _predict(s, u, kind, qm, own_q):
    """One predict on ``s``: ``kind`` 0 no increment, 9 ``u`` a (3, 3) matrix, 3 a rotation vector (rad);
    ``qm`` (3, 3) the process noise unless ``own_q`` (then the state's)."""
    P, q = _get9(s, B_P), _get4(s, B_Q)
    qn = _get9(s, B_QN) if own_q else _get9(qm.ravel(), 0)
    if kind == 0:
        U, uq = _I9, (1.0, 0.0, 0.0, 0.0)
    else:
        uf = u.ravel()
        U = _get9(uf, 0) if kind == 9 else exp_flat(uf[0], uf[1], uf[2])
        uq = quat_from_flat(U)
        s[B_XV] = 0.0
    if s[B_LEFT] != 0.0:
        q, Pn = predict_left(q, P, U, uq, qn)
    else:                               # P <- P + A Q A^T, A = x U
        q = quat_mul(q, uq)
        _put(s, B_Q, q)
        fill_x(s)                       # (the cache kept for no increment, else that of the new q)
        Pn = congruence(_get9(s, B_X), qn, P)
    _put(s, B_Q, q + Pn)                # (q and P adjacent in the layout, as x_prior and P_prior)
    _put(s, B_XPR, q + Pn)


@jitable
def _update_right(s, n, zf, r):
    """The right-error updates: rotation (``n`` 9, ``H = I``, information form) and direction (``n`` 3)."""
    fill_x(s)
    x, P, q = _get9(s, B_X), _get9(s, B_P), _get4(s, B_Q)
    if n == 9:
        y = log_flat(mul_nt_flat(_get9(zf, 0), x))
        K, Pn, S, SI, det, ok = _identity_gain(P, congruence(x, r, _ZERO9))
    else:
        b0, b1, b2 = s[B_B], s[B_B + 1], s[B_B + 2]
        xb0, xb1, xb2 = (x[0] * b0 + x[1] * b1 + x[2] * b2, x[3] * b0 + x[4] * b1 + x[5] * b2,
                         x[6] * b0 + x[7] * b1 + x[8] * b2)
        y = (zf[0] - xb0, zf[1] - xb1, zf[2] - xb2)
        h = hat_flat(xb0, xb1, xb2)
        K, Pn, S, SI, det, ok = _joseph(P, (-h[0], -h[1], -h[2], -h[3], -h[4], -h[5], -h[6], -h[7], -h[8]), y, r)
    return _correct(q, K, y, False), Pn, y, K, S, SI, det, ok


@njit
def _update(s, z, n, rm, own_r):
    """One update on ``s``: ``n`` 0 none (skip), 9 ``z`` a (3, 3) rotation, 3 a (3,) direction; ``rm`` (3, 3)
    the noise unless ``own_r``. Returns ``(done, det S)``, not done (state unchanged) for a singular ``S``."""
    if n == 0:
        s[B_ZN] = 0.0
        s[B_XPO:B_XPO + 13] = s[B_Q:B_Q + 13]
        _put(s, B_Y, _ZERO3)
        return True, s[B_DET]
    r = _get9(s, B_RN) if own_r else _get9(rm.ravel(), 0)
    zf = z.ravel()
    q, P = _get4(s, B_Q), _get9(s, B_P)
    if s[B_LEFT] == 0.0:
        q, Pn, y, K, S, SI, detS, ok = _update_right(s, n, zf, r)
    elif n == 9:
        q, Pn, y, K, S, SI, detS, ok = update_rotation_left(q, P, quat_from_flat(_get9(zf, 0)), r)
    else:
        fill_x(s)
        q, Pn, y, K, S, SI, detS, ok = update_direction_left(q, P, _get9(s, B_X), (zf[0], zf[1], zf[2]),
                                                             (s[B_B], s[B_B + 1], s[B_B + 2]), r)
    if not ok:
        return False, detS
    m = s[B_NUP] + 1.0
    s[B_NUP] = m
    if m % s[B_RENORM] == 0.0:
        q = quat_normalise(q)
    _put(s, B_Q, q + Pn)
    _put(s, B_XPO, q + Pn)
    s[B_XV] = 0.0
    s[B_Z:B_Z + n] = zf
    s[B_ZN] = float(n)
    _put(s, B_Y, y + K + S + SI)        # (y, K, S, S^-1 adjacent in the layout)
    s[B_DET] = detS
    return True, detS


def _array(a) -> np.ndarray:
    """``a`` as the compiled bodies take it: a C-contiguous float64 array."""
    if type(a) is np.ndarray and a.dtype == _F64 and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, dtype=float)


def _argument(v, error: str) -> tuple[np.ndarray, int]:
    """An increment or measurement as the compiled bodies take it and its kind: 0 (None), 9 ((3, 3)) or 3 ((3,));
    another shape raises ValueError ``error``."""
    if v is None:
        return _NONE, 0
    a = _array(v)
    if a.shape == (3, 3):
        return a, 9
    if a.shape == (3,):
        return a, 3
    raise ValueError(f"{error}, got {a.shape}")


def predict(s: np.ndarray, u, Q: np.ndarray | None) -> None:
    """``InvariantEKF.predict`` on the state ``s``: increment ``u`` (None, (3, 3) or a rotation vector, rad), noise
    ``Q`` ((3, 3); None: the state's). Raises ValueError naming a bad ``u``."""
    a, kind = _argument(u, _BAD_INCREMENT)
    _predict(s, a, kind, _NONE if Q is None else _array(Q), Q is None)


def update(s: np.ndarray, z, R: np.ndarray | None) -> None:
    """``InvariantEKF.update`` on the state ``s``: ``z`` None (skip), a (3, 3) rotation or a (3,) direction; noise
    ``R`` ((3, 3); None: the state's). Raises LinAlgError (singular ``S``, its determinant) or ValueError (a bad
    ``z``), the state unchanged."""
    a, n = _argument(z, "z must be a 3x3 rotation or a unit vector of shape (3,)")
    done, det = _update(s, a, n, _NONE if R is None else _array(R), R is None)
    if not done:
        raise np.linalg.LinAlgError(f"innovation covariance is singular (det = {det})")
