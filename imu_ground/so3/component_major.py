"""Batches of 3x3 rotations in component-major layout, shared by the batch preintegration and dead reckoning.

Component-major means a batch of 3x3 matrices is stored as an array of shape
``(3, 3, ...)`` (entry ``[i, j]`` first, batch axes after), so that every
elementwise operation runs over long contiguous rows of the batch; a batch of
vectors is ``(3, ...)``. Rotation conventions are those of :mod:`imu_ground.so3`
(its glossary): ``R_{a<-b}`` maps vectors from frame b into frame a.
"""
from __future__ import annotations

import numpy as np

from imu_ground.so3.group import project

__all__ = [
    "PROJECTION_TOL",
    "SMALL_ANGLE2",
    "cross_rows",
    "exp_and_left_jacobian",
    "hat_times",
    "mm",
    "project_if_needed",
    "scan_products",
]

#: theta^2 (rad^2) below which the Taylor series of the SO(3) coefficients are used
#: (theta < :data:`~imu_ground.so3.group.SMALL_ANGLE`, where they are exact to double precision).
SMALL_ANGLE2 = 1e-8
#: A rotation whose orthonormality defect ``max |R^T R - I|`` exceeds this is projected onto SO(3).
PROJECTION_TOL = 1e-12


def mm(A: np.ndarray, B: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Matrix product of component-major 3x3 batches, shapes (3, 3, ...) (broadcast over the batch)."""
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


def scan_products(M: np.ndarray) -> np.ndarray:
    """Inclusive product scan along axis 2 of component-major matrices (3, 3, L, B).

    ``out[:, :, k] = M[:, :, 0] @ M[:, :, 1] @ ... @ M[:, :, k]`` by Hillis-Steele
    doubling: ceil(log2 L) rounds of batched 3x3 products.
    """
    P = M.copy()
    n = P.shape[2]
    d = 1
    while d < n:
        Q = P.copy()
        mm(P[:, :, :-d], P[:, :, d:], out=Q[:, :, d:])
        P = Q
        d *= 2
    return P


def cross_rows(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Component-major ``M @ hat(x)``: row i of the result is ``M[i] x x`` (cross product)."""
    out = np.empty(np.broadcast_shapes(M.shape, (3, 3) + x.shape[1:]))
    x0, x1, x2 = x[0], x[1], x[2]
    for i in range(3):
        m0, m1, m2 = M[i, 0], M[i, 1], M[i, 2]
        out[i, 0] = m1 * x2 - m2 * x1
        out[i, 1] = m2 * x0 - m0 * x2
        out[i, 2] = m0 * x1 - m1 * x0
    return out


def hat_times(x: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Component-major ``hat(x) @ M``: column j of the result is ``x x M[:, j]``."""
    out = np.empty(np.broadcast_shapes(M.shape, (3, 3) + x.shape[1:]))
    x0, x1, x2 = x[0], x[1], x[2]
    for j in range(3):
        m0, m1, m2 = M[0, j], M[1, j], M[2, j]
        out[0, j] = x1 * m2 - x2 * m1
        out[1, j] = x2 * m0 - x0 * m2
        out[2, j] = x0 * m1 - x1 * m0
    return out


def exp_and_left_jacobian(x: np.ndarray, y: np.ndarray, z: np.ndarray,
                          jacobian: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """``Exp(phi)`` and ``J_l(phi)`` of rotation vectors given as component arrays (fused).

    The same formulas as :func:`imu_ground.so3.exp` and :func:`imu_ground.so3.left_jacobian`
    (``I + a K + b K^2`` and ``I + b K + c K^2``, ``K = hat(phi)``), evaluated once
    for both and written straight into the component-major layout the batch
    kernel works in.

    Parameters
    ----------
    x, y, z : ndarray, shape S
        Components of ``phi``, rad.
    jacobian : bool
        Also compute ``J_l`` (False: ``Jl`` is None and its coefficient is skipped).

    Returns
    -------
    E, Jl : ndarray, shape (3, 3) + S (``Jl`` None without ``jacobian``)
    """
    xx, yy, zz = x * x, y * y, z * z
    t2 = xx + yy + zz
    small = t2 < SMALL_ANGLE2
    any_small = bool(small.any())
    ts2 = np.where(small, 1.0, t2) if any_small else t2
    th = np.sqrt(ts2)
    sn = np.sin(th)
    hs = np.sin(0.5 * th)
    A = sn / th
    B = 2.0 * hs * hs / ts2
    C = (th - sn) / (ts2 * th) if jacobian else None
    if any_small:
        t2s = t2[small]
        tts = t2s * t2s
        A[small] = 1.0 - t2s / 6.0 + tts / 120.0
        B[small] = 0.5 - t2s / 24.0 + tts / 720.0
        if C is not None:
            C[small] = 1.0 / 6.0 - t2s / 120.0 + tts / 5040.0
    xy, xz, yz = x * y, x * z, y * z
    out = []
    for a, b in ((A, B), (B, C))[:2 if jacobian else 1]:   # Exp: I + A K + B K^2; Jl: I + B K + C K^2
        M = np.empty((3, 3) + x.shape)
        M[0, 0] = 1.0 - b * (yy + zz)
        M[1, 1] = 1.0 - b * (xx + zz)
        M[2, 2] = 1.0 - b * (xx + yy)
        bxy, bxz, byz = b * xy, b * xz, b * yz
        ax, ay, az = a * x, a * y, a * z
        M[0, 1] = bxy - az
        M[1, 0] = bxy + az
        M[0, 2] = bxz + ay
        M[2, 0] = bxz - ay
        M[1, 2] = byz - ax
        M[2, 1] = byz + ax
        out.append(M)
    return out[0], (out[1] if jacobian else None)


def project_if_needed(R: np.ndarray) -> np.ndarray:
    """Project onto SO(3) the rotations whose orthonormality defect exceeds :data:`PROJECTION_TOL`.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R`` itself where it is orthonormal to ``PROJECTION_TOL`` (rounding of long
        products), :func:`imu_ground.so3.project` of it elsewhere.
    """
    R = np.asarray(R, dtype=float)
    E = np.swapaxes(R, -1, -2) @ R - np.eye(3)
    bad = np.max(np.abs(E), axis=(-2, -1)) > PROJECTION_TOL
    if np.any(bad):
        R = R.copy()
        R[bad] = project(R[bad])
    return R
