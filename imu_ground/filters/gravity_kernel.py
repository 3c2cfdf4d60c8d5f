"""The gravity/velocity filter's per-frame kernel in pure Python: the reference its C twin is tested against.

:class:`~imu_ground.filters.gravity_velocity.GravityVelocityFilter` keeps its whole
state in one flat buffer ``s`` (layout below: a ``list`` for this module, a float64
``ndarray`` for the compiled twin ``imu_ground.filters._gravity_native``, built
from ``_gravity_native.c``) and calls :func:`step_frame` / :func:`step_sensor`
(one frame) or :func:`run_frames` (a drive) of whichever kernel is loaded; both
kernels run the same recursion :func:`_predict_update` in the same operation
order, and are held to the twin rule of :mod:`imu_ground._native` (this module's
:func:`run_frames` computes the forces vectorised, :func:`body_forces`: they round
differently in the last bit from the C's frame by frame).

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

Every entry is a float in both kernels (filterpy's ``Saver`` stores the buffer as an array). The
constraint's K, y and S fill the first 12, 2 and 3 of their slots; the rest keep their values.
"""
from __future__ import annotations

import math
from array import array
from math import isnan

import numpy as np

from imu_ground import so3
from imu_ground.so3 import exp_flat, log_flat, mul_flat, mul_nt_flat, renormalise_flat
from imu_ground.units import RENORM_EVERY

__all__ = ["BUF_LEN", "I_EXTR", "I_INIT", "I_LAST", "I_LEVER", "I_PRM", "I_REJECTED", "I_WPREV", "body_forces",
           "body_increment", "body_increments", "full_cov", "new_state", "run_frames", "step_frame", "step_sensor",
           "to_body"]

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


def full_cov(p21: np.ndarray) -> np.ndarray:
    """(..., 21) unique entries -> (..., 6, 6) symmetric covariances."""
    return np.asarray(p21)[..., _FULL_INDEX]


def new_state(x6, p21, r9, prm7, initialised: bool, lever=None, extrinsic9=None, q_gap_g2: float = 0.0) -> list:
    """A fresh state buffer (list, layout of the module docstring).

    Parameters
    ----------
    x6, p21, r9 : sequences of 6, 21 and 9 floats
        ``[v, g]``, P's unique entries, ``R0`` row-major.
    prm7 : sequence of 7 floats
        ``q_v^2, q_gap^2, q_g^2, sigma_zupt^2, sigma_nhc^2, zupt_gate, sigma_speed^2``.
    initialised : bool
        Gravity given (else taken from the first frame's specific force).
    lever, extrinsic9 : sequences of 3 and 9 floats, optional
        Lever arm (m) and ``R_gs`` (row-major); None: none.
    q_gap_g2 : float
        Gravity random walk added through a timestamp gap, (m/s^2)^2 per s.
    """
    s = [float(v) for v in x6] + [float(v) for v in p21] + [float(v) for v in r9] + [0.0]
    s += [1.0 if initialised else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0] + [float(v) for v in prm7]
    s += [0.0, 0.0, 0.0, 0.0] if lever is None else [1.0] + [float(v) for v in lever]
    s += [0.0] * 10 if extrinsic9 is None else [1.0] + [float(v) for v in extrinsic9]
    s += [float(RENORM_EVERY), so3.SMALL_ANGLE] + [0.0] * (I_QGAPG - I_LAST) + [float(q_gap_g2)]
    return s


def _record_last(s: list, last) -> None:
    """Write :func:`_predict_update`'s last step ``(kind, K, y, S, dt, qv, qg, prior)`` into ``s[66:125]`` as floats."""
    kind, K, y, S, dt, qv, qg, prior = last
    s[I_LAST], s[I_LAST + 1] = 1.0, float(kind)
    s[_I_K:_I_K + len(K)] = K
    s[_I_Y:_I_Y + len(y)] = y
    s[_I_S:_I_S + len(S)] = S
    s[_I_DT:_I_DT + 3] = float(dt), qv, qg
    s[_I_PRIOR:_I_PRIOR + 27] = prior


def body_increment(r9, d9, dv3):
    """``(R d R^T, R dv)`` of one frame as plain floats: sensor -> body with ``R = R_gs`` (9 row-major)."""
    return mul_nt_flat(mul_flat(r9, d9), r9), (r9[0] * dv3[0] + r9[1] * dv3[1] + r9[2] * dv3[2],
                                               r9[3] * dv3[0] + r9[4] * dv3[1] + r9[5] * dv3[2],
                                               r9[6] * dv3[0] + r9[7] * dv3[1] + r9[8] * dv3[2])


def _predict_update(s, frames, out=None, priors=None):
    """The filter's recursion over frames: one kernel for :meth:`GravityVelocityFilter.step` and ``run``.

    Unrolled scalar arithmetic on the state buffer ``s`` (module docstring: velocity,
    gravity, the 21 unique entries of P in ``_UPPER21`` order, ``R_{w<-body_k}`` as 9
    floats row-major, the frame count, the gravity-initialised flag, the rejected
    standstill flags, the noise parameters), updated in place. ``frames``: ``(d9, dv3, dt,
    stationary, valid, speed)`` per frame, body frame (``speed`` NaN: none). Per frame: the
    cumulative attitude (renormalised every ``RENORM_EVERY`` frames), the
    predict ``v += R_{k-1} dv - dt g``, ``P <- F P F^T + Q`` (written out for
    ``F = [[I, -dt I], [0, I]]`` and isotropic ``Q``), then the update with the
    body velocity (:func:`_velocity_update`): a measured forward ``speed`` as ``R_k^T v = (speed, 0,
    0)``, else the gated zero-velocity update, else the non-holonomic constraint on the body y and z
    axes, ``P <- P - K S K^T``. ``out`` (``array('d')``) receives the posterior state and ``R_k`` (36
    floats a frame), ``priors`` the prior state (27). Returns the last frame's ``(kind, K, y, S, dt,
    qv, qg, prior)`` (kind 0 constraint, 1 ZUPT, 2 speed), None without frames.
    """
    (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12, b20, b21, b22,
     c00, c01, c02, c11, c12, c22, r0, r1, r2, r3, r4, r5, r6, r7, r8, count, initialised) = s[:38]
    qv2, qgap2, qg2, rz, rn, gate, rs = s[I_PRM:I_PRM + 7]
    qgapg2 = s[I_QGAPG]
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
    s[:38] = (v0, v1, v2, g0, g1, g2, a00, a01, a02, a11, a12, a22, b00, b01, b02, b10, b11, b12, b20, b21, b22,
              c00, c01, c02, c11, c12, c22, r0, r1, r2, r3, r4, r5, r6, r7, r8, count, initialised)
    s[I_REJECTED] += rejected
    return last


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


def body_increments(r, d, dv):
    """:func:`body_increment` of many frames, vectorised: ``d`` (..., 3, 3), ``dv`` (..., 3), ``r`` (3, 3).

    Summed in :func:`body_increment`'s order (one rounding per product and sum, no
    matrix-product library), so each frame equals the scalar result bit for bit.
    """
    r = np.asarray(r, dtype=float)
    d, dv = np.asarray(d, dtype=float), np.asarray(dv, dtype=float)
    t = (r[:, 0, None] * d[..., None, 0, :] + r[:, 1, None] * d[..., None, 1, :]) + r[:, 2, None] * d[..., None, 2, :]
    b = (t[..., :, 0, None] * r[:, 0] + t[..., :, 1, None] * r[:, 1]) + t[..., :, 2, None] * r[:, 2]
    return b, (dv[..., 0, None] * r[:, 0] + dv[..., 1, None] * r[:, 1]) + dv[..., 2, None] * r[:, 2]


def step_frame(s: list, d9, dv3, dt: float, stationary: bool, valid: bool, speed: float, out=None):
    """One body-frame frame: :func:`_predict_update`, then the frame's mean forces (the C twin's ``step_frame``).

    Parameters
    ----------
    s : list
        The state buffer (module docstring), updated in place.
    d9, dv3 : sequences of 9 and 3 floats
        ``R_{body_{k-1}<-body_k}`` row-major; gravity-free velocity increment (body_{k-1}, m/s).
    dt : float
        Frame duration, s (> 0, else ValueError; nothing else is checked).
    stationary, valid : bool
        Standstill at the frame's end; False through a timestamp gap.
    speed : float or None
        Measured forward speed, m/s (None or NaN: none).
    out : ndarray (12,), optional
        Receives ``[v, g, acceleration, specific_force]``; only ``|v|`` is returned then.

    Returns
    -------
    specific_force, acceleration : tuple of 3 floats
        Frame means in the body frame at mid-frame, m/s^2 (lever arm applied, posterior gravity).
    speed : float
        ``|v|`` after the update, m/s.
    """
    if not dt > 0.0:
        raise ValueError(f"dt must be > 0 s, got {dt!r}")
    rprev = s[27:36]
    _record_last(s, _predict_update(s, ((d9, dv3, dt, stationary, valid,
                                         math.nan if speed is None else float(speed)),)))
    p0, p1, p2 = log_flat(d9)
    w = (p0 / dt, p1 / dt, p2 / dt)
    h0, h1, h2, h3, h4, h5, h6, h7, h8 = exp_flat(0.5 * p0, 0.5 * p1, 0.5 * p2)   # body_{k-1} <- mid
    u0, u1, u2 = dv3[0] / dt, dv3[1] / dt, dv3[2] / dt
    f0, f1, f2 = h0 * u0 + h3 * u1 + h6 * u2, h1 * u0 + h4 * u1 + h7 * u2, h2 * u0 + h5 * u1 + h8 * u2
    if s[I_LEVER]:
        r = s[I_LEVER + 1:I_LEVER + 4]
        wp = s[I_WPREV + 1:I_WPREV + 4] if s[I_WPREV] else w
        al = ((w[0] - wp[0]) / dt, (w[1] - wp[1]) / dt, (w[2] - wp[2]) / dt)
        ax, ay, az = al[1] * r[2] - al[2] * r[1], al[2] * r[0] - al[0] * r[2], al[0] * r[1] - al[1] * r[0]
        m0, m1, m2 = w[1] * r[2] - w[2] * r[1], w[2] * r[0] - w[0] * r[2], w[0] * r[1] - w[1] * r[0]   # w x r
        cx, cy, cz = w[1] * m2 - w[2] * m1, w[2] * m0 - w[0] * m2, w[0] * m1 - w[1] * m0
        f0, f1, f2 = f0 - ax - cx, f1 - ay - cy, f2 - az - cz
    s[I_WPREV:I_WPREV + 4] = (1.0,) + w
    v0, v1, v2, g0, g1, g2 = s[:6]
    q0, q1, q2 = (rprev[0] * g0 + rprev[3] * g1 + rprev[6] * g2, rprev[1] * g0 + rprev[4] * g1 + rprev[7] * g2,
                  rprev[2] * g0 + rprev[5] * g1 + rprev[8] * g2)       # R_{k-1}^T g
    f, a = (f0, f1, f2), (f0 - (h0 * q0 + h3 * q1 + h6 * q2), f1 - (h1 * q0 + h4 * q1 + h7 * q2),
                          f2 - (h2 * q0 + h5 * q1 + h8 * q2))
    speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if out is None:
        return f, a, speed
    out[:] = s[0:6] + list(a + f)
    return speed


def to_body(s: list, d9, dv3):
    """One sensor-frame frame ``(d9, dv3)`` in the body frame (the buffer's extrinsic, :func:`body_increment`)."""
    return body_increment(s[I_EXTR + 1:I_EXTR + 10], d9, dv3) if s[I_EXTR] else (tuple(d9), tuple(dv3))


def step_sensor(s: list, d9, dv3, dt: float, stationary: bool, valid: bool, speed: float, out=None):
    """:func:`step_frame` of a sensor-frame frame (the extrinsic of the buffer applied first)."""
    if s[I_EXTR]:
        d9, dv3 = body_increment(s[I_EXTR + 1:I_EXTR + 10], d9, dv3)
    return step_frame(s, d9, dv3, dt, stationary, valid, speed, out)


def run_frames(s: list, d, dv, dt, stationary, valid, speed, v_out, g_out, p_out, cum_out, f_out, a_out,
               speed_out, priors=None, body_out=None) -> None:
    """A drive into output arrays (the C twin's ``run_frames``).

    Parameters
    ----------
    s : list
        The state buffer, updated in place (as after the last frame of :func:`step_frame`).
    d, dv, dt, stationary, valid : ndarray (N, 3, 3), (N, 3), (N,), (N,) bool, (N,) bool
        Body-frame increments (sensor frame with ``body_out``; C-contiguous float64; bool flags).
    speed : ndarray (N,) or None
        Measured forward speed, m/s (NaN: none).
    v_out, g_out, p_out, cum_out, f_out, a_out, speed_out : ndarray
        (N, 3), (N, 3), (N, 6, 6), (N, 3, 3), (N, 3), (N, 3), (N,): posterior velocity and gravity,
        covariance, ``R_k``, specific force and acceleration (:func:`step_frame`), ``|v|``.
    priors : ndarray (N, 27), optional
        The prior state and P's unique entries of each frame (for the smoother).
    body_out : ndarray (N, 3, 3), optional
        Given: ``d``, ``dv`` are sensor-frame, turned into the body frame with the buffer's extrinsic
        (``R_gs d R_gs^T``, ``R_gs dv``), and the body-frame ``d`` is written here.
    """
    n = len(dt)
    if body_out is not None:
        if s[I_EXTR]:
            d, dv = body_increments(np.reshape(s[I_EXTR + 1:I_EXTR + 10], (3, 3)), d, dv)
        body_out[...] = d
    sp = [math.nan] * n if speed is None else np.asarray(speed, dtype=float).tolist()
    frames = list(zip(np.reshape(d, (n, 9)).tolist(), np.asarray(dv).tolist(), np.asarray(dt).tolist(),
                      np.asarray(stationary).tolist(), np.asarray(valid).tolist(), sp, strict=True))
    r_start, w_prev = s[27:36], s[I_WPREV:I_WPREV + 4]
    out, pri = array("d"), (array("d") if priors is not None else None)
    last = _predict_update(s, frames, out, pri)
    if not n:
        return
    _record_last(s, last)
    rows = np.frombuffer(out, dtype=float).reshape(n, 36)
    v_out[...], g_out[...], p_out[...] = rows[:, :3], rows[:, 3:6], full_cov(rows[:, 6:27])
    cum_out[...] = rows[:, 27:].reshape(n, 3, 3)
    speed_out[...] = np.linalg.norm(rows[:, :3], axis=1)
    if priors is not None:
        assert pri is not None                  # made with priors
        priors[...] = np.frombuffer(pri, dtype=np.float64).reshape(n, 27)
    lever = s[I_LEVER + 1:I_LEVER + 4] if s[I_LEVER] else None
    f, acc, w_last = body_forces(d, dv, dt, g_out, np.reshape(r_start, (3, 3)), cum_out, lever,
                                 w_prev[1:] if w_prev[0] else None)
    f_out[...], a_out[...] = f, acc
    s[I_WPREV:I_WPREV + 4] = [1.0] + w_last


def body_forces(d, dv, dt, g, r_start, cum, lever=None, w_prev=None):
    """Frame-mean specific force and acceleration of a drive, body frame at mid-frame (vectorised).

    Parameters
    ----------
    d, dv, dt : ndarray (N, 3, 3), (N, 3), (N,)
        Body-frame increments and durations (s).
    g : ndarray (N, 3)
        Gravity reaction after each frame (posterior or smoothed), world frame, m/s^2.
    r_start, cum : ndarray (3, 3), (N, 3, 3)
        ``R_{w<-body}`` before the first frame and after each frame.
    lever : sequence of 3 floats, optional
        Lever arm, m (body frame).
    w_prev : sequence of 3 floats, optional
        Mean body rate of the frame before the first, rad/s (None: the first frame's own).

    Returns
    -------
    f, acc : ndarray (N, 3)
        m/s^2, as :func:`step_frame`.
    w_last : list of 3 floats
        The last frame's mean rate, rad/s.
    """
    phi = so3.log(d)
    w = phi / dt[:, None]
    half = so3.exp(0.5 * phi)                  # body_{k-1} <- body at mid-frame
    f = np.einsum("nji,nj->ni", half, dv / dt[:, None])
    if lever is not None:
        wp = np.concatenate([[w[0] if w_prev is None else w_prev], w[:-1]])
        r = np.asarray(lever, dtype=float)
        f = f - np.cross((w - wp) / dt[:, None], r) - np.cross(w, np.cross(w, r))
    r_prev = np.concatenate([r_start[None], cum[:-1]])
    acc = f - np.einsum("nji,nj->ni", half, np.einsum("nji,nj->ni", r_prev, g))
    return f, acc, w[-1].tolist()
