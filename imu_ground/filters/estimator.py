r"""What every ground estimator shares: the protocol, its results, the output table, the frame checks.

Frames and signs (see the glossary of :mod:`imu_ground.so3`)
------------------------------------------------------------
- sensor ``s``: the frame of the ego-motion (IMU, camera, ...);
- body/ground ``g``: FLU vehicle frame, z along the road normal at rest on flat
  ground; ``R_gs`` (ground <- sensor) is the static extrinsic;
- world ``w``: the body frame at the start (``R0``); road ``r``: the slow state
  ``X`` (world <- road) of the estimators;
- residual ``E = X^T R`` (road <- body): the fast body motion, with ``R``
  (world <- body) the cumulative rotation.

Pitch is positive nose *down* (right-handed about y-left), roll positive left
side *up* (about x-forward); both are read off the road normal in the body
frame ``n_b = E^T e_z = [-sin p, sin r cos p, cos p cos r]`` (:func:`pitch_roll_from_normal`).
The normal in the sensor frame is ``n_s = (E R_gs)^T e_z``.

Every estimator (:class:`GroundEstimator`) has ``reset()``, ``step(frame) ->``
:class:`GroundEstimate` and ``run(egomotion, smooth=False) ->`` :class:`GroundTrack`;
:func:`track_table` is the one output table. The scalar residual filter both
invariant-EKF estimators run on is :class:`~imu_ground.filters.residual.ResidualKernel`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Optional, Protocol, runtime_checkable

import numpy as np

from imu_ground._native import load_native
from imu_ground.filters.rotations import as_rotations, matrix_from_quat, quat_from_matrix
from imu_ground.filters.status import GAP, INVALID, OK, STATUSES, status_names, status_reason
from imu_ground.units import DEFAULT_FRAME_RATE

if TYPE_CHECKING:                                   # imported lazily: the imu layer pulls in pandas
    import pandas as pd

    from imu_ground.imu.egomotion import EgoFrame, EgoMotion

__all__ = ["GroundEstimate", "GroundTrack", "GroundEstimator", "pitch_roll_from_normal", "track_table",
           "as_egomotion", "ON_INVALID", "ORTHO_TOL", "frame_status", "frame_problem",
           "BAD_ROTATION", "BAD_DELTA_V", "BAD_DELTA_T", "frame_problems", "frame_statuses", "checked_frames",
           "check_on_invalid",
           "bad_frame_error", "checked_frame", "coerce_frame", "bad_frame", "static_rotation", "frame_where",
           "hold_skipped"]

#: What a streaming estimator does with a bad frame: raise ``ValueError`` (state untouched) or
#: skip it and return an estimate flagged invalid.
ON_INVALID = ("raise", "skip")
#: Largest ``|R^T R - I|`` entry of an accepted rotation increment.
ORTHO_TOL = 1e-6
#: :func:`frame_status` codes of a bad frame.
BAD_ROTATION, BAD_DELTA_V, BAD_DELTA_T = 1, 2, 3
_NATIVE = load_native("imu_ground.filters._residual_native")     # its check/check_many twin frame_status
_EZ3 = (0.0, 0.0, 1.0)


def pitch_roll_from_normal(n_body):
    """Pitch and roll of the body relative to the road from the normal in the body frame.

    Parameters
    ----------
    n_body : array_like, shape (..., 3)
        Unit road normal in the body (FLU) frame.

    Returns
    -------
    pitch, roll : ndarray, shape (...)
        Radians; pitch positive nose down, roll positive left side up
        (``n_b = [-sin p, sin r cos p, cos p cos r]``).
    """
    n = np.asarray(n_body, dtype=float)
    pitch = np.arctan2(-n[..., 0], np.hypot(n[..., 1], n[..., 2]))
    roll = np.arctan2(n[..., 1], n[..., 2])
    return pitch, roll


class GroundEstimate:
    """One frame's result of an estimator's ``step``.

    Pitch, roll and the flag are plain floats; the arrays are built on first
    access (a streaming step that only needs pitch and roll does not pay for them).

    Attributes
    ----------
    normal : ndarray (3,)
        Unit ground normal in the sensor frame.
    pitch, roll : float
        Body attitude relative to the road, rad (pitch + nose down, roll + left up).
    residual : ndarray (3, 3)
        ``E = X^T R`` (road <- body), the fast body motion.
    extrinsic : ndarray (3, 3)
        Dynamic extrinsic rotation ``E R_gs`` (road-ground <- sensor).
    P : ndarray (3, 3)
        Covariance of the slow state, body tangent space (rad^2).
    valid : bool
        False for a frame the estimator skipped (``on_invalid="skip"``): the
        values are then those of the previous frame.
    pitch_std, roll_std : float
        Calibrated 1-sigma of pitch and roll, rad (:mod:`imu_ground.filters.status`; NaN when unknown).
    status : str
        One of :data:`~imu_ground.filters.status.STATUSES`; ``status_code`` its index.
    status_reason : str
        Why (empty for ``ok``, or a note such as why the road is not estimated).
    road_grade, road_bank, road_grade_std, road_bank_std : float
        The road's attitude relative to gravity and its 1-sigma, rad (:mod:`imu_ground.filters.road`;
        + uphill in the direction of travel, + left side up; NaN: not estimated).
    """
    __slots__ = ("pitch", "roll", "valid", "_q", "_E", "_Rgs", "_P", "status_code", "_info", "_road")

    # quaternion: a kernel output row (its first 4 entries, w x y z); P: a 3x3 array or the same row
    # (entries 4 and 5: diag(a, a, c))

    def __init__(self, pitch: float, roll: float, valid: bool = True, quaternion=None, residual=None,
                 Rgs: Optional[np.ndarray] = None, P=None, status_code: Optional[int] = None, info=None,
                 road=None) -> None:
        self.pitch, self.roll, self.valid = pitch, roll, valid
        self._q, self._E, self._Rgs, self._P = quaternion, residual, Rgs, P
        # info: (pitch model, roll model, a, u_x, u_y, tilt var pitch, tilt var roll, frame s, detail,
        # convergence threshold): the 1-sigma and the reason are built on access
        self.status_code = (OK if valid else INVALID) if status_code is None else status_code
        self._info = info
        self._road = road                   # (grade, bank, gravity's variance of each), filters.road, or None

    @property
    def pitch_std(self) -> float:
        i = self._info
        return math.nan if i is None else math.sqrt(i[0].variance(i[2], i[3], i[4], i[5]))

    @property
    def roll_std(self) -> float:
        i = self._info
        return math.nan if i is None else math.sqrt(i[1].variance(i[2], i[3], i[4], i[6]))

    @property
    def status(self) -> str:
        return STATUSES[self.status_code]

    road_grade = property(lambda self: math.nan if self._road is None else self._road[0],
                          doc="The road's grade relative to gravity, rad, + uphill (NaN: not estimated).")
    road_bank = property(lambda self: math.nan if self._road is None else self._road[1],
                         doc="The road's bank relative to gravity, rad, + left side up (NaN: not estimated).")
    road_grade_std = property(lambda self: math.nan if self._road is None else
                              math.sqrt(self.pitch_std ** 2 + self._road[2]), doc="1-sigma of ``road_grade``, rad.")
    road_bank_std = property(lambda self: math.nan if self._road is None else
                             math.sqrt(self.roll_std ** 2 + self._road[3]), doc="1-sigma of ``road_bank``, rad.")

    @property
    def status_reason(self) -> str:
        i = self._info
        if i is None:
            return status_reason(self.status_code)
        return status_reason(self.status_code, i[7], max(self.pitch_std, self.roll_std), i[8], i[9])

    @classmethod
    def of_residual(cls, E: np.ndarray, P: np.ndarray, Rgs: Optional[np.ndarray] = None,
                    valid: bool = True) -> "GroundEstimate":
        """The estimate of a residual ``E`` (road <- body, 3x3) with covariance ``P`` and static extrinsic ``Rgs``."""
        pitch, roll = pitch_roll_from_normal(E[2])
        return cls(float(pitch), float(roll), valid, None, E, Rgs, P)

    @property
    def residual(self) -> np.ndarray:
        if self._E is None:
            self._E = matrix_from_quat(np.array(self._q[:4]))
        return self._E

    @property
    def extrinsic(self) -> np.ndarray:
        return self.residual if self._Rgs is None else self.residual @ self._Rgs

    @property
    def normal(self) -> np.ndarray:
        return self.extrinsic[2].copy()

    @property
    def P(self) -> np.ndarray:
        p = self._P
        return np.diag([p[4], p[4], p[5]]) if isinstance(p, tuple) else p

    def __iter__(self):
        """``normal, pitch, roll, residual, extrinsic, P`` (the fields of the former named tuple)."""
        return iter((self.normal, self.pitch, self.roll, self.residual, self.extrinsic, self.P))

    def __repr__(self) -> str:
        return (f"GroundEstimate(pitch={self.pitch!r}, roll={self.roll!r}, valid={self.valid!r}, "
                f"normal={self.normal!r})")


@dataclass
class GroundTrack:
    """Per-frame results of an estimator's ``run`` (F frames).

    Attributes
    ----------
    normal : ndarray (F, 3)      unit ground normal, sensor frame.
    pitch, roll : ndarray (F,)   rad, body relative to road (signs as in :class:`GroundEstimate`).
    residual : ndarray (F, 3, 3) road <- body.
    extrinsic : ndarray (F, 3, 3) dynamic extrinsic, road-ground <- sensor.
    P : ndarray (F, 3, 3)        covariance of the slow state (rad^2).
    x : ndarray (F, 3, 3)        slow state, world <- road.
    cumulative : ndarray (F, 3, 3) cumulative body rotation, world <- body.
    translation : ndarray (3,)   static sensor position in the ground frame (m).
    t : ndarray (F,)             frame (end) times, s (NaN when unknown).
    valid : ndarray of bool (F,) False where the frame spans a gap in the source or was skipped.
    pitch_std, roll_std : ndarray (F,) calibrated 1-sigma of pitch and roll, rad (NaN: unknown).
    status : ndarray of uint8 (F,) code of :data:`~imu_ground.filters.status.STATUSES` (default: ok, or gap
                                 where not valid).
    status_reason : ndarray of object (F,) str, why (empty for ok).
    road_grade, road_bank : ndarray (F,) the road's attitude relative to gravity, rad (+ uphill in the
                                 direction of travel, + left side up; NaN: not estimated).
    road_grade_std, road_bank_std : ndarray (F,) their 1-sigma, rad.
    """
    normal: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    residual: np.ndarray
    extrinsic: np.ndarray
    P: np.ndarray
    x: np.ndarray
    cumulative: np.ndarray
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    t: Optional[np.ndarray] = None
    valid: Optional[np.ndarray] = None
    pitch_std: Optional[np.ndarray] = None
    roll_std: Optional[np.ndarray] = None
    status: Optional[np.ndarray] = None
    status_reason: Optional[np.ndarray] = None
    road_grade: Optional[np.ndarray] = None
    road_bank: Optional[np.ndarray] = None
    road_grade_std: Optional[np.ndarray] = None
    road_bank_std: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        n = len(self.pitch)
        self.t = np.full(n, np.nan) if self.t is None else np.asarray(self.t, dtype=float).reshape(n)
        self.valid = np.ones(n, dtype=bool) if self.valid is None else np.asarray(self.valid, dtype=bool).reshape(n)
        for name in ("pitch_std", "roll_std", "road_grade", "road_bank", "road_grade_std", "road_bank_std"):
            v = getattr(self, name)
            setattr(self, name, np.full(n, np.nan) if v is None else np.asarray(v, dtype=float).reshape(n))
        if self.status is None:
            self.status = np.where(self.valid, OK, GAP).astype(np.uint8)
        self.status = np.asarray(self.status, dtype=np.uint8).reshape(n)
        if self.status_reason is None:
            self.status_reason = np.where(self.status == GAP, "gap in the log", "").astype(object)
        self.status_reason = np.asarray(self.status_reason, dtype=object).reshape(n)

    def __len__(self) -> int:
        return len(self.pitch)

    @classmethod
    def from_residuals(cls, E: np.ndarray, X: np.ndarray, P: np.ndarray, cumulative: np.ndarray,
                       Rgs: Optional[np.ndarray] = None, translation=None, t=None, valid=None, **extra):
        """The track of residuals ``E`` (road <- body): normal, pitch, roll and dynamic extrinsic from them.

        Parameters
        ----------
        E, X, P, cumulative : ndarray (F, 3, 3)
            Residual, slow state (world <- road), its covariance, cumulative rotation (world <- body).
        Rgs : ndarray (3, 3), optional
            Static extrinsic ground <- sensor (None: identity).
        translation : array_like (3,), optional
            Static sensor position in the ground frame, m.
        t, valid : ndarray (F,), optional
            Frame times (s) and validity.
        **extra
            Further fields of a subclass.
        """
        E = np.asarray(E, dtype=float).reshape(-1, 3, 3)
        pitch, roll = pitch_roll_from_normal(E[:, 2, :])
        dyn = E if Rgs is None else E @ Rgs
        tr = np.zeros(3) if translation is None else np.array(translation, dtype=float)
        return cls(dyn[:, 2, :].copy(), pitch, roll, E, dyn, P, X, cumulative, tr, t, valid, **extra)

    def to_dataframe(self):
        """The output table, :func:`track_table`."""
        return track_table(self)


@runtime_checkable
class GroundEstimator(Protocol):
    """What every ground estimator offers (structural type: no base class needed)."""

    def reset(self) -> None:
        """Back to the initial state."""

    def step(self, frame: "EgoFrame") -> GroundEstimate:
        """Process one frame of ego-motion (sensor frame) and return its estimate."""

    def run(self, egomotion: "EgoMotion", smooth: bool = False) -> GroundTrack:
        """Process a whole drive, continuing from the current state as ``step`` would."""


def track_table(track: GroundTrack, max_gap_frames: int = 3) -> "pd.DataFrame":
    """THE output table of an estimate, one row a frame.

    Parameters
    ----------
    track : GroundTrack
    max_gap_frames : int
        Invalid frames in a run of more than this many consecutive invalid
        frames (a long gap in the source) get NaN values; shorter runs keep
        their (extrapolated) values. ``valid`` is False for all of them.

    Returns
    -------
    pandas.DataFrame
        Columns ``t`` (s), ``normal_x, normal_y, normal_z`` (unit normal, sensor
        frame), ``pitch_deg`` (+ nose down), ``roll_deg`` (+ left side up),
        ``qw, qx, qy, qz`` (residual rotation road <- body, scalar first,
        ``qw >= 0``), ``valid`` (bool), ``pitch_std_deg, roll_std_deg`` (calibrated
        1-sigma), ``road_grade_deg`` (+ uphill in the direction of travel),
        ``road_bank_deg`` (+ left side up), ``road_grade_std_deg, road_bank_std_deg``
        (NaN where not estimated), ``status`` (str, :data:`~imu_ground.filters.status.STATUSES`)
        and ``status_reason`` (str).
    """
    import pandas as pd
    n = len(track)
    q = quat_from_matrix(track.residual) if n else np.zeros((0, 4))
    valid = np.asarray(track.valid, dtype=bool)
    df = pd.DataFrame({"t": np.asarray(track.t, dtype=float),
                       "normal_x": track.normal[:, 0], "normal_y": track.normal[:, 1], "normal_z": track.normal[:, 2],
                       "pitch_deg": np.degrees(track.pitch), "roll_deg": np.degrees(track.roll),
                       "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3], "valid": valid,
                       **{f"{name}_deg": np.degrees(getattr(track, name)) for name in _EXTRA_ANGLES},
                       "status": status_names(track.status), "status_reason": track.status_reason})
    blank = _long_runs(~valid, max_gap_frames)
    if blank.any():
        cols = [c for c in df.columns if c not in ("t", "valid", "status", "status_reason")]
        df.loc[blank, cols] = np.nan
    return df


#: Angle fields of a track written to the table after ``valid``, as ``NAME_deg``.
_EXTRA_ANGLES = ("pitch_std", "roll_std", "road_grade", "road_bank", "road_grade_std", "road_bank_std")


def _long_runs(mask: np.ndarray, longer_than: int) -> np.ndarray:
    """Elements of ``mask`` that lie in runs of more than ``longer_than`` consecutive True."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    out = np.zeros(len(mask), dtype=bool)
    for a, b in zip(edges[::2], edges[1::2]):
        if b - a > longer_than:
            out[a:b] = True
    return out


def as_egomotion(data, rate: Optional[float] = None) -> "EgoMotion":
    """An :class:`~imu_ground.imu.egomotion.EgoMotion` from what an estimator's ``run`` accepts.

    Parameters
    ----------
    data : EgoMotion, ImuData or array_like
        Ego-motion (returned as is), a raw IMU log (preintegrated at ``rate``)
        or rotation increments sensor_{k-1} <- sensor_k, shape (F, 3, 3),
        (F, 4, 4) or (F, 3) (rotation vectors, rad), at ``rate``.
    rate : float, optional
        Frame rate, Hz, for the last two; :data:`~imu_ground.units.DEFAULT_FRAME_RATE` by default.
    """
    from imu_ground.imu.data import ImuData
    from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion
    if isinstance(data, EgoMotion):
        return data
    rate = DEFAULT_FRAME_RATE if rate is None else float(rate)
    if isinstance(data, ImuData):
        return imu_to_egomotion(data, rate=rate)
    d = np.asarray(data, dtype=float)
    if (d.ndim not in (2, 3) or (d.ndim == 2 and d.shape[1] != 3)
            or (d.ndim == 3 and d.shape[1:] not in ((3, 3), (4, 4)))):
        raise ValueError(f"expected an EgoMotion, an ImuData or rotation increments of shape (F, 3, 3), (F, 4, 4) "
                         f"or (F, 3), got {type(data).__name__} of shape {d.shape}")
    return EgoMotion.from_rotations(as_rotations(d, "delta_Rs"), rate=rate)


# ------------------------------------------------------------------------------------------ frame checks
def frame_status(d9, delta_v=None, delta_t: float = 1.0) -> int:
    """What is wrong with one frame, as a code (the scalar check the streaming estimators run).

    The compiled twin is ``check`` of :mod:`imu_ground.filters.residual` (same
    comparisons, same results); :func:`frame_problem` turns a code into the message.

    Parameters
    ----------
    d9 : sequence of 9 float
        ``delta_R`` row-major (sensor_{k-1} <- sensor_k).
    delta_v : sequence of 3 float, optional
        Velocity increment, m/s.
    delta_t : float
        Frame duration, s.

    Returns
    -------
    int
        0: a good frame; :data:`BAD_ROTATION` (non-finite, not orthonormal to
        :data:`ORTHO_TOL`, or det <= 0), :data:`BAD_DELTA_V` (not finite) or
        :data:`BAD_DELTA_T` (not a positive finite number of seconds).
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = d9
    lo, hi = 1.0 - ORTHO_TOL, 1.0 + ORTHO_TOL
    if not (lo <= r00 * r00 + r10 * r10 + r20 * r20 <= hi and lo <= r01 * r01 + r11 * r11 + r21 * r21 <= hi
            and lo <= r02 * r02 + r12 * r12 + r22 * r22 <= hi
            and -ORTHO_TOL <= r00 * r01 + r10 * r11 + r20 * r21 <= ORTHO_TOL
            and -ORTHO_TOL <= r00 * r02 + r10 * r12 + r20 * r22 <= ORTHO_TOL
            and -ORTHO_TOL <= r01 * r02 + r11 * r12 + r21 * r22 <= ORTHO_TOL
            and r00 * (r11 * r22 - r12 * r21) - r01 * (r10 * r22 - r12 * r20) + r02 * (r10 * r21 - r11 * r20) > 0.0):
        return BAD_ROTATION                         # (NaN fails every comparison)
    if delta_v is not None:
        vx, vy, vz = delta_v
        if not math.isfinite(vx + vy + vz):
            return BAD_DELTA_V
    if not delta_t > 0.0 or delta_t == math.inf:
        return BAD_DELTA_T
    return 0


def frame_problem(d9, delta_v=None, delta_t: float = 1.0, status: Optional[int] = None) -> Optional[str]:
    """What is wrong with one frame, or None (the message of :func:`frame_status`; the streaming
    twin of :func:`frame_problems`).

    Parameters
    ----------
    d9, delta_v, delta_t
        As in :func:`frame_status`.
    status : int, optional
        The frame's :func:`frame_status` when already known (e.g. from the compiled check).
    """
    status = frame_status(d9, delta_v, delta_t) if status is None else status
    if status == BAD_ROTATION:
        return _rotation_message(d9)
    if status == BAD_DELTA_V:
        vx, vy, vz = delta_v
        return f"delta_v is not finite ({vx}, {vy}, {vz})"
    if status == BAD_DELTA_T:
        return f"delta_t must be a positive number of seconds, got {delta_t}"
    return None


def _rotation_message(d9) -> str:
    m = np.array(d9, dtype=float).reshape(3, 3)
    if not np.all(np.isfinite(m)):
        return "delta_R is not finite"
    err = float(np.abs(m.T @ m - np.eye(3)).max())
    return (f"delta_R is not a rotation: |R^T R - I| = {err:.3g} (tolerance {ORTHO_TOL:g}), "
            f"det = {np.linalg.det(m):.6g} (must be +1)")


def frame_statuses(d: np.ndarray, dv: Optional[np.ndarray] = None, dt: Optional[np.ndarray] = None) -> np.ndarray:
    """:func:`frame_status` of every frame: the batch check.

    With the compiled residual kernel, its ``check_many`` (the same comparisons
    as the streaming check, so a batch flags exactly the frames a stream would);
    otherwise a vectorised numpy check (``|R^T R - I|`` and ``det``).

    Parameters
    ----------
    d : ndarray (F, 3, 3)
        Rotation increments.
    dv : ndarray (F, 3), optional
        Velocity increments, m/s.
    dt : ndarray (F,), optional
        Frame durations, s.

    Returns
    -------
    ndarray of uint8 (F,)
        0 for a good frame, else :data:`BAD_ROTATION`, :data:`BAD_DELTA_V` or :data:`BAD_DELTA_T`.
    """
    d = np.ascontiguousarray(d, dtype=float)
    n = len(d)
    dv = None if dv is None else np.ascontiguousarray(dv, dtype=float)
    dt = None if dt is None else np.ascontiguousarray(dt, dtype=float)
    out = np.zeros(n, dtype=np.uint8)
    if not n:
        return out
    if _NATIVE is not None:
        _NATIVE.check_many(d, dv, dt, out)
        return out
    with np.errstate(invalid="ignore", over="ignore"):
        err = np.abs(np.swapaxes(d, 1, 2) @ d - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(d)
        if dt is not None:
            out[~((dt > 0.0) & (dt < np.inf))] = BAD_DELTA_T
        if dv is not None:
            out[~np.isfinite(dv.sum(axis=1))] = BAD_DELTA_V
        out[~((err <= ORTHO_TOL) & (det > 0.0))] = BAD_ROTATION
    return out


def _problem_at(k: int, status: int, d: np.ndarray, dv, dt) -> str:
    return frame_problem(d[k].ravel().tolist(), None if dv is None else np.asarray(dv[k], dtype=float).tolist(),
                         1.0 if dt is None else float(dt[k]), status=status)


def frame_problems(d: np.ndarray, dv: Optional[np.ndarray] = None, dt: Optional[np.ndarray] = None) -> list:
    """Per frame, what is wrong with it (None for a good frame); the batch twin of :func:`frame_problem`.

    Parameters
    ----------
    d, dv, dt
        As in :func:`frame_statuses`.
    """
    status = frame_statuses(d, dv, dt)
    out: list = [None] * len(status)
    for k in np.flatnonzero(status).tolist():
        out[k] = _problem_at(k, int(status[k]), np.asarray(d, dtype=float), dv, dt)
    return out


def checked_frames(d: np.ndarray, dv: Optional[np.ndarray], dt: Optional[np.ndarray], t: np.ndarray,
                   on_invalid: str) -> np.ndarray:
    """Which frames of a batch an estimator's ``run`` processes (the others it skips); the first step of ``run``.

    Parameters
    ----------
    d, dv, dt
        As in :func:`frame_statuses`.
    t : ndarray (F,)
        Frame times, s (to name a bad frame).
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
        raise bad_frame_error(problem, frame_where(k, float(t[k])) + f"; {len(good) - good.sum()} bad of {len(good)}")
    return good


# ------------------------------------------------------------------------------------------ shared plumbing
def check_on_invalid(on_invalid: str) -> str:
    """``on_invalid`` validated (one of :data:`ON_INVALID`)."""
    if on_invalid not in ON_INVALID:
        raise ValueError(f"on_invalid must be 'raise' or 'skip', got {on_invalid!r}")
    return on_invalid


def bad_frame_error(problem: str, where: str) -> ValueError:
    """The error a streaming estimator raises for a bad frame (its state untouched)."""
    return ValueError(f"bad ego-motion frame ({where}): {problem}; the estimator's state is unchanged "
                      f"(construct it with on_invalid='skip' to skip such frames)")


def checked_frame(check, frame, delta_R, delta_v, delta_t: float, on_invalid: str, index: int) -> tuple | None:
    """A streamed frame's ``delta_R`` (3x3) and ``delta_v`` (3,) as float64 arrays, if the frame passes the check.

    The first step of every estimator's ``step`` on its general path: the
    kernel's ``check`` (C or Python twin of :func:`frame_status`), after
    :func:`coerce_frame` when the inputs are not float64 arrays already; a bad
    frame raises or is to be skipped (:func:`bad_frame`).

    Parameters
    ----------
    check : callable
        ``check(delta_R, delta_v, delta_t) -> int`` (:func:`imu_ground.filters.residual.check`).
    frame : object
        The frame as given to ``step``; its ``t`` (s), if it has one, locates the error.
    delta_R : array_like
        sensor_{k-1} <- sensor_k: a rotation matrix, a 4x4 relative pose or a rotation vector, rad.
    delta_v : array_like (3,) or None
        Velocity increment, m/s (None: not checked).
    delta_t : float
        Frame duration, s.
    on_invalid : {"raise", "skip"}
        The estimator's policy (:data:`ON_INVALID`).
    index : int
        0-based index of the frame in the estimator's run, for the message.

    Returns
    -------
    (ndarray (3, 3), ndarray (3,) or None) or None
        None: a bad frame to skip (``on_invalid="skip"``); the caller returns
        its current estimate flagged invalid.

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
    """A streamed frame's ``delta_R`` as one C-contiguous float64 3x3 rotation and ``delta_v`` as a float64 (3,)
    array (or None): what the kernels' ``step`` and ``check`` take (they raise TypeError/ValueError otherwise).

    Parameters
    ----------
    delta_R : array_like
        sensor_{k-1} <- sensor_k: a rotation matrix, a 4x4 relative pose or a
        rotation vector, rad (:func:`~imu_ground.filters.rotations.as_rotations`).
    delta_v : array_like (3,), optional
        Velocity increment, m/s.

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
    """A bad streamed frame (its :func:`frame_status` ``status`` > 0): raise the error, or return with
    ``on_invalid="skip"`` (the caller then returns its current estimate flagged invalid).

    Parameters
    ----------
    frame : object
        The frame as given to ``step``; its ``t`` (s), if it has one, locates the error.
    status : int
        The frame's :func:`frame_status`.
    d, dv, dt
        Its ``delta_R`` (3x3), ``delta_v`` (3,) or None, ``delta_t`` (s).
    on_invalid : {"raise", "skip"}
    index : int
        0-based index of the frame in the estimator's run, for the message.
    """
    if on_invalid == "raise":
        dv3 = None if dv is None else np.asarray(dv, dtype=float).ravel().tolist()
        problem = frame_problem(np.asarray(d, dtype=float).ravel().tolist(), dv3, dt, status)
        raise bad_frame_error(problem, frame_where(index, getattr(frame, "t", math.nan)))


def static_rotation(extrinsic) -> Optional[np.ndarray]:
    """The extrinsic's ground <- sensor rotation, or None when it is the identity (nothing to apply)."""
    R = extrinsic.rotation
    return None if np.array_equal(R, np.eye(3)) else R


def frame_where(index: int, t: float) -> str:
    """``"frame 12 of the run, t = 1.3 s"``-style location of a frame (0-based index)."""
    return f"frame index {index}" + ("" if math.isnan(t) else f", t = {t:.6g} s")


def hold_skipped(values: np.ndarray, good: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """Per-frame values of the good frames spread over all frames, a skipped frame holding the previous one.

    Parameters
    ----------
    values : ndarray (G, ...)
        One row per good frame.
    good : ndarray of bool (F,)
        Which frames were processed (``G = good.sum()``).
    initial : ndarray (...)
        The value before the first good frame.
    """
    if good.all():
        return values
    idx = np.cumsum(good) - 1
    padded = np.concatenate([np.asarray(initial, dtype=float)[None], values])
    return padded[idx + 1]
