"""SO(3) itself: hat/vee, exp/log and their Jacobians, projections, axis rotations, and the scalar kernels.

Every function takes one element or a batch (rotation vectors ``(..., 3)`` in rad, matrices ``(..., 3, 3)``) and
returns the same leading shape without a Python loop (except :func:`log`'s rotations near pi, which go through
:func:`log_flat`, one body for that branch). ``*_one``: the same formulas for one element; ``*_flat``: the
scalar kernels of the streaming filters (a 3x3 matrix as a row-major 9-tuple, a vector as 3 floats). The logarithm
is accurate over the whole range (Taylor series near 0, the symmetric part of ``R`` near pi). Conventions: the
glossary of :mod:`imu_ground.so3`.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["hat", "vee", "exp", "log", "right_jacobian", "left_jacobian", "right_jacobian_inv", "left_jacobian_inv",
           "project", "angle", "rotx", "roty", "rotz", "renormalise", "exp_one", "log_one", "exp_flat", "log_flat",
           "mul_flat", "mul_nt_flat", "transpose_flat", "renormalise_flat", "quat_from_flat", "flat_from_quat",
           "quat_mul", "quat_exp", "quat_normalise", "hat_flat", "SMALL_ANGLE"]

#: Below this angle (rad) the Taylor series are exact to double precision.
SMALL_ANGLE = 1e-4


def hat(phi: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix of a vector: ``hat(a) @ b == cross(a, b)``.

    Parameters
    ----------
    phi : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    phi = np.asarray(phi, dtype=float)
    out = np.zeros(phi.shape[:-1] + (3, 3))
    x, y, z = phi[..., 0], phi[..., 1], phi[..., 2]
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -z, y, -x
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = z, -y, x
    return out


def vee(m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hat`: ``0.5 * [m21 - m12, m02 - m20, m10 - m01]``, shape (..., 3).

    Parameters
    ----------
    m : array_like, shape (..., 3, 3)
        Any square matrices; the symmetric part is ignored.
    """
    m = np.asarray(m, dtype=float)
    return 0.5 * np.stack([m[..., 2, 1] - m[..., 1, 2],
                           m[..., 0, 2] - m[..., 2, 0],
                           m[..., 1, 0] - m[..., 0, 1]], axis=-1)


def _coefficients(theta: np.ndarray):
    """a = sin(t)/t, b = (1-cos t)/t^2, c = (t - sin t)/t^3, safe at 0."""
    small = theta < SMALL_ANGLE
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    a = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(t) / t)
    b = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - np.cos(t)) / (t * t))
    c = np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (t - np.sin(t)) / (t * t * t))
    return a, b, c


def exp(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues): ``I + sin(t)/t K + (1 - cos t)/t^2 K^2``, ``K = hat(phi)``.

    Parameters
    ----------
    phi : array_like, shape (..., 3)
        Rotation vector, rad (axis times angle ``t = |phi|``).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    phi = np.asarray(phi, dtype=float)
    theta = np.linalg.norm(phi, axis=-1)
    a, b, _ = _coefficients(theta)
    k = hat(phi)
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def log(r: np.ndarray) -> np.ndarray:
    """Rotation vector (rad) of a rotation matrix, angle in [0, pi] (at exactly pi the axis sign is arbitrary).

    Parameters
    ----------
    r : array_like, shape (..., 3, 3)
        Rotation matrices.

    Returns
    -------
    ndarray, shape (..., 3)
        ``phi`` with ``exp(phi) == r``.
    """
    r = np.asarray(r, dtype=float)
    w = vee(r)                                  # sin(t) * axis
    s = np.linalg.norm(w, axis=-1)              # sin(t) >= 0
    c = 0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1.0)
    theta = np.arctan2(s, np.clip(c, -1.0, 1.0))
    a, _, _ = _coefficients(theta)              # sin(t)/t, Taylor near 0
    phi = w / np.where(a > 0, a, 1.0)[..., None]
    near_pi = c < -0.9
    if np.any(near_pi):                         # the axis from the symmetric part: :func:`log_flat`'s branch
        phi[near_pi] = [log_flat(m) for m in r[near_pi].reshape(-1, 9).tolist()]
    return phi


def right_jacobian(phi: np.ndarray) -> np.ndarray:
    """Right Jacobian ``I - (1 - cos t)/t^2 K + (t - sin t)/t^3 K^2``: ``exp(phi + d) ~= exp(phi) exp(J_r d)``.

    Parameters
    ----------
    phi : array_like, shape (..., 3)
        Rotation vectors, rad.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    phi = np.asarray(phi, dtype=float)
    _, b, c = _coefficients(np.linalg.norm(phi, axis=-1))
    k = hat(phi)
    return np.eye(3) - b[..., None, None] * k + c[..., None, None] * (k @ k)


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """Left Jacobian ``J_l(phi) = J_r(-phi)``: ``exp(phi + d) ~= exp(J_l d) exp(phi)``; as :func:`right_jacobian`."""
    return right_jacobian(-np.asarray(phi, dtype=float))


def _inv_coefficient(theta: np.ndarray) -> np.ndarray:
    """``1/t^2 - (1 + cos t) / (2 t sin t)``, safe at 0 (-> 1/12)."""
    small = theta < 1e-3
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    with np.errstate(divide="ignore", invalid="ignore"):
        d = 1.0 / (t * t) - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t))
    return np.where(small, 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0, d)


def right_jacobian_inv(phi: np.ndarray) -> np.ndarray:
    """Inverse of :func:`right_jacobian`: ``I + K/2 + (1/t^2 - (1+cos t)/(2 t sin t)) K^2``.

    Parameters
    ----------
    phi : array_like, shape (..., 3)
        Rotation vectors, rad, angle at most pi (singular at 2 pi).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    phi = np.asarray(phi, dtype=float)
    d = _inv_coefficient(np.linalg.norm(phi, axis=-1))
    k = hat(phi)
    return np.eye(3) + 0.5 * k + d[..., None, None] * (k @ k)


def left_jacobian_inv(phi: np.ndarray) -> np.ndarray:
    """Inverse of :func:`left_jacobian`, ``J_r^{-1}(-phi)``; shapes as :func:`right_jacobian_inv`."""
    return right_jacobian_inv(-np.asarray(phi, dtype=float))


def project(m: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix in the Frobenius norm (SVD, det forced to +1), shape (..., 3, 3).

    Parameters
    ----------
    m : array_like, shape (..., 3, 3)
        Non-singular matrices, near SO(3) or not.
    """
    m = np.asarray(m, dtype=float)
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt))
    d = np.where(d == 0, 1.0, d)
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


def angle(r: np.ndarray) -> np.ndarray:
    """Rotation angle of ``r`` (..., 3, 3) in rad, in [0, pi], accurate at 0 and pi."""
    return np.linalg.norm(log(r), axis=-1)


def _axis_rotation(angle_rad, i: int, j: int) -> np.ndarray:
    a = np.asarray(angle_rad, dtype=float)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    k = 3 - i - j
    out[..., k, k] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rotx(a) -> np.ndarray:
    """Rotation about x by ``a`` rad (right-handed), shape ``a.shape + (3, 3)``."""
    return _axis_rotation(a, 1, 2)


def roty(a) -> np.ndarray:
    """Rotation about y by ``a`` rad (right-handed), shape ``a.shape + (3, 3)``."""
    return _axis_rotation(a, 2, 0)


def rotz(a) -> np.ndarray:
    """Rotation about z by ``a`` rad (right-handed), shape ``a.shape + (3, 3)``."""
    return _axis_rotation(a, 0, 1)


def renormalise(r: np.ndarray) -> np.ndarray:
    """One Newton step towards the nearest rotation, ``R (3 I - R^T R) / 2`` (error ``e`` -> ``e^2``).

    Parameters
    ----------
    r : array_like, shape (..., 3, 3)
        Nearly orthonormal matrices (:func:`project` for matrices far from SO(3)).

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    r = np.asarray(r, dtype=float)
    return r @ (1.5 * np.eye(3) - 0.5 * (np.swapaxes(r, -1, -2) @ r))


# -- the scalar kernels: the formulas and branches above on floats (a 3x3 matrix: row-major 9 floats) -----
def exp_flat(x: float, y: float, z: float) -> tuple:
    """:func:`exp` of the rotation vector ``(x, y, z)`` (rad) as a row-major 9-tuple (NaN: angle not finite)."""
    t2 = x * x + y * y + z * z
    if not math.isfinite(t2):           # an infinite angle (or one whose square overflows) has no rotation
        return (math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan)
    if t2 < SMALL_ANGLE * SMALL_ANGLE:
        a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        b = 0.5 - t2 / 24.0 + t2 * t2 / 720.0
    else:
        t = math.sqrt(t2)
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / t2
    bxy, bxz, byz = b * x * y, b * x * z, b * y * z
    ax, ay, az = a * x, a * y, a * z
    return (1.0 - b * (y * y + z * z), bxy - az, bxz + ay,
            bxy + az, 1.0 - b * (x * x + z * z), byz - ax,
            bxz - ay, byz + ax, 1.0 - b * (x * x + y * y))


def log_flat(r) -> tuple:
    """:func:`log` of one rotation given as a row-major sequence of 9 floats; returns ``(x, y, z)``, rad."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = r
    wx, wy, wz = 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)
    c = 0.5 * (r00 + r11 + r22 - 1.0)
    c = 1.0 if c > 1.0 else (-1.0 if c < -1.0 else c)
    s = math.sqrt(wx * wx + wy * wy + wz * wz)
    theta = math.atan2(s, c)
    if c >= -0.9:
        if theta < SMALL_ANGLE:
            t2 = theta * theta
            a = 1.0 - t2 / 6.0 + t2 * t2 / 120.0
        else:
            a = math.sin(theta) / theta
        return wx / a, wy / a, wz / a
    # near pi: (R + R^T)/2 = cos(t) I + (1 - cos t) u u^T, axis from its largest column
    d = 1.0 - c
    cols = (((r00 - c) / d, 0.5 * (r10 + r01) / d, 0.5 * (r20 + r02) / d),
            (0.5 * (r01 + r10) / d, (r11 - c) / d, 0.5 * (r21 + r12) / d),
            (0.5 * (r02 + r20) / d, 0.5 * (r12 + r21) / d, (r22 - c) / d))
    j = 1 if cols[1][1] > cols[0][0] else 0                     # the largest diagonal entry (the first of ties)
    j = 2 if cols[2][2] > cols[j][j] else j
    ux, uy, uz = cols[j]
    n = math.sqrt(ux * ux + uy * uy + uz * uz)
    sign = -1.0 if (ux * wx + uy * wy + uz * wz) < 0 else 1.0
    f = sign * theta / n
    return f * ux, f * uy, f * uz


def mul_flat(a, b) -> tuple:
    """``A @ B`` of two row-major 9-sequences (unrolled: 27 products)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


def transpose_flat(a) -> tuple:
    """``A^T`` of a row-major 9-sequence."""
    return a[0], a[3], a[6], a[1], a[4], a[7], a[2], a[5], a[8]


def mul_nt_flat(a, b) -> tuple:
    """``A @ B^T`` of two row-major 9-sequences."""
    return mul_flat(a, transpose_flat(b))


def renormalise_flat(r) -> tuple:
    """:func:`renormalise` of one row-major 9-sequence: ``R (3 I - R^T R) / 2``."""
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = r
    # M = 1.5 I - 0.5 R^T R (symmetric)
    m00 = 1.5 - 0.5 * (r0 * r0 + r3 * r3 + r6 * r6)
    m11 = 1.5 - 0.5 * (r1 * r1 + r4 * r4 + r7 * r7)
    m22 = 1.5 - 0.5 * (r2 * r2 + r5 * r5 + r8 * r8)
    m01 = -0.5 * (r0 * r1 + r3 * r4 + r6 * r7)
    m02 = -0.5 * (r0 * r2 + r3 * r5 + r6 * r8)
    m12 = -0.5 * (r1 * r2 + r4 * r5 + r7 * r8)
    return mul_flat(r, (m00, m01, m02, m01, m11, m12, m02, m12, m22))


def quat_from_flat(r) -> tuple:
    """Unit quaternion ``(w, x, y, z)``, ``w >= 0``, of a row-major 9-sequence (Shepperd's method, exact at pi)."""
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = r
    t = r0 + r4 + r8
    if t > 0.0:
        s = 2.0 * math.sqrt(t + 1.0)
        si = 1.0 / s
        return 0.25 * s, (r7 - r5) * si, (r2 - r6) * si, (r3 - r1) * si
    if r0 >= r4 and r0 >= r8:
        s = 2.0 * math.sqrt(1.0 + r0 - r4 - r8)
        q = (r7 - r5) / s, 0.25 * s, (r1 + r3) / s, (r2 + r6) / s
    elif r4 >= r8:
        s = 2.0 * math.sqrt(1.0 + r4 - r0 - r8)
        q = (r2 - r6) / s, (r1 + r3) / s, 0.25 * s, (r5 + r7) / s
    else:
        s = 2.0 * math.sqrt(1.0 + r8 - r0 - r4)
        q = (r3 - r1) / s, (r2 + r6) / s, (r5 + r7) / s, 0.25 * s
    return q if q[0] >= 0.0 else (-q[0], -q[1], -q[2], -q[3])


def flat_from_quat(q) -> tuple:
    """Row-major 9-tuple of the rotation of a unit quaternion ``(w, x, y, z)``."""
    w, x, y, z = q
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x, y * y, z * z, x * y, x * z, y * z, w * x, w * y, w * z
    return (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),
            2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),
            2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy))


def quat_mul(a, b) -> tuple:
    """Hamilton product ``a b`` of two quaternions ``(w, x, y, z)`` (the rotation ``R(a) @ R(b)``)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def quat_exp(x: float, y: float, z: float) -> tuple:
    """Unit quaternion ``(w, x, y, z)`` of the rotation vector ``(x, y, z)`` (rad)."""
    t = math.sqrt(x * x + y * y + z * z)
    h = 0.5 - t * t / 48.0 if t < SMALL_ANGLE else math.sin(0.5 * t) / t
    return math.cos(0.5 * t), h * x, h * y, h * z


def quat_normalise(q) -> tuple:
    """``q / |q|``: a quaternion back to unit norm against rounding drift."""
    w, x, y, z = q
    n = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    return w * n, x * n, y * n, z * n


def hat_flat(x: float, y: float, z: float) -> tuple:
    """:func:`hat` of ``(x, y, z)`` as a row-major 9-tuple."""
    return 0.0, -z, y, z, 0.0, -x, -y, x, 0.0


def exp_one(phi) -> np.ndarray:
    """:func:`exp` of one rotation vector (3,) as a 3x3 array, fast scalar path."""
    return np.array(exp_flat(float(phi[0]), float(phi[1]), float(phi[2]))).reshape(3, 3)


def log_one(r) -> np.ndarray:
    """:func:`log` of one 3x3 rotation as a (3,) array, fast scalar path."""
    flat = np.ravel(r).tolist() if hasattr(r, "shape") else [v for row in r for v in row]
    return np.array(log_flat(flat))
