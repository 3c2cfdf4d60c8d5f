r"""The scalar residual filter both invariant-EKF ground estimators run on, one frame or a whole drive.

With process and measurement noise symmetric about the up axis, the slow road
attitude ``X`` (world <- road) of an invariant EKF (left error) keeps a
covariance ``P = diag(a, a, c)`` whatever the data, and the residual
``E = X^T R`` (road <- body) follows a recursion that needs neither ``X`` nor
the cumulative rotation ``R``. Per frame, with ``dR`` the body increment and
``T = Rz(psi)`` its heading twist (``psi = 2 atan2(q_z, q_w)``):

- predict ``X^- = X T``:  ``E^- = T^T E dR``,  ``a += q_h``, ``c += q_v``;
- update with the rotation ``Z = R Exp(-b)`` (``b``: a modelled body tilt,
  zero for the paper's filter): ``y = Log(E^- Exp(-b))``, ``K = diag(k_a, k_a, k_c)``
  with ``k_a = a / (a + r_h)``, ``k_c = c / (c + r_v)``; or with the up axis
  ``R e_z``: ``y = E^- e_z - e_z``, correction ``k_a (e_z x y)``;
- ``E = Exp(-K y) E^-`` (the correction ``X = X^- Exp(K y)`` seen from the body);
- ``a = k_a r_h``, ``c = k_c r_v`` (``c`` unchanged with the up axis).

:class:`ResidualKernel` holds that state in one float64 buffer (``E`` and, when
asked, ``R`` as unit quaternions; the layout is below) and advances it with one
kernel, :func:`frame` (one body, compiled by :func:`imu_ground._jit.njit`):
:func:`step` (one frame, checked) serves the streaming ``step`` of the
filters, :func:`run` (many frames, into an output array) their batch ``run``,
so the two cannot drift apart.

Buffer layout (``BUF_LEN`` float64): ``[0:11]`` state ``ew ex ey ez a c rw rx ry rz
frames``; ``[11:22]`` the last frame's ``k_a k_c a_prior c_prior yx yy yz mw mx my mz``;
``[22]`` 1 once a frame was processed; ``[23:30]`` parameters ``r_h r_v up
follow_heading cumulative has_Rgs renorm_every``; ``[30:39]`` ``R_gs`` row-major.
"""
from __future__ import annotations

from math import atan2, cos, nan, sin, sqrt
from typing import Optional, Sequence

import numpy as np

from imu_ground._jit import njit
from imu_ground.filters.frame_checks import status_of, statuses_of
from imu_ground.so3 import matrix_from_quat
from imu_ground.units import RENORM_EVERY

__all__ = ["ResidualKernel", "frame", "run_frames", "step", "run", "check", "check_many", "BUF_LEN", "ROW_LEN"]

_L_KA, _L_HAS, _P_RH, _P_G = 11, 22, 23, 30
_F64 = np.dtype(np.float64)
#: Length of a kernel's state-and-parameter buffer (float64).
BUF_LEN = 39
#: Length of an output row of :func:`frame` (the last 4, the cumulative rotation, are NaN when not tracked).
ROW_LEN = 12
_NO_DV = np.zeros(3)


@njit
def frame(buf, d, q_h, q_v, tilt, bx, by, angles):
    """One frame of the filter in ``buf`` (the one body of the kernel; unrolled, hence its length).

    It unrolls: the quaternion of the increment (Shepperd), its rotation into
    the body frame, the twist, the scalar covariance and gain recursion, the
    residual update of the module docstring in quaternion products, the
    cumulative rotation, and pitch and roll from the third row of ``E``
    (:func:`~imu_ground.filters.estimator.pitch_roll_from_normal`).

    Parameters
    ----------
    buf : ndarray (BUF_LEN,) float64
        State and parameters (module docstring); updated in place.
    d : ndarray (3, 3) float64
        Increment sensor_{k-1} <- sensor_k (already checked: a rotation, see
        :func:`~imu_ground.filters.frame_checks.frame_status`).
    q_h, q_v : float
        Process noise of this frame, horizontal and about up, rad^2.
    tilt : bool
        Use the modelled body tilt ``b = (bx, by, 0)`` (rotation vector, rad; not used with ``up``).
    bx, by : float
        The tilt, rad.
    angles : bool
        Compute pitch and roll (a batch that derives them from the residuals
        afterwards passes False; they are then NaN).

    Returns
    -------
    tuple of ROW_LEN float
        ``(ew, ex, ey, ez, a, c, pitch, roll, rw, rx, ry, rz)`` (the last 4 NaN when the cumulative rotation is
        not tracked).
    """
    ew, ex, ey, ez, a, c = buf[0], buf[1], buf[2], buf[3], buf[4], buf[5]    # the layout of the module docstring
    rw, rx, ry, rz, count = buf[6], buf[7], buf[8], buf[9], buf[10]
    r_h, r_v, up, follow, cum, every = buf[23], buf[24], buf[25] != 0.0, buf[26] != 0.0, buf[27] != 0.0, buf[29]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = (d[0, 0], d[0, 1], d[0, 2], d[1, 0], d[1, 1], d[1, 2],
                                                   d[2, 0], d[2, 1], d[2, 2])
    # -- quaternion of the increment (Shepperd), w >= 0
    tr = r00 + r11 + r22
    if tr > 0.0:
        s = 2.0 * sqrt(tr + 1.0)
        si = 1.0 / s
        dw, dx, dy, dz = 0.25 * s, (r21 - r12) * si, (r02 - r20) * si, (r10 - r01) * si
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * sqrt(1.0 + r00 - r11 - r22)
        dw, dx, dy, dz = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * sqrt(1.0 + r11 - r00 - r22)
        dw, dx, dy, dz = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * sqrt(1.0 + r22 - r00 - r11)
        dw, dx, dy, dz = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    if dw < 0.0:
        dw, dx, dy, dz = -dw, -dx, -dy, -dz
    if buf[28] != 0.0:                          # body increment: vector part turned by R_gs
        dx, dy, dz = (buf[30] * dx + buf[31] * dy + buf[32] * dz, buf[33] * dx + buf[34] * dy + buf[35] * dz,
                      buf[36] * dx + buf[37] * dy + buf[38] * dz)
    # -- covariance and gains
    a += q_h
    c += q_v
    a_pr, c_pr = a, c
    ka = a / (a + r_h)
    a = ka * r_h
    if up:
        kc = 0.0
    else:
        kc = c / (c + r_v)
        c = kc * r_v
    # -- E^- = T^T E dR: p = E d, then m = conj(t) p with t = (ch, 0, 0, sh) the heading twist
    pw = ew * dw - ex * dx - ey * dy - ez * dz
    px = ew * dx + ex * dw + ey * dz - ez * dy
    py = ew * dy - ex * dz + ey * dw + ez * dx
    pz = ew * dz + ex * dy - ey * dx + ez * dw
    if follow and (dw > 0.0 or dz != 0.0):      # (a half turn about a level axis has no twist)
        h = 1.0 / sqrt(dw * dw + dz * dz)
        ch, sh = dw * h, dz * h
        mw, mx, my, mz = ch * pw + sh * pz, ch * px + sh * py, ch * py - sh * px, ch * pz - sh * pw
    else:
        mw, mx, my, mz = pw, px, py, pz
    if mw < 0.0:
        mw, mx, my, mz = -mw, -mx, -my, -mz
    # -- innovation y and correction g = K y
    if up:
        yx, yy, yz = 2.0 * (mx * mz + mw * my), 2.0 * (my * mz - mw * mx), -2.0 * (mx * mx + my * my)
        gx, gy, gz = -ka * yy, ka * yx, 0.0
    else:
        if tilt:                                # M = E^- Exp(-b), b = (bx, by, 0)
            bn = sqrt(bx * bx + by * by)
            hb = 0.5 - bn * bn / 48.0 if bn < 1e-4 else sin(0.5 * bn) / bn
            cw, cx, cy = cos(0.5 * bn), -hb * bx, -hb * by
            Mw = mw * cw - mx * cx - my * cy
            Mx = mw * cx + mx * cw - mz * cy
            My = mw * cy + my * cw + mz * cx
            Mz = mz * cw + mx * cy - my * cx
            if Mw < 0.0:
                Mw, Mx, My, Mz = -Mw, -Mx, -My, -Mz
        else:
            Mw, Mx, My, Mz = mw, mx, my, mz
        vn = sqrt(Mx * Mx + My * My + Mz * Mz)
        f = 2.0 * atan2(vn, Mw) / vn if vn > 1e-300 else 2.0
        yx, yy, yz = f * Mx, f * My, f * Mz
        gx, gy, gz = ka * yx, ka * yy, kc * yz
    # -- E = Exp(-g) E^- (re-normalised every RENORM_EVERY frames)
    th = sqrt(gx * gx + gy * gy + gz * gz)
    hs = 0.5 - th * th / 48.0 if th < 1e-4 else sin(0.5 * th) / th
    aw, ax, ay, az = cos(0.5 * th), -hs * gx, -hs * gy, -hs * gz
    ew = aw * mw - ax * mx - ay * my - az * mz
    ex = aw * mx + ax * mw + ay * mz - az * my
    ey = aw * my - ax * mz + ay * mw + az * mx
    ez = aw * mz + ax * my - ay * mx + az * mw
    count += 1.0
    renorm = count % every == 0.0
    if renorm:
        nrm = 1.0 / sqrt(ew * ew + ex * ex + ey * ey + ez * ez)
        ew, ex, ey, ez = ew * nrm, ex * nrm, ey * nrm, ez * nrm
    # -- pitch and roll from n_b = E^T e_z, the third row of E
    pitch = roll = nan
    if angles:
        n0 = 2.0 * (ex * ez - ew * ey)
        n1 = 2.0 * (ey * ez + ew * ex)
        n2 = 1.0 - 2.0 * (ex * ex + ey * ey)
        pitch, roll = atan2(-n0, sqrt(n1 * n1 + n2 * n2)), atan2(n1, n2)
    ow = ox = oy = oz = nan
    if cum:                                     # R = R dR
        rw, rx, ry, rz = (rw * dw - rx * dx - ry * dy - rz * dz, rw * dx + rx * dw + ry * dz - rz * dy,
                          rw * dy - rx * dz + ry * dw + rz * dx, rw * dz + rx * dy - ry * dx + rz * dw)
        if renorm:
            nrm = 1.0 / sqrt(rw * rw + rx * rx + ry * ry + rz * rz)
            rw, rx, ry, rz = rw * nrm, rx * nrm, ry * nrm, rz * nrm
        ow, ox, oy, oz = rw, rx, ry, rz
    new = (ew, ex, ey, ez, a, c, rw, rx, ry, rz, count, ka, kc, a_pr, c_pr, yx, yy, yz, mw, mx, my, mz, 1.0)
    for i in range(_P_RH):
        buf[i] = new[i]
    return ew, ex, ey, ez, a, c, pitch, roll, ow, ox, oy, oz


@njit
def run_frames(buf, d, q_h, q_v, tilt, tilt_x, tilt_y, angles, out):
    """Many frames (already checked) into ``out``: :func:`frame` over ``d`` (F, 3, 3), ``q_h`` (F,), the tilts
    (F,) when ``tilt``, rows into ``out`` (F, 8) or (F, 12)."""
    width = out.shape[1]
    for k in range(d.shape[0]):
        bx = tilt_x[k] if tilt else 0.0
        by = tilt_y[k] if tilt else 0.0
        row = frame(buf, d[k], q_h[k], q_v, tilt, bx, by, angles)
        for j in range(width):
            out[k, j] = row[j]


_NAN_ROW = (nan,) * ROW_LEN


@njit
def _step(buf, d, q_h, q_v, tilt, bx, by, has_dv, dv, dt):
    """:func:`step` once its inputs are checked: ``(status, row)``, the row NaN for a bad frame."""
    status = status_of(d, has_dv, dv, dt)
    if status:
        return status, _NAN_ROW
    return 0, frame(buf, d, q_h, q_v, tilt, bx, by, True)


def _checked(v, shape: tuple, name: str):
    """``v`` if it is a C-contiguous float64 ndarray of ``shape``; TypeError or ValueError otherwise (the filters
    then coerce it with :func:`~imu_ground.filters.frame_checks.coerce_frame` and retry)."""
    if type(v) is np.ndarray and v.shape == shape and (v.dtype is _F64 or v.dtype == _F64) and v.flags.c_contiguous:
        return v
    if type(v) is not np.ndarray or v.dtype != _F64 or not v.flags.c_contiguous:
        raise TypeError(f"{name} must be a C-contiguous float64 array, got {type(v).__name__}"
                        + (f" of {v.dtype}" if type(v) is np.ndarray else ""))
    raise ValueError(f"{name} must have shape {shape}, got {v.shape}")


_SHAPE_R, _SHAPE_V = (3, 3), (3,)


def step(buf: np.ndarray, d, q_h: float, q_v: float, tilt_x: Optional[float], tilt_y: Optional[float],
         dv, dt: float):
    """One checked frame: the row of :func:`frame`, or the frame's status with the state untouched.

    Parameters
    ----------
    buf : ndarray (BUF_LEN,) float64
        The kernel's buffer (:attr:`ResidualKernel.buf`), updated in place.
    d : ndarray (3, 3), float64
        Increment sensor_{k-1} <- sensor_k.
    q_h, q_v : float
        Process noise of this frame, horizontal and about up, rad^2.
    tilt_x, tilt_y : float or None
        Modelled body tilt, rad (None: none).
    dv : ndarray (3,) float64, or None
        Velocity increment to check (m/s; None: not checked).
    dt : float
        Frame duration to check, s.

    Returns
    -------
    tuple or int
        The row ``(ew, ex, ey, ez, a, c, pitch, roll, rw, rx, ry, rz)`` of :func:`frame`, or the
        status of :func:`~imu_ground.filters.frame_checks.frame_status` (> 0) of a bad frame.

    Raises
    ------
    TypeError, ValueError
        ``d`` or ``dv`` is not a float64 array of that shape: the caller coerces and retries.
    """
    d = _checked(d, _SHAPE_R, "delta_R")
    has_dv = dv is not None
    dv = _checked(dv, _SHAPE_V, "delta_v") if has_dv else _NO_DV
    tilt = tilt_x is not None
    status, row = _step(buf, d, float(q_h), float(q_v), tilt, 0.0 if tilt_x is None else float(tilt_x),
                        0.0 if tilt_y is None else float(tilt_y), has_dv, dv, float(dt))
    return status if status else row


def run(buf: np.ndarray, d, q_h, q_v: float, tilt_x, tilt_y, out: np.ndarray, angles: bool) -> None:
    """Many frames (already checked) into ``out``: the batch entry point.

    Parameters
    ----------
    buf : ndarray (BUF_LEN,) float64
        The kernel's buffer, updated in place.
    d : ndarray (F, 3, 3) or (F, 9), float64
        Increments sensor_{k-1} <- sensor_k.
    q_h : float or ndarray (F,)
        Horizontal process noise per frame, rad^2.
    q_v : float
        Process noise about up per frame, rad^2.
    tilt_x, tilt_y : ndarray (F,) or None
        Modelled body tilt per frame, rad.
    out : ndarray (F, 8) or (F, 12), float64
        Receives the rows of :func:`frame` (12 columns with the cumulative rotation).
    angles : bool
        Compute pitch and roll (else NaN).
    """
    d = np.ascontiguousarray(d, dtype=float).reshape(-1, 3, 3)
    n = len(d)
    qs = np.full(n, float(q_h)) if isinstance(q_h, (int, float)) else np.ascontiguousarray(q_h, dtype=float)
    tilt = tilt_x is not None
    tx = np.ascontiguousarray(tilt_x, dtype=float) if tilt else _NO_DV
    ty = np.ascontiguousarray(tilt_y, dtype=float) if tilt else _NO_DV
    if n:
        run_frames(buf, d, qs, float(q_v), tilt, tx, ty, bool(angles), out.reshape(n, -1))


def check(d, dv, dt: float) -> int:
    """The status of one frame (:func:`~imu_ground.filters.frame_checks.frame_status`; 0: good).

    Raises
    ------
    TypeError, ValueError
        ``d`` or ``dv`` is not a float64 array of shape (3, 3) or (3,): the caller coerces and retries.
    """
    d = _checked(d, _SHAPE_R, "delta_R")
    if dv is None:
        return int(status_of(d, False, _NO_DV, float(dt)))
    return int(status_of(d, True, _checked(dv, _SHAPE_V, "delta_v"), float(dt)))


def check_many(d: np.ndarray, dv: Optional[np.ndarray], dt: Optional[np.ndarray], out: np.ndarray) -> None:
    """:func:`check` of every frame into ``out`` (uint8 (F,)); see :func:`~imu_ground.filters.frame_checks.frame_statuses`."""
    statuses_of(d, dv, dt, out)


_LOADED: list = []


def _load_compiled() -> None:
    """Call the compiled step once per process, on a scratch buffer: numba's first call (its typing and the
    cached machine code, a fraction of a second) then happens when the first filter is built, not at the
    first frame of a live stream."""
    if not _LOADED:
        _LOADED.append(True)
        scratch = np.array([1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0] + [0.0] * 12
                           + [1.0, 1.0, 0.0, 1.0, 0.0, 0.0, float(RENORM_EVERY)] + [0.0] * 9)
        step(scratch, np.eye(3), 0.0, 0.0, None, None, _NO_DV, 1.0)


class ResidualKernel:
    """State ``(E, a, c[, R])`` of the residual filter in one buffer, and the kernel that advances it.

    Parameters
    ----------
    a, c : float
        Initial covariance ``diag(a, a, c)`` of the slow state, rad^2.
    r_h, r_v : float
        Measurement noise about the horizontal axes and about up, rad^2 (with
        ``up``: the noise of each component of the observed up axis).
    up : bool
        Observe only the up axis ``R e_z`` (tilt), not the whole rotation.
    follow_heading : bool
        Predict with the heading twist of each increment (False: random walk).
    Rgs : ndarray (3, 3), optional
        Static extrinsic ground <- sensor: increments are given in the sensor
        frame and turned into the body frame (``R_gs dR R_gs^T``). None: identity.
    cumulative : bool
        Also accumulate ``R_k = R_{k-1} dR_k`` (world <- body, from ``R0`` = identity).

    Attributes
    ----------
    buf : ndarray (BUF_LEN,) float64
        State and parameters (module docstring). The residual road <- body and the
        cumulative rotation are quaternions (w, x, y, z), re-normalised every
        :data:`~imu_ground.units.RENORM_EVERY` frames (so unit to ~1e-14 in between).
    """

    __slots__ = ("buf",)

    def __init__(self, a: float, c: float, r_h: float, r_v: float, up: bool = False, follow_heading: bool = True,
                 Rgs=None, cumulative: bool = False) -> None:
        g = [0.0] * 9 if Rgs is None else [float(v) for v in np.asarray(Rgs, dtype=float).ravel()]
        values = ([1.0, 0.0, 0.0, 0.0, float(a), float(c), 1.0, 0.0, 0.0, 0.0, 0.0] + [0.0] * 12
                  + [float(r_h), float(r_v), float(bool(up)), float(bool(follow_heading)),
                     float(bool(cumulative)), float(Rgs is not None), float(RENORM_EVERY)] + g)
        self.buf = np.array(values)
        _load_compiled()

    def read_state(self, reader, name: str) -> list:
        """The entry ``name`` of a saved state (a :class:`~imu_ground.imu.warm_start.StateReader`), checked to
        be a buffer of this kernel's layout: finite, NaN only in the record of the last frame."""
        return reader.floats(name, (len(self.buf),), nan=slice(_L_KA, _L_HAS)).tolist()

    def load(self, values: Sequence[float]) -> None:
        """A new :attr:`buf` of ``values`` (a saved state's)."""
        self.buf = np.array(values, dtype=float)

    def set_mount(self, Rgs: np.ndarray) -> None:
        """Turn sensor increments into the body frame with the static rotation ``Rgs`` (ground <- sensor) from
        the next frame on (in place: the buffer object stays the same)."""
        b = self.buf
        b[_P_RH + 5] = 1.0
        b[_P_G:_P_G + 9] = np.asarray(Rgs, dtype=float).ravel()

    step = staticmethod(step)
    check = staticmethod(check)

    @property
    def E(self) -> tuple:
        """Residual road <- body, quaternion (w, x, y, z)."""
        return tuple(self.buf[0:4].tolist())

    @property
    def R(self) -> Optional[tuple]:
        """Cumulative rotation world <- body (from identity), quaternion, or None when not tracked."""
        return tuple(self.buf[6:10].tolist()) if self.buf[_P_RH + 4] != 0.0 else None

    a = property(lambda self: float(self.buf[4]), doc="Covariance about the horizontal axes, rad^2.")
    c = property(lambda self: float(self.buf[5]), doc="Covariance about up, rad^2.")

    def residual_matrix(self) -> np.ndarray:
        """:attr:`E` as a rotation matrix (3, 3), road <- body."""
        return matrix_from_quat(self.buf[0:4].copy())

    def covariance(self) -> np.ndarray:
        """``diag(a, a, c)`` (3, 3), rad^2: the covariance of the slow state, body tangent space."""
        return np.diag([self.a, self.a, self.c])
    frames = property(lambda self: int(self.buf[10]), doc="Frames processed.")

    @property
    def last(self) -> Optional[tuple]:
        """Of the last frame: ``(k_a, k_c, a_prior, c_prior, yx, yy, yz, mw, mx, my, mz)``: gains,
        predicted covariance, innovation and predicted residual ``E^-``; None before the first."""
        return tuple(self.buf[_L_KA:_L_HAS].tolist()) if self.buf[_L_HAS] != 0.0 else None

    @property
    def width(self) -> int:
        """Columns of an output row: 8, or 12 with the cumulative rotation."""
        return 12 if self.buf[_P_RH + 4] != 0.0 else 8

    def run(self, d, q_h, q_v: float, tilt_x=None, tilt_y=None, angles: bool = False) -> np.ndarray:
        """:func:`run` into a new array (F, :attr:`width`)."""
        d = np.ascontiguousarray(d, dtype=float)
        out = np.empty((len(d), self.width))
        run(self.buf, d, q_h, q_v, tilt_x, tilt_y, out, angles)
        return out
