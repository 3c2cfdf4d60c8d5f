"""One log in, per-frame ground normals out: :func:`estimate_log`, the library form of ``imu-ground estimate``.

The input is an IMU log of any format :func:`imu_ground.datasets.read_imu` reads,
or an odometry pose file (KITTI odometry ``poses/00.txt``, TUM ``t x y z qx qy qz qw``).
The method is one of the registry's (:func:`available_methods`); ``"auto"``
picks the best for the input: the suspension-aware filter when the log has an
accelerometer, the invariant filter (``"filter"``) for poses.

Options are checked before any work, and a bad one raises :class:`OptionError`
(a ``ValueError``) whose message names the option as the user spells it:
``rate=...`` from Python, ``--rate`` from the command line
(:meth:`OptionError.cli_message`), as the readers'
:class:`~imu_ground.datasets.options.ImuInputError` does.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

__all__ = [
    "POSE_FORMATS",
    "EstimateResult",
    "OptionError",
    "available_methods",
    "check_options",
    "detect_input",
    "estimate_log",
    "estimate_to_files",
    "require_imu_log",
    "resolve_method",
]

#: ``--format`` names of the pose files :func:`estimate_log` reads, to :func:`imu_ground.datasets.read_poses` names.
POSE_FORMATS = {"kitti_poses": "kitti", "tum": "tum"}

class OptionError(ValueError):
    """A bad option value; the message names the option as Python keyword or CLI flag.

    Parameters
    ----------
    template : str
        Message with ``{opt}`` where the option's name goes.
    name : str
        Python keyword (e.g. ``"rate"``).
    flag : str, optional
        CLI flag (default ``--`` + name with ``_`` as ``-``).
    """

    def __init__(self, template: str, name: str, flag: str | None = None) -> None:
        self.template, self.name = template, name
        self.flag = flag or "--" + name.replace("_", "-")
        super().__init__(template.replace("{opt}", name))

    def cli_message(self) -> str:
        """The message with the option spelled as its ``imu-ground`` flag."""
        return self.template.replace("{opt}", self.flag)


class EstimateResult(NamedTuple):
    """What :func:`estimate_log` returns (unpacks as ``track, egomotion, meta``).

    Attributes
    ----------
    track : GroundTrack
        Per-frame normal (sensor frame), pitch and roll of the body relative to
        the road (rad), residual rotation road <- body; ``t`` (s) and ``valid``.
    egomotion : EgoMotion
        The frames the track belongs to.
    meta : dict
        ``source``, ``format``, ``kind`` ("imu" or "poses"), ``method``,
        ``method_description``, ``settings`` (everything that determines the
        numbers), ``warnings`` (one line each, ``file: message``), ``frame_id``
        (the log's, e.g. a ROS header's; else "imu"), ``t0_ns`` (the first stamp,
        ns, when the log has absolute times; the track's ``t`` starts at 0),
        ``imu_rate`` (Hz, IMU input), ``extrinsic`` (rotation ground <- sensor
        and translation, m); with a camera ``camera``, ``plane`` and ``bev``
        (see :func:`estimate_log`).
    """
    track: Any
    egomotion: Any
    meta: dict


def available_methods() -> dict[str, tuple[str, bool]]:
    """Method name -> (one-line description, needs accelerometer data), from :data:`imu_ground.filters.methods.METHODS`."""
    from imu_ground.filters.methods import METHODS
    return {name: (spec.description, bool(spec.needs_accel)) for name, spec in METHODS.items()}


def resolve_method(method: str, has_accel: bool) -> str:
    """The method to run: ``"auto"`` is the best for the input; others are checked against it."""
    from imu_ground.filters.methods import default_method
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
def _pose_format(path: Path) -> str | None:
    """``"kitti_poses"`` or ``"tum"`` when ``path`` is an odometry pose file, else None."""
    from imu_ground.datasets.poses import detect_pose_format
    name = detect_pose_format(path)
    return {"kitti": "kitti_poses", "tum": "tum"}.get(name) if name else None


def detect_input(path: str | Path, format: str | None = None) -> tuple[str, str | None]:
    """What ``path`` is: ``("poses", "kitti_poses" | "tum")`` or ``("imu", format or None)``.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    """
    p = Path(path)
    if format in POSE_FORMATS:
        return "poses", format
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if format is None:
        pose = _pose_format(p)
        if pose is not None:
            return "poses", pose
    return "imu", format


def require_imu_log(path: str | Path, format: str | None = None, what: str = "this command") -> None:
    """Raise a clear ``ValueError`` when ``path`` is a pose file where an IMU log is required."""
    kind, fmt = detect_input(path, format)
    if kind == "poses":
        raise ValueError(f"{path}: this is an odometry pose file ({fmt}), but {what} needs an IMU log with "
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


def _check_rate(rate: float | None) -> float | None:
    if rate is None:
        return None
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0):
        raise OptionError(f"{{opt}} must be a positive frame rate in Hz, got {rate!r}", "rate")
    return float(rate)


def check_options(*, method: str = "auto", rate: float | None = None, Q: Any = None, R: Any = None,
                  **reader_options: Any) -> dict:
    """Check :func:`estimate_log`'s options without reading anything; returns the reader keywords to pass.

    Raises
    ------
    OptionError
        Unknown method, non-positive rate or noise.
    TypeError
        A reader option that :data:`~imu_ground.datasets.options.READER_OPTIONS` does not have.
    """
    if method != "auto" and method not in available_methods():
        raise OptionError(f"unknown {{opt}} {method!r}; choose auto or one of {', '.join(available_methods())}",
                          "method")
    _check_rate(rate)
    _check_positive(Q, "Q", "process noise, rad^2 per frame")
    _check_positive(R, "R", "measurement noise")
    return _reader_kwargs(reader_options)


def _reader_kwargs(options: dict) -> dict:
    from imu_ground.datasets.options import READER_OPTIONS
    unknown = sorted(set(options) - set(READER_OPTIONS))
    if unknown:
        raise TypeError(f"estimate_log() got unknown reader options {unknown}; known: {sorted(READER_OPTIONS)}")
    return {k: v for k, v in options.items() if v is not None and k != "format"}


def _one_line(path: str | Path, message: Any) -> str:
    text = " ".join(str(message).split())
    return text if text.startswith(str(path)) else f"{path}: {text}"


# ------------------------------------------------------------------------------------------ estimate
def _check_camera(camera: Any, bev: Any) -> tuple[Any, Any]:
    """The :class:`~imu_ground.perception.Camera` and :class:`~imu_ground.perception.BevGrid` of the options
    (None when not given); a bad one raises :class:`OptionError` naming it."""
    if camera is None:
        if bev is not None:
            raise OptionError("{opt} needs a camera: add --camera NAME_OR_FILE", "bev")
        return None, None
    from imu_ground.perception import BevGrid, load_camera
    try:
        cam = load_camera(camera)
    except (ValueError, FileNotFoundError) as e:
        text = " ".join(str(e).split())
        raise OptionError(f"{{opt}} {text}" if text.startswith(str(camera)) else f"{{opt}} {camera}: {text}",
                          "camera") from e
    if bev is None:
        return cam, None
    if isinstance(bev, BevGrid):
        return cam, bev
    try:
        values = [float(v) for v in bev]
        if len(values) != 5:
            raise ValueError(f"needs 5 numbers X0 X1 Y0 Y1 RES (m), got {len(values)}")
        return cam, BevGrid(*values)
    except (TypeError, ValueError) as e:
        raise OptionError(f"{{opt}} {' '.join(map(str, bev)) if isinstance(bev, (list, tuple)) else bev!r}: {e}",
                          "bev") from e


def estimate_log(path: str | Path, *, format: str | None = None, method: str = "auto",
                 extrinsic: Any = None, rate: float | None = None, Q: Any = None, R: Any = None,
                 progress: bool = False, speed: Any = None, camera: Any = None, bev: Any = None,
                 **reader_options: Any) -> EstimateResult:
    """Per-frame ground normals of one log: what ``imu-ground estimate`` computes.

    Parameters
    ----------
    path : str or Path
        IMU log (any format of :func:`imu_ground.datasets.read_imu`) or pose file
        (KITTI odometry, TUM; detected from the content).
    format : str, optional
        Input format: a reader's name, or ``"kitti_poses"`` / ``"tum"``; detected when None.
    method : str
        ``"auto"`` (suspension-aware with an accelerometer, ``"filter"`` for poses)
        or a name of :func:`available_methods`.
    extrinsic : str, Path or Extrinsic, optional
        Static ground <- sensor extrinsic: a shipped name (``kitti_imu``,
        ``kitti_cam0`` for KITTI camera poses), a file (a calibration file also
        sets the suspension gains), or an :class:`~imu_ground.filters.Extrinsic`.
        Identity when None.
    rate : float, optional
        Frame rate, Hz; at most the IMU's sample rate. Default 10 Hz
        (:data:`~imu_ground.units.DEFAULT_FRAME_RATE`); for a TUM pose file its
        own times; for a KITTI pose file (no times) this rate or the default.
    Q, R : float or ndarray (3, 3), optional
        Process (rad^2 per frame) and measurement noise of the ``filter`` and
        ``paper`` methods; positive.
    progress : bool
        Progress bar on stderr.
    speed : None, "none", "auto", str, Path or ndarray, optional
        Measured vehicle speed for the speed-aided mode of the suspension methods
        (:mod:`imu_ground.datasets.speed`): ``None`` / ``"none"`` IMU only;
        ``"auto"`` the log's own speed where its format has one (else IMU only);
        a speed file (CSV ``t,speed``, s on the log's time base) or the name of a
        column of the log's table; or an array, one speed per frame (m/s). What
        was used is in ``meta["speed"]``.
    camera : str, Path or Camera, optional
        A camera on the same platform (:func:`imu_ground.perception.load_camera`:
        ``kitti_cam0`` ... ``kitti_cam3``, a camera file, or a KITTI raw calibration
        folder as ``"DIR:2"``); its static extrinsic is ground <- camera in the
        ground frame of ``extrinsic``. Adds ``meta["camera"]`` (the camera as plain
        numbers) and ``meta["plane"]``: a :class:`~imu_ground.perception.GroundPlane`
        of every frame (road plane in camera axes, road <- camera transforms, pixel
        queries; NaN on frames that span a gap).
    bev : sequence of 5 floats or BevGrid, optional
        Bird's-eye grid ``X0 X1 Y0 Y1 RES`` (m: ahead, left, metres a pixel), with a
        camera: ``meta["bev"]`` (the :class:`~imu_ground.perception.BevGrid`); the
        output table gains the homographies (:mod:`imu_ground.pipeline.planes`).
    **reader_options
        Entries of :data:`imu_ground.datasets.options.READER_OPTIONS`
        (``policy``, ``nonfinite``, ``gyro_unit``, ...), passed to the reader
        when not None.

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
    ValueError
        The log cannot be read (the reader's message: file, line, option to use).
    """
    reader_kw = check_options(method=method, rate=rate, Q=Q, R=R, **reader_options)
    cam, grid = _check_camera(camera, bev)
    kind, fmt = detect_input(path, format)
    settings: dict = {"method": method, "rate": rate, "extrinsic": None if extrinsic is None else str(extrinsic),
                      "Q": Q, "R": R, **reader_kw}
    bar = _steps(progress)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if kind == "poses":
            em, info = _poses_egomotion(path, fmt, rate)
        else:
            em, info, imu = _imu_egomotion(path, fmt, rate, extrinsic, reader_kw)
        bar.update()
        name = resolve_method(method, em.has_accel)
        if (Q is not None or R is not None) and name not in ("filter", "paper"):
            raise OptionError(f"{{opt}} sets the noise of the filter and paper methods; method {name} does not "
                              "use it (add --method filter, or leave it out)", "Q" if Q is not None else "R")
        frame_speeds, speed_info = _frame_speeds(speed, path, info.get("format"), imu if kind == "imu" else None,
                                                 em, name)
        from imu_ground.filters import Extrinsic
        ext = Extrinsic.coerce(extrinsic)
        track = _run_method(name, em, ext, Q, R, frame_speeds)
        bar.update()
    bar.close()
    messages = list(dict.fromkeys(_one_line(path, w.message) for w in caught))
    for m in messages:
        warnings.warn(m, UserWarning, stacklevel=2)
    settings.update(method=name, rate=float(em.rate), speed=speed_info)
    meta = {"source": str(path), "kind": kind, **info, "method": name,
            "method_description": available_methods().get(name, ("", False))[0],
            "settings": settings, "warnings": messages, "speed": speed_info,
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


def _imu_egomotion(path, fmt, rate, extrinsic, reader_kw):
    from imu_ground.datasets import detect_format, read_imu
    from imu_ground.imu import imu_to_egomotion
    from imu_ground.units import DEFAULT_FRAME_RATE
    fmt = detect_format(path) if fmt is None else fmt
    imu = read_imu(path, format=fmt, **reader_kw)
    imu_rate = 1.0 / float(np.median(np.diff(imu.t))) if len(imu) > 1 else float("nan")
    if rate is not None and math.isfinite(imu_rate) and rate > imu_rate * (1 + 1e-6):
        raise OptionError(f"{{opt}} {rate:g} Hz is above the IMU's own sample rate of {imu_rate:.4g} Hz in "
                          f"{path}; choose a frame rate of at most {imu_rate:.4g} Hz", "rate")
    if imu.frame != "FLU" and extrinsic is None:
        warnings.warn(f"{path}: the IMU's body frame is {imu.frame!r}, not FLU (x forward, y left, z up), and no "
                      "extrinsic was given: pitch and roll refer to the sensor's own axes; run 'imu-ground "
                      "calibrate' once and pass the result with --extrinsic")
    em = imu_to_egomotion(imu, rate=DEFAULT_FRAME_RATE if rate is None else rate)
    info = {"format": fmt, "imu_rate": imu_rate, "frame_id": imu.meta.get("frame_id") or "imu"}
    if imu.meta.get("t0_ns") is not None:
        info["t0_ns"] = int(imu.meta["t0_ns"])
    return em, info, imu


def _poses_egomotion(path, fmt, rate):
    from imu_ground.datasets import read_poses
    from imu_ground.imu import EgoMotion
    poses = read_poses(path, format=POSE_FORMATS[fmt])
    if len(poses) < 2:
        raise ValueError(f"{path}: {len(poses)} pose(s); at least 2 are needed for one frame")
    t = None
    if poses.t is not None:
        t = poses.t[1:]
        if rate is not None:
            warnings.warn(f"{path}: a TUM pose file carries its own times; --rate {rate:g} is not used "
                          "(one frame per pose)")
            rate = None
    em = EgoMotion.from_rotations(poses.relative_rotations(), t=t, rate=rate,
                                  meta={"source": str(path), "format": fmt})
    return em, {"format": fmt, "frame_id": "camera" if fmt == "kitti_poses" else "sensor"}


def _frame_speeds(speed, path, fmt, imu, em, method: str):
    """Per-frame speeds (m/s, NaN where unknown) for :func:`estimate_log`'s ``speed``, and what they are.

    Returns ``(None, "none")`` for IMU only; ``(array, description)`` otherwise. A ROS log's speed
    topic is found by its message type (``--topic`` names the IMU topic).
    """
    from imu_ground.filters.methods import METHODS
    if speed is None or (isinstance(speed, str) and speed == "none"):
        return None, "none"
    auto = isinstance(speed, str) and speed == "auto"
    if not METHODS[method].speed_aided:
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
    from imu_ground.datasets.speed import (
        SPEED_SOURCES,
        frame_speed,
        log_speed,
        read_speed,
    )
    if auto:
        got = log_speed(path, fmt, imu) if fmt in SPEED_SOURCES else None
        if got is None:
            return None, f"none (a {fmt} log has no speed signal)"
        what = f"the log's {SPEED_SOURCES[fmt]}"
    else:
        try:
            got = read_speed(speed, log=path, format=fmt, imu=imu)
        except (ValueError, FileNotFoundError) as e:
            raise OptionError(f"{{opt}} {speed}: {e}", "speed") from e
        what = f"{speed}"
    v = frame_speed(*got, em.t, em.delta_t)
    if not np.isfinite(v).any():
        raise OptionError(f"{{opt}} {speed}: the speed's times ({got[0][0]:.3f} .. {got[0][-1]:.3f} s) do not "
                          f"cover the log's frames ({em.t[0]:.3f} .. {em.t[-1]:.3f} s)", "speed")
    return v, f"{what} ({int(np.isfinite(v).sum())} of {len(v)} frames)"


def _run_method(name: str, em, ext, Q, R, speed=None):
    """Run method ``name`` of the registry over the ego-motion (noise options and speed only when given)."""
    from imu_ground.filters.methods import METHODS
    spec = METHODS[name]
    noise = {k: v for k, v in (("Q", Q), ("R", R)) if v is not None}
    extra = {} if speed is None else {"speed": speed}
    return spec.make(extrinsic=ext, **noise).run(em, smooth=bool(spec.smooth), **extra)


def estimate_to_files(path: str | Path, outputs, kinds=None, planes: str | Path | None = None, **kwargs: Any):
    """:func:`estimate_log` and write its table to ``outputs`` (all or none); what the CLI and batch run.

    Parameters
    ----------
    path : str or Path
        The log.
    outputs : sequence of str or Path
        Output files (writer by suffix, or by ``kinds``; see
        :func:`imu_ground.pipeline.output.write_outputs`).
    kinds : sequence of str or None, optional
    planes : str or Path, optional
        Folder of KITTI ``planes`` files, one per frame (needs ``camera=``;
        :func:`imu_ground.pipeline.planes.write_kitti_planes`), written before the outputs.
    **kwargs
        :func:`estimate_log`'s keywords.

    Returns
    -------
    result : EstimateResult
    table : pandas.DataFrame
        The table written.
    """
    from imu_ground.pipeline.output import result_table, write_outputs
    if planes is not None and kwargs.get("camera") is None:
        raise OptionError("{opt} needs a camera: add --camera NAME_OR_FILE", "planes")
    result = estimate_log(path, **kwargs)
    table = result_table(result)
    if planes is not None:
        from imu_ground.pipeline.planes import write_kitti_planes
        write_kitti_planes(planes, result.meta["plane"].coefficients)
    write_outputs(outputs, table, result.meta, kinds)
    return result, table
