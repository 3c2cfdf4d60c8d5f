"""One log in, per-frame ground normals out: :func:`estimate_log`, the library form of ``imu-ground estimate``.

The input is an IMU log of any format :func:`imu_ground.datasets.read_imu` reads, or an odometry
pose file (KITTI odometry ``poses/00.txt``, TUM ``t x y z qx qy qz qw``); the method one of the
registry's (:func:`available_methods`). Options are checked before any work; a bad one raises
:class:`~imu_ground.errors.OptionError` naming the option as the user spells it (``rate`` from
Python, ``--rate`` from the command line).
"""
from __future__ import annotations

import math
import os
import warnings
from pathlib import Path
from typing import IO, Any, NamedTuple

import numpy as np

from imu_ground.datasets import detect_format, read_imu, read_poses
from imu_ground.errors import ImuGroundError, OptionError, warn_user
from imu_ground.datasets.options import READER_OPTIONS, OptionText
from imu_ground.datasets.poses import detect_pose_format, moves_along_z
from imu_ground.datasets.speed import SPEED_SOURCES, check_speed, frame_speed, log_speed, read_speed
from imu_ground.datasets.storage import reads_sources
from imu_ground.filters import Extrinsic
from imu_ground.filters.methods import METHODS, default_method, live_methods, recalibrating_methods
from imu_ground.imu import EgoMotion, imu_to_egomotion
from imu_ground.pipeline.input_checks import (
    GRAVITY_REFUSE_DEG,
    GRAVITY_WARN_DEG,
    check_gravity_direction,
    check_recalibration,
    gravity_angle,
    requested_options,
)
from imu_ground.pipeline.output import result_table, write_outputs
from imu_ground.pipeline.planes import check_camera
from imu_ground.units import DEFAULT_FRAME_RATE, MAX_GAP_FRAMES

__all__ = [
    "GRAVITY_REFUSE_DEG",
    "GRAVITY_WARN_DEG",
    "NAIVE",
    "POSE_FORMATS",
    "EstimateResult",
    "OptionError",
    "available_methods",
    "check_frame_rate",
    "check_gravity_direction",
    "check_options",
    "detect_input",
    "estimate_log",
    "estimate_to_files",
    "gravity_angle",
    "live_policy",
    "require_imu_log",
    "requested_options",
    "resolve_method",
    "speed_samples",
]

#: ``--format`` names of the pose files :func:`estimate_log` reads, to :func:`imu_ground.datasets.read_poses` names.
POSE_FORMATS = {"kitti_poses": "kitti", "tum": "tum"}

class EstimateResult(NamedTuple):
    """What :func:`estimate_log` returns (unpacks as ``track, egomotion, meta``).

    Attributes
    ----------
    track : GroundTrack
        Per-frame normal (sensor frame), pitch and roll of the body relative to the road (rad), residual
        rotation road <- body; ``t`` (s) and ``valid``.
    egomotion : EgoMotion
        The frames the track belongs to.
    meta : dict
        ``source``, ``format``, ``kind`` ("imu" or "poses"), ``method``, ``method_description``, ``settings``
        (everything that determines the numbers), ``warnings`` (one line each), ``frame_id`` (the log's; else
        "imu"), ``t0_ns`` (the first stamp, ns, when the log has absolute times), ``imu_rate`` (Hz),
        ``extrinsic`` (rotation ground <- sensor and translation, m), ``speed`` (what speed was used) and
        ``frame_speed`` (m/s per frame, NaN where unknown, or None); with a camera ``camera``, ``plane``, ``bev``.
    """
    track: Any
    egomotion: Any
    meta: dict


#: The constant normal of the static extrinsic (a method of the registry, the baseline ``imu-ground evaluate`` runs).
NAIVE = "naive"


def available_methods() -> dict[str, tuple[str, bool]]:
    """Method name -> (one-line description, needs accelerometer data): the registry,
    :data:`imu_ground.filters.methods.METHODS`, in its order."""
    return {name: (spec.description, bool(spec.needs_accel)) for name, spec in METHODS.items()}


def resolve_method(method: str, has_accel: bool) -> str:
    """The method to run: ``"auto"`` is the best for the input; others are checked against it."""
    methods = available_methods()
    if method == "auto":
        return default_method(has_accel)
    if method not in methods:
        raise OptionError(f"unknown {{opt}} {method!r}; choose auto or one of {', '.join(methods)}", "method")
    if methods[method][1] and not has_accel:
        without = ", ".join(m for m, (_, acc) in methods.items() if not acc)
        raise OptionError(f"{{opt}} {method} needs accelerometer data and pose input has none; use one of "
                          f"{without} (or auto)", "method")
    return method


# ------------------------------------------------------------------------------------------ input kind
def detect_input(path: str | Path, format: str | None = None) -> tuple[str, str | None]:
    """What ``path`` is: ``("poses", "kitti_poses" | "tum")`` or ``("imu", format or None)``; FileNotFoundError
    when it does not exist."""
    p = Path(path)
    if format in POSE_FORMATS:
        return "poses", format
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    pose = {"kitti": "kitti_poses", "tum": "tum"}.get(detect_pose_format(p) or "") if format is None else None
    return ("poses", pose) if pose is not None else ("imu", format)


def require_imu_log(path: str | Path, format: str | None = None, what: str = "this command") -> None:
    """Raise a clear :class:`~imu_ground.errors.ImuGroundError` when ``path`` is a pose file where an IMU log is
    required."""
    kind, fmt = detect_input(path, format)
    if kind == "poses":
        raise ImuGroundError(f"{path}: this is an odometry pose file ({fmt}), but {what} needs an IMU log with "
                             f"gyro and accelerometer (poses work with 'imu-ground estimate')")


# ------------------------------------------------------------------------------------------ checks
def _check_positive(value: Any, name: str, what: str) -> Any:
    if value is None:
        return None
    a = np.asarray(value, dtype=float)
    if a.ndim == 0:
        ok = math.isfinite(float(a)) and float(a) > 0
    else:
        ok = bool(np.all(np.isfinite(a))) and a.ndim == 2 and a.shape[0] == a.shape[1] and bool(
            np.allclose(a, a.T)) and bool(np.all(np.linalg.eigvalsh(a) > 0))
    if not ok:
        raise OptionError(f"{{opt}} must be positive and finite ({what}), got {value!r}", name)
    return value


def check_options(*, method: str = "auto", rate: float | None = None, Q: Any = None, R: Any = None,
                  **reader_options: Any) -> dict:
    """:func:`estimate_log`'s options checked without reading anything; returns the reader keywords to pass.

    Raises
    ------
    OptionError
        Unknown method, non-positive rate or noise.
    TypeError
        An unknown reader option (not in :data:`~imu_ground.datasets.options.READER_OPTIONS`).
    """
    if method != "auto":
        resolve_method(method, True)
    if rate is not None and not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise OptionError(f"{{opt}} must be a positive frame rate in Hz, got {rate!r}", "rate")
    _check_positive(Q, "Q", "process noise, rad^2 per frame")
    _check_positive(R, "R", "measurement noise")
    unknown = sorted(set(reader_options) - set(READER_OPTIONS))
    if unknown:
        raise TypeError(f"estimate_log() got unknown reader options {unknown}; known: {sorted(READER_OPTIONS)}")
    return {k: v for k, v in reader_options.items() if v is not None and k != "format"}


def _one_line(path: str | Path, message: Any) -> str:
    """One line naming the file (a message naming an option keeps its CLI spelling)."""
    def line(text: str) -> str:
        text = " ".join(str(text).split())
        return text if text.startswith(str(path)) else f"{path}: {text}"
    if hasattr(message, "cli_message"):
        return OptionText(line(message), line(message.cli_message()))
    return line(message)


# ------------------------------------------------------------------------------------------ estimate
@reads_sources
def estimate_log(path: str | Path | IO, *, format: str | None = None, method: str = "auto",
                 extrinsic: Any = None, rate: float | None = None, Q: Any = None, R: Any = None,
                 progress: bool = False, speed: Any = "auto", camera: Any = None, bev: Any = None,
                 recalibrate_online: bool = False, causal: bool = False, **reader_options: Any) -> EstimateResult:
    """Per-frame ground normals of one log: what ``imu-ground estimate`` computes.

    Parameters
    ----------
    path : str, Path or file object
        IMU log (any format of :func:`imu_ground.datasets.read_imu`) or pose file (KITTI odometry, TUM;
        detected from the content); an fsspec URL of one (:mod:`imu_ground.datasets.storage`) or an open file.
    format : str, optional
        Input format: a reader's name, or ``"kitti_poses"`` / ``"tum"``; detected when None.
    method : str
        ``"auto"`` (suspension-aware with an accelerometer, ``"filter"`` for poses) or a name of
        :func:`available_methods`.
    extrinsic : str, Path or Extrinsic, optional
        Static ground <- sensor extrinsic: a shipped name (``kitti_imu``, ``kitti_cam0`` for KITTI camera
        poses), a file (a calibration file also sets the suspension gains), or an
        :class:`~imu_ground.filters.Extrinsic`. Identity when None.
    rate : float, optional
        Frame rate, Hz; at most the IMU's sample rate. Default :data:`~imu_ground.units.DEFAULT_FRAME_RATE`;
        a TUM pose file: its own times.
    Q, R : float or ndarray (3, 3), optional
        Process (rad^2 per frame) and measurement noise of the ``filter`` and ``paper`` methods; positive.
    progress : bool
        Progress bar on stderr.
    speed : None, "none", "auto", str, Path or ndarray, optional
        Measured vehicle speed for the suspension methods (:mod:`imu_ground.datasets.speed`): ``None`` /
        ``"none"`` IMU only; ``"auto"`` the log's own speed where its format has one; a speed file (CSV
        ``t,speed``, s on the log's time base) or a column of the log's table; or one speed per frame (m/s).
    camera : str, Path or Camera, optional
        A camera on the same platform (:func:`imu_ground.perception.load_camera`), its extrinsic ground <-
        camera in the ground frame of ``extrinsic``: adds ``meta["camera"]`` and ``meta["plane"]``, a
        :class:`~imu_ground.perception.GroundPlane` of every frame (NaN on frames that span a gap).
    bev : sequence of 5 floats or BevGrid, optional
        Bird's-eye grid ``X0 X1 Y0 Y1 RES`` (m: ahead, left, metres a pixel), with a camera: ``meta["bev"]``;
        the output table gains the homographies (:mod:`imu_ground.pipeline.planes`).
    recalibrate_online : bool
        Re-estimate the mount when the mount monitor sees it move (:mod:`imu_ground.filters.recalibration`);
        needs a measured speed (:func:`~imu_ground.pipeline.input_checks.check_recalibration`).
    causal : bool
        Every choice from the samples before it: the frames a
        :class:`~imu_ground.pipeline.streaming.StreamingEstimator` gives when fed the log sample by sample
        (IMU logs and the live methods only). The log is read with the reader policy ``"recorded"``;
        ``policy`` ``"retime"`` or ``"drop"`` is the sample clock's (:func:`live_policy`).
    **reader_options
        Entries of :data:`imu_ground.datasets.options.READER_OPTIONS` (``policy``, ``gyro_unit``, ...), passed
        to the reader when not None.

    Returns
    -------
    EstimateResult
        ``(track, egomotion, meta)``.

    Raises
    ------
    FileNotFoundError
        No such log.
    OptionError
        A bad option (message names it).
    ImuGroundError
        The log cannot be read (the reader's message: file, line, option to use).
    """
    reader_kw = check_options(method=method, rate=rate, Q=Q, R=R, **reader_options)
    cam, grid = check_camera(camera, bev)
    assert isinstance(path, (str, os.PathLike))         # reads_sources hands a URL or file object on as a local copy
    kind, fmt = detect_input(path, format)
    settings: dict = {"method": method, "rate": rate, "extrinsic": None if extrinsic is None else str(extrinsic),
                      "Q": Q, "R": R, **reader_kw}
    settings["options"] = requested_options(method=method, rate=rate, extrinsic=extrinsic, Q=Q, R=R, speed=speed,
                                            **reader_kw)
    if recalibrate_online:
        settings["recalibrate_online"] = settings["options"]["recalibrate_online"] = True
    bar = _steps(progress)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frame_speeds = None
        if causal:
            track, em, info, name, speed_info = _causal_estimate(path, kind, fmt, method, rate, extrinsic, speed, Q, R,
                                                                 recalibrate_online, reader_kw)
            frame_speeds = info.pop("frame_speed")
            settings["causal"] = settings["options"]["causal"] = True
            # the log is read with its stamps as recorded; the live clock applies the time-order policy
            settings.update(policy="recorded", clock_policy=live_policy(reader_kw.get("policy")))
        else:
            if reader_kw.get("policy") == "recorded":
                raise OptionError(f"{path}: {{opt}} recorded keeps the stamps out of order, for the live front end "
                                  "only (add --causal, or choose retime, drop, sort or strict)", "policy")
            imu = None
            if kind == "poses":
                em, info = _poses_egomotion(path, fmt, rate, reader_kw.get("times"), extrinsic)
            else:
                em, info, imu = _imu_egomotion(path, fmt, rate, extrinsic, reader_kw)
            bar.update()
            name = resolve_method(method, em.has_accel)
            noise = "Q" if Q is not None else "R"
            if (Q is not None or R is not None) and noise not in METHODS[name].options:
                takes = [m for m, spec in METHODS.items() if noise in spec.options]
                raise OptionError(f"{{opt}} sets the noise of the {' and '.join(takes)} methods; method {name} does "
                                  f"not use it (add --method {takes[0]}, or leave it out)", noise)
            if recalibrate_online and name not in recalibrating_methods():
                raise OptionError(f"{path}: {{opt}} re-estimates the mount, frame by frame, when the streaming "
                                  f"suspension method's mount monitor sees it move; method {name} cannot (use "
                                  f"--method {recalibrating_methods()[0]}, or leave it out)", "recalibrate_online")
            frame_speeds, speed_info = _frame_speeds(speed, path, info.get("format"), imu, em, name)
            segments = _segment_notes(em, imu)
            imu = None                                  # the samples freed before the filter (the job's peak memory)
            if recalibrate_online:
                check_recalibration(path, frame_speeds, speed_info, em)
            try:
                track = _run_method(name, em, Extrinsic.coerce(extrinsic), Q, R, frame_speeds, recalibrate_online)
            except ImuGroundError as e:                 # e.g. a frame the estimator refuses: name the log
                if hasattr(e, "cli_message") or str(e).startswith(str(path)):
                    raise
                raise ImuGroundError(f"{path}: {e}") from e
            for j, note in segments:                    # the first frame of each new segment says so, as live
                track.status_reason[j] = f"{track.status_reason[j]}; {note}" if track.status_reason[j] else note
        ext = Extrinsic.coerce(extrinsic)
        bar.update()
    bar.close()
    messages = list(dict.fromkeys(_one_line(path, w.message) for w in caught))
    for m in messages:
        warn_user(m, UserWarning)           # the caller's line (past the reads_sources wrapper)
    settings.update(method=name, rate=float(em.rate), speed=speed_info)
    meta = {"source": str(path), "kind": kind, **info, "method": name,
            "method_description": available_methods().get(name, ("", False))[0],
            "settings": settings, "warnings": messages, "speed": speed_info, "frame_speed": frame_speeds,
            "extrinsic": {"rotation": ext.rotation.tolist(), "translation": ext.translation.tolist()}}
    if cam is not None:
        from imu_ground.pipeline.planes import camera_plane
        settings["camera"] = str(camera if not hasattr(camera, "name") else camera.name)
        meta.update(camera=cam.to_dict(), plane=camera_plane(track.residual, track.valid, cam), bev=grid)
        if grid is not None:
            settings["bev"] = [grid.x0, grid.x1, grid.y0, grid.y1, grid.res]
    return EstimateResult(track, em, meta)


def _steps(progress: bool):
    from tqdm.auto import tqdm
    return tqdm(total=2, desc="estimate", unit="step", disable=not progress, leave=False)


def check_frame_rate(rate: float | None, t: np.ndarray, path) -> float:
    """The IMU's sample rate, Hz (``1 / median step`` of the times ``t``, s; NaN under two samples); a frame rate
    ``rate`` (Hz, None: the default) above it is an :class:`OptionError` naming ``rate``."""
    t = np.asarray(t, dtype=float)
    imu_rate = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    if rate is not None and math.isfinite(imu_rate) and rate > imu_rate * (1 + 1e-6):
        raise OptionError(f"{{opt}} {rate:g} Hz is above the IMU's own sample rate of {imu_rate:.4g} Hz in "
                          f"{path}; choose a frame rate of at most {imu_rate:.4g} Hz", "rate")
    return imu_rate


def _read_log(path, fmt, rate, reader_kw):
    """The IMU log read and its frame rate checked: ``(imu, info)`` (format, IMU rate, frame id, ``t0_ns``)."""
    fmt = detect_format(path) if fmt is None else fmt
    imu = read_imu(path, format=fmt, **reader_kw)
    info = {"format": fmt, "imu_rate": check_frame_rate(rate, imu.t, path), "frame_id": imu.meta.get("frame_id") or "imu"}
    if imu.meta.get("t0_ns") is not None:
        info["t0_ns"] = int(imu.meta["t0_ns"])
    return imu, info


def _imu_egomotion(path, fmt, rate, extrinsic, reader_kw):
    imu, info = _read_log(path, fmt, rate, reader_kw)
    if imu.frame != "FLU" and extrinsic is None:
        warn_user(f"{path}: the IMU's body frame is {imu.frame!r}, not FLU (x forward, y left, z up), and no "
                      "extrinsic was given: pitch and roll refer to the sensor's own axes; run 'imu-ground "
                      "calibrate' once and pass the result with --extrinsic", UserWarning)
    else:
        check_gravity_direction(imu, extrinsic, path)
    frame_rate = DEFAULT_FRAME_RATE if rate is None else rate
    try:
        em = imu_to_egomotion(imu, rate=frame_rate)
    except ImuGroundError as e:         # too short a log: the message names the file, as every other one
        if str(e).startswith(str(path)):
            raise
        raise ImuGroundError(f"{path}: {len(imu)} sample(s) over {imu.duration:.3g} s, too short for frames at "
                             f"{frame_rate:g} Hz ({e})") from e
    _warn_segments(path, imu, em, frame_rate, MAX_GAP_FRAMES)
    return em, info, imu


def _segment_note(imu, i: int) -> str:
    """What the first frame after a new segment (``i``: the sample before the step) says."""
    return (f"the stamps jump forward by {imu.t[i + 1] - imu.t[i]:.3f} s: a new segment from "
            f"t = {imu.t[i + 1]:.3f} s")


def _warn_segments(path, imu, em, rate: float, max_frames: int) -> None:
    """A warning naming each step of the stamps longer than the live limit (a new segment of frames)."""
    cuts = em.meta.get("segment_cuts") or []
    if not cuts:
        return
    from imu_ground.datasets.report import row_names
    report = imu.meta.get("validation")
    where = []
    for i in cuts:
        k = np.flatnonzero(report.gap_out_index == i) if report is not None else np.zeros(0, int)
        kind, rows = row_names(report.gap_index[k[:1]], imu.meta.get("row_lines")) if k.size else ("sample", [i])
        where.append(f"after {kind} {rows[0]} (t = {imu.t[i]:.3f} s) {_segment_note(imu, i)}")
    warn_user(f"{path}: {len(cuts)} step(s) of the stamps longer than the live limit of {max_frames} frames "
              f"({max_frames / rate:g} s at {rate:g} Hz) start a new segment each, as live (no frame across "
              f"them; the first frame after says so): " + "; ".join(where[:5])
              + (f"; ... ({len(where) - 5} more)" if len(where) > 5 else ""), UserWarning)


def _segment_notes(em, imu) -> list[tuple[int, str]]:
    """The first frame of each new segment of ``em`` (``imu``: its samples, or None) and what it says."""
    cuts = (em.meta.get("segment_cuts") or []) if imu is not None else []
    found = [(int(np.searchsorted(em.t, imu.t[i + 1], side="right")), _segment_note(imu, i)) for i in cuts]
    return [(j, note) for j, note in found if j < len(em)]


def _poses_egomotion(path, fmt, rate, times=None, extrinsic=None):
    poses = read_poses(path, format=POSE_FORMATS[fmt], times=times)
    if len(poses) < 2:
        raise ImuGroundError(f"{path}: {len(poses)} pose(s); at least 2 are needed for one frame")
    if extrinsic is None and moves_along_z(poses):
        raise OptionError(f"{path}: camera poses (the motion is along the sensor's +z axis: x right, y down, "
                          f"z forward), whose axes are not a vehicle's; pass {{opt}} kitti_cam0 (KITTI's camera 0) "
                          f"or the camera's own extrinsic", "extrinsic")
    t = None
    if poses.t is not None:
        t = poses.t[1:]
        clock = poses.clock
        if rate is not None:
            warn_user(f"{path}: the poses carry their own times ({clock}); --rate {rate:g} is not used "
                          "(one frame per pose)", UserWarning)
            rate = None
    else:
        clock = f"frame index / {DEFAULT_FRAME_RATE if rate is None else rate:g} Hz (no times)"
        if fmt == "kitti_poses":
            warn_user(f"{path}: a KITTI pose file has no times: frames are timed as index / "
                          f"{DEFAULT_FRAME_RATE if rate is None else rate:g} Hz, but KITTI's cameras run at about "
                          "9.65 Hz (t drifts by seconds over a sequence); pass --times with the sequence's "
                          "times.txt", UserWarning)
    em = EgoMotion.from_rotations(poses.relative_rotations(), t=t, rate=rate,
                                  meta={"source": str(path), "format": fmt})
    return em, {"format": fmt, "frame_id": "camera" if fmt == "kitti_poses" else "sensor", "clock": clock}


def _frame_speeds(speed, path, fmt, imu, em, method: str):
    """Per-frame speeds (m/s, NaN where unknown) for :func:`estimate_log`'s ``speed`` and what they are (``(None,
    "none")``: IMU only)."""
    if speed is None or (isinstance(speed, str) and speed == "none"):
        return None, "none"
    auto = isinstance(speed, str) and speed == "auto"
    if method not in METHODS or not METHODS[method].speed_aided:
        if auto:
            return None, f"none (method {method} does not use a speed)"
        raise OptionError(f"{{opt}} is used by the suspension methods only, not by method {method} (leave it out)",
                          "speed")
    if isinstance(speed, (np.ndarray, list, tuple)):
        v = np.asarray(speed, dtype=float)
        if v.shape != (len(em),):
            raise OptionError(f"{{opt}} as an array needs one value per frame ({len(em)}), got shape {v.shape}",
                              "speed")
        return v, "given per frame"
    got, what = speed_samples(speed, path, fmt, imu)
    if got is None:
        return None, what
    v = frame_speed(got[0], got[1], em.t, em.delta_t)
    holes = int(np.count_nonzero(~np.isfinite(got[1])))
    if holes:
        warn_user(f"speed {what}: {holes} of {len(got[1])} samples have no speed (nan): not interpolated "
                      f"across; the frames they reach run without a speed (IMU only)", UserWarning)
    if not np.isfinite(v).any():
        _refuse_speed_clock(speed, got[0], float(em.t[0]), float(em.t[-1]), "frames")
    return v, f"{what} ({int(np.isfinite(v).sum())} of {len(v)} frames)"


def speed_samples(speed, path, fmt, imu):
    """The speed samples ``(t, v)`` (s on the log's time base, m/s) of ``speed`` (``"auto"``, a file or a column),
    and what they are; ``(None, why)`` when ``"auto"`` finds none."""
    auto = isinstance(speed, str) and speed == "auto"
    if auto:
        got = log_speed(path, fmt, imu) if fmt in SPEED_SOURCES else None
        if got is None:
            why = ("a ROS log without a twist or odometry topic" if fmt == "rosbag"
                   else f"a {fmt} log has no speed signal")
            return None, f"none ({why})"
        what = f"the log's {SPEED_SOURCES[fmt]}"
    else:
        try:
            got = read_speed(speed, log=path, format=fmt, imu=imu)
            t_sp, v_sp, notes = check_speed(*got, str(speed), imu)
        except (ImuGroundError, FileNotFoundError) as e:
            text = str(e)
            rest = text.removeprefix(str(speed))      # the file named once: '--speed FILE[, line N]: ...'
            text = rest if rest.startswith((": ", ", line ")) else f": {text}"
            raise OptionError(f"{{opt}} {speed}{text}", "speed") from e
        for note in notes:
            warn_user(f"speed {note}", UserWarning)
        got = (t_sp, v_sp)
        what = f"{speed}"
        t = np.asarray(imu.t, dtype=float) if imu is not None and len(imu) else None
        if t is not None and len(t_sp) and (float(t_sp[-1]) < float(t.min()) or float(t_sp[0]) > float(t.max())):
            _refuse_speed_clock(speed, t_sp, float(t.min()), float(t.max()), "samples")
    return got, what


def _refuse_speed_clock(speed, t_speed, lo: float, hi: float, what: str) -> None:
    """The speed given is off the log's clock: an :class:`OptionError` naming ``speed``."""
    raise OptionError(f"{{opt}} {speed}: the speed's times ({t_speed[0]:.3f} .. {t_speed[-1]:.3f} s) do not cover "
                      f"the log's {what} ({lo:.3f} .. {hi:.3f} s): not on the log's clock (the times are s on the "
                      "log's time base)", "speed")


def live_policy(policy: str | None) -> str:
    """The live sample clock's policy for the time-order option ``policy`` (``estimate --causal``, ``stream``):
    ``retime`` (also for None and ``"recorded"``) or ``drop``; ``sort`` and ``strict`` need the whole log
    (:class:`OptionError` naming ``policy``)."""
    if policy in (None, "recorded"):
        return "retime"
    if policy in ("retime", "drop"):
        return policy
    raise OptionError(f"{{opt}} {policy} needs the whole log; the live front end (--causal, stream) takes retime "
                      "or drop, applied sample by sample to the stamps as recorded", "policy")


def _causal_estimate(path, kind, fmt, method, rate, extrinsic, speed, Q, R, recalibrate_online, reader_kw):
    """:func:`estimate_log` with ``causal=True`` (:func:`~imu_ground.pipeline.streaming.causal_track`): ``track,
    egomotion, info, method name, speed description``."""
    from imu_ground.pipeline.streaming import causal_track
    if kind != "imu":
        raise OptionError(f"{path}: {{opt}} runs the live front end on IMU samples; a pose file has none (leave it "
                          "out)", "causal")
    name = resolve_method(method, True)
    if name not in live_methods():
        raise OptionError(f"{{opt}} {name} does not run live, so not with --causal; choose one of "
                          f"{', '.join(live_methods())} (or auto)", "method")
    if Q is not None or R is not None:
        raise OptionError("{opt} is not a setting of the live estimator (leave it out with --causal)",
                          "Q" if Q is not None else "R")
    clock_policy = live_policy(reader_kw.get("policy"))
    imu, info = _read_log(path, fmt, rate, {**reader_kw, "policy": "recorded"})
    fmt = info["format"]
    check_gravity_direction(imu, extrinsic, path)
    signal, what = None, "none"
    if METHODS[name].speed_aided and isinstance(speed, (np.ndarray, list, tuple)):
        raise OptionError("{opt} per frame cannot be used live (--causal): give a speed file or column, or auto",
                          "speed")
    if METHODS[name].speed_aided and not (speed is None or (isinstance(speed, str) and speed == "none")):
        signal, what = speed_samples(speed, path, fmt, imu)
    elif speed not in (None, "none", "auto"):
        raise OptionError(f"{{opt}} is used by the suspension methods only, not by method {name} (leave it out)",
                          "speed")
    frame_rate = DEFAULT_FRAME_RATE if rate is None else rate
    track, em = causal_track(imu.t, imu.gyro, imu.accel, method=name, extrinsic=extrinsic, rate=frame_rate,
                             speed=signal, policy=clock_policy, recalibrate_online=recalibrate_online)
    info["frame_speed"] = None
    if signal is not None:
        what = f"{what} (each frame's from the samples up to its decision)"
        info["frame_speed"] = frame_speed(*signal, em.t, em.delta_t)     # the frames' mean speed, for pictures
    em.meta["source"] = str(path)
    return track, em, info, name, what


def _run_method(name: str, em, ext, Q, R, speed=None, recalibrate_online: bool = False):
    """Method ``name`` of the registry run over the ego-motion (the options only when given)."""
    spec = METHODS[name]
    noise = {k: v for k, v in (("Q", Q), ("R", R)) if v is not None}
    if recalibrate_online:
        noise["recalibrate_online"] = True
    extra = {} if speed is None else {"speed": speed}
    return spec.make(extrinsic=ext, **noise).run(em, smooth=bool(spec.smooth), **extra)


def estimate_to_files(path: str | Path, outputs, kinds=None, planes: str | Path | None = None, **kwargs: Any):
    """:func:`estimate_log` and write its table to ``outputs`` (all or none); what the CLI and batch run.

    Parameters
    ----------
    path : str or Path
    outputs, kinds : sequence
        Output files and their writers (:func:`imu_ground.pipeline.output.write_outputs`).
    planes : str or Path, optional
        Folder of KITTI ``planes`` files (needs ``camera=``; :func:`imu_ground.pipeline.planes.write_kitti_planes`),
        written before the outputs.
    **kwargs
        :func:`estimate_log`'s keywords.

    Returns
    -------
    result : EstimateResult
    table : pandas.DataFrame
        The table written.
    """
    if planes is not None and kwargs.get("camera") is None:
        raise OptionError("{opt} needs a camera: add --camera NAME_OR_FILE", "planes")
    result = estimate_log(path, **kwargs)
    table = result_table(result)
    if planes is not None:
        from imu_ground.pipeline.planes import write_kitti_planes
        write_kitti_planes(planes, result.meta["plane"].coefficients, inputs=[path], keep=outputs)
    write_outputs(outputs, table, result.meta, kinds)
    return result, table
