"""Checks of :func:`~imu_ground.pipeline.estimate_log`'s input that need no estimate: options, axes, settings,
output paths (:class:`OptionError` re-exported from :mod:`imu_ground.errors`)."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import ImuGroundError, OptionError, warn_user
from imu_ground.filters import Extrinsic

__all__ = ["GRAVITY_REFUSE_DEG", "GRAVITY_WARN_DEG", "OptionError", "check_creatable", "check_gravity_direction",
           "check_recalibration", "gravity_angle", "process_running", "requested_options"]


def requested_options(*, method: str = "auto", rate: float | None = None, extrinsic: Any = None, Q: Any = None,
                      R: Any = None, speed: Any = None, **reader_options: Any) -> dict:
    """The options of a run as the user gave them, in JSON form: what an output records as ``settings["options"]``
    (``format`` and None-valued reader options left out; a speed array as ``"per-frame array"``)."""
    if speed is None or isinstance(speed, str) and speed == "none":
        speed_text = "none"
    elif isinstance(speed, (np.ndarray, list, tuple)):
        speed_text = "per-frame array"
    else:
        speed_text = str(speed)
    out = {"method": method, "rate": None if rate is None else float(rate),
           "extrinsic": None if extrinsic is None else str(extrinsic), "Q": Q, "R": R, "speed": speed_text,
           **{k: v for k, v in reader_options.items() if v is not None and k != "format"}}
    return json.loads(json.dumps(out, sort_keys=True, default=str))


#: Angle (deg) between the log's mean specific force and the extrinsic's up axis above which a warning is given.
GRAVITY_WARN_DEG = 10.0
#: Above this angle (deg) the axes do not match the extrinsic at all (a z-down sensor, a camera extrinsic): refused.
GRAVITY_REFUSE_DEG = 60.0


def gravity_angle(accel: np.ndarray, extrinsic: Any = None) -> float:
    """Angle, deg, between the mean specific force of a log ("up" on average) and the up axis the extrinsic
    (ground <- sensor) gives the sensor, its third row; NaN under 1 m/s^2.

    Parameters
    ----------
    accel : ndarray (N, 3)
        Specific force, m/s^2, sensor frame (non-finite rows are left out).
    extrinsic : None, str, Path, Extrinsic or ndarray (3, 3)
        As :func:`estimate_log` takes it (None: identity, up = sensor z).
    """
    a = np.asarray(accel, dtype=float).reshape(-1, 3)
    # a finite mean of all rows is the mean of the finite rows (the same sums) without their copy
    f = a.mean(axis=0) if len(a) and a.flags.c_contiguous else np.full(3, np.nan)
    if not np.all(np.isfinite(f)):
        a = a[np.all(np.isfinite(a), axis=1)]
        if not len(a):
            return float("nan")
        f = a.mean(axis=0)
    norm = float(np.linalg.norm(f))
    if norm < 1.0:
        return float("nan")
    up = Extrinsic.coerce(extrinsic).rotation[2]
    return float(np.degrees(np.arccos(np.clip(f @ up / norm, -1.0, 1.0))))


def check_gravity_direction(imu, extrinsic: Any, path: str | Path) -> float:
    """Warn (above :data:`GRAVITY_WARN_DEG`), or refuse (above :data:`GRAVITY_REFUSE_DEG`, an :class:`OptionError`
    naming ``extrinsic``), when a log's mean specific force is off the extrinsic's up axis; returns
    :func:`gravity_angle` (deg)."""
    angle = gravity_angle(imu.accel, extrinsic)
    if not math.isfinite(angle) or angle <= GRAVITY_WARN_DEG:
        return angle
    given = "the identity (sensor z up; no extrinsic given)" if extrinsic is None else f"{extrinsic}"
    what = (f"{path}: the log's mean specific force (gravity) is {angle:.1f} deg from the up axis of the extrinsic, "
            f"{given}")
    if angle > GRAVITY_REFUSE_DEG:
        raise OptionError(what + ": the sensor's axes do not match it (a z-down sensor?); run 'imu-ground calibrate' "
                          "on this log and pass the file with {opt}, or the {opt} of this sensor", "extrinsic")
    warn_user(what + ": pitch and roll carry that tilt; calibrate the mounting ('imu-ground calibrate') and "
                  "pass it with --extrinsic", UserWarning)
    return angle


def check_creatable(path: Path, option: str, start: Path | None = None) -> None:
    """``path`` (a file or folder to be written) can be created: the nearest existing folder from ``start`` (default:
    its parent) up is writable; else an ImuGroundError naming ``path`` and the CLI ``option`` to change."""
    anc = path.parent if start is None else start
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise ImuGroundError(f"{path}: cannot be created because {anc} is a file, not a folder; "
                             f"choose another {option}")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise ImuGroundError(f"{path}: no permission to write in {anc}; choose another {option}")


def check_recalibration(path: str | Path, speeds: np.ndarray | None, speed_info: str, em) -> None:
    """What ``recalibrate_online`` needs: a measured speed, and frames with one spanning the mount monitor's
    :data:`~imu_ground.filters.mount_monitor.HOLD_OFF` + :data:`~imu_ground.filters.mount_monitor.GATE` s (else
    a warning).

    Parameters
    ----------
    path : str or Path
    speeds : ndarray (F,) or None
        Speed per frame, m/s (NaN where unknown); None: IMU only.
    speed_info : str
        What the speed is (``meta["speed"]``), for the message.
    em : EgoMotion

    Raises
    ------
    OptionError
        No measured speed (names ``speed``, ``--speed``).
    """
    from imu_ground.filters.mount_monitor import GATE, HOLD_OFF
    have = np.zeros(len(em), bool) if speeds is None else np.isfinite(speeds)
    if not have.any():
        raise OptionError(f"{path}: re-estimating the mount online (recalibrate) needs a measured speed, and the run "
                          f"has none (speed {speed_info}); give {{opt}} FILE or COLUMN, or leave out the online "
                          "re-estimation", "speed")
    t = np.asarray(em.t, dtype=float)[have]
    span = float(t[-1] - t[0])
    if span < HOLD_OFF + GATE:
        warn_user(f"{path}: --recalibrate-online cannot act: the mount monitor judges from "
                      f"{HOLD_OFF + GATE:g} s after the first frame with a speed, and the frames with a speed "
                      f"span {span:.1f} s", UserWarning)


def process_running(pid: int) -> bool:
    """Whether a process with id ``pid`` runs on this machine (what tells a stale lock or leftover from a live one)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:                 # it runs, as another user
        return True
    except OSError:
        return False
    return True
