r"""Exact kinematics of the simulated sensor: attitude, angular rate, specific force, position.

Frames and signs: :mod:`imu_ground.evaluation.simulate`; ``R_wb = Rz Ry Rx Ry Rx`` of ``(heading, -grade,
bank, pitch, roll)``, its rates through the kinematic chain (:func:`chain`).
"""
from __future__ import annotations

import math

import numpy as np

from imu_ground.so3 import rotx, roty, rotz
from imu_ground.units import GRAVITY

__all__ = ["G_W", "chain", "quat_wxyz", "road_positions", "sensor_kinematics"]

#: Gravity in the world frame (z up), m/s^2.
G_W = np.array([0.0, 0.0, -GRAVITY])
_AXES = {"x": rotx, "y": roty, "z": rotz}
_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}
_EZ = np.array([0.0, 0.0, 1.0])


def chain(axes: str, q, qd, qdd):
    """Rotation ``R = R_1(q_1) ... R_n(q_n)`` with its body-frame angular velocity and acceleration.

    ``w = sum_i u_i q_i'`` with ``u_i = (R_{i+1} ... R_n)^T a_i``, and
    ``w' = sum_i u_i q_i'' + sum_i q_i' u_i x w_(i)`` with ``w_(i) = sum_{j > i} u_j q_j'``.

    Parameters
    ----------
    axes : str
        One of ``x``, ``y``, ``z`` per elementary rotation, outermost first.
    q, qd, qdd : sequence of ndarray (N,)
        Angles (rad) and their first and second time derivatives.

    Returns
    -------
    R, w, wd : ndarray (N, 3, 3), (N, 3), (N, 3)
        The rotation, its angular velocity (rad/s) and acceleration (rad/s^2) in the rotated frame.
    """
    n = q[0].shape[0]
    c = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    w = np.zeros((n, 3))
    wd = np.zeros((n, 3))
    for ax, qi, qdi, qddi in reversed(list(zip(axes, q, qd, qdd, strict=True))):
        ui = c[:, _AXIS_INDEX[ax], :]                 # (C^T a)_k = C[a, k]
        wd += ui * qddi[:, None] + qdi[:, None] * np.cross(ui, w)
        w += ui * qdi[:, None]
        c = _AXES[ax](qi) @ c
    return c, w, wd


def quat_wxyz(r: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(w, x, y, z)`` with ``w >= 0`` of rotation matrices (N, 3, 3)."""
    from scipy.spatial.transform import Rotation
    q = Rotation.from_matrix(r).as_quat()            # x, y, z, w
    q = q[:, [3, 0, 1, 2]]
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


def sensor_kinematics(a, v, s, layout, body, R_gs, t_gs):
    """Exact attitude, angular rate, specific force and velocity of the sensor.

    Parameters
    ----------
    a, v, s : ndarray (N,)
        Longitudinal acceleration (m/s^2), speed (m/s), distance (m) at the IMU samples.
    layout, body
        Road profiles ``(curvature, grade, bank)`` along s; ``(pitch, roll, heave)``, each
        ``(value, rate, acceleration)`` at the samples (rad or m).
    R_gs, t_gs : ndarray
        Body <- sensor rotation (3, 3) and sensor origin in the body frame (3,), m.

    Returns
    -------
    dict
        ``R_wb``, ``R_ws``, ``R_wr`` (N, 3, 3); ``gyro`` (rad/s), ``accel`` (specific force, m/s^2), sensor
        frame; ``v_ws`` (world, m/s); ``curvature``, ``heading``, ``grade``, ``bank``, ``acc_lat`` (N,).
    """
    kappa_pw, grade_pw, bank_pw = layout
    (th, th_d1, th_d2), (ph, ph_d1, ph_d2), (_, zh_d1, zh_d2) = body
    kap, kap_s, _, psi, _ = kappa_pw(s)
    al, al_s, al_ss, _, _ = grade_pw(s)
    bk, bk_s, bk_ss, _, _ = bank_pw(s)
    v2 = v * v
    q = [psi, -al, bk, th, ph]
    qd = [kap * v, -al_s * v, bk_s * v, th_d1, ph_d1]
    qdd = [kap_s * v2 + kap * a, -(al_ss * v2 + al_s * a), bk_ss * v2 + bk_s * a, th_d2, ph_d2]
    r_wb, w_b, wd_b = chain("zyxyx", q, qd, qdd)
    r_ws = r_wb @ R_gs
    r_wr = chain("zyx", q[:3], qd[:3], qdd[:3])[0]

    ca, sa, cp, sp = np.cos(al), np.sin(al), np.cos(psi), np.sin(psi)
    x_r = np.stack([ca * cp, ca * sp, sa], axis=1)
    ald, psd = al_s * v, kap * v
    xd_r = np.stack([-sa * ald * cp - ca * sp * psd, -sa * ald * sp + ca * cp * psd, ca * ald], axis=1)
    lever_b = np.broadcast_to(t_gs, w_b.shape)
    w_x_t = np.cross(w_b, lever_b)
    acc_w = (a[:, None] * x_r + v[:, None] * xd_r + zh_d2[:, None] * _EZ
             + np.einsum("nij,nj->ni", r_wb, np.cross(wd_b, lever_b) + np.cross(w_b, w_x_t)))
    vel_w = v[:, None] * x_r + zh_d1[:, None] * _EZ + np.einsum("nij,nj->ni", r_wb, w_x_t)
    f_s = np.einsum("nji,nj->ni", r_ws, acc_w - G_W)
    w_s = w_b @ R_gs
    w_rz = -np.sin(bk) * qd[1] + np.cos(bk) * np.cos(q[1]) * qd[0]
    return dict(R_wb=r_wb, R_ws=r_ws, R_wr=r_wr, gyro=w_s, accel=f_s, v_ws=vel_w,
                curvature=kap, heading=psi, grade=al, bank=bk, acc_lat=v * w_rz)


def road_positions(t_imu, dt: float, motion, layout) -> np.ndarray:
    """Road-point positions (m, world frame, from the origin at t = 0) at the IMU samples (3-node Gauss-Legendre).

    Parameters
    ----------
    t_imu : ndarray (N,)
        Sample times, s, spaced ``dt``.
    motion : callable
        ``t -> (acceleration, speed, distance)``.
    layout : (curvature, grade, bank)
    """
    kappa_pw, grade_pw, _ = layout
    gl = 0.5 * np.array([1.0 - math.sqrt(0.6), 1.0, 1.0 + math.sqrt(0.6)])
    glw = np.array([5.0, 8.0, 5.0]) / 18.0
    tn = (t_imu[:-1, None] + dt * gl[None, :]).ravel()
    _, vn, sn = motion(tn)
    psi_n = kappa_pw(sn)[3]
    al_n = grade_pw(sn)[0]
    vel_n = vn[:, None] * np.stack([np.cos(al_n) * np.cos(psi_n), np.cos(al_n) * np.sin(psi_n),
                                   np.sin(al_n)], axis=1)
    steps = dt * np.einsum("k,nkj->nj", glw, vel_n.reshape(-1, 3, 3))
    return np.vstack([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
