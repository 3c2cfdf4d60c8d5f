"""From a raw IMU log to per-frame ego-motion, the front-end every estimator shares (:func:`imu_to_egomotion`).

Frames (glossary: :mod:`imu_ground.so3`): the IMU's body frame; ``delta_R`` is ``R_{body_{k-1}<-body_k}``
(``R_k = R_{k-1} @ delta_R_k`` for ``R_{world<-body}`` attitudes), ``delta_v`` the gravity-free velocity
increment in the body frame at the frame's start (m/s); ``t`` the frame *end* times, s.
"""
from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from imu_ground.errors import ImuGroundError
from imu_ground.imu.data import ImuData
from imu_ground.imu.preintegration import preintegrate, segment_frame_times
from imu_ground.imu.standstill import WindowSums, detect_standstill, estimate_gyro_bias
from imu_ground.units import DEFAULT_FRAME_RATE, MAX_GAP_FRAMES

__all__ = ["EgoFrame", "EgoMotion", "imu_to_egomotion"]


class EgoFrame(NamedTuple):
    """One frame of ego-motion: what a streaming estimator's ``step`` takes.

    Attributes
    ----------
    delta_R, delta_v : ndarray (3, 3), (3,)
        As in the module docstring (``delta_v`` zeros when the source has no accelerometer).
    delta_t : float
        Frame duration, s (> 0).
    stationary : bool
        The frame ends inside a standstill.
    valid : bool
        False when the frame spans a gap in the source (integrated through).
    t : float
        Frame (end) time, s; NaN when unknown.
    """
    delta_R: np.ndarray
    delta_v: np.ndarray
    delta_t: float
    stationary: bool = False
    valid: bool = True
    t: float = float("nan")

    @classmethod
    def of(cls, frame, stationary: bool = False) -> "EgoFrame":
        """The EgoFrame of a preintegrated frame (a :class:`~imu_ground.imu.preintegration.PreintegratedImu`)."""
        return cls(frame.delta_R, frame.delta_v, float(frame.delta_t), bool(stationary),
                   bool(getattr(frame, "valid", True)), float(getattr(frame, "t_end", float("nan"))))


@dataclass
class EgoMotion:
    """Per-frame ego-motion of a body (F frames).

    Attributes
    ----------
    t, delta_R, delta_v, delta_t, stationary, valid : ndarray (F,), (F, 3, 3), (F, 3), (F,), (F,), (F,)
        Per frame, as :class:`EgoFrame`'s fields.
    bias_gyro : ndarray (3,)
        Gyro bias removed before integration, rad/s, body frame.
    frame : str
        Body frame name of the IMU.
    meta : dict
        Where the numbers came from (standstill intervals, gap count, source).
    rate : float
        Nominal frame rate, Hz, the one owner of it (estimators derive their discrete-time design from it).
    has_accel : bool
        False when ``delta_v`` is not measured (ego-motion from poses).
    """
    t: np.ndarray
    delta_R: np.ndarray
    delta_v: np.ndarray
    delta_t: np.ndarray
    stationary: np.ndarray
    valid: np.ndarray
    bias_gyro: np.ndarray = field(default_factory=lambda: np.zeros(3))
    frame: str = "FLU"
    meta: dict = field(default_factory=dict)
    rate: float = DEFAULT_FRAME_RATE
    has_accel: bool = True

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def frame_at(self, k: int) -> EgoFrame:
        """Frame ``k`` as an :class:`EgoFrame` (views, no copies)."""
        return EgoFrame(self.delta_R[k], self.delta_v[k], float(self.delta_t[k]), bool(self.stationary[k]),
                        bool(self.valid[k]), float(self.t[k]))

    def frames(self) -> Iterator[EgoFrame]:
        """The frames one at a time, for streaming estimators."""
        return map(self.frame_at, range(len(self)))

    @classmethod
    def from_rotations(cls, delta_R: np.ndarray, t: np.ndarray | None = None,
                       rate: float | None = None, frame: str = "FLU", meta: dict | None = None) -> EgoMotion:
        """Ego-motion from rotation increments alone (visual odometry, pose files).

        Parameters
        ----------
        delta_R : ndarray (F, 3, 3)
            ``R_{body_{k-1} <- body_k}`` increments.
        t : ndarray (F,), optional
            Frame end times, s. Default ``(k + 1) / rate``.
        rate : float, optional
            Frame rate, Hz. Default: from the median step of ``t``, else
            :data:`~imu_ground.units.DEFAULT_FRAME_RATE`.
        frame, meta :
            Body frame name and provenance.

        Returns
        -------
        EgoMotion
            ``delta_v`` zeros and ``has_accel = False``; no frame stationary.
        """
        d = np.asarray(delta_R, dtype=float).reshape(-1, 3, 3)
        n = len(d)
        if t is None:
            rate = DEFAULT_FRAME_RATE if rate is None else float(rate)
            t = np.arange(1, n + 1, dtype=float) / rate
        else:
            t = np.asarray(t, dtype=float).reshape(n)
            if rate is None:
                rate = 1.0 / float(np.median(np.diff(t))) if n > 1 else DEFAULT_FRAME_RATE
        dt = np.diff(t, prepend=t[0] - 1.0 / rate) if n else np.zeros(0)
        return cls(t, d, np.zeros((n, 3)), dt, np.zeros(n, dtype=bool), np.ones(n, dtype=bool),
                   np.zeros(3), frame, dict(meta or {}), float(rate), False)

    @property
    def specific_force(self) -> np.ndarray:
        """Mean specific force over each frame, m/s^2, body frame at the frame's end: ``delta_R^T delta_v / delta_t``
        (first order in the rotation within the frame)."""
        dv_end = np.einsum("nji,nj->ni", self.delta_R, self.delta_v)
        return dv_end / self.delta_t[:, None]


def imu_to_egomotion(imu: ImuData, rate: float = DEFAULT_FRAME_RATE, *, frame_times: np.ndarray | None = None,
                     bias_gyro: str | Sequence[float] | None = "auto", max_gap: float | None = None,
                     standstill_window: float = 1.0, max_gap_frames: int | None = MAX_GAP_FRAMES) -> EgoMotion:
    """Preintegrate an IMU log into frames.

    Parameters
    ----------
    imu : ImuData
        Validated log (strictly increasing times).
    rate : float
        Frame rate, Hz (frames at ``t[0] + k / rate``). Ignored with ``frame_times``.
    frame_times : ndarray (F + 1,), optional
        Explicit frame boundaries, s (e.g. camera times).
    bias_gyro : "auto", array_like (3,) or None
        ``"auto"``: the mean rate over the log's standstills (zero if it has
        none); an array: this bias, rad/s; None: no correction.
    max_gap : float, optional
        Sample steps longer than this (s) are gaps; frames across them are integrated with the held
        signal and flagged ``valid = False``. Default 10 times the median sample step.
    standstill_window : float
        Shortest standstill (s) used for the per-frame ``stationary`` flags.
    max_gap_frames : int, optional
        A sample step longer than this many frame periods starts a new segment (as the live clock restarts):
        frames start again on the grid of the first sample after it (``meta["segment_cuts"]``: the sample index
        before each). None: gaps of any length are integrated through. Not with ``frame_times``.

    Returns
    -------
    EgoMotion
    """
    meta: dict = {"source": imu.source}
    if max_gap is None:
        max_gap = 10.0 * float(np.median(np.diff(imu.t))) if len(imu) > 1 else 0.1
    meta["max_gap"] = max_gap
    intervals = None
    if isinstance(bias_gyro, str):
        if bias_gyro != "auto":
            raise ValueError(f"bias_gyro must be 'auto', a 3-vector or None, got {bias_gyro!r}")
        sums = WindowSums(imu) if len(imu) > 1 else None      # shared by the bias's and the flags' windows
        est = estimate_gyro_bias(imu, max_gap=max_gap, sums=sums)
        bg = est.bias
        meta["standstill_for_bias"] = est.intervals.tolist()
        # the flags' standstills now (times checked above), so the sums are freed before preintegrating
        intervals = detect_standstill(imu, window=standstill_window, max_gap=max_gap, sums=sums)
        del sums
    else:
        bg = np.zeros(3) if bias_gyro is None else np.asarray(bias_gyro, dtype=float).reshape(3)
    T = None if frame_times is None else np.asarray(frame_times, dtype=float)
    keep: slice | np.ndarray = slice(None)          # the frames of T that are frames (not across a segment cut)
    segments = None
    if frame_times is None and max_gap_frames is not None and len(imu) > 1:
        segment_gap = max_gap_frames / rate
        segments = segment_frame_times(imu.t, rate, segment_gap)
    if segments is not None:
        T, keep, cuts = segments
        if not keep.any():
            raise ImuGroundError(f"no frame at {rate:g} Hz: each of the {cuts.size + 1} segments between steps of "
                                 f"more than {segment_gap:g} s is shorter than a frame")
        meta["segment_cuts"] = cuts.tolist()
    fd = preintegrate(imu, T, rate=rate if T is None else None, bias_gyro=bg, max_gap=max_gap, on_gap="flag",
                      uncertainty=False)
    if intervals is None:
        intervals = detect_standstill(imu, window=standstill_window, max_gap=max_gap)
    te = fd.t_end[keep]
    stationary = np.zeros(len(te), dtype=bool)
    if len(intervals):
        i = np.searchsorted(intervals[:, 0], te, side="right") - 1
        ok = i >= 0
        stationary[ok] = te[ok] <= intervals[i[ok], 1]
    meta["standstill_intervals"] = intervals.tolist()
    meta["invalid_frames"] = int(np.sum(~fd.valid[keep]))
    if frame_times is not None and T is not None and len(T) > 1:
        rate = 1.0 / float(np.median(np.diff(T)))
    return EgoMotion(te.copy(), fd.delta_R[keep], fd.delta_v[keep], fd.delta_t[keep], stationary, fd.valid[keep].copy(),
                     bg, imu.frame, meta, float(rate), True)
