"""Rotations in other forms: increments in any form, heading twist, ZYX Euler angles, quaternions (scalar
first, ``(w, x, y, z)``, ``w >= 0``), cumulative rotations. Frames and signs: the glossary of :mod:`imu_ground.so3`.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from imu_ground.so3.group import exp, exp_one, renormalise

__all__ = ["as_rotations", "twist_angle", "euler_zyx", "quat_from_matrix", "matrix_from_quat",
           "cumulative_rotations", "heading_change"]

_I3 = np.eye(3)


def as_rotations(delta_R, name: str = "delta_R") -> np.ndarray:
    """Rotation matrices from rotation matrices, 4x4 relative poses or rotation vectors (rad).

    Parameters
    ----------
    delta_R : array_like, shape (3, 3), (4, 4), (3,), (N, 3, 3), (N, 4, 4) or (N, 3)
        One increment or a batch; a 4x4 pose's upper-left 3x3 block; a (3, 3) array is one matrix.
    name : str
        Argument name used in the error message.

    Returns
    -------
    ndarray, shape (3, 3) or (N, 3, 3)
        The rotations (a view where no conversion is needed).

    Raises
    ------
    ValueError
        Any other shape.
    """
    d = np.asarray(delta_R, dtype=float)
    if d.ndim in (2, 3) and d.shape[-2:] == (3, 3):        # (3, 3) is one matrix, not three vectors
        return d
    if d.ndim in (2, 3) and d.shape[-2:] == (4, 4):
        return d[..., :3, :3]
    if d.shape == (3,):
        return exp_one(d)
    if d.ndim == 2 and d.shape[1] == 3:
        return exp(d)
    raise ValueError(f"{name} must be a 3x3 rotation, a 4x4 pose or a rotation vector (or a batch of them), "
                     f"got shape {d.shape}")


def twist_angle(d: np.ndarray) -> np.ndarray:
    """Twist about z of rotations ``d`` (..., 3, 3) (swing-twist), rad in (-pi, pi], shape (...).

    ``psi = 2 atan2(q_z, q_w) = atan2(R_10 - R_01, R_00 + R_11)``: the heading change of a body increment.
    """
    return np.arctan2(d[..., 1, 0] - d[..., 0, 1], d[..., 0, 0] + d[..., 1, 1])


def euler_zyx(R: np.ndarray) -> np.ndarray:
    """``(roll, pitch, yaw)`` (..., 3), rad, with ``R = Rz(yaw) Ry(pitch) Rx(roll)``; pitch in [-pi/2, pi/2].

    Parameters
    ----------
    R : ndarray (..., 3, 3)
        Rotations (e.g. world <- body, or ground <- sensor for a mounting).
    """
    R = np.asarray(R, dtype=float)
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    pitch = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 2, 1], R[..., 2, 2]))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    return np.stack([roll, pitch, yaw], axis=-1)


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(w, x, y, z)`` (..., 4), ``w >= 0``, of rotation matrices ``R`` (..., 3, 3) (Shepperd)."""
    R = np.asarray(R, dtype=float)
    m = R.reshape(-1, 3, 3)
    r00, r11, r22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    # 4 q_i^2 for i = w, x, y, z; use the largest for the division (well conditioned)
    sq = np.stack([1.0 + r00 + r11 + r22, 1.0 + r00 - r11 - r22, 1.0 - r00 + r11 - r22, 1.0 - r00 - r11 + r22], 1)
    i = np.argmax(sq, axis=1)
    s = 2.0 * np.sqrt(np.maximum(sq[np.arange(len(m)), i], 1e-300))
    a21, a12 = m[:, 2, 1], m[:, 1, 2]
    a02, a20 = m[:, 0, 2], m[:, 2, 0]
    a10, a01 = m[:, 1, 0], m[:, 0, 1]
    cand = np.stack([np.stack([0.25 * s, (a21 - a12) / s, (a02 - a20) / s, (a10 - a01) / s], 1),
                     np.stack([(a21 - a12) / s, 0.25 * s, (a01 + a10) / s, (a02 + a20) / s], 1),
                     np.stack([(a02 - a20) / s, (a01 + a10) / s, 0.25 * s, (a12 + a21) / s], 1),
                     np.stack([(a10 - a01) / s, (a02 + a20) / s, (a12 + a21) / s, 0.25 * s], 1)], 1)
    q = cand[np.arange(len(m)), i]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1.0
    return q.reshape(R.shape[:-2] + (4,))


def matrix_from_quat(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions ``q`` (..., 4), ``(w, x, y, z)``, normalised first."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    out = np.stack([1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),
                    2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),
                    2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)], axis=-1)
    return out.reshape(q.shape[:-1] + (3, 3))


def cumulative_rotations(d: np.ndarray, R0=None, count: int = 0, *, renorm_every: int) -> np.ndarray:
    """``R_k = R_{k-1} d_k`` (increments in the moving frame), kept on SO(3).

    Parameters
    ----------
    d : ndarray (N, 3, 3)
        Increments ``R_{body_{k-1} <- body_k}``.
    R0 : ndarray (3, 3), optional
        ``R`` before the first increment (world <- body); identity by default.
    count : int
        Products already taken before ``d[0]`` (to continue a sequence).
    renorm_every : int
        Products between re-orthonormalisations (:func:`imu_ground.so3.renormalise`), counted from ``count``.

    Returns
    -------
    ndarray (N, 3, 3)
        World <- body after each increment.
    """
    out = np.empty((len(d), 3, 3))
    R = _I3 if R0 is None else np.asarray(R0, dtype=float)
    for k in range(len(d)):
        R = R @ d[k]
        if (count + k + 1) % renorm_every == 0:
            R = renormalise(R)
        out[k] = R
    return out


def heading_change(d: np.ndarray, Rgs: Optional[np.ndarray] = None) -> float:
    """:func:`twist_angle` (rad, + counter-clockwise seen from above) of one increment, as a float.

    Parameters
    ----------
    d : ndarray (3, 3)
        Increment sensor_{k-1} <- sensor_k.
    Rgs : ndarray (3, 3), optional
        Static rotation ground <- sensor: the increment is taken in the ground frame, ``Rgs d Rgs^T``.
    """
    if Rgs is not None:
        d = Rgs @ d @ Rgs.T
    return math.atan2(d[1, 0] - d[0, 1], d[0, 0] + d[1, 1])
