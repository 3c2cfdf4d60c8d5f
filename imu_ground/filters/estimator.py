r"""What every ground estimator shares: the protocol, its results, and the input it accepts.

Frames and signs (glossary: :mod:`imu_ground.so3`): sensor ``s``, the frame of the ego-motion; body/ground ``g``,
FLU, z along the road normal at rest on flat ground, ``R_gs`` (ground <- sensor) the static extrinsic; world ``w``,
the body frame at the start (``R0``); road ``r``, the slow state ``X`` (world <- road); residual ``E = X^T R``
(road <- body), the fast body motion, ``R`` (world <- body) the cumulative rotation. Pitch is positive nose *down*
(about y-left), roll positive left side *up* (about x-forward), both read off the road normal in the body frame
``n_b = E^T e_z = [-sin p, sin r cos p, cos p cos r]``; the normal in the sensor frame is ``n_s = (E R_gs)^T e_z``.

Every estimator (:class:`GroundEstimator`) has ``reset()``, ``step(frame) ->`` :class:`GroundEstimate` and
``run(egomotion, smooth=False) ->`` :class:`GroundTrack`; frame checks: :mod:`imu_ground.filters.frame_checks`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Optional, Protocol, TypeVar, runtime_checkable

import numpy as np

from imu_ground.imu.data import ImuData
from imu_ground.filters.status import GAP, INVALID, OK, STATUSES, frame_reason, frame_std, status_reason
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion
from imu_ground.so3 import as_rotations, matrix_from_quat
from imu_ground.units import DEFAULT_FRAME_RATE

if TYPE_CHECKING:
    from imu_ground.imu.egomotion import EgoFrame

__all__ = ["GroundEstimate", "GroundTrack", "SuspensionTrack", "GroundEstimator", "pitch_roll_from_normal", "as_egomotion"]


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


_Estimate = TypeVar("_Estimate", bound="GroundEstimate")


class GroundEstimate:
    """One frame's result of an estimator's ``step`` (the arrays built on first access).

    Attributes
    ----------
    normal : ndarray (3,)
        Unit ground normal in the sensor frame.
    pitch, roll : float
        Body attitude relative to the road, rad (pitch + nose down, roll + left up).
    residual, extrinsic : ndarray (3, 3)
        ``E = X^T R`` (road <- body) and the dynamic extrinsic ``E R_gs`` (road-ground <- sensor).
    P : ndarray (3, 3)
        Covariance of the slow state, body tangent space (rad^2).
    valid : bool
        False for a frame skipped (``on_invalid="skip"``), the values those of the previous frame.
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

    # quaternion: a kernel output row (w x y z first); P: a 3x3 array or that row (entries 4, 5: diag(a, a, c))

    def __init__(self, pitch: float, roll: float, valid: bool = True, quaternion=None, residual=None,
                 Rgs: Optional[np.ndarray] = None, P=None, status_code: Optional[int] = None, info=None,
                 road=None) -> None:
        self.pitch, self.roll, self.valid = pitch, roll, valid
        self._q, self._E, self._Rgs, self._P = quaternion, residual, Rgs, P
        # info: the frame's 1-sigma inputs (SigmaModel.frame), read on access by status.frame_std / frame_reason
        self.status_code = (OK if valid else INVALID) if status_code is None else status_code
        self._info = info
        self._road = road                   # (grade, bank, gravity's variance of each), filters.road, or None

    @property
    def pitch_std(self) -> float:
        return math.nan if self._info is None else frame_std(self._info, 0)

    @property
    def roll_std(self) -> float:
        return math.nan if self._info is None else frame_std(self._info, 1)

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
        if self._info is None:
            return status_reason(self.status_code)
        return frame_reason(self._info, self.status_code, max(self.pitch_std, self.roll_std))

    @classmethod
    def copy_of(cls: type[_Estimate], est: GroundEstimate) -> _Estimate:
        """A value copy of ``est`` as a ``cls`` (a subclass then sets its own fields)."""
        out = cls.__new__(cls)
        out.pitch, out.roll, out.valid, out.status_code = est.pitch, est.roll, est.valid, est.status_code
        out._q, out._E, out._Rgs, out._P, out._info, out._road = est._q, est._E, est._Rgs, est._P, est._info, est._road
        return out

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
    """Per-frame results of an estimator's ``run`` (F frames): the fields of :class:`GroundEstimate` stacked
    (``normal`` (F, 3); ``residual``, ``extrinsic``, ``P`` (F, 3, 3); the others (F,), ``status`` its uint8 code,
    by default ok, or gap where not valid), and the following.

    Attributes
    ----------
    x, cumulative : ndarray (F, 3, 3)  slow state (world <- road) and cumulative body rotation (world <- body).
    translation : ndarray (3,)         static sensor position in the ground frame, m.
    t : ndarray (F,)                   frame (end) times, s (NaN when unknown).
    valid : ndarray of bool (F,)       False where the frame spans a gap in the source or was skipped.
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
        self.valid = np.ones(n, dtype=bool) if self.valid is None else np.asarray(self.valid, dtype=bool).reshape(n)
        for name in ("t", "pitch_std", "roll_std", "road_grade", "road_bank", "road_grade_std", "road_bank_std"):
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
        """The track of residuals ``E``: normal, pitch, roll and dynamic extrinsic from them.

        Parameters
        ----------
        E, X, P, cumulative : ndarray (F, 3, 3)
            Residual (road <- body), slow state (world <- road), its covariance, cumulative rotation (world <- body).
        Rgs, translation : ndarray (3, 3) and (3,), optional
            Static extrinsic ground <- sensor (None: identity) and sensor position in the ground frame, m.
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


@runtime_checkable
class GroundEstimator(Protocol):
    """What every ground estimator offers (structural type: no base class needed)."""

    def reset(self) -> None:
        """Back to the initial state."""

    def step(self, frame: "EgoFrame") -> GroundEstimate:
        """Process one frame of ego-motion (sensor frame) and return its estimate."""

    def run(self, egomotion: "EgoMotion", smooth: bool = False) -> GroundTrack:
        """Process a whole drive, continuing from the current state as ``step`` would."""


def as_egomotion(data, rate: Optional[float] = None) -> "EgoMotion":
    """An :class:`~imu_ground.imu.egomotion.EgoMotion` from what an estimator's ``run`` accepts.

    Parameters
    ----------
    data : EgoMotion, ImuData or array_like
        Ego-motion (returned as is), a raw IMU log (preintegrated at ``rate``) or rotation increments
        sensor_{k-1} <- sensor_k, (F, 3, 3), (F, 4, 4) or (F, 3) (rotation vectors, rad), at ``rate``.
    rate : float, optional
        Frame rate, Hz, for the last two; :data:`~imu_ground.units.DEFAULT_FRAME_RATE` by default.
    """
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


@dataclass
class SuspensionTrack(GroundTrack):
    """A :class:`GroundTrack` plus the suspension model's inputs (F frames).

    Attributes
    ----------
    load : ndarray (F, 2)       load ``(u_x, u_y)`` entering the model, m/s^2, body frame.
    speed : ndarray (F,)        speed in the road noise, m/s (measured where given, else the gravity filter's).
    gains : ndarray (F, 2)      ``(k_pitch, k_roll)`` used, rad per m/s^2.
    suspension : ndarray (F, 2) modelled tilt ``(k_pitch u_x + cross_gain u_y, k_roll u_y)``, rad.
    gravity : ndarray (F, 3)    reaction to gravity, world frame, m/s^2.
    """
    load: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gains: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    suspension: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    gravity: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
