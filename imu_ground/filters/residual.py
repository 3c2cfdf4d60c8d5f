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
kernel: :func:`step` (one frame, checked) serves the streaming ``step`` of the
filters, :func:`run` (many frames, into an output array) their batch ``run``,
so the two cannot drift apart. Both exist twice: compiled
(``_residual_native.c``, :data:`imu_ground._native.RESIDUAL`)
and as the pure-Python reference here (:func:`advance` is the loop), which the
C twin is tested against and which is used when the extension is not built or
``IMU_GROUND_PURE_PYTHON=1``.

Buffer layout (``BUF_LEN`` float64): ``[0:11]`` state ``ew ex ey ez a c rw rx ry rz
frames``; ``[11:22]`` the last frame's ``k_a k_c a_prior c_prior yx yy yz mw mx my mz``;
``[22]`` 1 once a frame was processed; ``[23:30]`` parameters ``r_h r_v up
follow_heading cumulative has_Rgs renorm_every``; ``[30:39]`` ``R_gs`` row-major.
"""
from __future__ import annotations

from array import array
from collections.abc import MutableSequence
from math import atan2, cos, nan, sin, sqrt
from types import SimpleNamespace
from typing import Optional, Sequence

import numpy as np

from imu_ground import _native
from imu_ground.filters.frame_checks import frame_status
from imu_ground.so3 import matrix_from_quat
from imu_ground.units import RENORM_EVERY

__all__ = ["ResidualKernel", "advance", "step", "run", "check", "BUF_LEN", "NATIVE", "PYTHON"]

_L_KA, _L_HAS, _P_RH, _P_G = 11, 22, 23, 30
_F64 = np.dtype(np.float64)
#: Length of a kernel's state-and-parameter buffer (float64).
BUF_LEN = 39


def advance(buf: MutableSequence[float], frames: Sequence[Sequence[float]], q_h: Sequence[float], q_v: float,
            tilt_x: Optional[Sequence[float]] = None, tilt_y: Optional[Sequence[float]] = None,
            angles: bool = True) -> list:
    """Advance the filter in ``buf`` over frames: the pure-Python reference loop (unrolled, hence its length).

    It unrolls, per frame: the quaternion of the increment (Shepperd), its
    rotation into the body frame, the twist, the scalar covariance and gain
    recursion, the residual update of the module docstring in quaternion
    products, the cumulative rotation, and pitch and roll from the third
    row of ``E`` (:func:`~imu_ground.filters.estimator.pitch_roll_from_normal`).

    Parameters
    ----------
    buf : array of float64 (BUF_LEN,) or list of float
        State and parameters (module docstring); updated in place.
    frames : sequence of 9-float sequences
        Increments sensor_{k-1} <- sensor_k, row-major (already checked:
        rotations, see :func:`~imu_ground.filters.frame_checks.frame_status`).
    q_h : sequence of float
        Horizontal process noise of each frame, rad^2 (a sequence at least as long as ``frames``).
    q_v : float
        Process noise about up per frame, rad^2.
    tilt_x, tilt_y : sequence of float, optional
        Modelled body tilt ``b = (b_x, b_y, 0)`` (rotation vector, rad) per
        frame; not used with ``up``.
    angles : bool
        Compute pitch and roll (a batch that derives them from the residuals
        afterwards passes False; they are then NaN).

    Returns
    -------
    list of tuple
        Per frame ``(ew, ex, ey, ez, a, c, pitch, roll)``, plus ``(rw, rx, ry, rz)``
        when the cumulative rotation is tracked.
    """
    ew, ex, ey, ez, a, c, rw, rx, ry, rz, count = buf[:_L_KA]       # the layout of the module docstring
    r_h, r_v, up, follow, cum, g, every = buf[_P_RH:_P_G]             # (flags and counts as floats: exact)
    if g:
        g00, g01, g02, g10, g11, g12, g20, g21, g22 = buf[_P_G:BUF_LEN]
    tilt = tilt_x is not None and not up
    out: list[tuple] = []
    append = out.append
    pitch = roll = nan
    for k in range(len(frames)):
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = frames[k]
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
        if g:                                   # body increment: vector part turned by R_gs
            dx, dy, dz = (g00 * dx + g01 * dy + g02 * dz, g10 * dx + g11 * dy + g12 * dz,
                          g20 * dx + g21 * dy + g22 * dz)
        # -- covariance and gains
        a += q_h[k]
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
        if follow and (dw > 0.0 or dz != 0.0):    # (a half turn about a level axis has no twist)
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
            if tilt:                            # M = E^- Exp(-b), b = (bx, by, 0)
                assert tilt_x is not None and tilt_y is not None
                bx, by = tilt_x[k], tilt_y[k]
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
        count += 1
        renorm = count % every == 0
        if renorm:
            nrm = 1.0 / sqrt(ew * ew + ex * ex + ey * ey + ez * ez)
            ew, ex, ey, ez = ew * nrm, ex * nrm, ey * nrm, ez * nrm
        # -- pitch and roll from n_b = E^T e_z, the third row of E
        if angles:
            n0 = 2.0 * (ex * ez - ew * ey)
            n1 = 2.0 * (ey * ez + ew * ex)
            n2 = 1.0 - 2.0 * (ex * ex + ey * ey)
            pitch, roll = atan2(-n0, sqrt(n1 * n1 + n2 * n2)), atan2(n1, n2)
        if cum:                                 # R = R dR
            rw, rx, ry, rz = (rw * dw - rx * dx - ry * dy - rz * dz, rw * dx + rx * dw + ry * dz - rz * dy,
                              rw * dy - rx * dz + ry * dw + rz * dx, rw * dz + rx * dy - ry * dx + rz * dw)
            if renorm:
                nrm = 1.0 / sqrt(rw * rw + rx * rx + ry * ry + rz * rz)
                rw, rx, ry, rz = rw * nrm, rx * nrm, ry * nrm, rz * nrm
            append((ew, ex, ey, ez, a, c, pitch, roll, rw, rx, ry, rz))
        else:
            append((ew, ex, ey, ez, a, c, pitch, roll))
    if out:
        new = (ew, ex, ey, ez, a, c, rw, rx, ry, rz, count, ka, kc, a_pr, c_pr, yx, yy, yz, mw, mx, my, mz, 1.0)
        buf[:_P_RH] = new if type(buf) is list else array("d", new)
    return out


def _floats(v, shape: tuple, name: str) -> list:
    """``v``, a float64 ndarray of ``shape``, as a flat list of Python floats; TypeError or
    ValueError otherwise, as the C twin raises them (the C twin also refuses a non-contiguous array,
    which the filters then copy; the result is the same)."""
    if type(v) is np.ndarray and v.shape == shape and (v.dtype is _F64 or v.dtype == _F64):
        return v.ravel().tolist()
    if type(v) is not np.ndarray or v.dtype != _F64:
        raise TypeError(f"{name} must be a C-contiguous float64 array, got {type(v).__name__}"
                        + (f" of {v.dtype}" if type(v) is np.ndarray else ""))
    raise ValueError(f"{name} must have shape {shape}, got {v.shape}")


_SHAPE_R, _SHAPE_V = (3, 3), (3,)


def step(buf: array, d, q_h: float, q_v: float, tilt_x: Optional[float], tilt_y: Optional[float],
         dv, dt: float):
    """One checked frame: the row of :func:`advance`, or the frame's status with the state untouched.

    Parameters
    ----------
    buf : array of float64 (BUF_LEN,) or list of float
        The kernel's buffer (:attr:`ResidualKernel.buf`), updated in place.
    d : ndarray (3, 3), float64
        Increment sensor_{k-1} <- sensor_k.
    q_h, q_v : float
        Process noise of this frame, horizontal and about up, rad^2 (Python floats: the loop
        computes in the type it is given).
    tilt_x, tilt_y : float or None
        Modelled body tilt, rad (None: none).
    dv : ndarray (3,) float64, or None
        Velocity increment to check (m/s; None: not checked).
    dt : float
        Frame duration to check, s.

    Returns
    -------
    tuple or int
        The row ``(ew, ex, ey, ez, a, c, pitch, roll[, rw, rx, ry, rz])``, or the
        status of :func:`~imu_ground.filters.frame_checks.frame_status` (> 0) of a bad frame.

    Raises
    ------
    TypeError, ValueError
        ``d`` or ``dv`` is not a float64 array of that shape: the caller coerces and retries.
    """
    d9 = _floats(d, _SHAPE_R, "delta_R")
    status = frame_status(d9, None if dv is None else _floats(dv, _SHAPE_V, "delta_v"), dt)
    if status:
        return status
    if tilt_x is None:
        return advance(buf, (d9,), (q_h,), q_v)[0]
    return advance(buf, (d9,), (q_h,), q_v, (tilt_x,), (0.0 if tilt_y is None else tilt_y,))[0]


def run(buf: array, d, q_h, q_v: float, tilt_x, tilt_y, out: np.ndarray, angles: bool) -> None:
    """Many frames (already checked) into ``out``: the batch entry point.

    Parameters
    ----------
    buf : array of float64 (BUF_LEN,) or list of float
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
        Receives the rows of :func:`advance` (12 columns with the cumulative rotation).
    angles : bool
        Compute pitch and roll (else NaN).
    """
    frames = np.asarray(d, dtype=float).reshape(-1, 9).tolist()
    n = len(frames)
    qs = [float(q_h)] * n if isinstance(q_h, (int, float)) else np.asarray(q_h, dtype=float).tolist()
    tx = None if tilt_x is None else np.asarray(tilt_x, dtype=float).tolist()
    ty = None if tilt_x is None else np.asarray(tilt_y, dtype=float).tolist()
    rows = advance(buf, frames, qs, float(q_v), tx, ty, angles=bool(angles))
    if n:
        out.reshape(n, -1)[:] = rows


def check(d, dv, dt: float) -> int:
    """The status of one frame (:func:`~imu_ground.filters.frame_checks.frame_status`; 0: good)."""
    dv3 = None if dv is None else _floats(dv, _SHAPE_V, "delta_v")
    return frame_status(_floats(d, _SHAPE_R, "delta_R"), dv3, dt)


#: The pure-Python kernel (``step``, ``run``, ``check``): the reference.
PYTHON = SimpleNamespace(step=step, run=run, check=check, BUF_LEN=BUF_LEN)
#: The kernel in use by default: the compiled twin (:data:`imu_ground._native.RESIDUAL`) when built, else
#: :data:`PYTHON`.
NATIVE = _native.RESIDUAL
if NATIVE is not None and getattr(NATIVE, "BUF_LEN", None) != BUF_LEN:
    raise ImportError(f"{NATIVE.__file__} is older than residual.py (its state buffer has "
                      f"{getattr(NATIVE, 'BUF_LEN', '?')} floats, residual.py {BUF_LEN}): "
                      f"rebuild with `pip install -e .`")


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
    native : bool, optional
        None: the compiled kernel when built, else the Python one; False: the
        Python reference; True: the compiled kernel (ImportError when not built).

    Attributes
    ----------
    buf : array of float64 (BUF_LEN,), or list of float
        State and parameters (module docstring); a list for the Python kernel
        (faster to unpack in pure Python). The residual road <- body and the
        cumulative rotation are quaternions (w, x, y, z), re-normalised every
        :data:`~imu_ground.units.RENORM_EVERY` frames (so unit to ~1e-14 in between).
    native : bool
        Whether :attr:`impl` is the compiled kernel.
    """

    __slots__ = ("buf", "native")

    def __init__(self, a: float, c: float, r_h: float, r_v: float, up: bool = False, follow_heading: bool = True,
                 Rgs=None, cumulative: bool = False, native: Optional[bool] = None) -> None:
        g = [0.0] * 9 if Rgs is None else [float(v) for v in np.asarray(Rgs, dtype=float).ravel()]
        values = ([1.0, 0.0, 0.0, 0.0, float(a), float(c), 1.0, 0.0, 0.0, 0.0, 0.0] + [0.0] * 12
                  + [float(r_h), float(r_v), float(bool(up)), float(bool(follow_heading)),
                     float(bool(cumulative)), float(Rgs is not None), float(RENORM_EVERY)] + g)
        if native is True and NATIVE is None:
            raise ImportError("the compiled residual kernel is not built (or IMU_GROUND_PURE_PYTHON is set)")
        self.native = native is not False and NATIVE is not None
        self.buf: MutableSequence[float] = array("d", values) if self.native else values

    def read_state(self, reader, name: str) -> list:
        """The entry ``name`` of a saved state (a :class:`~imu_ground.imu.warm_start.StateReader`), checked to
        be a buffer of this kernel's layout: finite, NaN only in the record of the last frame."""
        return reader.floats(name, (len(self.buf),), nan=slice(_L_KA, _L_HAS)).tolist()

    def load(self, values: Sequence[float]) -> None:
        """A new :attr:`buf` of ``values`` (a saved state's), in the container this kernel runs on."""
        self.buf = array("d", values) if self.native else [float(v) for v in values]

    def set_mount(self, Rgs: np.ndarray) -> None:
        """Turn sensor increments into the body frame with the static rotation ``Rgs`` (ground <- sensor) from
        the next frame on (in place: the buffer object stays the same)."""
        b = self.buf
        b[_P_RH + 5] = 1.0
        b[_P_G:_P_G + 9] = array("d", Rgs.ravel().tolist()) if self.native else Rgs.ravel().tolist()

    @property
    def impl(self):
        """``step(buf, ...)``, ``run(buf, ...)``, ``check(...)``: the compiled twin or :data:`PYTHON`."""
        return NATIVE if self.native else PYTHON

    @property
    def E(self) -> tuple:
        """Residual road <- body, quaternion (w, x, y, z)."""
        return tuple(self.buf[0:4])

    @property
    def R(self) -> Optional[tuple]:
        """Cumulative rotation world <- body (from identity), quaternion, or None when not tracked."""
        return tuple(self.buf[6:10]) if self.buf[_P_RH + 4] != 0.0 else None

    a = property(lambda self: self.buf[4], doc="Covariance about the horizontal axes, rad^2.")
    c = property(lambda self: self.buf[5], doc="Covariance about up, rad^2.")

    def residual_matrix(self) -> np.ndarray:
        """:attr:`E` as a rotation matrix (3, 3), road <- body."""
        return matrix_from_quat(np.array(self.E))

    def covariance(self) -> np.ndarray:
        """``diag(a, a, c)`` (3, 3), rad^2: the covariance of the slow state, body tangent space."""
        return np.diag([self.a, self.a, self.c])
    frames = property(lambda self: int(self.buf[10]), doc="Frames processed.")

    @property
    def last(self) -> Optional[tuple]:
        """Of the last frame: ``(k_a, k_c, a_prior, c_prior, yx, yy, yz, mw, mx, my, mz)``: gains,
        predicted covariance, innovation and predicted residual ``E^-``; None before the first."""
        return tuple(self.buf[_L_KA:_L_HAS]) if self.buf[_L_HAS] != 0.0 else None

    @property
    def width(self) -> int:
        """Columns of an output row: 8, or 12 with the cumulative rotation."""
        return 12 if self.buf[_P_RH + 4] != 0.0 else 8

    def advance(self, frames: Sequence[Sequence[float]], q_h: Sequence[float], q_v: float,
                tilt_x: Optional[Sequence[float]] = None, tilt_y: Optional[Sequence[float]] = None,
                angles: bool = True) -> list:
        """:func:`advance` (the pure-Python loop, whatever :attr:`impl` is) on this kernel's state."""
        return advance(self.buf, frames, q_h, q_v, tilt_x, tilt_y, angles)

    def run(self, d, q_h, q_v: float, tilt_x=None, tilt_y=None, angles: bool = False) -> np.ndarray:
        """:func:`run` through :attr:`impl` into a new array (F, :attr:`width`)."""
        d = np.ascontiguousarray(d, dtype=float)
        out = np.empty((len(d), self.width))
        if tilt_x is not None:
            tilt_x, tilt_y = (np.ascontiguousarray(t, dtype=float) for t in (tilt_x, tilt_y))
        if not isinstance(q_h, (int, float)):
            q_h = np.ascontiguousarray(q_h, dtype=float)
        self.impl.run(self.buf, d, q_h, q_v, tilt_x, tilt_y, out, angles)
        return out
