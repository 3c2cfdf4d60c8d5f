r"""The ground filters' invariant EKF on the residual, one frame or a whole drive: the one body every estimator runs.

Both ground estimators (:class:`~imu_ground.filters.ground.GroundNormalFilter`,
:class:`~imu_ground.filters.suspension.SuspensionAwareFilter`) filter the slow road attitude ``X`` (world <- road)
with a left-invariant EKF (``X = Xhat Exp(xi)``): predict ``X <- X T`` (``T = Rz(psi)``, the heading twist of the
body increment ``dR``, ``psi = 2 atan2(q_z, q_w)``; identity for a random walk) with noise ``Q``, update with the
cumulative rotation ``R`` (world <- body) seen as ``Z = R Exp(-b)`` (``b``: a modelled body tilt, zero for the
paper's filter) or with one of its axes ``R b_axis``. Written on ``W = R^T X`` (body <- road, the inverse of the
residual ``E = X^T R``; a known rotation on the left leaves the error ``xi`` unchanged) it needs neither ``X`` nor
``R``: predict ``W <- dR^T W T``, ``P <- T^T P T + Q``; update with the rotation ``W^T Z' = E Exp(-b)``,
``Z' = Exp(-b)``, or the direction ``z' = b_axis`` (noise ``R^T R_n R``): the InvariantEKF's own functions of
:mod:`~imu_ground.filters.invariant_ekf_kernel`, compiled into :func:`frame`. With ``P``, ``Q``, ``R`` =
diag(a, a, c) (the defaults and the paper's) ``P`` stays diag(a, a, c).

Buffer layout (``BUF_LEN`` float64, matrices row-major, rotations quaternions): ``[0:4]`` ``E``; ``[4:13]`` ``P``;
``[13:17]`` ``R``; ``[17]`` frames; the last frame's ``[18:27]`` ``K``, ``[27:36]`` ``S``, ``[36:45]`` ``P`` after
the predict, ``[45:48]`` ``y``, ``[48:52]`` ``E^-``, ``[52]`` 1 once a frame was processed; parameters ``[53:62]``
``Q`` (added to the per-frame ``diag(q_h, q_h, q_v)``), ``[62:71]`` ``R_n``, ``[71:74]`` the observed body axis,
``[74:79]`` ``direction follow_heading cumulative has_Rgs renorm_every``, ``[79:88]`` ``R_gs``.
"""
from __future__ import annotations

import functools
from math import atan2, nan, sqrt
from typing import Mapping, Optional, Sequence

import numpy as np

from imu_ground._jit import njit
from imu_ground.filters.frame_checks import status_of, statuses_of
from imu_ground.filters.invariant_ekf_kernel import (congruence, predict_left, update_direction_left,
                                                     update_rotation_left)
from imu_ground.so3 import (flat_from_quat, matrix_from_quat, quat_exp, quat_from_flat, quat_mul, quat_normalise,
                            transpose_flat)
from imu_ground.units import RENORM_EVERY

__all__ = ["ResidualKernel", "frame", "frame_checked", "run_frames", "step", "run", "check", "check_many", "BUF_LEN", "ROW_LEN"]

_E, _P, _R, _N, _K, _S, _PP, _Y, _M, _HAS = 0, 4, 13, 17, 18, 27, 36, 45, 48, 52
_Q, _RN, _B, _DIR, _FOLLOW, _CUM, _HAS_G, _EVERY, _G = 53, 62, 71, 74, 75, 76, 77, 78, 79
#: Length of a kernel's state-and-parameter buffer (float64).
BUF_LEN = 88
#: Length of an output row of :func:`frame` (the last 4, the cumulative rotation, are NaN when not tracked).
ROW_LEN = 12
#: The ``dv`` of a frame without one (zeros pass the check).
NO_DV = _NO_DV = np.zeros(3)
_NO_P = np.zeros((0, 9))
_ZERO9 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@njit
def frame(buf, d, q_h, q_v, tilt, bx, by, angles):
    """One frame of the filter in ``buf`` (module docstring), updated in place.

    Parameters
    ----------
    buf : ndarray (BUF_LEN,) float64
        State and parameters.
    d : ndarray (3, 3) float64
        Increment sensor_{k-1} <- sensor_k, already checked (:func:`~imu_ground.filters.frame_checks.frame_status`).
    q_h, q_v : float
        Process noise of this frame, horizontal and about up, rad^2 (added to the buffer's ``Q``).
    tilt, bx, by : bool, float, float
        Use the modelled body tilt ``b = (bx, by, 0)`` (rotation vector, rad; not with a direction).
    angles : bool
        Compute pitch and roll (from the third row of ``E``; else NaN).

    Returns
    -------
    tuple of ROW_LEN float
        ``(ew, ex, ey, ez, a, P22, pitch, roll, rw, rx, ry, rz)``, ``a = (P00 + P11) / 2`` the level variance
        (the last 4 NaN when the cumulative rotation is not tracked).
    """
    dw, dx, dy, dz = quat_from_flat((d[0, 0], d[0, 1], d[0, 2], d[1, 0], d[1, 1], d[1, 2], d[2, 0], d[2, 1], d[2, 2]))
    if buf[_HAS_G] != 0.0:                      # body increment: vector part turned by R_gs
        g = buf[_G:_G + 9]
        dx, dy, dz = (g[0] * dx + g[1] * dy + g[2] * dz, g[3] * dx + g[4] * dy + g[5] * dz,
                      g[6] * dx + g[7] * dy + g[8] * dz)
    count = buf[_N] + 1.0
    renorm = count % buf[_EVERY] == 0.0
    rw, rx, ry, rz = buf[_R], buf[_R + 1], buf[_R + 2], buf[_R + 3]
    cum = buf[_CUM] != 0.0
    if cum:                                     # R <- R dR
        rw, rx, ry, rz = quat_mul((rw, rx, ry, rz), (dw, dx, dy, dz))
        if renorm:
            rw, rx, ry, rz = quat_normalise((rw, rx, ry, rz))
    # -- predict W <- dR^T W T, P <- T^T P T + Q (W = conj(E))
    w = quat_mul((dw, -dx, -dy, -dz), (buf[_E], -buf[_E + 1], -buf[_E + 2], -buf[_E + 3]))
    t = (1.0, 0.0, 0.0, 0.0)
    if buf[_FOLLOW] != 0.0 and (dw > 0.0 or dz != 0.0):     # (a half turn about a level axis has no twist)
        h = 1.0 / sqrt(dw * dw + dz * dz)
        t = (dw * h, 0.0, 0.0, dz * h)
    qn = buf[_Q:_Q + 9]
    Qn = (qn[0] + q_h, qn[1], qn[2], qn[3], qn[4] + q_h, qn[5], qn[6], qn[7], qn[8] + q_v)
    p = buf[_P:_P + 9]
    w, Pp = predict_left(w, (p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8]), flat_from_quat(t), t, Qn)
    # -- update
    rn = buf[_RN:_RN + 9]
    Rn = (rn[0], rn[1], rn[2], rn[3], rn[4], rn[5], rn[6], rn[7], rn[8])
    if buf[_DIR] != 0.0:                        # z' = b (world noise R^T Rn R)
        b = (buf[_B], buf[_B + 1], buf[_B + 2])
        Rn = congruence(transpose_flat(flat_from_quat((rw, rx, ry, rz))), Rn, _ZERO9)
        wn, P, y, K, S, _, _, _ = update_direction_left(w, Pp, flat_from_quat(w), b, b, Rn)
    else:
        qz = quat_exp(-bx, -by, 0.0) if tilt else (1.0, 0.0, 0.0, 0.0)
        wn, P, y, K, S, _, _, _ = update_rotation_left(w, Pp, qz, Rn)
    ew, ex, ey, ez = wn[0], -wn[1], -wn[2], -wn[3]
    if renorm:
        ew, ex, ey, ez = quat_normalise((ew, ex, ey, ez))
    pitch = roll = nan
    if angles:                                  # n_b = E^T e_z, the third row of E
        n0 = 2.0 * (ex * ez - ew * ey)
        n1 = 2.0 * (ey * ez + ew * ex)
        n2 = 1.0 - 2.0 * (ex * ex + ey * ey)
        pitch, roll = atan2(-n0, sqrt(n1 * n1 + n2 * n2)), atan2(n1, n2)
    buf[0], buf[1], buf[2], buf[3] = ew, ex, ey, ez
    for i in range(9):
        buf[_P + i], buf[_K + i], buf[_S + i], buf[_PP + i] = P[i], K[i], S[i], Pp[i]
    buf[_R], buf[_R + 1], buf[_R + 2], buf[_R + 3], buf[_N] = rw, rx, ry, rz, count
    buf[_Y], buf[_Y + 1], buf[_Y + 2] = y
    buf[_M], buf[_M + 1], buf[_M + 2], buf[_M + 3], buf[_HAS] = w[0], -w[1], -w[2], -w[3], 1.0
    if not cum:
        rw = rx = ry = rz = nan
    return ew, ex, ey, ez, 0.5 * (P[0] + P[4]), P[8], pitch, roll, rw, rx, ry, rz


@njit
def run_frames(buf, d, q_h, q_v, tilt, tilt_x, tilt_y, angles, out, P_out):
    """Many frames (already checked) into ``out``: :func:`frame` over ``d`` (F, 3, 3), ``q_h`` (F,), the tilts
    (F,) when ``tilt``, rows into ``out`` (F, 8) or (F, 12), each covariance into ``P_out`` (F, 9) unless empty."""
    width, full = out.shape[1], P_out.shape[0] != 0
    for k in range(d.shape[0]):
        bx = tilt_x[k] if tilt else 0.0
        by = tilt_y[k] if tilt else 0.0
        row = frame(buf, d[k], q_h[k], q_v, tilt, bx, by, angles)
        for j in range(width):
            out[k, j] = row[j]
        if full:
            for j in range(9):
                P_out[k, j] = buf[_P + j]


_NAN_ROW = (nan,) * ROW_LEN


@njit
def _step(buf, d, q_h, q_v, tilt, bx, by, has_dv, dv, dt):
    """:func:`step` once its inputs are checked: ``(status, row)``, the row NaN for a bad frame."""
    status = status_of(d, has_dv, dv, dt)
    if status:
        return status, _NAN_ROW
    return 0, frame(buf, d, q_h, q_v, tilt, bx, by, True)


@njit
def frame_checked(buf, d, dv, dt):
    """The ground filter's streaming step: :func:`frame` (no tilt, the buffer's noise, angles) of a frame that
    passes :func:`~imu_ground.filters.frame_checks.status_of` (``d`` (3, 3), ``dv`` (3,) m/s, ``dt`` s, float64),
    else a NaN row, the state untouched: the row's first 8 entries. Compiled for those types only (others raise
    TypeError)."""
    if status_of(d, True, dv, dt):
        return _NAN_ROW[:8]
    return frame(buf, d, 0.0, 0.0, False, 0.0, 0.0, True)[:8]


def _checked(v, shape: tuple, name: str):
    """``v`` if it is a C-contiguous float64 ndarray of ``shape``; TypeError or ValueError otherwise."""
    if type(v) is not np.ndarray or v.dtype != np.float64 or not v.flags.c_contiguous:
        raise TypeError(f"{name} must be a C-contiguous float64 array, got {type(v).__name__}"
                        + (f" of {v.dtype}" if type(v) is np.ndarray else ""))
    if v.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {v.shape}")
    return v


def step(buf: np.ndarray, d, q_h: float, q_v: float, tilt_x: Optional[float], tilt_y: Optional[float],
         dv, dt: float):
    """One checked frame: the row of :func:`frame`, or the frame's status (> 0) with the state untouched.

    ``buf``, ``d``, ``q_h``, ``q_v`` as in :func:`frame`; ``tilt_x, tilt_y`` the modelled body tilt (rad, None:
    none); ``dv`` (3,) m/s (None: not checked) and ``dt`` (s) are checked.

    Returns
    -------
    tuple or int
        The row of :func:`frame`, or the :func:`~imu_ground.filters.frame_checks.frame_status` (> 0) of a bad frame.

    Raises
    ------
    TypeError, ValueError
        ``d`` or ``dv`` is not a float64 array of that shape: the caller coerces and retries.
    """
    d = _checked(d, (3, 3), "delta_R")
    dv3 = _NO_DV if dv is None else _checked(dv, (3,), "delta_v")
    tilt = tilt_x is not None
    status, row = _step(buf, d, float(q_h), float(q_v), tilt, 0.0 if tilt_x is None else float(tilt_x),
                        0.0 if tilt_y is None else float(tilt_y), dv is not None, dv3, float(dt))
    return status if status else row


def run(buf: np.ndarray, d, q_h, q_v: float, tilt_x, tilt_y, out: np.ndarray, angles: bool,
        P_out: Optional[np.ndarray] = None) -> None:
    """:func:`frame` over many checked frames: ``d`` (F, 3, 3) or (F, 9); ``q_h`` a float or (F,); ``tilt_x,
    tilt_y`` (F,) or None (rad); rows into ``out`` (F, 8) or (F, 12, with the cumulative rotation), each
    covariance (rad^2) into ``P_out`` (F, 3, 3) if given."""
    d = np.ascontiguousarray(d, dtype=float).reshape(-1, 3, 3)
    n = len(d)
    qs = np.full(n, float(q_h)) if isinstance(q_h, (int, float)) else np.ascontiguousarray(q_h, dtype=float)
    tilt = tilt_x is not None
    tx, ty = (np.ascontiguousarray(v, dtype=float) if tilt else _NO_DV for v in (tilt_x, tilt_y))
    if n:
        run_frames(buf, d, qs, float(q_v), tilt, tx, ty, bool(angles), out.reshape(n, -1),
                   _NO_P if P_out is None else P_out.reshape(n, 9))


def check(d, dv, dt: float) -> int:
    """The status of one frame (:func:`~imu_ground.filters.frame_checks.frame_status`; 0: good).

    Raises
    ------
    TypeError, ValueError
        As :func:`step`.
    """
    d = _checked(d, (3, 3), "delta_R")
    dv3 = _NO_DV if dv is None else _checked(dv, (3,), "delta_v")
    return int(status_of(d, dv is not None, dv3, float(dt)))


#: :func:`check` of every frame into ``out`` (uint8 (F,)): :func:`~imu_ground.filters.frame_checks.statuses_of`.
check_many = statuses_of


def _buffer(P, Q, R, axis, follow_heading: bool, cumulative: bool, Rgs) -> np.ndarray:
    """A fresh buffer (layout: module docstring); ``axis`` None for the rotation measurement."""
    b = np.zeros(BUF_LEN)
    b[_E] = b[_R] = 1.0
    b[_P:_P + 9], b[_Q:_Q + 9], b[_RN:_RN + 9] = (np.asarray(m, dtype=float).ravel() for m in (P, Q, R))
    if axis is not None:
        b[_B:_B + 3], b[_DIR] = axis, 1.0
    b[_FOLLOW], b[_CUM], b[_EVERY] = float(bool(follow_heading)), float(bool(cumulative)), float(RENORM_EVERY)
    if Rgs is not None:
        b[_HAS_G], b[_G:_G + 9] = 1.0, np.asarray(Rgs, dtype=float).ravel()
    return b


#: Length of the buffer of the earlier closed-form kernel: ``[0:4]`` E, ``[4:6]`` the variances ``a`` (level) and
#: ``c`` (about up) of ``P = diag(a, a, c)``, ``[6:10]`` R, ``[10]`` frames, ``[11:22]`` the last frame's ``k_a k_c
#: a_prior c_prior y (3) E^- (4)``, ``[22]`` 1 once a frame was processed, ``[23:30]`` ``r_h r_v up follow_heading
#: cumulative has_Rgs renorm_every``, ``[30:39]`` R_gs.
CLOSED_FORM_LEN = 39


def _from_closed_form(old: np.ndarray, template: np.ndarray) -> np.ndarray:
    """``template`` (the loading filter's parameters) with the state and last-frame record of the closed-form buffer
    ``old`` (its matrices the diagonal ones the closed form implies)."""
    b = template.copy()
    a, c, k_a, k_c, a_p, c_p = old[4], old[5], old[11], old[12], old[13], old[14]
    b[_E:_E + 4], b[_R:_R + 4], b[_N], b[_HAS] = old[0:4], old[6:10], old[10], old[22]
    b[_P:_P + 9] = np.diag([a, a, c]).ravel()
    b[_PP:_PP + 9] = np.diag([a_p, a_p, c_p]).ravel()
    b[_S:_S + 9] = b[_PP:_PP + 9] + b[_RN:_RN + 9]
    b[_K:_K + 9] = 0.0                          # the gains where :attr:`ResidualKernel.last` reads them
    if b[_DIR] != 0.0:
        b[_K + 3] = k_a
    else:
        b[_K] = b[_K + 4] = k_a
    b[_K + 8] = k_c
    b[_Y:_Y + 3], b[_M:_M + 4] = old[15:18], old[18:22]
    b[_HAS_G], b[_G:_G + 9] = old[28], old[30:39]
    return b


@functools.cache
def _load_compiled() -> None:
    """Call the compiled steps once per process, when the first filter is built."""
    buf = _buffer(np.eye(3), np.zeros((3, 3)), np.eye(3), None, True, True, None)
    step(buf, np.eye(3), 0.0, 0.0, None, None, _NO_DV, 1.0)
    frame_checked(buf, np.eye(3), _NO_DV, 1.0)
    getattr(frame_checked, "disable_compile", lambda: None)()     # (numba's: other types raise TypeError)


class ResidualKernel:
    """State ``(E, P[, R])`` of the ground filters' invariant EKF in one buffer, and the kernel that advances it.

    Parameters
    ----------
    a, c : float
        Initial covariance ``diag(a, a, c)`` of the slow state, rad^2.
    r_h, r_v : float
        Measurement noise about the horizontal axes and about up, rad^2 (with ``up``: ``r_h`` per component).
    up : bool
        Observe only the up axis ``R e_z`` (tilt), not the whole rotation.
    follow_heading : bool
        Predict with the heading twist of each increment (False: random walk).
    Rgs : ndarray (3, 3), optional
        Static extrinsic ground <- sensor turning sensor increments into the body frame. None: identity.
    cumulative : bool
        Also accumulate ``R_k = R_{k-1} dR_k`` (world <- body, from the identity).
    P, Q, R : ndarray (3, 3), optional
        Initial covariance, process noise added to every frame's (body tangent space) and measurement noise
        (rad^2; world axes for a direction, which then needs ``cumulative`` unless isotropic), in place of
        ``a, c``, zero and ``r_h, r_v``.
    axis : array_like (3,), optional
        Observe the direction ``R axis`` (a unit body axis, e.g. ``e_x``) instead of the rotation.

    Attributes
    ----------
    buf : ndarray (BUF_LEN,) float64
        State and parameters (module docstring); quaternions re-normalised every
        :data:`~imu_ground.units.RENORM_EVERY` frames.
    """

    __slots__ = ("buf",)

    def __init__(self, a: float, c: float, r_h: float, r_v: float, up: bool = False, follow_heading: bool = True,
                 Rgs=None, cumulative: bool = False, *, P=None, Q=None, R=None, axis=None) -> None:
        if up:
            axis = (0.0, 0.0, 1.0)
            r_v = r_h
        self.buf = _buffer(np.diag([a, a, c]) if P is None else P, np.zeros((3, 3)) if Q is None else Q,
                           np.diag([r_h, r_h, r_v]) if R is None else R, axis, follow_heading, cumulative, Rgs)
        _load_compiled()

    def read_state(self, reader, name: str) -> list:
        """Entry ``name`` of a saved state (a :class:`~imu_ground.imu.warm_start.StateReader`) checked as a buffer
        of this layout (finite, NaN only in the last frame's record); one of the earlier closed-form layout
        (:data:`CLOSED_FORM_LEN` floats) is converted, so a state saved before an upgrade resumes."""
        v = reader.state.get(name) if isinstance(reader.state, Mapping) else None
        if isinstance(v, (list, tuple, np.ndarray)) and len(v) == CLOSED_FORM_LEN:
            return _from_closed_form(reader.floats(name, (CLOSED_FORM_LEN,), nan=slice(11, 22)), self.buf).tolist()
        return reader.floats(name, (len(self.buf),), nan=slice(_K, _HAS)).tolist()

    def load(self, values: Sequence[float]) -> None:
        """A new :attr:`buf` of ``values`` (a saved state's)."""
        self.buf = np.array(values, dtype=float)

    def set_mount(self, Rgs: np.ndarray) -> None:
        """Turn sensor increments into the body frame with ``Rgs`` (ground <- sensor) from the next frame on (in
        place)."""
        self.buf[_HAS_G] = 1.0
        self.buf[_G:_G + 9] = np.asarray(Rgs, dtype=float).ravel()

    step = staticmethod(step)
    check = staticmethod(check)

    @property
    def R(self) -> Optional[tuple]:
        """Cumulative rotation world <- body (from identity), quaternion, or None when not tracked."""
        return tuple(self.buf[_R:_R + 4].tolist()) if self.buf[_CUM] != 0.0 else None

    a = property(lambda self: float(self.buf[_P]), doc="Covariance about the first horizontal axis, rad^2.")
    c = property(lambda self: float(self.buf[_P + 8]), doc="Covariance about up, rad^2.")
    frames = property(lambda self: int(self.buf[_N]), doc="Frames processed.")

    def residual_matrix(self) -> np.ndarray:
        """:attr:`E` as a rotation matrix (3, 3), road <- body."""
        return matrix_from_quat(self.buf[0:4].copy())

    def covariance(self) -> np.ndarray:
        """``P`` (3, 3), rad^2: the covariance of the slow state, body tangent space."""
        return self.buf[_P:_P + 9].reshape(3, 3).copy()

    def last_matrices(self) -> Optional[tuple]:
        """The last frame's ``K``, ``S``, ``P`` after the predict (each (3, 3)) and ``y`` (3,); None before one."""
        if self.buf[_HAS] == 0.0:
            return None
        b = self.buf
        return (b[_K:_K + 9].reshape(3, 3).copy(), b[_S:_S + 9].reshape(3, 3).copy(),
                b[_PP:_PP + 9].reshape(3, 3).copy(), b[_Y:_Y + 3].copy())

    @property
    def last(self) -> Optional[tuple]:
        """The last frame's ``(k_a, k_c, a_prior, c_prior, yx, yy, yz, mw, mx, my, mz)``: horizontal and up gains,
        predicted covariance, innovation and predicted residual ``E^-``; None before one."""
        b = self.buf
        if b[_HAS] == 0.0:
            return None
        k_a = b[_K + 3] if b[_DIR] != 0.0 else b[_K]
        return (float(k_a), float(b[_K + 8]), float(b[_PP]), float(b[_PP + 8]), *b[_Y:_Y + 3].tolist(),
                *b[_M:_M + 4].tolist())

    @property
    def width(self) -> int:
        """Columns of an output row: 8, or 12 with the cumulative rotation."""
        return 12 if self.buf[_CUM] != 0.0 else 8

    def run(self, d, q_h, q_v: float, tilt_x=None, tilt_y=None, angles: bool = False, P_out=None) -> np.ndarray:
        """:func:`run` into a new array (F, :attr:`width`) (and each covariance into ``P_out`` (F, 3, 3))."""
        d = np.ascontiguousarray(d, dtype=float)
        out = np.empty((len(d), self.width))
        run(self.buf, d, q_h, q_v, tilt_x, tilt_y, out, angles, P_out)
        return out
