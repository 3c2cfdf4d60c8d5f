"""``imu-ground estimate LOG``: one IMU log or pose file -> per-frame ground normals (CSV, Parquet, TUM, ROS)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from imu_ground.cli._common import (add_progress_flag, add_reader_flags, input_paths, no_warnings, positive_float,
                                    progress_enabled, reader_options, say, warn_line)
from imu_ground.datasets.storage import with_suffix
from imu_ground.filters.methods import default_method
from imu_ground.pipeline.estimate import available_methods, estimate_to_files
from imu_ground.pipeline.output import check_output_path, check_run_paths, default_output_name, summarize_table
from imu_ground.pipeline.planes import check_planes_dir
from imu_ground.pipeline.plot import check_plot_path

__all__ = ["add_method_flags", "method_kwargs", "register", "run"]


def _methods_epilog() -> str:
    methods = {"auto": ((f"the best for the input (default): {default_method(True)} for IMU logs with an "
                         f"accelerometer, {default_method(False)} for pose files"), False), **available_methods()}
    width = max(map(len, methods)) + 2
    return "\n".join(["methods (--method):", *(f"  {name:<{width}}{' '.join(desc.split())}"
                                                for name, (desc, _) in methods.items())])


def add_method_flags(p: argparse.ArgumentParser) -> None:
    """Method, extrinsic, frame rate and noise flags (shared by ``estimate`` and ``batch``)."""
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = _methods_epilog()
    g = p.add_argument_group("estimation")
    g.add_argument("--method", default="auto", choices=["auto", *available_methods()], metavar="NAME",
                   help="estimation method: auto (default) or one of those listed below")
    g.add_argument("--extrinsic", metavar="NAME_OR_FILE",
                   help="static sensor-to-ground extrinsic: a shipped name (kitti_imu; kitti_cam0 for KITTI "
                        "camera poses) or a calibration file from 'imu-ground calibrate'; identity by default")
    g.add_argument("--rate", type=positive_float, metavar="HZ",
                   help="frame rate, Hz, at most the IMU's sample rate (default 10; pose files: a TUM file's own "
                        "times, a KITTI pose file 10 Hz unless given)")
    g.add_argument("--Q", type=positive_float, metavar="RAD2",
                   help="process noise of --method filter or paper, rad^2 per frame (> 0)")
    g.add_argument("--R", type=positive_float, metavar="VAR", help="measurement noise of --method filter or paper (> 0)")


def method_kwargs(a: argparse.Namespace) -> dict:
    """:func:`~imu_ground.pipeline.estimate_log` keywords from the parsed flags."""
    return dict(method=a.method, extrinsic=a.extrinsic, rate=a.rate, Q=a.Q, R=a.R, **reader_options(a))


def register(sub) -> None:
    """Add the ``estimate`` sub-command."""
    e = sub.add_parser("estimate", help="IMU log or pose file -> per-frame ground normals",
                       description="Per-frame ground normal, pitch and roll of the body relative to the road from "
                                   "one IMU log (KITTI, nuScenes, comma2k19, CSV table, ROS bag) or odometry pose "
                                   "file (KITTI odometry, TUM).")
    e.add_argument("log", help="IMU log file or folder, or a pose file (format detected; see --format)")
    e.add_argument("-o", "--output", metavar="FILE",
                   help="output file; .csv, .parquet, .tum (valid frames only), .bag or .mcap "
                        "(default: <log name>_ground.csv in the current folder)")
    e.add_argument("--tum", metavar="FILE",
                   help="also write the dynamic extrinsic (ground <- sensor) of the valid frames as TUM poses "
                        "(t x y z qx qy qz qw), e.g. for evo")
    e.add_argument("--plot", metavar="FILE",
                   help="also draw the estimate: pitch and roll over time with their 1-sigma band, the status as "
                        "shading and the speed the estimate used; .png, .pdf or .svg")
    add_method_flags(e)
    e.add_argument("--speed", default="auto", metavar="auto|none|FILE|COLUMN",
                   help="measured vehicle speed for the suspension methods (speed-aided mode): auto (default: the "
                        "log's own where its format has one: KITTI INS horizontal speed, nuScenes CAN pose, comma2k19 "
                        "CAN, ROS twist/odometry; else IMU only); none (IMU only); a CSV file whose header names the "
                        "columns t or time (s on the log's time base) and speed or v (m/s); or the name of a speed "
                        "column of a CSV log (of a ROS log: a twist or odometry topic)")
    e.add_argument("--recalibrate-online", action="store_true",
                   help="re-estimate the mount when the mount monitor sees it move (status degraded): 15 s of frames "
                        "with a measured speed after the alarm, then the static rotation is corrected and the status "
                        "is ok again, its reason saying so (method suspension; needs --speed or the log's own)")
    e.add_argument("--causal", action="store_true",
                   help="every choice from the samples before it, as live (the numbers 'imu-ground stream' and "
                        "imu_ground.StreamingEstimator give fed this log sample by sample): sample clock, "
                        "standstills and gyro bias seen so far, each frame's speed from the samples up to it; the "
                        "stamps as recorded, in file order (--policy retime or drop: the live clock's policy)")
    g = e.add_argument_group("camera (road plane in a camera's axes)")
    g.add_argument("--camera", metavar="NAME_OR_FILE",
                   help="a camera on the platform: kitti_cam0 .. kitti_cam3, a camera file (calib/README.md), or a "
                        "KITTI raw calibration folder and camera index as DIR:2; the outputs gain the road plane in "
                        "its axes, plane_a .. plane_d (ROS: a road <- camera transform topic)")
    g.add_argument("--bev", nargs=5, type=float, metavar=("X0", "X1", "Y0", "Y1", "RES"),
                   help="with --camera: bird's-eye grid X0..X1 m ahead, Y0..Y1 m to the left, RES m a pixel; the "
                        "outputs gain its homography bev_h00 .. bev_h22 (bird's-eye pixel <- image pixel) per frame")
    g.add_argument("--planes", metavar="DIR",
                   help="with --camera: also write one KITTI object planes file per frame, DIR/000000.txt, ... "
                        "(nan on frames that span a gap; the folder is replaced as a whole, and only a folder this "
                        "tool wrote, marked by its .imu-ground-planes file: any other non-empty folder is refused)")
    add_reader_flags(e, poses=True)
    add_progress_flag(e)
    e.set_defaults(func=run)


def run(a: argparse.Namespace) -> int:
    """Estimate, write the outputs (atomically, all or none) and print a three-line summary."""
    t0 = time.perf_counter()
    named = [("-o", a.output or default_output_name(a.log)), ("--tum", a.tum), ("--plot", a.plot),
             ("--planes", a.planes)]
    check_run_paths(named)          # first, on the paths as given: -o x.png --plot x.png is one mistake, not two
    outputs = [check_output_path(a.output or default_output_name(a.log), [a.log])]
    kinds: list[str | None] = [None]
    if a.tum:
        outputs.append(check_output_path(a.tum, [a.log], "--tum", kind=".tum"))
        kinds.append(".tum")
    if a.plot:
        plot = check_output_path(check_plot_path(a.plot), [a.log], "--plot", kind=".png")
        outputs.append(plot)
        kinds.append(Path(str(plot)).suffix.lower())
    inputs = input_paths(a)
    check_run_paths(named, inputs)  # then each output against the inputs (after the log's own check, which says so)
    if a.planes is not None:
        check_planes_dir(a.planes, inputs=[p for _, p in inputs if p is not None], outputs=outputs)
    if a.camera is not None and Path(str(outputs[0])).suffix.lower() == ".tum":
        warn_line(f"a TUM file holds poses only, not the road plane of --camera {a.camera}"
                  + (" nor the --bev homographies" if a.bev is not None else "")
                  + f": write it with -o {with_suffix(outputs[0], '.csv')} (or .parquet, .mcap)", outputs[0])
    with no_warnings():
        res, table = estimate_to_files(a.log, outputs, kinds, planes=a.planes, progress=progress_enabled(a),
                                       speed=a.speed, camera=a.camera, bev=a.bev,
                                       **({"recalibrate_online": True} if a.recalibrate_online else {}),
                                       **({"causal": True} if a.causal else {}), **method_kwargs(a))
    for w in res.meta["warnings"]:
        warn_line(w, a.log)
    s = summarize_table(table)
    em = res.egomotion
    say(f"{res.meta['format']} {'pose file' if res.meta['kind'] == 'poses' else 'log'} {a.log}: {s['frames']} frames "
        f"at {em.rate:g} Hz, method {res.meta['method']}, {s['frames'] - s['valid_frames']} across gaps, "
        f"{int(em.stationary.sum())} stationary, speed {res.meta['speed']}"
        + (f", t on {res.meta['clock']}" if res.meta.get("clock") else "") + f" ({time.perf_counter() - t0:.2f} s)")
    if s["valid_frames"]:
        say(f"pitch {s['pitch_mean_deg']:+.3f} +- {s['pitch_std_deg']:.3f} deg (range {s['pitch_min_deg']:+.2f} .. "
            f"{s['pitch_max_deg']:+.2f}), roll {s['roll_mean_deg']:+.3f} +- {s['roll_std_deg']:.3f} deg "
            f"over the {s['valid_frames']} valid frames")
    else:
        say("no valid frame: every frame spans a gap in the log")
    if res.meta.get("plane") is not None:
        h = res.meta["plane"].height
        say(f"camera {a.camera}: height above the road {np.nanmean(h):.3f} m (range {np.nanmin(h):.3f} .. "
            f"{np.nanmax(h):.3f}) over the {int(np.isfinite(h).sum())} frames with a plane")
    wrote = [str(p) for p in outputs]
    if a.planes is not None:
        wrote.append(f"{len(table)} planes files in {a.planes}")
    say("wrote " + " and ".join(wrote))
    return 0
