"""Gravity and velocity from an IMU alone, with vehicle constraints: a linear Kalman filter on frames.

Frames and signs follow the glossary of :mod:`imu_ground.so3`: world ``w`` is the
gyro-integrated body frame at the start (``R0 = R_{w<-body_0}``), body ``b`` FLU
(x forward, y left, z up), gravity stored as its reaction (+9.81 m/s^2 up at rest).

One scalar kernel (:func:`_predict_update`, unrolled arithmetic on the 21 unique
covariance entries) serves :meth:`GravityVelocityFilter.step` and ``run``, so the
two cannot drift; the forces are scalar in ``step``, vectorised in ``run``.
"""
from __future__ import annotations

import math
from array import array
from dataclasses import dataclass
from math import isnan
from types import SimpleNamespace
from typing import NamedTuple, Optional, Sequence, Union

import numpy as np

from imu_ground import so3
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.rotations import as_rotations
from imu_ground.imu.data import ImuData
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion
from imu_ground.so3 import exp_flat, log_flat, mul_flat, mul_nt_flat, renormalise_flat
from imu_ground.units import RENORM_EVERY

__all__ = ["GravityEstimate", "GravityTrack", "GravityVelocityFilter", "egomotion_arrays"]

_I3 = np.eye(3)
#: (row, column) of P's 21 unique entries: cov(v) upper triangle, cov(v, g) row-major, cov(g) upper triangle.
_UPPER21 = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2),
            (0, 3), (0, 4), (0, 5), (1, 3), (1, 4), (1, 5), (2, 3), (2, 4), (2, 5),
            (3, 3), (3, 4), (3, 5), (4, 4), (4, 5), (5, 5))
_FULL_INDEX = np.empty((6, 6), dtype=int)
for _m, (_i, _j) in enumerate(_UPPER21):
    _FULL_INDEX[_i, _j] = _FULL_INDEX[_j, _i] = _m


def _full_cov(p21: np.ndarray) -> np.ndarray:
    """(..., 21) unique entries -> (..., 6, 6) symmetric covariances."""
    return np.asarray(p21)[..., _FULL_INDEX]


def egomotion_arrays(ego: Union[EgoMotion, ImuData]):
    """``(delta_R, delta_v, delta_t, stationary, valid)`` of an EgoMotion (an ImuData is preintegrated).

    Raises
    ------
    TypeError, ValueError
        Not an EgoMotion; inconsistent shapes; non-finite increments or non-positive durations.
    """
    if isinstance(ego, ImuData):
        ego = imu_to_egomotion(ego)
    if not isinstance(ego, EgoMotion):
        raise TypeError(f"expected an EgoMotion (or ImuData), got {type(ego).__name__}")
    d, dv, dt = (np.asarray(a, dtype=float) for a in (ego.delta_R, ego.delta_v, ego.delta_t))
    st, valid = (np.asarray(a, dtype=bool) for a in (ego.stationary, ego.valid))
    n = len(d)
    if d.shape != (n, 3, 3) or dv.shape != (n, 3) or dt.shape != (n,) or st.shape != (n,) or valid.shape != (n,):
        raise ValueError("EgoMotion arrays have inconsistent shapes")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(dv)) and np.all(dt > 0)):
        raise ValueError("EgoMotion has non-finite increments or non-positive frame durations")
    return d, dv, dt, st, valid


def _predict_update(s, frames, prm, out=None, priors=None):
    """The filter's recursion over frames: one kernel for :meth:`GravityVelocityFilter.step` and ``run``.

    Unrolled scalar arithmetic on the state list ``s`` (velocity, gravity, the 21
    unique entries of P in ``_UPPER21`` order, ``R_{w<-body_k}`` as 9 floats
    row-major, the frame count), updated in place. ``frames``: ``(d9, dv3, dt,
    stationary, valid, speed)`` per frame, body frame (``speed`` NaN: none). ``prm``: ``(q_v^2,
    q_gap^2, q_g^2, sigma_zupt^2, sigma_nhc^2, zupt_gate, sigma_speed^2, initialised)``. Per frame: the
    cumulative attitude (renormalised every ``RENORM_EVERY`` frames), the
    predict ``v += R_{k-1} dv - dt g``, ``P <- F P F^T + Q`` (written out for
    ``F = [[I, -dt I], [0, I]]`` and isotropic ``Q``), then the update with the
    body velocity (:func:`_velocity_update`): a measured forward ``speed`` as ``R_k^T v = (speed, 0,
    0)``, else the gated zero-velocity update, else the non-holonomic constraint on the body y and z
    axes, ``P <- P - K S K^T``. ``out`` (``array('d')``) receives the posterior state and ``R_k`` (36
    floats a frame), ``priors`` the prior state (27). Returns the last frame's ``(kind, K, y, S, dt,
    qv, qg, prior)`` (kind 0 constraint, 1 ZUPT, 2 speed), the rejected standstill flags, g set.
    """
    (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12, b20, b21, b22,
     c00, c01, c02, c11, c12, c22, r0, r1, r2, r3, r4, r5, r6, r7, r8, count) = s
    qv2, qgap2, qg2, rz, rn, gate, rs, initialised = prm
    nz = (rz, 0.0, 0.0, rz, 0.0, rz)
    rejected, last = 0, None
    for (d0, d1, d2, d3, d4, d5, d6, d7, d8), (dv0, dv1, dv2), dt, stationary, valid, speed in frames:
        p0, p1, p2, p3, p4, p5, p6, p7, p8 = r0, r1, r2, r3, r4, r5, r6, r7, r8
        count += 1
        r0, r1, r2 = p0 * d0 + p1 * d3 + p2 * d6, p0 * d1 + p1 * d4 + p2 * d7, p0 * d2 + p1 * d5 + p2 * d8
        r3, r4, r5 = p3 * d0 + p4 * d3 + p5 * d6, p3 * d1 + p4 * d4 + p5 * d7, p3 * d2 + p4 * d5 + p5 * d8
        r6, r7, r8 = p6 * d0 + p7 * d3 + p8 * d6, p6 * d1 + p7 * d4 + p8 * d7, p6 * d2 + p7 * d5 + p8 * d8
        if count % RENORM_EVERY == 0:
            r0, r1, r2, r3, r4, r5, r6, r7, r8 = renormalise_flat((r0, r1, r2, r3, r4, r5, r6, r7, r8))
        w0, w1, w2 = p0 * dv0 + p1 * dv1 + p2 * dv2, p3 * dv0 + p4 * dv1 + p5 * dv2, p6 * dv0 + p7 * dv1 + p8 * dv2
        if not initialised:                         # gravity from the first frame's mean specific force
            g0, g1, g2 = w0 / dt, w1 / dt, w2 / dt
            initialised = True
        v0, v1, v2 = v0 + w0 - dt * g0, v1 + w1 - dt * g1, v2 + w2 - dt * g2
        qv = (qv2 if valid else qv2 + qgap2) * dt
        qg = qg2 * dt
        a00, a11, a22 = (a00 - dt * (2.0 * b00 - dt * c00) + qv, a11 - dt * (2.0 * b11 - dt * c11) + qv,
                         a22 - dt * (2.0 * b22 - dt * c22) + qv)
        a01, a02, a12 = a01 - dt * (b01 + b10 - dt * c01), a02 - dt * (b02 + b20 - dt * c02), \
            a12 - dt * (b12 + b21 - dt * c12)
        b00, b01, b02 = b00 - dt * c00, b01 - dt * c01, b02 - dt * c02
        b10, b11, b12 = b10 - dt * c01, b11 - dt * c11, b12 - dt * c12
        b20, b21, b22 = b20 - dt * c02, b21 - dt * c12, b22 - dt * c22
        c00, c11, c22 = c00 + qg, c11 + qg, c22 + qg
        prior = (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12,
                 b20, b21, b22, c00, c01, c02, c11, c12, c22)
        if priors is not None:
            priors.extend(prior)
        zupt = 0
        if not isnan(speed):                        # measured forward speed along the body x axis (r0, r3, r6)
            ds = rs - rn
            st = _velocity_update(prior, (rn + ds * r0 * r0, ds * r0 * r3, ds * r0 * r6, rn + ds * r3 * r3,
                                          ds * r3 * r6, rn + ds * r6 * r6), (speed * r0, speed * r3, speed * r6))
            zupt = 2
        elif stationary:
            st = _velocity_update(prior, nz, (0.0, 0.0, 0.0), gate)
            if st is None:
                rejected += 1                       # a smooth cruise flagged as standstill: constraint instead
            else:
                zupt = 1
        if zupt:
            ((v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12,
                  b20, b21, b22, c00, c01, c02, c11, c12, c22), K, y, S) = st
        if not zupt:
            # non-holonomic constraint: body y and z velocity, h = columns 1 and 2 of R_k
            uy0, uy1, uy2 = a00 * r1 + a01 * r4 + a02 * r7, a01 * r1 + a11 * r4 + a12 * r7, \
                a02 * r1 + a12 * r4 + a22 * r7
            uy3, uy4, uy5 = b00 * r1 + b10 * r4 + b20 * r7, b01 * r1 + b11 * r4 + b21 * r7, \
                b02 * r1 + b12 * r4 + b22 * r7
            uz0, uz1, uz2 = a00 * r2 + a01 * r5 + a02 * r8, a01 * r2 + a11 * r5 + a12 * r8, \
                a02 * r2 + a12 * r5 + a22 * r8
            uz3, uz4, uz5 = b00 * r2 + b10 * r5 + b20 * r8, b01 * r2 + b11 * r5 + b21 * r8, \
                b02 * r2 + b12 * r5 + b22 * r8
            s00 = r1 * uy0 + r4 * uy1 + r7 * uy2 + rn
            s01 = r1 * uz0 + r4 * uz1 + r7 * uz2
            s11 = r2 * uz0 + r5 * uz1 + r8 * uz2 + rn
            det = s00 * s11 - s01 * s01
            i00, i01, i11 = s11 / det, -s01 / det, s00 / det
            e0 = -(r1 * v0 + r4 * v1 + r7 * v2)
            e1 = -(r2 * v0 + r5 * v1 + r8 * v2)
            ky0, kz0 = uy0 * i00 + uz0 * i01, uy0 * i01 + uz0 * i11
            ky1, kz1 = uy1 * i00 + uz1 * i01, uy1 * i01 + uz1 * i11
            ky2, kz2 = uy2 * i00 + uz2 * i01, uy2 * i01 + uz2 * i11
            ky3, kz3 = uy3 * i00 + uz3 * i01, uy3 * i01 + uz3 * i11
            ky4, kz4 = uy4 * i00 + uz4 * i01, uy4 * i01 + uz4 * i11
            ky5, kz5 = uy5 * i00 + uz5 * i01, uy5 * i01 + uz5 * i11
            v0, v1, v2 = v0 + ky0 * e0 + kz0 * e1, v1 + ky1 * e0 + kz1 * e1, v2 + ky2 * e0 + kz2 * e1
            g0, g1, g2 = g0 + ky3 * e0 + kz3 * e1, g1 + ky4 * e0 + kz4 * e1, g2 + ky5 * e0 + kz5 * e1
            # P - K S K^T = P - K PHT^T (upper triangle)
            a00, a01, a02 = a00 - ky0 * uy0 - kz0 * uz0, a01 - ky0 * uy1 - kz0 * uz1, a02 - ky0 * uy2 - kz0 * uz2
            a11, a12, a22 = a11 - ky1 * uy1 - kz1 * uz1, a12 - ky1 * uy2 - kz1 * uz2, a22 - ky2 * uy2 - kz2 * uz2
            b00, b01, b02 = b00 - ky0 * uy3 - kz0 * uz3, b01 - ky0 * uy4 - kz0 * uz4, b02 - ky0 * uy5 - kz0 * uz5
            b10, b11, b12 = b10 - ky1 * uy3 - kz1 * uz3, b11 - ky1 * uy4 - kz1 * uz4, b12 - ky1 * uy5 - kz1 * uz5
            b20, b21, b22 = b20 - ky2 * uy3 - kz2 * uz3, b21 - ky2 * uy4 - kz2 * uz4, b22 - ky2 * uy5 - kz2 * uz5
            c00, c01, c02 = c00 - ky3 * uy3 - kz3 * uz3, c01 - ky3 * uy4 - kz3 * uz4, c02 - ky3 * uy5 - kz3 * uz5
            c11, c12, c22 = c11 - ky4 * uy4 - kz4 * uz4, c12 - ky4 * uy5 - kz4 * uz5, c22 - ky5 * uy5 - kz5 * uz5
        if out is not None:
            out.extend((v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12,
                        b20, b21, b22, c00, c01, c02, c11, c12, c22, r0, r1, r2, r3, r4, r5, r6, r7, r8))
    if frames:
        if not zupt:
            K = (ky0, kz0, ky1, kz1, ky2, kz2, ky3, kz3, ky4, kz4, ky5, kz5)
            y, S = (e0, e1), (s00, s01, s11)
        last = (zupt, K, y, S, dt, qv, qg, prior)
    s[:] = (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12, b20, b21, b22,
            c00, c01, c02, c11, c12, c22, r0, r1, r2, r3, r4, r5, r6, r7, r8, count)
    return last, rejected, initialised


def _velocity_update(xp, n6, z, gate=math.inf):
    """Update with the velocity ``z`` (world frame, noise ``n6``), or None when gated out.

    The body-frame measurement ``R_k^T v = z_b``, noise ``N_b``, is the world-frame ``v = R_k z_b``,
    noise ``N = R_k N_b R_k^T``: ``H = [I, 0]``, ``S = A + N``, ``K = [A; B^T] S^-1``, ``P <- P - K S
    K^T`` (zero-velocity update: ``z = 0``, ``N = sigma_zupt^2 I``). ``n6``: upper triangle of ``N``;
    ``gate``: largest squared Mahalanobis distance; ``xp``: the 6-state then P's 21 unique entries
    (``_UPPER21`` order). Returns ``(xp, K, y, S)``, world axes (K row-major 6x3, S upper triangle).
    """
    v0, v1, v2 = xp[0:3]
    a00, a01, a02, a11, a12, a22 = xp[6:12]
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = xp[12:21]
    c00, c01, c02, c11, c12, c22 = xp[21:27]
    s0, s1, s2, s4, s5, s8 = a00 + n6[0], a01 + n6[1], a02 + n6[2], a11 + n6[3], a12 + n6[4], a22 + n6[5]
    j00, j01, j02 = s4 * s8 - s5 * s5, s2 * s5 - s1 * s8, s1 * s5 - s2 * s4
    det = s0 * j00 + s1 * j01 + s2 * j02
    j11, j12, j22 = s0 * s8 - s2 * s2, s1 * s2 - s0 * s5, s0 * s4 - s1 * s1
    d = 1.0 / det
    i00, i01, i02, i11, i12, i22 = j00 * d, j01 * d, j02 * d, j11 * d, j12 * d, j22 * d
    y0, y1, y2 = y = (z[0] - v0, z[1] - v1, z[2] - v2)
    w0, w1, w2 = i00 * y0 + i01 * y1 + i02 * y2, i01 * y0 + i11 * y1 + i12 * y2, i02 * y0 + i12 * y1 + i22 * y2
    if y0 * w0 + y1 * w1 + y2 * w2 > gate:
        return None
    pht = ((a00, a01, a02), (a01, a11, a12), (a02, a12, a22), (b0, b3, b6), (b1, b4, b7), (b2, b5, b8))
    K = [(r0 * i00 + r1 * i01 + r2 * i02, r0 * i01 + r1 * i11 + r2 * i12, r0 * i02 + r1 * i12 + r2 * i22)
         for r0, r1, r2 in pht]
    xn = [xp[i] + k0 * y0 + k1 * y1 + k2 * y2 for i, (k0, k1, k2) in enumerate(K)]
    (k00, k01, k02), (k10, k11, k12), (k20, k21, k22), (k30, k31, k32), (k40, k41, k42), (k50, k51, k52) = K
    pn = (a00 - (k00 * a00 + k01 * a01 + k02 * a02), a01 - (k00 * a01 + k01 * a11 + k02 * a12),
          a02 - (k00 * a02 + k01 * a12 + k02 * a22), a11 - (k10 * a01 + k11 * a11 + k12 * a12),
          a12 - (k10 * a02 + k11 * a12 + k12 * a22), a22 - (k20 * a02 + k21 * a12 + k22 * a22),
          b0 - (k00 * b0 + k01 * b3 + k02 * b6), b1 - (k00 * b1 + k01 * b4 + k02 * b7),
          b2 - (k00 * b2 + k01 * b5 + k02 * b8), b3 - (k10 * b0 + k11 * b3 + k12 * b6),
          b4 - (k10 * b1 + k11 * b4 + k12 * b7), b5 - (k10 * b2 + k11 * b5 + k12 * b8),
          b6 - (k20 * b0 + k21 * b3 + k22 * b6), b7 - (k20 * b1 + k21 * b4 + k22 * b7),
          b8 - (k20 * b2 + k21 * b5 + k22 * b8), c00 - (k30 * b0 + k31 * b3 + k32 * b6),
          c01 - (k30 * b1 + k31 * b4 + k32 * b7), c02 - (k30 * b2 + k31 * b5 + k32 * b8),
          c11 - (k40 * b1 + k41 * b4 + k42 * b7), c12 - (k40 * b2 + k41 * b5 + k42 * b8),
          c22 - (k50 * b2 + k51 * b5 + k52 * b8))
    return tuple(xn) + pn, tuple(v for r in K for v in r), y, (s0, s1, s2, s4, s5, s8)


class GravityEstimate(NamedTuple):
    """One frame of :meth:`GravityVelocityFilter.step`.

    Attributes
    ----------
    velocity : ndarray (3,)          m/s, world frame (gyro-integrated body frame at the start).
    gravity : ndarray (3,)           reaction to gravity (+9.81 m/s^2 up at rest), m/s^2, world frame.
    acceleration : ndarray (3,)      gravity-compensated, frame mean, m/s^2, body frame at mid-frame.
    specific_force : ndarray (3,)    what an accelerometer reads, frame mean, m/s^2, body frame at mid-frame.
    speed : float                    ``|velocity|``, m/s.
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

    observed by the non-holonomic constraint ``[e_y, e_z]^T R_k^T v_k = 0 + n`` (a car
    neither slides sideways nor moves vertically in its own frame) while moving, by ``v_k = 0 +
    n`` at standstill frames, or by a measured speed (``sigma_speed``). The constraint needs the
    body frame to be the vehicle's (FLU): give the ``extrinsic`` when it is mounted otherwise.

    Parameters
    ----------
    sigma_nhc, sigma_zupt : float
        Std of the body lateral and vertical velocity (0.3) and of the velocity
        at standstill (0.05), m/s.
    q_v, q_g : float
        Velocity (m/s/sqrt(s), 0.05) and gravity (m/s^2/sqrt(s), 1e-6) random walks.
    q_gap : float
        Extra velocity random walk through a timestamp gap (``valid`` False), m/s/sqrt(s) (1.0).
    zupt_gate : float
        A standstill flag is ignored (the constraint used instead) when the predicted velocity is
        this far from zero, squared Mahalanobis distance (100: ten sigma; detectors flag cruising too).
    sigma_v0, sigma_g0, v0, g0
        Initial std of velocity (m/s, 30) and gravity (m/s^2, 1); initial velocity and gravity
        reaction (array_like (3,), world frame; default zero and the first frame's specific force).
    extrinsic : Extrinsic or ndarray (3, 3), optional
        Static ground <- sensor rotation (inputs are sensor-frame increments).
    lever_arm : array_like (3,), optional
        Sensor position relative to the body's pitch/roll centre, ground frame, m: the accelerations
        are moved there, ``f_0 = f_s - alpha x r - w x (w x r)`` (``w`` the frame's mean rate,
        ``alpha`` its backward difference: half a frame late). Default: none.
    R0 : ndarray (3, 3), optional
        Initial attitude, world <- body (identity).
    sigma_speed : float
        Std of a measured forward speed (``speed`` of :meth:`step` / :meth:`run`, wheel or CAN),
        m/s (0.1; at most 1000): the update is then ``R_k^T v = (speed, 0, 0)``, noise ``diag(sigma_speed^2,
        sigma_nhc^2, sigma_nhc^2)``, in place of the zero-velocity update and the constraint.

    Attributes
    ----------
    x, P : ndarray (6,), (6, 6)
        State and covariance; ``x_prior``, ``P_prior``, ``x_post``, ``P_post``, ``F``, ``Q``,
        ``H``, ``R``, ``K``, ``y``, ``S`` of the last step (filterpy's names, built on access).
    cumulative : ndarray (3, 3)
        ``R_k``, world <- body.
    zupt_rejected : int
        Standstill flags overruled by the gate so far.

    Notes
    -----
    Building blocks for estimators on this filter: :meth:`to_body` (:meth:`to_body_flat`),
    :meth:`step_body` (plain floats, the fast path), :meth:`run_body`, :func:`egomotion_arrays`.
    """

    def __init__(self, sigma_nhc: float = 0.3, sigma_zupt: float = 0.05, q_v: float = 0.05,
                 q_g: float = 1e-6, q_gap: float = 1.0, sigma_v0: float = 30.0, sigma_g0: float = 1.0,
                 zupt_gate: float = 100.0, v0: Optional[Sequence[float]] = None,
                 g0: Optional[Sequence[float]] = None, extrinsic: Union[Extrinsic, np.ndarray, None] = None,
                 lever_arm: Optional[Sequence[float]] = None, R0: Optional[np.ndarray] = None,
                 sigma_speed: float = 0.1) -> None:
        if not 0 < float(sigma_speed) <= 1e3:     # (larger: no information, and S ill-conditioned)
            raise ValueError(f"sigma_speed must be in (0, 1000] m/s (no speed: leave it out), got {sigma_speed!r}")
        self.sigma_speed, self.sigma_nhc, self.sigma_zupt = float(sigma_speed), float(sigma_nhc), float(sigma_zupt)
        self.q_v, self.q_g, self.q_gap = float(q_v), float(q_g), float(q_gap)
        self.sigma_v0, self.sigma_g0 = float(sigma_v0), float(sigma_g0)
        self.zupt_gate = float(zupt_gate)
        self.extrinsic = Extrinsic.coerce(extrinsic)
        self._Rgs = self.extrinsic.rotation
        self._identity_extrinsic = bool(np.array_equal(self._Rgs, _I3))
        self._rgs9 = self._Rgs.ravel().tolist()
        self.lever_arm = None if lever_arm is None else np.asarray(lever_arm, dtype=float).reshape(3)
        self._lever = None if self.lever_arm is None else tuple(self.lever_arm.tolist())
        self.R0 = _I3.copy() if R0 is None else np.array(R0, dtype=float)
        self._v0 = None if v0 is None else np.asarray(v0, dtype=float).reshape(3)
        self._g0 = None if g0 is None else np.asarray(g0, dtype=float).reshape(3)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state."""
        v = [0.0] * 3 if self._v0 is None else self._v0.tolist()
        g = [0.0] * 3 if self._g0 is None else self._g0.tolist()
        sv, sg = self.sigma_v0 ** 2, self.sigma_g0 ** 2
        p = [sv, 0.0, 0.0, sv, 0.0, sv] + [0.0] * 9 + [sg, 0.0, 0.0, sg, 0.0, sg]
        self._s = v + g + p + self.R0.ravel().tolist() + [0]     # the kernel's state list
        # arrays handed out by x / P / cumulative (_pull), last step: one object for filterpy's Saver
        self._w = SimpleNamespace(sync=None, last=None)
        self._initialised = self._g0 is not None
        self._prm = (self.q_v ** 2, self.q_gap ** 2, self.q_g ** 2, self.sigma_zupt ** 2, self.sigma_nhc ** 2,
                     self.zupt_gate, self.sigma_speed ** 2)
        self._w_prev = None                 # mean body rate of the previous frame (rad/s)
        self.zupt_rejected = 0

    # -- state as numpy arrays (built on access; in-place changes are seen by the next frame) --------
    def _pull(self) -> None:
        """Copy arrays handed out by ``x``, ``P`` or ``cumulative`` back into the kernel's state."""
        x, P, R = self._w.sync
        self._s[0:36] = x.tolist() + [float(P[i, j]) for i, j in _UPPER21] + R.ravel().tolist()
        self._w.sync = None

    def _arrays(self):
        if self._w.sync is None:
            s = self._s
            self._w.sync = (np.array(s[0:6]), _full_cov(np.array(s[6:27])), np.array(s[27:36]).reshape(3, 3))
        return self._w.sync

    def _set_array(self, i: int, value) -> None:
        a = self._arrays()[i]
        a[...] = np.asarray(value, dtype=float).reshape(a.shape)

    x = property(lambda self: self._arrays()[0], lambda self, v: self._set_array(0, v),
                 doc="State ``[v_w, g_w]`` (6,): velocity (m/s) and gravity reaction (m/s^2), world frame.")
    P = property(lambda self: self._arrays()[1], lambda self, v: self._set_array(1, v),
                 doc="Covariance of ``[v, g]`` (6, 6).")
    cumulative = property(lambda self: self._arrays()[2], lambda self, v: self._set_array(2, v),
                          doc="``R_k = R_{w<-body_k}`` (3, 3), the gyro-integrated attitude at the last frame's end.")
    x_prior = property(lambda self: np.array(self._last_step()[7][:6]), doc="State after the last predict (6,).")
    P_prior = property(lambda self: _full_cov(np.array(self._last_step()[7][6:27])), doc="P after the last predict.")
    x_post = property(lambda self: self.x.copy(), doc="State after the last update (6,).")
    P_post = property(lambda self: self.P.copy(), doc="P after the last update (6, 6).")

    # -- filterpy-style matrices of the last step, built on demand ----------------------------------
    def _last_step(self):
        last = self._w.last
        return last if last is not None else (False, (0.0,) * 12, (0.0, 0.0), (0.0,) * 3, 0.0, 0.0, 0.0,
                                              tuple(self._s[:27]))

    def _update_matrices(self):
        """``H, R, K, y, S`` of the last update in body axes (forward row/column zero for the NHC)."""
        zupt, K, y, S, _, _, _, _ = self._last_step()
        Rk = self.cumulative
        H = np.zeros((3, 6))
        H[:, :3] = Rk.T
        sn = self.sigma_nhc ** 2
        if zupt:                                # kept in world axes by the kernel: rotate to the body
            s0, s1, s2, s4, s5, s8 = S
            return (H, self.sigma_zupt ** 2 * _I3 if zupt == 1 else np.diag([self.sigma_speed ** 2, sn, sn]),
                    np.array(K).reshape(6, 3) @ Rk, Rk.T @ np.array(y),
                    Rk.T @ np.array([[s0, s1, s2], [s1, s4, s5], [s2, s5, s8]]) @ Rk)
        H[0] = 0.0
        Kb, Sb = np.zeros((6, 3)), np.zeros((3, 3))
        Kb[:, 1:] = np.array(K).reshape(6, 2)
        Sb[1:, 1:] = [[S[0], S[1]], [S[1], S[2]]]
        return H, np.diag([0.0, sn, sn]), Kb, np.array([0.0, y[0], y[1]]), Sb

    F = property(lambda self: np.eye(6) - self._last_step()[4] * np.eye(6, k=3),
                 doc="State transition of the last predict (6x6), ``[[I, -dt I], [0, I]]``.")
    Q = property(lambda self: np.diag([self._last_step()[5]] * 3 + [self._last_step()[6]] * 3),
                 doc="Process noise of the last predict (6x6).")
    H = property(lambda self: self._update_matrices()[0],
                 doc="Measurement matrix of the last update (3x6): body-frame velocity ``R_k^T v``.")
    R = property(lambda self: self._update_matrices()[1], doc="Measurement noise of the last update, (m/s)^2.")
    K = property(lambda self: self._update_matrices()[2], doc="Gain of the last update (6x3, body axes).")
    y = property(lambda self: self._update_matrices()[3], doc="Innovation of the last update (3,), body axes.")
    S = property(lambda self: self._update_matrices()[4], doc="Innovation covariance of the last update (3x3).")

    # -- public building blocks (SuspensionAwareFilter) --------------------------------------------
    def to_body(self, d: np.ndarray, dv: np.ndarray):
        """Sensor-frame increments ``d`` (..., 3, 3), sensor_{k-1} <- sensor_k, and ``dv`` (..., 3), m/s,
        to the body frame: ``R_gs d R_gs^T``, ``R_gs dv``."""
        R = self._Rgs
        return (d, dv) if self._identity_extrinsic else (R @ d @ R.T, dv @ R.T)

    def to_body_flat(self, d9, dv3):
        """:meth:`to_body` of one frame as plain floats (9 row-major, 3)."""
        if self._identity_extrinsic:
            return d9, dv3
        R = self._rgs9
        return mul_nt_flat(mul_flat(R, d9), R), (R[0] * dv3[0] + R[1] * dv3[1] + R[2] * dv3[2],
                                                 R[3] * dv3[0] + R[4] * dv3[1] + R[5] * dv3[2],
                                                 R[6] * dv3[0] + R[7] * dv3[1] + R[8] * dv3[2])

    def step_body(self, d9, dv3, dt: float, stationary: bool = False, valid: bool = True,
                  speed: Optional[float] = None):
        """One frame already in the body frame, as plain floats: the fast path of :meth:`step`.

        Parameters
        ----------
        d9, dv3 : sequences of 9 and 3 floats
            ``R_{body_{k-1}<-body_k}`` row-major; gravity-free velocity increment (body_{k-1}, m/s).
        dt, stationary, valid, speed
            As in :meth:`step` (``dt`` > 0, s).

        Returns
        -------
        specific_force, acceleration : tuple of 3 floats
            Frame means in the body frame at mid-frame, m/s^2 (see :class:`GravityEstimate`).
        speed : float
            ``|v|`` after the update, m/s.
        """
        if self._w.sync is not None:
            self._pull()
        s = self._s
        rprev = s[27:36]
        sp = math.nan if speed is None else float(speed)
        last, rej, self._initialised = _predict_update(s, ((d9, dv3, dt, stationary, valid, sp),),
                                                       self._prm + (self._initialised,))
        self._w.last = last
        self.zupt_rejected += rej
        # forces with the posterior gravity, frame means at mid-frame
        p0, p1, p2 = log_flat(d9)
        w = (p0 / dt, p1 / dt, p2 / dt)
        h0, h1, h2, h3, h4, h5, h6, h7, h8 = exp_flat(0.5 * p0, 0.5 * p1, 0.5 * p2)   # body_{k-1} <- mid
        u0, u1, u2 = dv3[0] / dt, dv3[1] / dt, dv3[2] / dt
        f0, f1, f2 = h0 * u0 + h3 * u1 + h6 * u2, h1 * u0 + h4 * u1 + h7 * u2, h2 * u0 + h5 * u1 + h8 * u2
        if self._lever is not None:
            r = self._lever
            wp = w if self._w_prev is None else self._w_prev
            al = ((w[0] - wp[0]) / dt, (w[1] - wp[1]) / dt, (w[2] - wp[2]) / dt)
            ax, ay, az = al[1] * r[2] - al[2] * r[1], al[2] * r[0] - al[0] * r[2], al[0] * r[1] - al[1] * r[0]
            m0, m1, m2 = w[1] * r[2] - w[2] * r[1], w[2] * r[0] - w[0] * r[2], w[0] * r[1] - w[1] * r[0]   # w x r
            cx, cy, cz = w[1] * m2 - w[2] * m1, w[2] * m0 - w[0] * m2, w[0] * m1 - w[1] * m0
            f0, f1, f2 = f0 - ax - cx, f1 - ay - cy, f2 - az - cz
        self._w_prev = w
        g0, g1, g2 = s[3], s[4], s[5]
        q0, q1, q2 = (rprev[0] * g0 + rprev[3] * g1 + rprev[6] * g2, rprev[1] * g0 + rprev[4] * g1 + rprev[7] * g2,
                      rprev[2] * g0 + rprev[5] * g1 + rprev[8] * g2)       # R_{k-1}^T g
        return ((f0, f1, f2), (f0 - (h0 * q0 + h3 * q1 + h6 * q2), f1 - (h1 * q0 + h4 * q1 + h7 * q2),
                               f2 - (h2 * q0 + h5 * q1 + h8 * q2)), math.sqrt(s[0] ** 2 + s[1] ** 2 + s[2] ** 2))

    # -- streaming ----------------------------------------------------------------------------
    def step(self, delta_R, delta_v=None, delta_t=None, stationary: bool = False,
             valid: bool = True, speed: Optional[float] = None) -> GravityEstimate:
        """Process one frame.

        Parameters
        ----------
        delta_R : ndarray (3, 3), (4, 4) or (3,), or EgoFrame
            Sensor rotation increment, sensor_{k-1} <- sensor_k; or an
            :class:`~imu_ground.imu.egomotion.EgoFrame` carrying every field.
        delta_v : ndarray (3,)
            Gravity-free velocity increment, sensor frame at the frame's start, m/s.
        delta_t : float
            Frame duration, s.
        stationary, valid : bool
            The frame ends at a standstill (zero-velocity update); False through a timestamp gap.
        speed : float, optional
            Measured forward speed at the frame's end (wheel / CAN), m/s; None or NaN: none.

        Returns
        -------
        GravityEstimate

        Raises
        ------
        ValueError
            Non-finite increments or a non-positive ``delta_t`` (the state is unchanged).
        """
        if delta_v is None:
            delta_R, delta_v, delta_t, stationary, valid = delta_R[:5]
        d9 = (delta_R if type(delta_R) is np.ndarray and delta_R.shape == (3, 3) else
              as_rotations(delta_R)).ravel().tolist()
        dv = np.asarray(delta_v, dtype=float).reshape(3).tolist()
        dt = float(delta_t)
        if not (dt > 0.0 and math.isfinite(dt + sum(d9) + sum(dv))):
            raise ValueError(f"bad frame: delta_t = {dt!r} must be > 0 and delta_R, delta_v finite")
        d9, dv = self.to_body_flat(d9, dv)
        f, a, speed = self.step_body(d9, dv, dt, bool(stationary), bool(valid), speed)
        e = np.array(self._s[0:6] + list(a + f))          # one array, four views
        return GravityEstimate(e[0:3], e[3:6], e[6:9], e[9:12], speed)

    # -- batch -------------------------------------------------------------------------------
    def run(self, egomotion: Union[EgoMotion, ImuData], smooth: bool = False,
            speed: Optional[np.ndarray] = None) -> GravityTrack:
        """Process a whole drive, continuing from the current state as :meth:`step` would.

        Parameters
        ----------
        egomotion : EgoMotion or ImuData
            Per-frame increments (an ImuData is preintegrated at 10 Hz).
        smooth : bool
            Rauch-Tung-Striebel smoother over the drive (offline).
        speed : ndarray (N,), optional
            Measured forward speed per frame, m/s (NaN: none at that frame).

        Returns
        -------
        GravityTrack
        """
        d, dv, dt, st, valid = egomotion_arrays(egomotion)
        return self.run_body(*self.to_body(d, dv), dt, st, valid, smooth, speed)

    def run_body(self, d, dv, dt, stationary, valid, smooth: bool = False, speed=None) -> GravityTrack:
        """:meth:`run` on body-frame arrays (``d`` (N, 3, 3), ``dv`` (N, 3), ``dt``, ``stationary``,
        ``valid``, ``speed`` (N,) or None), already checked (:func:`egomotion_arrays`)."""
        n = len(dt)
        sp = [math.nan] * n if speed is None else np.asarray(speed, dtype=float).reshape(n).tolist()
        if self._w.sync is not None:
            self._pull()
        r_start = np.array(self._s[27:36]).reshape(3, 3)
        frames = list(zip(np.reshape(d, (n, 9)).tolist(), np.asarray(dv).tolist(), np.asarray(dt).tolist(),
                          np.asarray(stationary).tolist(), np.asarray(valid).tolist(), sp))
        out, priors = array("d"), (array("d") if smooth else None)
        last, rej, self._initialised = _predict_update(self._s, frames, self._prm + (self._initialised,),
                                                       out, priors)
        self.zupt_rejected += rej
        if n:
            self._w.last = last
        rows = np.frombuffer(out, dtype=float).reshape(n, 36)
        xs, Ps, cum = rows[:, :6], _full_cov(rows[:, 6:27]), rows[:, 27:].reshape(n, 3, 3)
        if smooth and n:
            pr = np.frombuffer(priors, dtype=float).reshape(n, 27)
            xs, Ps = _rts(xs, Ps, pr[:, :6], _full_cov(pr[:, 6:27]), dt)
        if n:
            # forces with the posterior gravity, frame means at mid-frame (as step_body, vectorised)
            phi = so3.log(d)
            w = phi / dt[:, None]
            half = so3.exp(0.5 * phi)                  # body_{k-1} <- body at mid-frame
            f = np.einsum("nji,nj->ni", half, dv / dt[:, None])
            if self.lever_arm is not None:
                w_prev = np.concatenate([[w[0] if self._w_prev is None else self._w_prev], w[:-1]])
                r = self.lever_arm
                f = f - np.cross((w - w_prev) / dt[:, None], r) - np.cross(w, np.cross(w, r))
            Rprev = np.concatenate([r_start[None], cum[:-1]])
            acc = f - np.einsum("nji,nj->ni", half, np.einsum("nji,nj->ni", Rprev, xs[:, 3:]))
            self._w_prev = tuple(w[-1].tolist())
        else:
            f = acc = np.zeros((0, 3))
        return GravityTrack(xs[:, :3].copy(), xs[:, 3:].copy(), acc, f, np.linalg.norm(xs[:, :3], axis=1),
                            Ps, cum, d)


def _rts(xs, Ps, xps, Pps, dt):
    """Rauch-Tung-Striebel smoother of the filter's forward pass (F = [[I, -dt I], [0, I]])."""
    xs, Ps = xs.copy(), Ps.copy()
    F = np.eye(6)
    for k in range(len(dt) - 2, -1, -1):
        F[:3, 3:] = -dt[k + 1] * _I3
        C = np.linalg.solve(Pps[k + 1], F @ Ps[k]).T
        xs[k] = xs[k] + C @ (xs[k + 1] - xps[k + 1])
        P = Ps[k] + C @ (Ps[k + 1] - Pps[k + 1]) @ C.T
        Ps[k] = 0.5 * (P + P.T)
    return xs, Ps
