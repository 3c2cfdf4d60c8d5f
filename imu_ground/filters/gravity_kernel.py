"""The gravity/velocity filter's per-frame body, :func:`frame`, compiled by :func:`imu_ground._jit.njit`.

:class:`~imu_ground.filters.gravity_velocity.GravityVelocityFilter` keeps its whole state in one flat
float64 buffer ``s`` (layout below); :func:`step_frame` / :func:`step_sensor` run one frame,
:func:`run_frames` the same body over a drive.

Buffer layout (indices; frames and units as in the filter's docstring)::

    0-2 v (m/s, world)   3-5 g (m/s^2, world)   6-26 P (21 unique entries, _UPPER21 order)
    27-35 R_k (world <- body_k, row-major)   36 frames processed   37 gravity initialised (0/1)
    38 previous mean rate known (0/1), 39-41 that rate (rad/s, body)   42 standstill flags rejected
    43-49 q_v^2, q_gap^2, q_g^2, sigma_zupt^2, sigma_nhc^2, zupt_gate, sigma_speed^2
    50 lever arm given (0/1), 51-53 lever arm (m, body)   54 extrinsic given (0/1), 55-63 R_gs row-major
    64 RENORM_EVERY   65 so3's small-angle threshold (rad)
    66 last step recorded (0/1)   67 its kind (0 constraint, 1 ZUPT, 2 speed)   68-85 K   86-88 y
    89-94 S   95 dt   96 q_v^2 dt (+ gap)   97 q_g^2 dt (+ gap)   98-124 the prior (x then P's 21 entries)
    125 q_gap_g^2 (gravity random walk added through a gap)

The constraint's K, y and S fill the first 12, 2 and 3 of their slots; the rest keep their values.
"""
from __future__ import annotations

import math
from math import isnan, sqrt

import numpy as np

from imu_ground import so3
from imu_ground._jit import jitable, njit
from imu_ground.so3 import exp_flat, log_flat, mul_flat, mul_nt_flat, renormalise_flat
from imu_ground.units import RENORM_EVERY

__all__ = ["BUF_LEN", "I_EXTR", "I_INIT", "I_LAST", "I_LEVER", "I_PRM", "I_REJECTED", "I_WPREV", "body_forces",
           "body_increment", "body_increments", "frame", "frame_forces", "full_cov", "new_state", "run_frames",
           "step_frame", "step_sensor", "to_body"]

#: (row, column) of P's 21 unique entries: cov(v) upper triangle, cov(v, g) row-major, cov(g) upper triangle.
_UPPER21 = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2),
            (0, 3), (0, 4), (0, 5), (1, 3), (1, 4), (1, 5), (2, 3), (2, 4), (2, 5),
            (3, 3), (3, 4), (3, 5), (4, 4), (4, 5), (5, 5))
_FULL_INDEX = np.empty((6, 6), dtype=int)
for _m, (_i, _j) in enumerate(_UPPER21):
    _FULL_INDEX[_i, _j] = _FULL_INDEX[_j, _i] = _m

I_INIT, I_WPREV, I_REJECTED, I_PRM, I_LEVER, I_EXTR = 37, 38, 42, 43, 50, 54
I_RENORM, I_SMALL, I_LAST, I_QGAPG, BUF_LEN = 64, 65, 66, 125, 126
_I_K, _I_Y, _I_S, _I_DT, _I_PRIOR = 68, 86, 89, 95, 98      # the last step's record (I_LAST + 1: its kind)
_ZERO18 = (0.0,) * 18
_F64 = np.dtype(np.float64)
for _helper in (exp_flat, log_flat, mul_flat, mul_nt_flat, renormalise_flat, so3.transpose_flat):
    jitable(_helper)                    # so3's scalar kernels, compiled into the bodies below that call them


def full_cov(p21: np.ndarray) -> np.ndarray:
    """(..., 21) unique entries -> (..., 6, 6) symmetric covariances."""
    return np.asarray(p21)[..., _FULL_INDEX]


def new_state(x6, p21, r9, prm7, initialised: bool, lever=None, extrinsic9=None, q_gap_g2: float = 0.0) -> list:
    """A fresh state buffer (list, the layout of the module docstring): ``[v, g]``, P's 21 entries, ``R0``
    row-major, the noise parameters (``prm7``, in layout order), gravity given, lever arm and extrinsic (None:
    none), the gravity random walk through a gap."""
    s = [float(v) for v in x6] + [float(v) for v in p21] + [float(v) for v in r9] + [0.0]
    s += [1.0 if initialised else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0] + [float(v) for v in prm7]
    s += [0.0, 0.0, 0.0, 0.0] if lever is None else [1.0] + [float(v) for v in lever]
    s += [0.0] * 10 if extrinsic9 is None else [1.0] + [float(v) for v in extrinsic9]
    s += [float(RENORM_EVERY), so3.SMALL_ANGLE] + [0.0] * (I_QGAPG - I_LAST) + [float(q_gap_g2)]
    return s


@jitable
def body_increment(r9, d9, dv3):
    """``(R d R^T, R dv)`` of one frame as plain floats: sensor -> body with ``R = R_gs`` (9 row-major)."""
    return mul_nt_flat(mul_flat(r9, d9), r9), (r9[0] * dv3[0] + r9[1] * dv3[1] + r9[2] * dv3[2],
                                               r9[3] * dv3[0] + r9[4] * dv3[1] + r9[5] * dv3[2],
                                               r9[6] * dv3[0] + r9[7] * dv3[1] + r9[8] * dv3[2])


@njit
def _body_frames(r9, d, dv, d_out, dv_out):
    for k in range(d.shape[0]):
        b9, b3 = body_increment(r9, d[k], dv[k])
        for i in range(9):
            d_out[k, i] = b9[i]
        dv_out[k, 0], dv_out[k, 1], dv_out[k, 2] = b3


def body_increments(r, d, dv):
    """:func:`body_increment` of many frames (a compiled loop): ``d`` (..., 3, 3), ``dv`` (..., 3), ``r`` (3, 3)."""
    d, dv = np.asarray(d, dtype=float), np.asarray(dv, dtype=float)
    n = d.size // 9
    d_out, dv_out = np.empty((n, 9)), np.empty((n, 3))
    r9 = tuple(np.asarray(r, dtype=float).ravel().tolist())
    _body_frames(r9, np.ascontiguousarray(d).reshape(n, 9), np.ascontiguousarray(dv).reshape(n, 3), d_out, dv_out)
    return d_out.reshape(d.shape), dv_out.reshape(dv.shape)


@njit
def _velocity_update(xp, n6, z0, z1, z2, gate):
    """Update of ``xp`` (state, P's 21 entries) with the velocity ``z`` (world frame, noise of upper triangle
    ``n6``) unless its squared Mahalanobis distance exceeds ``gate``: ``(accepted, xp, K, y, S)``."""
    v0, v1, v2 = xp[0], xp[1], xp[2]
    a00, a01, a02, a11, a12, a22 = xp[6], xp[7], xp[8], xp[9], xp[10], xp[11]
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = xp[12], xp[13], xp[14], xp[15], xp[16], xp[17], xp[18], xp[19], xp[20]
    c00, c01, c02, c11, c12, c22 = xp[21], xp[22], xp[23], xp[24], xp[25], xp[26]
    s0, s1, s2, s4, s5, s8 = a00 + n6[0], a01 + n6[1], a02 + n6[2], a11 + n6[3], a12 + n6[4], a22 + n6[5]
    j00, j01, j02 = s4 * s8 - s5 * s5, s2 * s5 - s1 * s8, s1 * s5 - s2 * s4
    det = s0 * j00 + s1 * j01 + s2 * j02
    j11, j12, j22 = s0 * s8 - s2 * s2, s1 * s2 - s0 * s5, s0 * s4 - s1 * s1
    d = 1.0 / det
    i00, i01, i02, i11, i12, i22 = j00 * d, j01 * d, j02 * d, j11 * d, j12 * d, j22 * d
    y0, y1, y2 = z0 - v0, z1 - v1, z2 - v2
    w0, w1, w2 = i00 * y0 + i01 * y1 + i02 * y2, i01 * y0 + i11 * y1 + i12 * y2, i02 * y0 + i12 * y1 + i22 * y2
    S = (s0, s1, s2, s4, s5, s8)
    if y0 * w0 + y1 * w1 + y2 * w2 > gate:
        return False, xp, _ZERO18, (y0, y1, y2), S
    # K = P H^T S^-1, the rows of P H^T: (a00, a01, a02), (a01, a11, a12), (a02, a12, a22), (b0, b3, b6), ...
    k00, k01, k02 = a00 * i00 + a01 * i01 + a02 * i02, a00 * i01 + a01 * i11 + a02 * i12, a00 * i02 + a01 * i12 + a02 * i22
    k10, k11, k12 = a01 * i00 + a11 * i01 + a12 * i02, a01 * i01 + a11 * i11 + a12 * i12, a01 * i02 + a11 * i12 + a12 * i22
    k20, k21, k22 = a02 * i00 + a12 * i01 + a22 * i02, a02 * i01 + a12 * i11 + a22 * i12, a02 * i02 + a12 * i12 + a22 * i22
    k30, k31, k32 = b0 * i00 + b3 * i01 + b6 * i02, b0 * i01 + b3 * i11 + b6 * i12, b0 * i02 + b3 * i12 + b6 * i22
    k40, k41, k42 = b1 * i00 + b4 * i01 + b7 * i02, b1 * i01 + b4 * i11 + b7 * i12, b1 * i02 + b4 * i12 + b7 * i22
    k50, k51, k52 = b2 * i00 + b5 * i01 + b8 * i02, b2 * i01 + b5 * i11 + b8 * i12, b2 * i02 + b5 * i12 + b8 * i22
    xn = (xp[0] + k00 * y0 + k01 * y1 + k02 * y2, xp[1] + k10 * y0 + k11 * y1 + k12 * y2,
          xp[2] + k20 * y0 + k21 * y1 + k22 * y2, xp[3] + k30 * y0 + k31 * y1 + k32 * y2,
          xp[4] + k40 * y0 + k41 * y1 + k42 * y2, xp[5] + k50 * y0 + k51 * y1 + k52 * y2,
          a00 - (k00 * a00 + k01 * a01 + k02 * a02), a01 - (k00 * a01 + k01 * a11 + k02 * a12),
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
    K = (k00, k01, k02, k10, k11, k12, k20, k21, k22, k30, k31, k32, k40, k41, k42, k50, k51, k52)
    return True, xn, K, (y0, y1, y2), S


@njit
def _predict_update(s, d9, dv3, dt, stationary, valid, speed):
    """The filter's recursion of one body-frame frame on ``s`` (in place, with the step's record; ``speed`` NaN:
    none)."""
    (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12, b20, b21, b22,
     c00, c01, c02, c11, c12, c22) = (s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10], s[11],
                                      s[12], s[13], s[14], s[15], s[16], s[17], s[18], s[19], s[20], s[21],
                                      s[22], s[23], s[24], s[25], s[26])
    p0, p1, p2, p3, p4, p5, p6, p7, p8 = s[27], s[28], s[29], s[30], s[31], s[32], s[33], s[34], s[35]
    count, initialised = s[36], s[37]
    qv2, qgap2, qg2, rz, rn, gate, rs = s[I_PRM], s[I_PRM + 1], s[I_PRM + 2], s[I_PRM + 3], s[I_PRM + 4], \
        s[I_PRM + 5], s[I_PRM + 6]
    qgapg2 = s[I_QGAPG]
    d0, d1, d2, d3, d4, d5, d6, d7, d8 = d9
    dv0, dv1, dv2 = dv3
    count += 1.0
    r0, r1, r2 = p0 * d0 + p1 * d3 + p2 * d6, p0 * d1 + p1 * d4 + p2 * d7, p0 * d2 + p1 * d5 + p2 * d8
    r3, r4, r5 = p3 * d0 + p4 * d3 + p5 * d6, p3 * d1 + p4 * d4 + p5 * d7, p3 * d2 + p4 * d5 + p5 * d8
    r6, r7, r8 = p6 * d0 + p7 * d3 + p8 * d6, p6 * d1 + p7 * d4 + p8 * d7, p6 * d2 + p7 * d5 + p8 * d8
    if count % RENORM_EVERY == 0.0:
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = renormalise_flat((r0, r1, r2, r3, r4, r5, r6, r7, r8))
    w0, w1, w2 = p0 * dv0 + p1 * dv1 + p2 * dv2, p3 * dv0 + p4 * dv1 + p5 * dv2, p6 * dv0 + p7 * dv1 + p8 * dv2
    if not initialised:                         # gravity from the first frame's mean specific force
        g0, g1, g2 = w0 / dt, w1 / dt, w2 / dt
        initialised = 1.0
    v0, v1, v2 = v0 + w0 - dt * g0, v1 + w1 - dt * g1, v2 + w2 - dt * g2
    qv = (qv2 if valid else qv2 + qgap2) * dt
    qg = (qg2 if valid else qg2 + qgapg2) * dt
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
    zupt = 0
    ok, post, K, y, S = False, prior, _ZERO18, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if not isnan(speed):                        # measured forward speed along the body x axis (r0, r3, r6)
        ds = rs - rn
        ok, post, K, y, S = _velocity_update(prior, (rn + ds * r0 * r0, ds * r0 * r3, ds * r0 * r6, rn + ds * r3 * r3,
                                                     ds * r3 * r6, rn + ds * r6 * r6),
                                             speed * r0, speed * r3, speed * r6, np.inf)
        zupt = 2
    elif stationary:
        ok, post, K, y, S = _velocity_update(prior, (rz, 0.0, 0.0, rz, 0.0, rz), 0.0, 0.0, 0.0, gate)
        if ok:
            zupt = 1
        else:
            s[I_REJECTED] += 1.0                # a smooth cruise flagged as standstill: constraint instead
    if zupt:
        (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12,
         b20, b21, b22, c00, c01, c02, c11, c12, c22) = post
        for i in range(18):
            s[_I_K + i] = K[i]
        for i in range(3):
            s[_I_Y + i] = y[i]
        for i in range(6):
            s[_I_S + i] = S[i]
    else:
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
        Kc = (ky0, kz0, ky1, kz1, ky2, kz2, ky3, kz3, ky4, kz4, ky5, kz5)
        for i in range(12):
            s[_I_K + i] = Kc[i]
        s[_I_Y], s[_I_Y + 1] = e0, e1
        s[_I_S], s[_I_S + 1], s[_I_S + 2] = s00, s01, s11
    new = (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12, b20, b21, b22,
           c00, c01, c02, c11, c12, c22, r0, r1, r2, r3, r4, r5, r6, r7, r8, count, initialised)
    for i in range(38):
        s[i] = new[i]
    s[I_LAST], s[I_LAST + 1] = 1.0, float(zupt)
    s[_I_DT], s[_I_DT + 1], s[_I_DT + 2] = dt, qv, qg
    for i in range(27):
        s[_I_PRIOR + i] = prior[i]


@njit
def frame_forces(d9, dv3, dt, g0, g1, g2, rp, lever, r, wprev, wp):
    """Frame-mean specific force and acceleration (m/s^2, body frame at mid-frame) and mean rate (rad/s),
    ``(f0, f1, f2, a0, a1, a2, w0, w1, w2)``: ``g0..g2`` gravity after the frame (world), ``rp`` ``R_{w<-body}``
    before it, ``lever``/``r`` the lever arm (m, body), ``wprev``/``wp`` the previous frame's mean rate."""
    p0, p1, p2 = log_flat(d9)
    w0, w1, w2 = p0 / dt, p1 / dt, p2 / dt
    h0, h1, h2, h3, h4, h5, h6, h7, h8 = exp_flat(0.5 * p0, 0.5 * p1, 0.5 * p2)   # body_{k-1} <- mid
    u0, u1, u2 = dv3[0] / dt, dv3[1] / dt, dv3[2] / dt
    f0, f1, f2 = h0 * u0 + h3 * u1 + h6 * u2, h1 * u0 + h4 * u1 + h7 * u2, h2 * u0 + h5 * u1 + h8 * u2
    if lever:
        q0, q1, q2 = (wp[0], wp[1], wp[2]) if wprev else (w0, w1, w2)
        l0, l1, l2 = (w0 - q0) / dt, (w1 - q1) / dt, (w2 - q2) / dt
        ax, ay, az = l1 * r[2] - l2 * r[1], l2 * r[0] - l0 * r[2], l0 * r[1] - l1 * r[0]
        m0, m1, m2 = w1 * r[2] - w2 * r[1], w2 * r[0] - w0 * r[2], w0 * r[1] - w1 * r[0]   # w x r
        cx, cy, cz = w1 * m2 - w2 * m1, w2 * m0 - w0 * m2, w0 * m1 - w1 * m0
        f0, f1, f2 = f0 - ax - cx, f1 - ay - cy, f2 - az - cz
    q0, q1, q2 = (rp[0] * g0 + rp[3] * g1 + rp[6] * g2, rp[1] * g0 + rp[4] * g1 + rp[7] * g2,
                  rp[2] * g0 + rp[5] * g1 + rp[8] * g2)       # R_{k-1}^T g
    return (f0, f1, f2, f0 - (h0 * q0 + h3 * q1 + h6 * q2), f1 - (h1 * q0 + h4 * q1 + h7 * q2),
            f2 - (h2 * q0 + h5 * q1 + h8 * q2), w0, w1, w2)


@njit
def frame(s, d9, dv3, dt, stationary, valid, speed, sensor):
    """One frame (``sensor``: the buffer's extrinsic applied first): :func:`_predict_update`, then
    :func:`frame_forces` with the posterior gravity. Returns ``(f0, f1, f2, a0, a1, a2, |v|)``, ``d9``, ``dv3``."""
    if sensor and s[I_EXTR]:
        d9, dv3 = body_increment((s[55], s[56], s[57], s[58], s[59], s[60], s[61], s[62], s[63]), d9, dv3)
    rp = (s[27], s[28], s[29], s[30], s[31], s[32], s[33], s[34], s[35])
    _predict_update(s, d9, dv3, dt, stationary, valid, speed)
    f0, f1, f2, a0, a1, a2, w0, w1, w2 = frame_forces(d9, dv3, dt, s[3], s[4], s[5], rp, s[I_LEVER] != 0.0,
                                                      (s[51], s[52], s[53]), s[I_WPREV] != 0.0,
                                                      (s[39], s[40], s[41]))
    s[I_WPREV], s[I_WPREV + 1], s[I_WPREV + 2], s[I_WPREV + 3] = 1.0, w0, w1, w2
    return (f0, f1, f2, a0, a1, a2, sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])), d9, dv3


@njit
def _frame_of_arrays(s, d, dv, dt, stationary, valid, speed, sensor):
    """:func:`frame` of ``d`` (3, 3) or (9,) and ``dv`` (3,) float64 arrays: ``(f, a, |v|)``."""
    d = d.reshape(9)
    (f0, f1, f2, a0, a1, a2, sp), _, _ = frame(s, (d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7], d[8]),
                                               (dv[0], dv[1], dv[2]), dt, stationary, valid, speed, sensor)
    return (f0, f1, f2), (a0, a1, a2), sp


def _step(s: np.ndarray, d9, dv3, dt: float, stationary: bool, valid: bool, speed, out, sensor: bool):
    if not dt > 0.0:
        raise ValueError(f"dt must be > 0 s, got {dt!r}")
    if type(d9) is not np.ndarray or d9.dtype != _F64 or not d9.flags.c_contiguous:
        d9 = np.array(d9, dtype=float)
    if type(dv3) is not np.ndarray or dv3.dtype != _F64 or dv3.ndim != 1:
        dv3 = np.array(dv3, dtype=float).reshape(3)
    f, a, sp = _frame_of_arrays(s, d9, dv3, float(dt), stationary, valid, math.nan if speed is None else speed,
                                sensor)
    if out is None:
        return f, a, sp
    out[0:6] = s[0:6]
    out[6:9], out[9:12] = a, f
    return sp


def step_frame(s: np.ndarray, d9, dv3, dt: float, stationary: bool, valid: bool, speed: float, out=None):
    """One body-frame frame (:func:`frame`) on the buffer ``s``: arguments and returns as
    :meth:`~imu_ground.filters.gravity_velocity.GravityVelocityFilter.step_body` (``dt`` > 0, else ValueError);
    ``out`` (12,), optional, receives ``[v, g, acceleration, specific_force]`` and only ``|v|`` is returned."""
    return _step(s, d9, dv3, dt, stationary, valid, speed, out, False)


def to_body(s: np.ndarray, d9, dv3):
    """One sensor-frame frame ``(d9, dv3)`` in the body frame (the buffer's extrinsic, :func:`body_increment`)."""
    return body_increment(s[I_EXTR + 1:I_EXTR + 10].tolist(), d9, dv3) if s[I_EXTR] else (tuple(d9), tuple(dv3))


def step_sensor(s: np.ndarray, d9, dv3, dt: float, stationary: bool, valid: bool, speed: float, out=None):
    """:func:`step_frame` of a sensor-frame frame (the extrinsic of the buffer applied first)."""
    return _step(s, d9, dv3, dt, stationary, valid, speed, out, True)


@njit
def _run(s, d, dv, dt, stationary, valid, speed, rows, fa, priors, has_priors, body, sensor):
    for k in range(dt.shape[0]):
        (f0, f1, f2, a0, a1, a2, sp), d9, dv3 = frame(
            s, (d[k, 0], d[k, 1], d[k, 2], d[k, 3], d[k, 4], d[k, 5], d[k, 6], d[k, 7], d[k, 8]),
            (dv[k, 0], dv[k, 1], dv[k, 2]), dt[k], stationary[k], valid[k], speed[k], sensor)
        for i in range(36):
            rows[k, i] = s[i]
        fa[k, 0], fa[k, 1], fa[k, 2], fa[k, 3], fa[k, 4], fa[k, 5], fa[k, 6] = f0, f1, f2, a0, a1, a2, sp
        if has_priors:
            for i in range(27):
                priors[k, i] = s[_I_PRIOR + i]
        if sensor:
            for i in range(9):
                body[k, i] = d9[i]


def run_frames(s: np.ndarray, d, dv, dt, stationary, valid, speed, v_out, g_out, p_out, cum_out, f_out, a_out,
               speed_out, priors=None, body_out=None) -> None:
    """:func:`frame` over a drive (a compiled loop) into the output arrays (N, ...); ``priors`` (N, 27): each
    frame's prior (for the smoother); with ``body_out`` (N, 3, 3) the increments are sensor-frame and their
    body-frame values written there; ``speed`` None or NaN: none."""
    n = len(dt)
    if not n:
        return
    d = np.ascontiguousarray(d, dtype=float).reshape(n, 9)
    dv, dt = np.ascontiguousarray(dv, dtype=float).reshape(n, 3), np.ascontiguousarray(dt, dtype=float)
    st, va = (np.ascontiguousarray(a, dtype=np.bool_).reshape(n) for a in (stationary, valid))
    sp = np.full(n, math.nan) if speed is None else np.ascontiguousarray(speed, dtype=float)
    rows, fa = np.empty((n, 36)), np.empty((n, 7))
    pri = np.empty((n, 27)) if priors is None else priors
    body = np.empty((n, 9))
    _run(s, d, dv, dt, st, va, sp, rows, fa, pri, priors is not None, body, body_out is not None)
    v_out[...], g_out[...], p_out[...] = rows[:, :3], rows[:, 3:6], full_cov(rows[:, 6:27])
    cum_out[...] = rows[:, 27:].reshape(n, 3, 3)
    f_out[...], a_out[...], speed_out[...] = fa[:, 0:3], fa[:, 3:6], fa[:, 6]
    if body_out is not None:
        body_out[...] = (body if s[I_EXTR] else d).reshape(n, 3, 3)


@njit
def _forces(d, dv, dt, g, r_start, cum, lever, r, wprev, wp, out):
    for k in range(dt.shape[0]):
        if k == 0:
            rp = (r_start[0], r_start[1], r_start[2], r_start[3], r_start[4], r_start[5], r_start[6], r_start[7],
                  r_start[8])
        else:
            rp = (cum[k - 1, 0], cum[k - 1, 1], cum[k - 1, 2], cum[k - 1, 3], cum[k - 1, 4], cum[k - 1, 5],
                  cum[k - 1, 6], cum[k - 1, 7], cum[k - 1, 8])
        f0, f1, f2, a0, a1, a2, w0, w1, w2 = frame_forces(
            (d[k, 0], d[k, 1], d[k, 2], d[k, 3], d[k, 4], d[k, 5], d[k, 6], d[k, 7], d[k, 8]),
            (dv[k, 0], dv[k, 1], dv[k, 2]), dt[k], g[k, 0], g[k, 1], g[k, 2], rp, lever, r, wprev,
            (wp[0], wp[1], wp[2]))
        out[k, 0], out[k, 1], out[k, 2], out[k, 3], out[k, 4], out[k, 5] = f0, f1, f2, a0, a1, a2
        wp[0], wp[1], wp[2] = w0, w1, w2
        wprev = True


def body_forces(d, dv, dt, g, r_start, cum, lever=None, w_prev=None):
    """:func:`frame_forces` of every frame of a drive (a smoothed gravity's): ``r_start`` ``R_{w<-body}`` before
    the first frame, ``cum`` after each, ``w_prev`` the mean rate before (None: its own). Returns ``f``, ``acc``
    (N, 3), m/s^2, and the last mean rate."""
    n = len(dt)
    c = lambda a, shape: np.ascontiguousarray(a, dtype=float).reshape(shape)  # noqa: E731
    out, wp = np.empty((n, 6)), (np.zeros(3) if w_prev is None else c(w_prev, 3).copy())
    _forces(c(d, (n, 9)), c(dv, (n, 3)), c(dt, n), c(g, (n, 3)), c(r_start, 9), c(cum, (n, 9)), lever is not None,
            (0.0, 0.0, 0.0) if lever is None else tuple(float(v) for v in lever), w_prev is not None, wp, out)
    return out[:, :3], out[:, 3:], wp.tolist()
