r"""Per-platform calibration from one drive: static sensor-to-ground extrinsic and suspension gains.

Calibrate once per vehicle and IMU mounting, save, then run the
:class:`~imu_ground.filters.suspension.SuspensionAwareFilter` with the fixed result::

    cal = calibrate(imu)                  # ImuData or EgoMotion of a calibration drive
    cal.save("my_car.txt")                # the calib/ text format, plus a suspension_gains line
    track = estimate_suspension_aware(egomotion, extrinsic="my_car.txt")   # imu_ground.filters.methods

What an IMU alone can tell (ground frame FLU, z along the road normal on level ground, ``R_gs`` ground <- sensor):

- **Tilt.** At a standstill the accelerometer reads "up"; cruising straight at constant speed the body sits at its
  static stance, so the mean specific force over cruising frames is "up" relative to the drive's mean road plane.
  An IMU cannot tell a mounting tilt from a grade or cross-slope (or an accelerometer bias: 0.2 m/s^2 is 1.2 deg),
  so the tilt carries the mean grade and cross-slope of the frames used: calibrate on level ground or a long loop.
  ``stats`` reports each estimate available.
- **Forward axis (yaw).** In turns the lateral acceleration is ``v * yaw_rate`` with ``v > 0``, which fixes the axes
  and their sign; the longitudinal axis is refined as the principal direction of the horizontal acceleration
  driving straight. Without turns the sign is the sensor's x axis'; without either the yaw is unobservable.
- **Suspension gains** (:func:`~imu_ground.filters.gains.bandpass_gain_regression`): the gyro's body tilt regressed
  on the gravity-compensated acceleration (:class:`~imu_ground.filters.gravity_velocity.GravityVelocityFilter` with
  the extrinsic just found), both band-passed to :data:`~imu_ground.filters.gains.GAIN_BAND` (lower, the road
  correlates with the acceleration; higher, the suspension's resonance and noise).

The calibration file format (:class:`~imu_ground.filters.extrinsics.Calibration`) lives with the extrinsics.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Optional, Sequence, Union

import numpy as np

from imu_ground import so3
from imu_ground.errors import ImuGroundError, OptionError, warn_user
from imu_ground.filters.estimator import as_egomotion
from imu_ground.filters.extrinsics import Calibration, Extrinsic, load_calibration
from imu_ground.filters.gains import DEFAULT_GAINS, GAIN_BAND, bandpass_gain_regression
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.so3 import euler_zyx

if TYPE_CHECKING:
    from imu_ground.imu.data import ImuData
    from imu_ground.imu.egomotion import EgoMotion

__all__ = ["MAX_OFFSET_M", "Calibration", "TooLittleDataError", "calibrate", "load_calibration"]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _extrinsic_from_axes(up: np.ndarray, fwd: np.ndarray) -> np.ndarray:
    """ground <- sensor rotation whose rows are the ground axes (x forward, y left, z up) in sensor axes."""
    z = _unit(up)
    x = _unit(fwd - (fwd @ z) * z)
    return np.vstack([x, np.cross(z, x), z])


def _pooled_frames(egos, R, min_speed, lever_arm=None):
    """Per-frame quantities of all drives, concatenated; the gravity filter runs in the ground frame of ``R``."""
    parts = []
    for em in egos:
        gt = GravityVelocityFilter(extrinsic=Extrinsic(R), lever_arm=lever_arm).run(em, smooth=True)
        dt = np.asarray(em.delta_t, dtype=float)
        valid = np.asarray(em.valid, dtype=bool)
        flagged = np.asarray(em.stationary, dtype=bool)
        parts.append(dict(
            dt=dt, valid=valid, fs=em.specific_force,
            ws=so3.log(np.asarray(em.delta_R, dtype=float)) / dt[:, None],
            still=flagged & valid & (gt.speed < 0.5),
            moving=valid & ~flagged & (gt.speed > min_speed),
            acc=gt.acceleration, gt=gt))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k != "gt"}, [p["gt"] for p in parts], \
        [p["moving"] for p in parts]


def _forward_axis(fs, up, yaw_rate, moving, max_yaw_rate, x_prev):
    """The ground's forward axis in sensor axes (or None) and where it came from (module docstring)."""
    Ph = np.eye(3) - np.outer(up, up)
    fh = fs @ Ph                                         # horizontal specific force, sensor frame
    fwd_turn = np.cross(Ph @ (fh[moving].T @ yaw_rate[moving]), up)       # left x up = forward
    has_turns = bool(np.linalg.norm(fwd_turn) > 1e-9)
    straight = moving & (np.abs(yaw_rate) < max_yaw_rate)
    fwd, yaw_src = None, "assumed (sensor x axis)"
    if np.count_nonzero(straight) >= 20:
        h = fh[straight] - fh[straight].mean(axis=0)
        evals, evecs = np.linalg.eigh(h.T @ h)
        if evals[2] > 4.0 * evals[1]:
            fwd = evecs[:, 2]
            if fwd @ (fwd_turn if has_turns else x_prev) < 0:
                fwd = -fwd
            yaw_src = "straight accelerations, sign from " + ("turns" if has_turns else "the sensor x axis")
    if fwd is None and has_turns:
        fwd, yaw_src = fwd_turn, "turns"
    return fwd, yaw_src


def _suspension_gains(egos, R, min_speed, lever_arm, band, stats: dict) -> np.ndarray:
    """Pooled band-pass gain regression in the ground frame of ``R`` (rad per m/s^2); notes go to ``stats``."""
    _, tracks, movings = _pooled_frames(egos, R, min_speed, lever_arm)
    sxy, sxx = np.zeros(2), np.zeros(2)
    for em, gt, mv in zip(egos, tracks, movings, strict=True):
        if len(em) < 2:
            continue
        _, a, b = bandpass_gain_regression(gt.body_increments, gt.acceleration, band=band,
                                           frame_rate=em.rate, mask=mv)
        sxy, sxx = sxy + a, sxx + b
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(sxx > 0, sxy / sxx, np.nan)
    stats.update(gain_frames=int(sum(np.count_nonzero(m) for m in movings)), gain_sxx=sxx.tolist())
    # braking pitches the nose down (k_pitch < 0), a car rolls out of a turn (k_roll > 0): the other sign has
    # measured something else (typically superelevation in curves), so the default gain is kept and said so
    for i, (name, sign) in enumerate((("pitch", -1.0), ("roll", 1.0))):
        if np.isfinite(k[i]) and np.sign(k[i]) != sign:
            stats[f"{name}_gain_rejected"] = (f"{np.degrees(k[i]):+.3f} deg per m/s^2 has the wrong sign "
                                              f"(road geometry, not suspension); default kept")
            k[i] = DEFAULT_GAINS[i]
    return k


def _auto_tilt_source(cruise_s: float, still_s: float, valid_s: float, min_cruise_s: float,
                      min_standstill_s: float, min_all_s: float) -> tuple[str, str]:
    """Where ``tilt="auto"`` takes "up" from, and why; raises when no source has enough frames."""
    have = f"{cruise_s:.1f} s of straight constant-speed driving (cruise), {still_s:.1f} s standing still"
    if cruise_s >= min_cruise_s:
        return "cruise", f"{have}; cruise needs {min_cruise_s:g} s"
    if still_s >= min_standstill_s:
        return "standstill", f"{have}; cruise needs {min_cruise_s:g} s, so the standstills"
    if valid_s >= min_all_s:
        return "all", (f"{have}; cruise needs {min_cruise_s:g} s and there is no standstill, so the mean of all "
                       f"{valid_s:.0f} s (the drive's accelerations and grades tilt it)")
    raise TooLittleDataError(f"too little data for the tilt: {have} and {valid_s:.1f} s in all; it needs "
                             f"{min_cruise_s:g} s of cruise, {min_standstill_s:g} s standing still, or a drive of "
                             f"{min_all_s:g} s", "tilt", "calibrate on a longer drive, or pass tilt='all'")


class TooLittleDataError(ImuGroundError):
    """The drive has too little of what a part of the calibration needs (the message says how much of which kind).

    Attributes
    ----------
    base : str
        What is missing and how much is needed, without advice.
    part : {"tilt", "gains"}
        The part of the calibration that cannot be determined.
    """

    def __init__(self, base: str, part: str, advice: str) -> None:
        self.base, self.part = base, part
        super().__init__(f"{base}: {advice}")


#: Largest sensor offset a calibration takes, m per axis (``translation``, ``lever_arm``): more is a unit mistake.
MAX_OFFSET_M = 50.0


def _finite3(value: Sequence[float], option: str) -> np.ndarray:
    """``value`` as 3 finite numbers (m), each within :data:`MAX_OFFSET_M`; else an :class:`OptionError` naming
    ``option`` (``--lever-arm`` ...)."""
    v = np.asarray(value, dtype=float).ravel()
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise OptionError(f"{{opt}} must be 3 finite numbers X Y Z (m), got {' '.join(f'{x:g}' for x in v)}", option)
    if np.any(np.abs(v) > MAX_OFFSET_M):
        raise OptionError(f"{{opt}} {' '.join(f'{x:g}' for x in v)}: over {MAX_OFFSET_M:g} m from the vehicle's "
                          "centre; the offsets are in metres (divide millimetres by 1000)", option)
    return v


def calibrate(data: Union["ImuData", "EgoMotion", Sequence[Union["ImuData", "EgoMotion"]]], *, tilt: str = "auto",
              translation: Optional[Sequence[float]] = None, lever_arm: Optional[Sequence[float]] = None,
              gains: bool = True, band: Sequence[float] = GAIN_BAND, min_cruise_s: float = 20.0,
              min_speed: float = 3.0, max_yaw_rate: float = 0.02, max_accel: float = 0.15,
              rate: Optional[float] = None, min_drive_s: float = 20.0, min_standstill_s: float = 1.0,
              min_all_s: float = 60.0) -> Calibration:
    """Static sensor-to-ground extrinsic and suspension gains from a drive, or several of one platform (module
    docstring: what is observable and how each part is found).

    Parameters
    ----------
    data : ImuData, EgoMotion, or a sequence of them
        The calibration drive(s), sensor frame (ImuData preintegrated at ``rate``), pooled frame by frame.
    tilt : {"auto", "cruise", "standstill", "all"}
        Frames whose mean specific force defines "up": straight constant-speed driving, standstills, or every
        frame; ``"auto"``: cruise if there are ``min_cruise_s`` seconds of it, else standstill, else all.
    translation : array_like (3,), optional
        Sensor origin in the ground frame, m, stored in the extrinsic (not observable; default zero).
    lever_arm : array_like (3,), optional
        Sensor position from the body's pitch/roll centre (ground frame, m), removed from the gain regression.
    gains : bool
        Estimate the suspension gains.
    band : (float, float)
        Gain regression band, Hz.
    min_cruise_s, min_standstill_s, min_all_s : float
        Seconds of cruising, standing still or valid frames for ``tilt="auto"`` to use each (fewer valid
        seconds than ``min_all_s``: ``"auto"`` raises).
    min_speed : float
        Slower frames (m/s) are not "moving" for cruise, yaw and gains.
    max_yaw_rate, max_accel : float
        Straight driving: yaw rate below this, rad/s; constant speed: horizontal acceleration below this, m/s^2.
    rate : float, optional
        Frame rate for ImuData, Hz (default :data:`~imu_ground.units.DEFAULT_FRAME_RATE`).
    min_drive_s : float
        Seconds of driving (faster than ``min_speed``) the yaw and the gains need; with less the yaw stays the
        sensor's x axis (``stats["yaw_source"]``, a warning) and ``gains=True`` raises.

    Returns
    -------
    Calibration
        ``extrinsic.rotation`` ground <- sensor; ``gains`` ``(k_pitch, k_roll)`` rad per m/s^2; ``stats``.

    Raises
    ------
    OptionError
        ``translation`` or ``lever_arm`` not 3 finite numbers (names the option).
    ValueError
        No frames, none of the kind ``tilt`` asks for, or too little of what ``"auto"`` or ``gains=True`` needs
        (the message says how much of which kind).

    Warns
    -----
    UserWarning
        ``tilt="auto"`` not from cruising (which source and why); a yaw left at the sensor's x axis.
    """
    if tilt not in ("auto", "cruise", "standstill", "all"):
        raise ImuGroundError(f"tilt must be 'auto', 'cruise', 'standstill' or 'all', got {tilt!r}")
    egos = [as_egomotion(d, rate) for d in (data if isinstance(data, (list, tuple)) else [data])]
    if not egos or sum(len(e) for e in egos) < 2:
        raise ImuGroundError("calibration needs at least two frames")
    t_gs = np.zeros(3) if translation is None else _finite3(translation, "translation")
    lever = None if lever_arm is None else _finite3(lever_arm, "lever_arm")

    def up_of(fs, mask):
        if not np.any(mask):
            return None
        mean = fs[mask].mean(axis=0)
        if not (np.all(np.isfinite(mean)) and np.linalg.norm(mean) > 0):
            raise ImuGroundError("no gravity in the accelerometer (its mean specific force is 0 or not finite): a "
                                 "dead or disconnected accelerometer cannot give the sensor's tilt")
        return _unit(mean)

    # provisional ground frame: up from the flagged standstills (or all frames), forward the sensor's x
    fs0 = np.concatenate([e.specific_force for e in egos])
    v0 = np.concatenate([np.asarray(e.valid, dtype=bool) for e in egos])
    s0 = np.concatenate([np.asarray(e.stationary, dtype=bool) for e in egos]) & v0
    up = up_of(fs0, s0) if np.any(s0) else up_of(fs0, v0)
    if up is None:
        raise ImuGroundError("no valid frames to calibrate from")
    R = _extrinsic_from_axes(up, np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 1.0, 0.0]))
    for _ in range(2):           # the speed and acceleration need the ground frame: iterate once
        F, _, _ = _pooled_frames(egos, R, min_speed)
        fs, dt, moving = F["fs"], F["dt"], F["moving"]
        yaw_rate = F["ws"] @ up
        cruise = moving & (np.abs(yaw_rate) < max_yaw_rate) & np.all(np.abs(F["acc"][:, :2]) < max_accel, axis=1)
        # -- tilt
        candidates = {"cruise": up_of(fs, cruise), "standstill": up_of(fs, F["still"]), "all": up_of(fs, F["valid"])}
        cruise_s, still_s, moving_s, valid_s = (float(dt[m].sum()) for m in (cruise, F["still"], moving, F["valid"]))
        if tilt == "auto":
            src, why = _auto_tilt_source(cruise_s, still_s, valid_s, min_cruise_s, min_standstill_s, min_all_s)
        else:
            src, why = tilt, f"as asked (tilt={tilt!r})"
        if candidates[src] is None:
            raise ImuGroundError(f"tilt={tilt!r}: the drive has no {src} frames")
        up = candidates[src]
        if moving_s >= min_drive_s:
            fwd, yaw_src = _forward_axis(fs, up, yaw_rate, moving, max_yaw_rate, R[0])
        else:
            fwd, yaw_src = None, (f"assumed (sensor x axis): {moving_s:.1f} s of driving above {min_speed:g} m/s, "
                                  f"the yaw needs {min_drive_s:g} s with turns or speed changes")
        R = _extrinsic_from_axes(up, R[0] if fwd is None else fwd)
    if tilt == "auto" and src != "cruise":
        warn_user(f"calibration: tilt ('up') from the {src} frames: {why}", UserWarning)
    if fwd is None and moving_s < min_drive_s:
        warn_user(f"calibration: mounting yaw not determined, the sensor's x axis is taken as forward: "
                      f"{moving_s:.1f} s of driving above {min_speed:g} m/s; the yaw needs {min_drive_s:g} s with "
                      "turns or speed changes", UserWarning)
    if gains and moving_s < min_drive_s:
        never = "the drive never moves: " if moving_s == 0 else ""
        raise TooLittleDataError(f"{never}{moving_s:.1f} s of driving above {min_speed:g} m/s; the suspension "
                                 f"gains need at least {min_drive_s:g} s of driving (over uneven road, with braking "
                                 "and turns)", "gains", "calibrate on a longer drive, or with gains=False for the "
                                 "tilt alone")
    stats: dict[str, Any] = {"drives": len(egos), "frames": int(len(dt)), "tilt_source": src, "tilt_reason": why,
                             "yaw_source": yaw_src, "cruise_s": round(cruise_s, 1), "standstill_s": round(still_s, 1),
                             "moving_s": round(moving_s, 1)}
    for name, u in candidates.items():
        if u is not None:
            r, p, _ = np.degrees(euler_zyx(_extrinsic_from_axes(u, R[0])))
            stats[f"tilt_{name}_deg"] = (round(float(p), 4), round(float(r), 4))
    k = _suspension_gains(egos, R, min_speed, lever, band, stats) if gains else None
    meta = {"calibrated_by": "imu_ground.filters.calibration.calibrate", "tilt_source": src, "yaw_source": yaw_src}
    return Calibration(Extrinsic(R, t_gs, meta), k, stats)
