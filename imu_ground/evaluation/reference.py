r"""Reference pitch relative to the road on real drives (KITTI OXTS at 100 Hz).

No per-frame LiDAR road plane is available for the real recordings, so the
reference for the ground normal is built from the GPS/INS (OXTS RT3003)
solution that comes with every ``kitti_imu100`` drive::

    pitch_rel_road(t) = pitch(t) + grade(t),   grade = atan2(vu, hypot(ve, vn))

Conventions (KITTI's): pitch positive = nose down; the grade is positive
uphill. On an uphill road a car on its wheels pitches nose up by the grade
(pitch = -grade), so ``pitch + grade`` is the body's pitch relative to the road
tangent, nose down positive -- the quantity a ground-normal estimator reports.
Roll relative to the road is *not* observable from these signals (the road's
cross-slope is unknown), so only pitch has a real-data reference.

How the reference is built (every choice, and why)
--------------------------------------------------
1. **Time order.** The OXTS extract timestamps step backwards by about 0.05 s
   at times. Only samples later than every earlier sample are kept (the same
   rule as ``imu_ground.datasets.validation``'s ``policy="drop"``); data already cleaned
   that way passes unchanged. Gaps (over 1 s on two drives) are kept: nothing
   is interpolated across them (see 5).
2. **Travelled distance** ``s`` is the trapezoidal integral of the horizontal
   speed ``hypot(ve, vn)`` over time, not the positions ``px, py``: the
   positions jump by decimetres to metres when the GPS fix changes, the
   velocity does not.
3. **Grade smoothing over 10 m of travel** (``window_m=10``). The raw grade is
   noisy (OXTS ``vu`` noise of a few cm/s is 0.5 deg of grade at 3 m/s) and
   the road plane under a car spans its wheelbase (about 2.7 m). The grade is
   averaged over a centred window of ``window_m`` metres of *distance*, each
   sample weighted by the distance it covers::

       grade_s(s) = [G(s + w/2) - G(s - w/2)] / [W(s + w/2) - W(s - w/2)]
       G(s) = integral of grade ds,  W(s) = integral of ds  (moving samples only)

   computed with cumulative sums and ``np.interp`` (vectorised, O(N)). Only
   samples above ``min_speed`` enter the average: below it ``atan2(vu, v)``
   is noise, and weighting by distance already gives stops no weight. The
   window is thus the same stretch of road at any speed. (Averaging all
   samples by distance instead gives a noisier reference: the constant
   normal's error against it rises.)
   10 m is a few wheelbases: enough to average the noise (about 0.5 s of
   data at 20 m/s, 3 s at 3 m/s), short against the length of vertical
   curves on roads (radii of hundreds of metres: a 10 m centred mean of a
   linearly varying grade is unbiased, and a 500 m crest changes the grade
   by only 1.1 deg over the window). Near the start and end of a drive, and
   next to stops, the window is truncated to the moving distance available
   (one-sided there).
4. **Moving frames only** (``min_speed=3`` m/s). Below 3 m/s the grade is ill
   defined (``vu / v`` with a small ``v``) and the body's pitch is dominated by
   stopping and starting; frames at or below it are not valid.
5. **Frames.** The reference is evaluated at the estimator's frame times
   (default: a 10 Hz grid from the first sample, :func:`frame_times`) by linear
   interpolation of the 100 Hz series. A frame farther than ``max_gap``
   (0.1 s) from the nearest kept sample lies inside a data gap and is not
   valid.
6. **Mean removal.** The drive mean of ``pitch + grade`` over the valid frames
   is subtracted (and returned as ``offset``). That mean is the static
   mounting offset between the IMU/INS and the car body (plus the car's static
   stance), which a calibration removes and which the OXTS attitude cannot
   tell apart from the road; an estimator's output is compared after removing
   its own mean (see :mod:`imu_ground.evaluation.metrics`).

Known limitation
----------------
The reference's slow part is only as good as the INS vertical velocity: a
``vu`` bias of 0.1 m/s is 1.4 deg of grade at 4 m/s. On a few good drives
(2011_09_26_drive_0022, _0019, _0091) ``pitch + grade`` drifts by 1-3 deg
over tens of seconds at low speed, which no suspension moves a car by; every
estimator inherits that error floor.

Faulty drives
-------------
:func:`check_reference` decides from the data alone whether the reference of
a drive can be trusted (no list of drive names is consulted). See its
docstring for the criteria and thresholds.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from imu_ground.errors import ImuGroundError

__all__ = [
    "WINDOW_M",
    "MIN_SPEED",
    "FRAME_RATE",
    "MAX_GRADE_DEG",
    "MAX_PITCH_REL_ROAD_DEG",
    "MIN_MOVING_FRAMES",
    "Reference",
    "ReferenceCheck",
    "drop_out_of_order",
    "frame_times",
    "travelled_distance",
    "smoothed_grade",
    "pitch_reference",
    "check_reference",
]

#: Length of the centred distance window over which the grade is averaged, m.
WINDOW_M = 10.0
#: Speed above which a frame is "moving" and the reference valid, m/s.
MIN_SPEED = 3.0
#: Frame rate of the estimator and of the reference, Hz.
FRAME_RATE = 10.0

_REQUIRED = ("t", "pitch", "ve", "vn", "vu")


def drop_out_of_order(df: pd.DataFrame) -> pd.DataFrame:
    """Keep only the rows whose time is later than every earlier row's.

    The OXTS extract timestamps sometimes step back by about 0.05 s; those
    samples (and exact repeats of a time) are dropped, everything else is kept
    in its order. Idempotent: cleaned data comes back unchanged.

    Parameters
    ----------
    df : pandas.DataFrame
        With a column ``t`` (seconds).

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
    t : array_like, shape (N,)
        Sample times, s (any order; only the min and max are used).
    rate : float
        Frames per second (10 Hz, the rate of the camera frames of the paper).

    Returns
    -------
    ndarray
        ``t_min + k / rate`` for ``k = 0, 1, ...`` up to ``t_max``.
    """
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        return np.zeros(0)
    t0, t1 = float(np.min(t)), float(np.max(t))
    n = int(np.floor((t1 - t0) * rate + 1e-9)) + 1
    return t0 + np.arange(n) / rate


def travelled_distance(t: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Cumulative distance, m: trapezoidal integral of ``speed`` over ``t``.

    Parameters
    ----------
    t : array_like, shape (N,)
        Increasing sample times, s.
    speed : array_like, shape (N,)
        Horizontal speed, m/s.

    Returns
    -------
    ndarray, shape (N,)
        Starts at 0, non-decreasing for non-negative speed.
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(speed, dtype=float)
    s = np.zeros_like(t)
    if t.size > 1:
        s[1:] = np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))
    return s


def smoothed_grade(s: np.ndarray, grade: np.ndarray, window_m: float = WINDOW_M,
                   use: np.ndarray | None = None) -> np.ndarray:
    """Distance-weighted centred moving average of the grade over ``window_m`` metres.

    Each segment between consecutive samples contributes its mean grade times
    its length, if both its ends are in ``use``; the average over
    ``[s - w/2, s + w/2]`` (clipped to the drive) is the sum of those
    contributions divided by the used length in the window. Both sums come
    from cumulative sums evaluated with ``np.interp`` (vectorised, exact for
    partial segments at the window ends). Where the window holds no used
    length the raw grade is returned.

    Parameters
    ----------
    s : array_like, shape (N,)
        Non-decreasing travelled distance, m.
    grade : array_like, shape (N,)
        Grade, rad (any unit: the average keeps it).
    window_m : float
        Full window length, m.
    use : array_like of bool, shape (N,), optional
        Samples allowed in the average (default all). :func:`pitch_reference`
        passes the moving samples: below ``min_speed`` ``atan2(vu, v)`` is
        noise (a 2 cm/s ``vu`` error is 1 deg of grade at 1 m/s).

    Returns
    -------
    ndarray, shape (N,)
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
    # The cumulative sums only change where s does, so interpolating them on
    # the non-decreasing s is well defined even across stops (repeated s).
    num = np.interp(hi, s, big_g) - np.interp(lo, s, big_g)
    den = np.interp(hi, s, big_w) - np.interp(lo, s, big_w)
    out = g.copy()
    ok = den > 1e-6
    out[ok] = num[ok] / den[ok]
    return out


@dataclass
class Reference:
    """Reference pitch relative to the road at frame times.

    Attributes
    ----------
    t : ndarray, shape (M,)
        Frame times, s.
    pitch_rel_road : ndarray, shape (M,)
        ``pitch + grade - offset``, rad, nose down positive. Defined on every
        frame (NaN only where there is no data), to be used where ``valid``.
    valid : ndarray of bool, shape (M,)
        Moving (speed above ``min_speed``) and not inside a data gap.
    pitch : ndarray
        OXTS pitch at the frames, rad.
    grade : ndarray
        Smoothed road grade at the frames, rad, uphill positive.
    speed : ndarray
        Horizontal speed at the frames, m/s.
    distance : ndarray
        Travelled distance at the frames, m.
    offset : float
        The mean of ``pitch + grade`` over the valid frames that was removed,
        rad (NaN when no frame is valid).
    params : dict
        ``window_m``, ``min_speed``, ``max_gap``, number of samples dropped for
        time order.
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

    @property
    def n_valid(self) -> int:
        """Number of valid frames."""
        return int(np.count_nonzero(self.valid))

    def to_frame(self) -> pd.DataFrame:
        """All per-frame arrays as one DataFrame (angles in rad)."""
        return pd.DataFrame({"t": self.t, "pitch_rel_road": self.pitch_rel_road,
                             "valid": self.valid, "pitch": self.pitch, "grade": self.grade,
                             "speed": self.speed, "distance": self.distance})


def _check_columns(df: pd.DataFrame) -> None:
    missing = [c for c in _REQUIRED if c not in df.columns]
    if missing:
        raise ImuGroundError(f"drive data lacks column(s) {missing}; needs {list(_REQUIRED)}")


def pitch_reference(df: pd.DataFrame, times: np.ndarray | None = None, *,
                    window_m: float = WINDOW_M, min_speed: float = MIN_SPEED,
                    max_gap: float = 0.1, rate: float = FRAME_RATE) -> Reference:
    """Reference pitch relative to the road of one drive, at frame times.

    Parameters
    ----------
    df : pandas.DataFrame
        A ``kitti_imu100`` drive: columns ``t, pitch, ve, vn, vu`` at least
        (radians, m/s). Raw (out-of-order timestamps are dropped here, see
        :func:`drop_out_of_order`) or already cleaned.
    times : array_like, optional
        Frame times, s, on the same clock as ``df.t``. Default: the 10 Hz grid
        of :func:`frame_times`.
    window_m : float
        Length of the centred distance window of the grade average, m (10).
    min_speed : float
        Frames with horizontal speed at or below it are not valid, m/s (3).
    max_gap : float
        A frame farther than this from the nearest sample is in a gap and not
        valid, s (0.1: one frame period).
    rate : float
        Frame rate of the default grid, Hz.

    Returns
    -------
    Reference
        See the module docstring for the construction.
    """
    _check_columns(df)
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
    # distance to the nearest sample, for gaps
    j = np.clip(np.searchsorted(t, tf), 1, max(t.size - 1, 1))
    if t.size > 1:
        near = np.minimum(np.abs(tf - t[j - 1]), np.abs(t[j] - tf))
    else:
        near = np.abs(tf - t[0])
    nan = np.nan
    f_pitch = np.interp(tf, t, pitch, left=nan, right=nan)
    f_grade = np.interp(tf, t, grade_s, left=nan, right=nan)
    f_speed = np.interp(tf, t, speed, left=nan, right=nan)
    f_dist = np.interp(tf, t, s, left=nan, right=nan)
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
    """Verdict of :func:`check_reference`.

    Attributes
    ----------
    valid : bool
        True when the reference can be used for evaluation.
    reasons : list of str
        One human-readable sentence per failed criterion (empty when valid).
    stats : dict
        The numbers the verdict was based on.
    """

    valid: bool
    reasons: list[str]
    stats: dict[str, Any]

    @property
    def reason(self) -> str:
        """All reasons in one string (``"ok"`` when valid)."""
        return "; ".join(self.reasons) if self.reasons else "ok"

    def __bool__(self) -> bool:
        return self.valid


#: Steepest smoothed grade accepted on a moving frame, deg. Public roads stay
#: below about 20 deg (36 %: the steepest streets in the world); the 30 good
#: KITTI drives stay below 8 deg (car-park ramps), the faulty drive 0093 shows
#: 25-50 deg for half a minute (``vu`` stuck near -6.5 m/s).
MAX_GRADE_DEG = 20.0
#: Largest body pitch relative to the road accepted on a moving frame, deg
#: (after mean removal). Suspension pitch is within about +-2 deg even under
#: hard braking; a kerb or a ramp transition adds a little for a moment (the
#: good drives stay below 4.3 deg). 10 deg can only come from an INS fault.
MAX_PITCH_REL_ROAD_DEG = 10.0
#: Fewest valid (moving) frames for a drive to be evaluated: 50 frames = 5 s
#: at 10 Hz, the shortest span over which a per-drive mean (the mounting
#: offset) and per-drive error statistics mean anything. The good drives with
#: the least motion have 61 (2011_09_26_drive_0057) and 74 (0018) frames.
MIN_MOVING_FRAMES = 50


def check_reference(df: pd.DataFrame, ref: Reference | None = None, *,
                    max_grade_deg: float = MAX_GRADE_DEG,
                    max_pitch_rel_road_deg: float = MAX_PITCH_REL_ROAD_DEG,
                    min_moving_frames: int = MIN_MOVING_FRAMES,
                    **reference_kwargs: Any) -> ReferenceCheck:
    """Decide from the data alone whether a drive's pitch reference is usable.

    No list of drive names is used. A drive fails when any of these holds:

    1. **Too little motion**: fewer than ``min_moving_frames`` valid frames
       (speed above ``min_speed``, default 50 frames = 5 s at 10 Hz). Without
       motion there is no grade and no pitch relative to the road to compare.
    2. **Impossible road grade**: on some valid frame the smoothed grade
       ``atan2(vu, hypot(ve, vn))`` exceeds ``max_grade_deg`` (20 deg) in
       magnitude. This is what vertical-velocity faults of the INS look like:
       several m/s of ``vu`` at a few m/s of horizontal speed.
    3. **Impossible body pitch relative to the road**: some valid frame has
       ``|pitch + grade - offset|`` above ``max_pitch_rel_road_deg`` (10 deg).
       A car body follows the road within a couple of degrees, so a vertical
       velocity that disagrees with the INS pitch by this much is a fault of
       one of them; either way the reference is wrong.

    On the 33 ``kitti_imu100`` drives this flags 2011_09_26_drive_0093 (``vu``
    stuck near -6.5 m/s for 30 s: 49 deg "grades", 31 deg "pitch relative to
    the road") and 2011_09_28_drive_0039 (parked: top speed 0.26 m/s). The
    data README also lists 2011_09_28_drive_0002 for lack of motion, but its
    data pass every check: 81 moving frames (73 m, braking from 11.7 m/s to a
    stop), INS pitch, velocity and IMU mutually consistent. Two drives the
    README counts as valid move less (2011_09_26_drive_0057: 61 frames, 48 m;
    _0018: 74 frames, 51 m), so no motion threshold flags 0002 alone:
    ``min_moving_frames=82`` flags 0002, 0057 and 0018 together.

    Parameters
    ----------
    df : pandas.DataFrame
        The drive (as for :func:`pitch_reference`).
    ref : Reference, optional
        Its reference, if already computed (otherwise computed here with
        ``reference_kwargs``).
    max_grade_deg, max_pitch_rel_road_deg, min_moving_frames
        Thresholds, see above and the module constants for their rationale.
    **reference_kwargs
        Passed to :func:`pitch_reference` (``window_m``, ``min_speed``, ...).

    Returns
    -------
    ReferenceCheck
        ``valid``, ``reasons`` (one sentence per failed criterion; joined in
        ``.reason``) and ``stats``: ``n_frames``, ``n_moving_frames``,
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
