r"""Reference pitch relative to the road on real drives (KITTI OXTS at 100 Hz), from the GPS/INS solution::

    pitch_rel_road(t) = pitch(t) + grade(t),   grade = atan2(vu, hypot(ve, vn))

KITTI's signs: pitch + nose down, grade + uphill. Roll relative to the road is not
observable (the cross-slope is unknown): pitch only.

Construction: out-of-order samples dropped (:func:`drop_out_of_order`; gaps kept, never
interpolated across); distance = trapezoidal integral of ``hypot(ve, vn)``; the grade
averaged over a centred window of ``window_m`` m of distance, moving samples only
(:func:`smoothed_grade`, one-sided at the ends and next to stops); frames at or below
``min_speed`` or farther than ``max_gap`` from a sample not valid; linear interpolation
to the frame times; the drive mean over the valid frames (the mounting offset) removed
and returned as ``offset``. :func:`check_reference` decides from the data alone whether
a drive's reference (only as good as the INS vertical velocity) can be trusted.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from imu_ground.errors import ImuGroundError

__all__ = [
    "WINDOW_M", "MIN_SPEED", "FRAME_RATE", "MAX_GRADE_DEG", "MAX_PITCH_REL_ROAD_DEG", "MIN_MOVING_FRAMES", "Reference",
    "ReferenceCheck", "drop_out_of_order", "frame_times", "travelled_distance", "smoothed_grade", "pitch_reference",
    "check_reference", "sample_gap"
]

#: Length of the centred distance window over which the grade is averaged, m.
WINDOW_M = 10.0
#: Speed above which a frame is "moving" and the reference valid, m/s.
MIN_SPEED = 3.0
#: Frame rate of the estimator and of the reference, Hz.
FRAME_RATE = 10.0

_REQUIRED = ("t", "pitch", "ve", "vn", "vu")


def drop_out_of_order(df: pd.DataFrame) -> pd.DataFrame:
    """The rows whose time is later than every earlier row's (repeats dropped; idempotent).

    Parameters
    ----------
    df : pandas.DataFrame
        With a column ``t`` (s).

    Returns
    -------
    pandas.DataFrame
        The kept rows, index reset.
    """
    t = df["t"].to_numpy(dtype=float)
    if t.size == 0:
        return df.reset_index(drop=True)
    prev_max = np.maximum.accumulate(t)
    keep = np.ones(t.size, dtype=bool)
    keep[1:] = t[1:] > prev_max[:-1]
    return df.loc[keep].reset_index(drop=True)


def frame_times(t: np.ndarray, rate: float = FRAME_RATE) -> np.ndarray:
    """A regular frame grid from the first to the last sample time.

    Parameters
    ----------
    t, rate : array_like (N,), float
        Sample times (s, any order) and frames per second.

    Returns
    -------
    ndarray
        ``min(t) + k / rate`` up to ``max(t)``, s.
    """
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        return np.zeros(0)
    t0, t1 = float(np.min(t)), float(np.max(t))
    n = int(np.floor((t1 - t0) * rate + 1e-9)) + 1
    return t0 + np.arange(n) / rate


def travelled_distance(t: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Cumulative distance: trapezoidal integral of ``speed`` over ``t``.

    Parameters
    ----------
    t, speed : array_like (N,)
        Increasing sample times (s) and horizontal speed (m/s).

    Returns
    -------
    ndarray (N,)
        m, from 0.
    """
    from scipy.integrate import cumulative_trapezoid
    t = np.asarray(t, dtype=float)
    return cumulative_trapezoid(np.asarray(speed, dtype=float), t, initial=0) if t.size > 1 else np.zeros_like(t)


def smoothed_grade(s: np.ndarray, grade: np.ndarray, window_m: float = WINDOW_M,
                   use: np.ndarray | None = None) -> np.ndarray:
    """Distance-weighted centred moving average of the grade over ``window_m`` metres.

    Each segment whose ends are both in ``use`` weighs its mean grade by its length; the
    window ``[s - w/2, s + w/2]`` (clipped to the drive) is read off cumulative sums. Where
    it holds no used length the raw grade is kept.

    Parameters
    ----------
    s, grade : array_like (N,)
        Non-decreasing travelled distance (m) and grade (any unit: the average keeps it).
    window_m : float
        Full window length, m.
    use : array_like of bool (N,), optional
        Samples allowed in the average (default all).
    """
    s = np.asarray(s, dtype=float)
    g = np.asarray(grade, dtype=float)
    if s.size < 2:
        return g.copy()
    seg_len = np.diff(s)
    if use is not None:
        u = np.asarray(use, dtype=bool)
        seg_len = seg_len * (u[1:] & u[:-1])
    seg_g = 0.5 * (g[1:] + g[:-1])
    big_g = np.concatenate(([0.0], np.cumsum(seg_g * seg_len)))
    big_w = np.concatenate(([0.0], np.cumsum(seg_len)))
    half = 0.5 * window_m
    lo = np.clip(s - half, s[0], s[-1])
    hi = np.clip(s + half, s[0], s[-1])
    num = np.interp(hi, s, big_g) - np.interp(lo, s, big_g)
    den = np.interp(hi, s, big_w) - np.interp(lo, s, big_w)
    out = g.copy()
    ok = den > 1e-6
    out[ok] = num[ok] / den[ok]
    return out


def sample_gap(t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Distance from each of ``times`` to the nearest of the increasing sample times ``t`` (non-empty), s."""
    if t.size < 2:
        return np.abs(times - t[0])
    j = np.clip(np.searchsorted(t, times), 1, t.size - 1)
    return np.minimum(np.abs(times - t[j - 1]), np.abs(t[j] - times))


@dataclass
class Reference:
    """Reference pitch relative to the road at frame times (rad unless said).

    Attributes
    ----------
    t : ndarray (M,)
        Frame times, s.
    pitch_rel_road : ndarray (M,)
        ``pitch + grade - offset``, nose down positive, used where ``valid`` (moving, not in a gap).
    valid : ndarray of bool (M,)
    pitch, grade, speed, distance : ndarray (M,)
        OXTS pitch, smoothed grade (uphill +), horizontal speed (m/s), travelled distance (m).
    offset : float
        The removed mean of ``pitch + grade`` over the valid frames (NaN when none is valid).
    params : dict
        ``window_m``, ``min_speed``, ``max_gap``, ``dropped_out_of_order``.
    """

    t: np.ndarray
    pitch_rel_road: np.ndarray
    valid: np.ndarray
    pitch: np.ndarray
    grade: np.ndarray
    speed: np.ndarray
    distance: np.ndarray
    offset: float
    params: dict[str, Any] = field(default_factory=dict)


def pitch_reference(df: pd.DataFrame, times: np.ndarray | None = None, *,
                    window_m: float = WINDOW_M, min_speed: float = MIN_SPEED,
                    max_gap: float = 0.1, rate: float = FRAME_RATE) -> Reference:
    """Reference pitch relative to the road of one drive, at frame times.

    Parameters
    ----------
    df : pandas.DataFrame
        A ``kitti_imu100`` drive: columns ``t, pitch, ve, vn, vu`` at least (s, rad, m/s), raw or cleaned.
    times : array_like, optional
        Frame times, s, on ``df.t``'s clock (default: :func:`frame_times` at ``rate`` Hz).
    window_m, min_speed, max_gap : float
        The grade window (m), the speed at or below which a frame is not valid (m/s), the
        largest distance to a sample (s): see the module docstring.

    Returns
    -------
    Reference

    Raises
    ------
    ImuGroundError
        Missing columns or no samples.
    """
    missing = [c for c in _REQUIRED if c not in df.columns]
    if missing:
        raise ImuGroundError(f"drive data lacks column(s) {missing}; needs {list(_REQUIRED)}")
    n_raw = len(df)
    d = drop_out_of_order(df)
    t = d["t"].to_numpy(dtype=float)
    if t.size == 0:
        raise ImuGroundError("drive data has no samples")
    ve, vn, vu = (d[c].to_numpy(dtype=float) for c in ("ve", "vn", "vu"))
    speed = np.hypot(ve, vn)
    s = travelled_distance(t, speed)
    grade_s = smoothed_grade(s, np.arctan2(vu, speed), window_m, use=speed > min_speed)
    pitch = d["pitch"].to_numpy(dtype=float)

    tf = frame_times(t, rate) if times is None else np.asarray(times, dtype=float)
    inside = (tf >= t[0]) & (tf <= t[-1])
    near = sample_gap(t, tf)
    f_pitch, f_grade, f_speed, f_dist = (np.interp(tf, t, x, left=np.nan, right=np.nan)
                                         for x in (pitch, grade_s, speed, s))
    valid = inside & (near <= max_gap + 1e-9) & (f_speed > min_speed)
    raw = f_pitch + f_grade
    offset = float(np.mean(raw[valid])) if np.any(valid) else float("nan")
    rel = raw - (offset if np.isfinite(offset) else 0.0)
    return Reference(t=tf, pitch_rel_road=rel, valid=valid, pitch=f_pitch, grade=f_grade,
                     speed=f_speed, distance=f_dist, offset=offset,
                     params={"window_m": window_m, "min_speed": min_speed, "max_gap": max_gap,
                             "dropped_out_of_order": n_raw - len(d)})


@dataclass
class ReferenceCheck:
    """Verdict of :func:`check_reference`: ``valid``, ``reasons`` (one sentence a failed criterion), ``stats``."""

    valid: bool
    reasons: list[str]
    stats: dict[str, Any]

    @property
    def reason(self) -> str:
        """All reasons in one string (``"ok"`` when valid)."""
        return "; ".join(self.reasons) if self.reasons else "ok"

    def __bool__(self) -> bool:
        return self.valid


#: Steepest smoothed grade accepted on a moving frame, deg (public roads stay below about 20).
MAX_GRADE_DEG = 20.0
#: Largest body pitch relative to the road accepted on a moving frame (mean removed), deg: beyond, an INS fault.
MAX_PITCH_REL_ROAD_DEG = 10.0
#: Fewest valid (moving) frames for a drive to be evaluated (5 s at 10 Hz).
MIN_MOVING_FRAMES = 50


def check_reference(df: pd.DataFrame, ref: Reference | None = None, *,
                    max_grade_deg: float = MAX_GRADE_DEG,
                    max_pitch_rel_road_deg: float = MAX_PITCH_REL_ROAD_DEG,
                    min_moving_frames: int = MIN_MOVING_FRAMES,
                    **reference_kwargs: Any) -> ReferenceCheck:
    """Decide from the data alone whether a drive's pitch reference is usable.

    It fails with fewer than ``min_moving_frames`` valid frames, a smoothed grade beyond
    ``max_grade_deg`` or ``|pitch + grade - offset|`` beyond ``max_pitch_rel_road_deg`` on
    a valid frame (INS faults).

    Parameters
    ----------
    df : pandas.DataFrame
        The drive (as for :func:`pitch_reference`).
    ref : Reference, optional
        Its reference (default: computed with ``reference_kwargs``, passed to :func:`pitch_reference`).
    max_grade_deg, max_pitch_rel_road_deg, min_moving_frames
        Thresholds (deg, deg, frames).

    Returns
    -------
    ReferenceCheck
        ``valid``, ``reasons`` (joined in ``.reason``) and ``stats``: ``n_frames``, ``n_moving_frames``,
        ``moving_distance_m``, ``max_speed``, ``max_abs_vu``,
        ``max_abs_grade_deg``, ``max_abs_pitch_rel_road_deg``, ``offset_deg``.
    """
    if ref is None:
        ref = pitch_reference(df, **reference_kwargs)
    d = drop_out_of_order(df)
    v = ref.valid
    n_mov = int(np.count_nonzero(v))
    speed = np.hypot(d["ve"].to_numpy(float), d["vn"].to_numpy(float))
    min_speed = ref.params.get("min_speed", MIN_SPEED)
    moving_samples = speed > min_speed
    vu = d["vu"].to_numpy(float)
    t = d["t"].to_numpy(float)
    moving_dist = float(np.sum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t)
                               * (moving_samples[1:] & moving_samples[:-1]))) if t.size > 1 else 0.0
    stats: dict[str, Any] = {
        "n_frames": int(ref.t.size),
        "n_moving_frames": n_mov,
        "moving_distance_m": moving_dist,
        "max_speed": float(np.max(speed)) if speed.size else 0.0,
        "max_abs_vu": float(np.max(np.abs(vu[moving_samples]))) if moving_samples.any() else 0.0,
        "max_abs_grade_deg": float(np.degrees(np.max(np.abs(ref.grade[v])))) if n_mov else 0.0,
        "max_abs_pitch_rel_road_deg": (float(np.degrees(np.max(np.abs(ref.pitch_rel_road[v]))))
                                       if n_mov else 0.0),
        "offset_deg": float(np.degrees(ref.offset)) if n_mov else float("nan"),
    }
    reasons: list[str] = []
    if n_mov < min_moving_frames:
        reasons.append(
            f"too little motion: {n_mov} frames above {min_speed:g} m/s "
            f"({moving_dist:.0f} m, top speed {stats['max_speed']:.2f} m/s), "
            f"fewer than the {min_moving_frames} needed")
    if n_mov and stats["max_abs_grade_deg"] > max_grade_deg:
        reasons.append(
            f"impossible road grade: {stats['max_abs_grade_deg']:.1f} deg "
            f"(over {max_grade_deg:g}) from vertical velocities up to "
            f"{stats['max_abs_vu']:.1f} m/s: INS vertical-velocity fault")
    if n_mov and stats["max_abs_pitch_rel_road_deg"] > max_pitch_rel_road_deg:
        reasons.append(
            f"impossible body pitch relative to the road: "
            f"{stats['max_abs_pitch_rel_road_deg']:.1f} deg (over {max_pitch_rel_road_deg:g}): "
            f"INS pitch and vertical velocity disagree")
    return ReferenceCheck(valid=not reasons, reasons=reasons, stats=stats)
