"""``imu-ground preview -o bev.png``: bird's-eye views with the static and the dynamic ground plane.

Without a log: a synthetic drive whose camera sees lane markings and a metric grid on the true moving road (the camera
view, the bird's-eye views with the static extrinsic, the estimate and the truth, the lane-width error against
distance). With a log: ``imu-ground preview LOG --images DIR --times FILE [--camera NAME] -o F`` shows the user's
images with the log's estimate (camera :data:`DEFAULT_CAMERA` unless given). ``-o x.gif`` animates the frames.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from imu_ground.cli._common import estimate_said, input_paths, no_warnings, nonnegative_int, say
from imu_ground.errors import ImuGroundError
from imu_ground.evaluation.preview import (DRAWN_BEV_PIXELS, PREVIEW_GRID, drawn_grid, images_preview, render_preview,
                                           synthetic_preview)
from imu_ground.perception import BevGrid, load_camera
from imu_ground.pipeline.output import atomic_path, check_output_path, check_run_paths, result_table

__all__ = ["DEFAULT_CAMERA", "register", "run"]

#: The camera when ``--camera`` is not given (KITTI's left colour camera).
DEFAULT_CAMERA = "kitti_cam2"


def register(sub) -> None:
    """Add the ``preview`` sub-command."""
    p = sub.add_parser("preview", help="bird's-eye views with the static and the dynamic ground plane (PNG or GIF)",
                       description="Inverse perspective (bird's-eye) views of a camera made with the static "
                                   "extrinsic and with the per-frame ground plane: of a synthetic drive (no LOG; "
                                   "with the truth and the lane-width error against distance), or of your own "
                                   "images with LOG's estimate.")
    p.add_argument("log", nargs="?", help="IMU log or pose file whose estimate to use with --images (optional)")
    p.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="picture to write: .png (one frame) or .gif (every frame, animated)")
    p.add_argument("--images", metavar="DIR", help="with LOG: folder of the camera's images, in name order")
    p.add_argument("--times", metavar="FILE", help="with LOG: one time a line (s, on the log's clock), one per image")
    p.add_argument("--camera", metavar="NAME_OR_FILE",
                   help="the camera: kitti_cam0 .. kitti_cam3, a camera file, or a KITTI raw calibration folder as "
                        "DIR:2 (default kitti_cam2)")
    p.add_argument("--extrinsic", metavar="NAME_OR_FILE",
                   help="with LOG: the log's static sensor-to-ground extrinsic (as for 'imu-ground estimate')")
    p.add_argument("--lidar", metavar="DIR",
                   help="with LOG: a folder of LiDAR scans (KITTI .bin, .pcd, .ply), one per image: adds the bird's-eye view with "
                        "the plane fitted to each scan and a distance the LiDAR measured, read off every view "
                        "(needs --lidar-extrinsic and the extra .[lidar])")
    p.add_argument("--lidar-extrinsic", metavar="SPEC",
                   help="with --lidar: a KITTI raw calibration folder (calib_imu_to_velo.txt) or an extrinsic file "
                        "(R, t: ground <- LiDAR)")
    p.add_argument("--frame", type=nonnegative_int, default=0,
                   help="with LOG and a .png: the image to show, 0-based in name order (default 0)")
    p.add_argument("--bev", nargs=5, type=float, metavar=("X0", "X1", "Y0", "Y1", "RES"),
                   help="bird's-eye grid: X0..X1 m ahead, Y0..Y1 m to the left, RES m a pixel (default 5 45 -7 7 0.05)")
    p.add_argument("--seed", type=nonnegative_int, default=3, help="synthetic drive's seed (default 3)")
    p.add_argument("--frames", type=nonnegative_int, default=20,
                   help="synthetic drive: frames in a .gif (default 20, around the largest true pitch)")
    p.set_defaults(func=run)


def _check(a: argparse.Namespace):
    out = Path(a.output)
    if out.suffix.lower() not in (".png", ".gif"):
        raise ImuGroundError(f"{out}: unknown picture type {out.suffix or '(no suffix)'!r}; end the -o file name with "
                             ".png or .gif")
    check_output_path(out, [a.log] if a.log else [], "-o", kind=".png")
    inputs = input_paths(a) + [("--lidar", a.lidar)]
    check_run_paths([("-o", out)], inputs)
    if a.log is None and (a.images or a.times or a.extrinsic):
        raise ImuGroundError("--images, --times and --extrinsic go with a LOG: imu-ground preview LOG --images DIR "
                             "--times FILE --camera NAME -o F")
    if a.frame and not (a.log and out.suffix.lower() == ".png"):
        raise ImuGroundError(f"--frame {a.frame} goes with a LOG and a .png output (a .gif shows every frame)")
    if (a.lidar or a.lidar_extrinsic) and not (a.log and a.lidar and a.lidar_extrinsic):
        raise ImuGroundError("--lidar DIR and --lidar-extrinsic SPEC go together, with a LOG and its images: "
                             "imu-ground preview LOG --images DIR --times FILE --camera NAME --lidar DIR "
                             "--lidar-extrinsic SPEC -o F")
    if a.log is not None and not Path(a.log).exists():
        raise ImuGroundError(f"{a.log}: no such file or folder (LOG: the IMU log or pose file whose estimate to show)")
    if a.log is not None and not (a.images and a.times):
        raise ImuGroundError(f"{a.log}: a log needs its images: add --images DIR --times FILE (and --camera NAME; "
                             f"default {DEFAULT_CAMERA})")
    if a.bev is None:
        return out, PREVIEW_GRID
    try:
        return out, BevGrid(*a.bev)
    except ValueError as e:
        raise ImuGroundError(f"--bev {' '.join(f'{v:g}' for v in a.bev)}: {e}") from None


def run(a: argparse.Namespace) -> int:
    """Build the preview, draw it and write it atomically; print what the picture shows."""
    t0 = time.perf_counter()
    out, grid = _check(a)
    fmt = out.suffix.lower()[1:]
    if a.log is None:
        with no_warnings():
            preview = synthetic_preview(seed=a.seed, frames=1 if fmt == "png" else max(a.frames, 1), grid=grid,
                                        camera=a.camera or DEFAULT_CAMERA)
    else:
        camera = a.camera or DEFAULT_CAMERA
        res = estimate_said(a.log, camera=camera, extrinsic=a.extrinsic)
        table = result_table(res)                   # the captions say what the CSV says (nan inside long gaps)
        preview = images_preview(a.images, a.times, load_camera(camera), res.track.t, res.meta["plane"],
                                 np.radians(table["pitch_deg"].to_numpy(float)),
                                 np.radians(table["roll_deg"].to_numpy(float)),
                                 title=f"{Path(a.log).name}, camera {camera}: bird's-eye views with the static "
                                       f"and the estimated plane (method {res.meta['method']})")
        if a.lidar:
            from imu_ground.evaluation.lidar_preview import add_lidar_plane
            preview = add_lidar_plane(preview, a.lidar, a.lidar_extrinsic, imu_extrinsic=a.extrinsic)
        if a.frame and fmt == "png":
            from imu_ground.evaluation.lidar_preview import preview_frame
            preview = preview_frame(preview, a.frame)
    data = render_preview(preview, fmt, grid)
    with atomic_path(out) as tmp:
        tmp.write_bytes(data)
    if preview.lane_error is not None:
        le = preview.lane_error
        picks = [i for i, d in enumerate(le["distance_m"]) if d in (20.0, 40.0, 60.0)]
        say("mean |lane-width error| over the moving frames: " + ", ".join(
            f"{le['distance_m'][i]:g} m: static {le['static'][i]:.3f} m, dynamic {le['dynamic'][i]:.3f} m"
            for i in picks))
    frames = 1 if fmt == "png" else len(preview.times)
    drawn = drawn_grid(grid)
    note = (f"; bird's-eye views drawn at {drawn.res:.4g} m a pixel, at most {DRAWN_BEV_PIXELS} pixels a side"
            if drawn != grid else "")
    if a.log is None and fmt != "png" and frames < a.frames:
        note += f"; --frames {a.frames}: the synthetic drive has {frames}"
    say(f"wrote {out} ({frames} frame{'s' if frames > 1 else ''}, {time.perf_counter() - t0:.1f} s{note})")
    return 0
