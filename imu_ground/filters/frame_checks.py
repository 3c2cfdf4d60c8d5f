"""Checks of the frames an estimator is given, and what it does with a bad one.

A frame is an ego-motion increment: ``delta_R`` (sensor_{k-1} <- sensor_k, a rotation), ``delta_v`` (m/s, sensor
frame, optional) and ``delta_t`` (s); arguments named ``d, dv, dt`` are those, (3, 3), (3,) (None: not checked) and
a float, or (F, ...) for a batch. The check is one compiled body, :func:`status_of`, run on every streamed frame
and over a batch (:func:`frame_statuses`); :func:`frame_problem` names what is wrong, and :func:`checked_frame`,
:func:`bad_frame` and :func:`checked_frames` apply the ``on_invalid`` policy with one message
(:func:`bad_frame_error`).
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Optional

import numpy as np

from imu_ground._jit import njit
from imu_ground.errors import ImuGroundError
from imu_ground.so3 import as_rotations

__all__ = ["frames_of", "ON_INVALID", "ORTHO_TOL", "BAD_ROTATION", "BAD_DELTA_V", "BAD_DELTA_T", "MAX_DELTA_V", "MIN_DELTA_T",
           "MAX_DELTA_T", "status_of", "statuses_of", "frame_status", "frame_problem",
           "frame_problems", "frame_statuses", "checked_frames", "check_on_invalid", "bad_frame_error",
           "checked_frame", "coerce_frame", "bad_frame", "static_rotation", "frame_where", "hold_skipped"]

#: What a streaming estimator does with a bad frame: raise ``ValueError`` (state untouched) or
#: skip it and return an estimate flagged invalid.
ON_INVALID = ("raise", "skip")
#: Largest ``|R^T R - I|`` entry of an accepted rotation increment.
ORTHO_TOL = 1e-6
#: Largest ``|delta_v|`` component of an accepted frame, m/s: no vehicle's velocity changes by more within a
#: frame, and larger values overflow the filters' squares (a frame beyond it is bad, as a non-finite one).
MAX_DELTA_V = 1e6
#: Shortest accepted frame, s: shorter ones are no IMU's (1 MHz) and their rates overflow the filters' squares.
MIN_DELTA_T = 1e-6
#: Longest accepted frame, s (11.6 days: a longer one joins two recordings; its noise terms overflow).
MAX_DELTA_T = 1e6
#: :func:`frame_status` codes of a bad frame.
BAD_ROTATION, BAD_DELTA_V, BAD_DELTA_T = 1, 2, 3


@njit
def status_of(d, has_dv, dv, delta_t):
    """:func:`frame_status` of ``d`` (ndarray (3, 3) float64), ``dv`` (ndarray (3,), read when ``has_dv``) and
    ``delta_t`` (float, s): the one compiled check of a frame."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = (d[0, 0], d[0, 1], d[0, 2], d[1, 0], d[1, 1], d[1, 2],
                                                   d[2, 0], d[2, 1], d[2, 2])
    lo, hi = 1.0 - ORTHO_TOL, 1.0 + ORTHO_TOL
    if not (lo <= r00 * r00 + r10 * r10 + r20 * r20 <= hi and lo <= r01 * r01 + r11 * r11 + r21 * r21 <= hi
            and lo <= r02 * r02 + r12 * r12 + r22 * r22 <= hi
            and -ORTHO_TOL <= r00 * r01 + r10 * r11 + r20 * r21 <= ORTHO_TOL
            and -ORTHO_TOL <= r00 * r02 + r10 * r12 + r20 * r22 <= ORTHO_TOL
            and -ORTHO_TOL <= r01 * r02 + r11 * r12 + r21 * r22 <= ORTHO_TOL
            and r00 * (r11 * r22 - r12 * r21) - r01 * (r10 * r22 - r12 * r20) + r02 * (r10 * r21 - r11 * r20) > 0.0):
        return BAD_ROTATION                         # (NaN fails every comparison)
    if has_dv and not (abs(dv[0]) <= MAX_DELTA_V and abs(dv[1]) <= MAX_DELTA_V and abs(dv[2]) <= MAX_DELTA_V):
        return BAD_DELTA_V                          # (NaN fails the comparison)
    if not MIN_DELTA_T <= delta_t <= MAX_DELTA_T:
        return BAD_DELTA_T
    return 0


@njit
def _statuses(d, has_dv, dv, has_dt, dt, out):
    for k in range(d.shape[0]):
        out[k] = status_of(d[k], has_dv, dv[k] if has_dv else dv[0], dt[k] if has_dt else 1.0)


_NO_FRAMES = np.zeros((1, 3))


def statuses_of(d: np.ndarray, dv: Optional[np.ndarray], dt: Optional[np.ndarray], out: np.ndarray) -> None:
    """:func:`status_of` of every frame into ``out`` (uint8 (F,)); C-contiguous float64 arrays."""
    _statuses(d, dv is not None, _NO_FRAMES if dv is None else dv, dt is not None,
              _NO_FRAMES[0] if dt is None else dt, out)


def frame_status(d9, delta_v=None, delta_t: float = 1.0) -> int:
    """What is wrong with one frame, as a code (:func:`status_of`; :func:`frame_problem` gives the message).

    Parameters
    ----------
    d9 : sequence of 9 float
        ``delta_R`` row-major (sensor_{k-1} <- sensor_k).
    delta_v, delta_t : sequence of 3 float (optional), float
        Velocity increment, m/s, and frame duration, s.

    Returns
    -------
    int
        0: good; :data:`BAD_ROTATION` (non-finite, not orthonormal to :data:`ORTHO_TOL`, or det <= 0),
        :data:`BAD_DELTA_V` (not finite or beyond :data:`MAX_DELTA_V`) or :data:`BAD_DELTA_T` (not from
        :data:`MIN_DELTA_T` to :data:`MAX_DELTA_T` s).
    """
    d = np.array(d9, dtype=float).reshape(3, 3)
    dv = _NO_FRAMES[0] if delta_v is None else np.array(delta_v, dtype=float).reshape(3)
    return int(status_of(d, delta_v is not None, dv, float(delta_t)))


def frame_problem(d9, delta_v=None, delta_t: float = 1.0, status: Optional[int] = None) -> Optional[str]:
    """What is wrong with one frame (arguments as :func:`frame_status`), or None; ``status`` its code if known."""
    status = frame_status(d9, delta_v, delta_t) if status is None else status
    if status == BAD_ROTATION:
        return _rotation_message(d9)
    if status == BAD_DELTA_V:
        vx, vy, vz = delta_v
        return f"delta_v is not finite or beyond {MAX_DELTA_V:g} m/s ({vx}, {vy}, {vz})"
    if status == BAD_DELTA_T:
        return (f"delta_t must be a positive number of seconds, got {delta_t} (from {MIN_DELTA_T:g} to "
                f"{MAX_DELTA_T:g} s)")
    return None


def _rotation_message(d9) -> str:
    m = np.array(d9, dtype=float).reshape(3, 3)
    if not np.all(np.isfinite(m)):
        return "delta_R is not finite"
    with np.errstate(over="ignore", invalid="ignore"):      # a huge matrix: the message says inf
        err = float(np.abs(m.T @ m - np.eye(3)).max())
        det = float(np.linalg.det(m))
    return (f"delta_R is not a rotation: |R^T R - I| = {err:.3g} (tolerance {ORTHO_TOL:g}), "
            f"det = {det:.6g} (must be +1)")


def frame_statuses(d: np.ndarray, dv: Optional[np.ndarray] = None, dt: Optional[np.ndarray] = None) -> np.ndarray:
    """:func:`frame_status` of every frame (uint8 (F,)): a batch flags exactly the frames a stream would."""
    d = np.ascontiguousarray(d, dtype=float)
    out = np.zeros(len(d), dtype=np.uint8)
    if len(d):
        statuses_of(d, None if dv is None else np.ascontiguousarray(dv, dtype=float),
                    None if dt is None else np.ascontiguousarray(dt, dtype=float), out)
    return out


def _problem_at(k: int, status: int, d: np.ndarray, dv, dt) -> Optional[str]:
    return frame_problem(d[k].ravel().tolist(), None if dv is None else np.asarray(dv[k], dtype=float).tolist(),
                         1.0 if dt is None else float(dt[k]), status=status)


def frame_problems(d: np.ndarray, dv: Optional[np.ndarray] = None, dt: Optional[np.ndarray] = None) -> list:
    """:func:`frame_problem` of every frame (None for a good one)."""
    status = frame_statuses(d, dv, dt)
    out: list = [None] * len(status)
    for k in np.flatnonzero(status).tolist():
        out[k] = _problem_at(k, int(status[k]), np.asarray(d, dtype=float), dv, dt)
    return out


def checked_frames(d: np.ndarray, dv: Optional[np.ndarray], dt: Optional[np.ndarray], t: np.ndarray,
                   on_invalid: str) -> np.ndarray:
    """Which frames of a batch an estimator's ``run`` processes (the others it skips).

    Parameters
    ----------
    d, dv, dt, t : ndarray
        The frames (module docstring) and their times, s (to name a bad frame).
    on_invalid : {"raise", "skip"}
        The estimator's policy (:data:`ON_INVALID`).

    Returns
    -------
    ndarray of bool (F,)
        True for a good frame.

    Raises
    ------
    ValueError
        A bad frame with ``on_invalid="raise"``: the first one is named, with the count.
    """
    status = frame_statuses(d, dv, dt)
    good = status == 0
    if on_invalid == "raise" and not good.all():
        k = int(np.argmin(good))
        problem = _problem_at(k, int(status[k]), np.asarray(d, dtype=float), dv, dt)
        assert problem is not None          # the frame's status is not OK
        raise bad_frame_error(problem, frame_where(k, float(t[k])) + f"; {len(good) - good.sum()} bad of {len(good)}")
    return good


def check_on_invalid(on_invalid: str) -> str:
    """``on_invalid`` validated (one of :data:`ON_INVALID`)."""
    if on_invalid not in ON_INVALID:
        raise ValueError(f"on_invalid must be 'raise' or 'skip', got {on_invalid!r}")
    return on_invalid


def bad_frame_error(problem: str, where: str) -> ImuGroundError:
    """The error a streaming estimator raises for a bad frame (its state untouched): bad input data."""
    return ImuGroundError(f"bad ego-motion frame ({where}): {problem}; the estimator's state is unchanged "
                          f"(construct it with on_invalid='skip' to skip such frames)")


def checked_frame(check, frame, delta_R, delta_v, delta_t: float, on_invalid: str, index: int) -> tuple | None:
    """A streamed frame's ``delta_R`` (3x3) and ``delta_v`` (3,) as float64 arrays, if the frame passes the check.

    Parameters
    ----------
    check : callable
        ``check(delta_R, delta_v, delta_t) -> int`` (:func:`imu_ground.filters.residual.check`), run after
        :func:`coerce_frame` when the inputs are not float64 arrays already.
    frame, delta_R, delta_v, delta_t, on_invalid, index
        As for :func:`bad_frame` (``delta_R`` in any form of :func:`coerce_frame`).

    Returns
    -------
    (ndarray (3, 3), ndarray (3,) or None) or None
        None: a bad frame to skip (``on_invalid="skip"``).

    Raises
    ------
    ValueError
        ``delta_R`` is not one rotation, or a bad frame with ``on_invalid="raise"``.
    """
    d, dv = delta_R, delta_v
    try:
        status = check(d, dv, delta_t)
    except (TypeError, ValueError):
        d, dv = coerce_frame(d, dv)
        status = check(d, dv, delta_t)
    if status:
        bad_frame(frame, status, d, dv, delta_t, on_invalid, index)
        return None
    return d, dv


def coerce_frame(delta_R, delta_v=None) -> tuple:
    """A streamed frame as the kernels take it: one C-contiguous float64 3x3 rotation and a float64 (3,) or None.

    Parameters
    ----------
    delta_R, delta_v : array_like
        sensor_{k-1} <- sensor_k (a matrix, a 4x4 relative pose or a rotation vector, rad,
        :func:`~imu_ground.so3.as_rotations`) and the velocity increment (3,), m/s, or None.

    Raises
    ------
    ValueError
        ``delta_R`` is not one rotation (e.g. a batch) or ``delta_v`` not 3 values.
    """
    d = as_rotations(delta_R)
    if d.shape != (3, 3):
        raise ValueError(f"delta_R must be one rotation, got shape {d.shape}")
    dv = None if delta_v is None else np.ascontiguousarray(np.asarray(delta_v, dtype=float).reshape(3))
    return np.ascontiguousarray(d, dtype=float), dv


def bad_frame(frame, status: int, d: np.ndarray, dv, dt: float, on_invalid: str, index: int) -> None:
    """A bad streamed frame: raise the error, or return with ``on_invalid="skip"``.

    Parameters
    ----------
    frame : object
        The frame as given to ``step``; its ``t`` (s), if it has one, locates the error.
    status : int
        The frame's :func:`frame_status` (> 0).
    d, dv, dt
        The frame (module docstring).
    on_invalid : {"raise", "skip"}
        The estimator's policy (:data:`ON_INVALID`).
    index : int
        0-based index of the frame in the estimator's run, for the message.
    """
    if on_invalid == "raise":
        dv3 = None if dv is None else np.asarray(dv, dtype=float).ravel().tolist()
        problem = frame_problem(np.asarray(d, dtype=float).ravel().tolist(), dv3, dt, status)
        assert problem is not None          # called for a frame whose status is not OK
        raise bad_frame_error(problem, frame_where(index, getattr(frame, "t", math.nan)))


def static_rotation(extrinsic) -> Optional[np.ndarray]:
    """The extrinsic's ground <- sensor rotation, or None when it is the identity (nothing to apply)."""
    R = extrinsic.rotation
    return None if np.array_equal(R, np.eye(3)) else R


def frame_where(index: int, t: float) -> str:
    """``"frame 12 of the run, t = 1.3 s"``-style location of a frame (0-based index)."""
    return f"frame index {index}" + ("" if math.isnan(t) else f", t = {t:.6g} s")


def hold_skipped(values: np.ndarray, good: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """Per-frame ``values`` (G, ...) of the ``good`` frames (bool (F,)) spread over all frames, a skipped frame
    holding the previous value (``initial`` before the first)."""
    if good.all():
        return values
    idx = np.cumsum(good) - 1
    padded = np.concatenate([np.asarray(initial, dtype=float)[None], values])
    return padded[idx + 1]


def frames_of(em, keep: np.ndarray):
    """The ego-motion restricted to the frames ``keep`` (same rate and metadata)."""
    return replace(em, t=em.t[keep], delta_R=em.delta_R[keep], delta_v=em.delta_v[keep], delta_t=em.delta_t[keep],
                   stationary=em.stationary[keep], valid=em.valid[keep])
