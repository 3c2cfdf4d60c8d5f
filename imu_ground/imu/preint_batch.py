"""Batch preintegration of a whole log into frames, vectorised (no Python loop over samples).

Fused batched ``Exp`` and left Jacobians, a log-depth (Hillis-Steele) product
scan for ``delta_R`` within each frame, cumulative sums for ``delta_v``/``delta_p``,
and the closed-form solution of the covariance and Jacobian recursions,
``sum_k G_k Q_k G_k^T`` and ``sum_k G_k``, where ``G_k`` is the sensitivity of the
frame's deltas to the noise of interval ``k`` (see :func:`_blocks_kernel`). The
only Python loop runs over chunks of about 32k intervals, to keep the
temporaries in cache. Frames with many more intervals than the others are cut
into blocks that are merged with the associative composition
:func:`~imu_ground.imu.preint_measurement.compose_left` (a log-depth tree).
The knots, held values and gap rules are those of the module docstring of
:mod:`imu_ground.imu.preintegration`, as in the streaming front-end.

Without uncertainty (the whole job's path) each frame's deltas are those of the
streaming front-end: its kernel (:func:`~imu_ground.imu.preint_kernel.integrate`)
run over the frame's knots in one compiled loop (:func:`_frames_deltas`, through
:mod:`imu_ground._jit`), reading the knots' values where they are.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from imu_ground._jit import njit
from imu_ground.errors import ImuGroundError
from imu_ground.imu.data import ImuData
from imu_ground.imu.preint_frames import FrameDeltas, make_frame_times
from imu_ground.imu.preint_kernel import integrate
from imu_ground.imu.preint_measurement import compose_left, left_to_right
from imu_ground.imu.preint_params import PreintegrationParams, gap_message
from imu_ground.so3.conversions import matrix_from_quat
from imu_ground.so3.component_major import (
    cross_rows,
    exp_and_left_jacobian,
    hat_times,
    mm,
    project_if_needed,
    scan_products,
)

__all__ = ["preintegrate"]

_CHUNK = 1 << 15         # intervals per vectorised chunk (cache-sized temporaries)


def _running_sum(x: np.ndarray, axis: int) -> np.ndarray:
    """``np.cumsum(x, axis)`` along a short axis (a block's intervals): one vectorised add over the blocks per step.

    The same additions in the same order as ``cumsum`` (equal to the bit), without its per-lane
    loop over a strided axis, which is several times slower on these shapes.
    """
    out = np.array(x, dtype=float)
    v = np.moveaxis(out, axis, 0)
    for k in range(1, v.shape[0]):
        v[k] += v[k - 1]
    return out


def _blocks_kernel(dt: np.ndarray, w: np.ndarray, f: np.ndarray, qg: float, qa: float) -> tuple:
    """Preintegrate padded blocks of intervals in closed form, left-error form.

    Parameters are component-major, interval index before block index (so that
    every elementwise operation runs over long contiguous rows): ``dt`` (L, B)
    with zeros as padding, ``w`` and ``f`` (3, L, B) bias-corrected held rate and
    specific force. Interval ``k``
    of a block has rotation ``Rk`` before it, rotated velocity increment ``c_k``,
    deltas ``V_k``/``P_k`` after it and ends at ``e_k``; with ``xv_k = v_n - V_k`` and
    ``xp_k = p_n - P_k - V_k (T - e_k)`` a left rotation perturbation ``u`` at the end
    of interval ``k`` moves ``(dtheta, dv, dp)`` by ``(u, -hat(xv_k) u, -hat(xp_k) u)``.
    Hence, with ``U_k = Rk Jl(phi_k) dt_k``:

    - Jacobians: ``Th = -sum U_k``, ``Vg = sum hat(xv_k) U_k``, ``Pg = sum hat(xp_k) U_k``,
      ``Va = -sum Rk dt_k``, ``Pa = -sum Rk dt_k (T - e_k + dt_k / 2)``;
    - covariance: ``sum_k G_k Q_k G_k^T`` with ``W_k = q_g U_k U_k^T / dt_k``
      (rotation rows) and the isotropic accelerometer terms.

    Returns (T, R, v, p, J, S) with shapes (B,), (B,3,3), (B,3), (B,3), (B,9,6), (B,9,9);
    """
    L, nb = dt.shape
    phi = w * dt
    E, Jl = exp_and_left_jacobian(phi[0], phi[1], phi[2], jacobian=True)
    del phi
    P = scan_products(E)                                   # delta_R after interval k
    del E
    Rk = np.empty_like(P)                                   # delta_R before interval k
    Rk[:, :, 0] = np.eye(3)[:, :, None]
    Rk[:, :, 1:] = P[:, :, :-1]
    fd = f * dt
    c = np.empty_like(fd)
    for i in range(3):
        c[i] = Rk[i, 0] * fd[0] + Rk[i, 1] * fd[1] + Rk[i, 2] * fd[2]
    del fd
    V = _running_sum(c, 1)                                  # delta_v after interval k
    Vb = np.empty_like(V)                                   # ... and before
    Vb[:, 0] = 0.0
    Vb[:, 1:] = V[:, :-1]
    Pp = _running_sum(dt * (Vb + 0.5 * c), 1)               # delta_p after interval k
    del Vb, c
    e = _running_sum(dt, 0)                                 # end time of interval k
    T = e[-1].copy()
    Rn = np.ascontiguousarray(P[:, :, -1].transpose(2, 0, 1))
    vn = np.ascontiguousarray(V[:, -1].T)
    pn = np.ascontiguousarray(Pp[:, -1].T)
    assert Jl is not None                                  # jacobian=True
    Uo = mm(Rk, Jl)                                        # U / dt
    del Jl, P
    U = Uo * dt
    xv = vn.T[:, None, :] - V
    rem = T[None, :] - e                                    # time left after interval k
    xp = pn.T[:, None, :] - Pp - V * rem
    del V, Pp
    wa = dt * (rem + 0.5 * dt)                              # dt (T - midpoint of interval k)
    J = np.zeros((nb, 9, 6))
    J[:, 0:3, 0:3] = -U.sum(axis=2).transpose(2, 0, 1)
    J[:, 3:6, 0:3] = hat_times(xv, U).sum(axis=2).transpose(2, 0, 1)
    J[:, 6:9, 0:3] = hat_times(xp, U).sum(axis=2).transpose(2, 0, 1)
    J[:, 3:6, 3:6] = -(Rk * dt).sum(axis=2).transpose(2, 0, 1)
    J[:, 6:9, 3:6] = -(Rk * wa).sum(axis=2).transpose(2, 0, 1)
    S = np.zeros((nb, 9, 9))
    if qg != 0.0:
        # W = q_g dt Uo Uo^T (symmetric); rv = sum W hat(xv), rp = sum W hat(xp),
        # vv = sum hat(xv) W hat(xv)^T = -sum hat(xv) (W hat(xv)), vp, pp alike.
        W = np.empty((3, 3, L, nb))
        qdt = qg * dt
        for i in range(3):
            for j in range(i, 3):
                W[i, j] = (Uo[i, 0] * Uo[j, 0] + Uo[i, 1] * Uo[j, 1] + Uo[i, 2] * Uo[j, 2]) * qdt
                if j != i:
                    W[j, i] = W[i, j]
        M1 = cross_rows(W, xv)
        M2 = cross_rows(W, xp)
        S[:, 0:3, 0:3] = W.sum(axis=2).transpose(2, 0, 1)
        S[:, 0:3, 3:6] = M1.sum(axis=2).transpose(2, 0, 1)
        S[:, 0:3, 6:9] = M2.sum(axis=2).transpose(2, 0, 1)
        S[:, 3:6, 3:6] = -hat_times(xv, M1).sum(axis=2).transpose(2, 0, 1)
        S[:, 3:6, 6:9] = -hat_times(xv, M2).sum(axis=2).transpose(2, 0, 1)
        S[:, 6:9, 6:9] = -hat_times(xp, M2).sum(axis=2).transpose(2, 0, 1)
        S[:, 3:6, 0:3] = S[:, 0:3, 3:6].transpose(0, 2, 1)
        S[:, 6:9, 0:3] = S[:, 0:3, 6:9].transpose(0, 2, 1)
        S[:, 6:9, 3:6] = S[:, 3:6, 6:9].transpose(0, 2, 1)
    if qa != 0.0:
        s0 = qa * T
        s1 = qa * wa.sum(axis=0)
        s2 = qa * (wa * (rem + 0.5 * dt)).sum(axis=0)
        i3 = np.arange(3)
        S[:, 3 + i3, 3 + i3] += s0[:, None]
        S[:, 3 + i3, 6 + i3] += s1[:, None]
        S[:, 6 + i3, 3 + i3] += s1[:, None]
        S[:, 6 + i3, 6 + i3] += s2[:, None]
    return T, Rn, vn, pn, J, 0.5 * (S + S.transpose(0, 2, 1))


@njit
def _knot(gyro: np.ndarray, accel: np.ndarray, ki: np.ndarray, yb: np.ndarray, g: int, at: int,
          o: np.ndarray) -> int:
    """The 6 values of knot ``g`` (position in the samples with the boundaries inserted, see :func:`_knots`)
    into ``o``; ``at`` is the number of boundaries before the knot looked up last (returned updated: cheapest
    when ``g`` never decreases from call to call)."""
    m = ki.size
    while at > 0 and ki[at - 1] + (at - 1) >= g:
        at -= 1
    while at < m and ki[at] + at < g:
        at += 1
    if at < m and ki[at] + at == g:
        for r in range(6):
            o[r] = yb[r, at]
        return at
    s = g - at
    for r in range(3):
        o[r] = gyro[s, r]
        o[3 + r] = accel[s, r]
    return at


@njit
def _frames_deltas(dt: np.ndarray, gyro: np.ndarray, accel: np.ndarray, ki: np.ndarray, yb: np.ndarray, j0: int,
                   b: np.ndarray, bias: np.ndarray, midpoint: bool, out: np.ndarray) -> None:
    """Each frame's deltas by the streaming front-end's kernel (:func:`~imu_ground.imu.preint_kernel.integrate`),
    interval after interval, as :class:`~imu_ground.imu.live.preint_stream.StreamingPreintegrator` integrates them.

    Frame ``f`` integrates the knot intervals ``[b[f], b[f + 1])`` of ``dt`` (s); knot ``j`` of ``dt`` is
    knot ``j0 + j`` of the samples ``gyro``, ``accel`` (N, 3; rad/s, m/s^2, body frame) with the boundaries
    ``yb`` (6, M) inserted before samples ``ki`` (:func:`_knots`). Held value, less ``bias`` (6): the two
    knots' mean (``midpoint``) or the left knot's. Out: ``out[f]`` the 11 floats of the deltas
    (layout in :mod:`imu_ground.imu.preint_kernel`).
    """
    s = np.empty(11)
    none = np.zeros(0)
    a = np.empty(6)
    c = np.empty(6)
    at = 0
    for f in range(b.size - 1):
        s[:] = 0.0
        s[1] = 1.0                              # identity quaternion
        at = _knot(gyro, accel, ki, yb, j0 + b[f], at, a)
        for r in range(6):
            a[r] = a[r] - bias[r]
        for j in range(b[f], b[f + 1]):
            at = _knot(gyro, accel, ki, yb, j0 + j + 1, at, c)
            for r in range(6):
                c[r] = c[r] - bias[r]
            h = dt[j]
            if midpoint:                        # mean of the two knots, the 1/2 folded into dt
                hh = 0.5 * h
                integrate(s, none, h, (a[0] + c[0]) * hh, (a[1] + c[1]) * hh, (a[2] + c[2]) * hh,
                          (a[3] + c[3]) * hh, (a[4] + c[4]) * hh, (a[5] + c[5]) * hh, 0.0, 0.0)
            else:                               # the left knot's value
                integrate(s, none, h, a[0] * h, a[1] * h, a[2] * h, a[3] * h, a[4] * h, a[5] * h, 0.0, 0.0)
            a[:] = c
        out[f] = s


def _merge_blocks(res: tuple, block_frame: np.ndarray, n_frames: int) -> tuple:
    """Merge consecutive blocks of the same frame with a log-depth tree of compositions."""
    counts = np.bincount(block_frame, minlength=n_frames)
    if np.all(counts == 1):
        return res
    first = np.concatenate([[0], np.cumsum(counts)[:-1]])
    multi = np.flatnonzero(counts > 1)
    width = int(counts.max())
    pos = np.arange(block_frame.size) - first[block_frame]
    # padded (n_multi, width) table of blocks with identity padding
    sel = np.isin(block_frame, multi)
    row = np.searchsorted(multi, block_frame[sel])
    col = pos[sel]

    def pad(x, ident):
        out = np.broadcast_to(ident, (multi.size, width) + ident.shape).copy()
        out[row, col] = x[sel]
        return out

    ident: tuple[np.ndarray | np.float64, ...] = (np.float64(0.0), np.eye(3), np.zeros(3), np.zeros(3), np.zeros((9, 6)), np.zeros((9, 9)))
    cur = [pad(x, i) for x, i in zip(res, ident, strict=True)]
    while cur[0].shape[1] > 1:
        if cur[0].shape[1] % 2:
            cur = [np.concatenate([x, np.broadcast_to(i, (x.shape[0], 1) + i.shape)], axis=1)
                   for x, i in zip(cur, ident, strict=False)]
        a = tuple(x[:, 0::2] for x in cur)
        b = tuple(x[:, 1::2] for x in cur)
        cur = list(compose_left(a, b))
    out = []
    single = counts == 1
    for x, c in zip(res, cur, strict=True):
        o = np.empty((n_frames,) + x.shape[1:])
        o[single] = x[first[single]]
        o[multi] = c[:, 0]
        out.append(o)
    return tuple(out)


def _validate_times(t: np.ndarray) -> None:
    if t.ndim != 1 or t.size < 2:
        raise ImuGroundError(f"need at least 2 samples, got t of shape {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("IMU timestamps contain NaN or inf")
    d = np.diff(t)
    bad = np.flatnonzero(~(d > 0))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"IMU timestamps must be strictly increasing: t[{i + 1}] = {t[i + 1]!r} s comes after "
            f"t[{i}] = {t[i]!r} s ({bad.size} non-increasing step(s)); drop non-increasing samples "
            f"upstream (validation) before preintegrating")


def _inputs(imu: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, gyro, accel) as float arrays from an ImuData or a tuple, checked."""
    if isinstance(imu, ImuData):
        t, gyro, accel = imu.t, imu.gyro, imu.accel
    else:
        t, gyro, accel = imu
    t = np.ascontiguousarray(t, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    accel = np.asarray(accel, dtype=float)
    if gyro.shape != (t.size, 3) or accel.shape != (t.size, 3):
        raise ValueError(f"gyro and accel must have shape ({t.size}, 3), got {gyro.shape}, {accel.shape}")
    _validate_times(t)
    return t, gyro, accel


def _boundaries(t: np.ndarray, frame_times: Any, rate: float | None, every: int | None,
                t_origin: float | None, snap_tol: float) -> np.ndarray:
    """Frame boundaries (F + 1,) inside the log, checked."""
    if frame_times is None:
        T = make_frame_times(t, rate=rate, every=every, t_origin=t_origin, snap_tol=snap_tol)
    else:
        if rate is not None or every is not None:
            raise ValueError("give frame_times or rate/every, not both")
        T = np.asarray(frame_times, dtype=float).reshape(-1)
    if T.size < 2:
        raise ImuGroundError(f"need at least 2 frame boundaries inside the log, got {T.size}")
    if not np.all(np.diff(T) > 2 * snap_tol):
        raise ValueError("frame_times must be strictly increasing (by more than 2 * snap_tol)")
    if T[0] < t[0] - snap_tol or T[-1] > t[-1] + snap_tol:
        raise ValueError(f"frame boundaries [{T[0]!r}, {T[-1]!r}] s are not inside the log "
                         f"[{t[0]!r}, {t[-1]!r}] s")
    return T


def _knots(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, T: np.ndarray, par: PreintegrationParams,
           values: bool = True) -> tuple:
    """Integration intervals: the samples plus the boundaries that fall between samples.

    Returns ``(dt, kv, b, valid, inserted)``: interval lengths (K,), the values at
    the knots, component-major (6, K + 1): gyro then accel, bias not removed (a
    view; None unless ``values``), the knot index of each boundary relative to the
    first (F + 1,), the per-frame validity (F,) after the gap rule (raises for
    ``on_gap="raise"``), and ``inserted = (ki, yb, j0)``: the boundaries put between
    samples (before sample ``ki``, values ``yb`` (6, M)) and the first knot's index,
    from which the compiled kernel reads the knots' values without ``kv``.
    """
    n = t.size
    k = np.searchsorted(t, T)                       # t[k-1] < T <= t[k]
    hi = np.minimum(k, n - 1)
    lo = np.maximum(k - 1, 0)
    d_hi = np.abs(t[hi] - T)
    d_lo = np.abs(T - t[lo])
    near = np.where(d_hi <= d_lo, hi, lo)
    snapped = np.minimum(d_hi, d_lo) <= par.snap_tol
    ins = ~snapped
    ki = k[ins]
    Ti = T[ins]
    yb = np.empty((6, ki.size))                     # component-major: gyro then accel, as the knots
    for rows, x in ((slice(0, 3), gyro), (slice(3, 6), accel)):
        if par.hold == "midpoint":
            wgt = (Ti - t[ki - 1]) / (t[ki] - t[ki - 1])
            yb[rows] = (x[ki - 1] + (x[ki] - x[ki - 1]) * wgt[:, None]).T
        else:
            yb[rows] = x[ki - 1].T
    kt = np.insert(t, ki, Ti)
    b = np.searchsorted(kt, np.where(snapped, t[near], T))     # knot index of each boundary
    if np.any(np.diff(b) <= 0):
        raise ValueError("two frame boundaries fall on the same sample; frames must be longer "
                         "than the snapping tolerance")
    j0, j1 = int(b[0]), int(b[-1])
    dt = np.diff(kt[j0:j1 + 1])
    # gaps, on the original sample intervals: sample interval s holds the knot intervals from sample s's
    # knot to sample s + 1's (sample s is knot s + the boundaries inserted before it); a frame that holds
    # one of those knot intervals is invalid
    nfr = T.size - 1
    valid = np.ones(nfr, dtype=bool)
    gaps = np.flatnonzero(np.diff(t) > par.max_gap)
    if gaps.size:
        first = gaps + np.searchsorted(ki, gaps, side="right")              # knot of sample s
        last = gaps + 1 + np.searchsorted(ki, gaps + 1, side="right")       # knot of sample s + 1
        lo, hi = np.maximum(first, j0), np.minimum(last, j1)
        inside = lo < hi                                                     # knot intervals [lo, hi) used
        if np.any(inside):
            if par.on_gap == "raise":
                g = int(gaps[inside][0])
                raise ValueError(gap_message(float(t[g]), float(t[g + 1] - t[g]), par.max_gap))
            f0 = np.searchsorted(b, lo[inside], side="right") - 1          # frames of the first and the last
            f1 = np.searchsorted(b, hi[inside] - 1, side="right") - 1       # knot interval of each gap
            hit = np.bincount(f0, minlength=nfr + 1) - np.bincount(f1 + 1, minlength=nfr + 1)
            valid &= np.cumsum(hit)[:nfr] == 0
    kv = None
    if values:
        y = np.empty((6, t.size))
        y[0:3] = gyro.T
        y[3:6] = accel.T
        kv = np.insert(y, ki, yb, axis=1)[:, j0:j1 + 1]
    return dt, kv, b - j0, valid, (ki, yb, j0)


def _integrate_frames(dt: np.ndarray, kv: np.ndarray | None, b: np.ndarray, par: PreintegrationParams,
                      samples: tuple | None = None) -> tuple:
    """Left-form (T, R, v, p, J, S) per frame: frames cut into padded blocks, chunked kernel, merge.

    ``kv`` holds the values at the knots, component-major (6, K + 1) (None: the
    compiled kernel reads them from ``samples = (gyro, accel, (ki, yb, j0))``, the
    samples and :func:`_knots`' inserted boundaries). The
    padded blocks and their held values (the knots' mean for ``"midpoint"``,
    the left knot's value for ``"left"``) are made chunk by chunk, so every
    temporary stays cache-sized whatever the log's length.
    """
    nfr = b.size - 1
    bias = np.concatenate([np.asarray(par.bias_gyro, dtype=float), np.asarray(par.bias_accel, dtype=float)])
    if kv is None:                      # deltas only: the streaming kernel, compiled, over each frame
        gyro, accel, (ki, yb, j0) = samples  # type: ignore[misc]
        d = np.empty((nfr, 11))
        _frames_deltas(np.ascontiguousarray(dt), gyro, accel, ki.astype(np.int64), np.ascontiguousarray(yb),
                       int(j0), b.astype(np.int64), bias, par.hold == "midpoint", d)
        return d[:, 0], matrix_from_quat(d[:, 1:5]), d[:, 5:8].copy(), d[:, 8:11].copy(), None, None
    nint = np.diff(b)
    Lb = int(min(nint.max(), max(16, 2 * math.ceil(dt.size / nfr))))
    nblk = -(-nint // Lb)
    block_frame = np.repeat(np.arange(nfr), nblk)
    nbt = int(nblk.sum())
    first_blk = np.cumsum(nblk) - nblk
    blk_in_frame = np.arange(nbt) - np.repeat(first_blk, nblk)
    start = b[:-1][block_frame] + Lb * blk_in_frame
    stop = np.minimum(start + Lb, b[1:][block_frame])
    bias = bias[:, None, None]
    qg, qa = par.gyro_noise_density ** 2, par.accel_noise_density ** 2
    # chunks of about _CHUNK intervals keep the temporaries in cache (a loop over groups of frames)
    step = max(1, _CHUNK // Lb)
    lanes = np.arange(Lb)[:, None]
    parts = []
    for i in range(0, nbt, step):
        idx = start[None, i:i + step] + lanes                  # (Lb, blocks of this chunk)
        pad = idx >= stop[None, i:i + step]
        idx[pad] = 0
        dtp = dt[idx]
        dtp[pad] = 0.0
        if par.hold == "midpoint":                             # component-major (6, Lb, blocks)
            hp = (kv[:, idx] + kv[:, idx + 1]) * 0.5
        else:
            hp = kv[:, idx]
        hp[:, pad] = 0.0
        hp -= bias
        parts.append(_blocks_kernel(dtp, hp[0:3], hp[3:6], qg, qa))
    res = tuple(np.concatenate([r[j] for r in parts]) for j in range(6))
    return _merge_blocks(res, block_frame, nfr)


def preintegrate(imu: ImuData | tuple[np.ndarray, np.ndarray, np.ndarray],
                 frame_times: np.ndarray | None = None, *,
                 rate: float | None = None, every: int | None = None,
                 t_origin: float | None = None, params: PreintegrationParams | None = None,
                 **options: Any) -> FrameDeltas:
    """Preintegrate a whole log into frames, vectorised (no Python loop over samples).

    Parameters
    ----------
    imu : ImuData or (t, gyro, accel)
        Times (s, strictly increasing), angular rate (rad/s) and specific force
        (m/s^2), both in the body frame.
    frame_times : array_like, shape (F + 1,), optional
        Frame boundaries, s, strictly increasing and inside ``[t[0], t[-1]]``;
        frame ``i`` spans ``[frame_times[i], frame_times[i+1]]``.
    rate, every, t_origin :
        Instead of ``frame_times``: frames at ``rate`` Hz from ``t_origin``
        (default ``t[0]``), or every ``every`` samples (see :func:`make_frame_times`).
    params : PreintegrationParams, optional
        Biases, noise densities, hold, gap rule, snapping, ``uncertainty``
        (False: no covariance or bias Jacobians; those fields are None).
    **options
        Fields of :class:`~imu_ground.imu.preint_params.PreintegrationParams`
        overriding ``params`` (``bias_gyro=..., on_gap="flag"``).

    Returns
    -------
    FrameDeltas
        Per frame: ``delta_R`` (``R_{start<-end}``), ``delta_v``, ``delta_p``
        (start body frame), 9x9 covariance, bias Jacobians, validity.

    Raises
    ------
    ValueError
        Non-increasing timestamps, frame boundaries outside the log or not
        increasing, or a gap inside a frame with ``on_gap="raise"``.
    """
    par = PreintegrationParams.coerce(params, **options)
    t, gyro, accel = _inputs(imu)
    T = _boundaries(t, frame_times, rate, every, t_origin, par.snap_tol)
    if not par.uncertainty:
        gyro, accel = np.ascontiguousarray(gyro), np.ascontiguousarray(accel)
    dt, kv, b, valid, inserted = _knots(t, gyro, accel, T, par, values=par.uncertainty)
    Tn, Rn, vn, pn, Jn, Sn = _integrate_frames(dt, kv, b, par, (gyro, accel, inserted))
    Rn = project_if_needed(Rn)
    names = ("d_R_d_bg", "d_v_d_bg", "d_p_d_bg", "d_v_d_ba", "d_p_d_ba")
    jac: dict[str, np.ndarray | None]
    if par.uncertainty:
        Jr, Sr = left_to_right(Rn, Jn, Sn)
        blocks = ((0, 0), (3, 0), (6, 0), (3, 3), (6, 3))
        jac = {k: Jr[:, r:r + 3, c:c + 3].copy() for k, (r, c) in zip(names, blocks, strict=True)}
    else:
        Sr, jac = None, dict.fromkeys(names)
    return FrameDeltas(
        t_start=T[:-1].copy(), t_end=T[1:].copy(), delta_t=np.asarray(Tn, dtype=float),
        delta_R=Rn, delta_v=vn, delta_p=pn, covariance=Sr, **jac, valid=valid,
        n_intervals=np.diff(b).astype(int), params=par)
