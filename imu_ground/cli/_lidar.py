"""``imu-ground evaluate --lidar LOG SCANS``: every method against road planes fitted to LiDAR scans.

The log is read and estimated once (:func:`~imu_ground.pipeline.estimate_log`, the
``estimate`` command's default: the row ``estimate``); the methods of ``evaluate
--real`` run on the same frames; each is compared with the LiDAR planes at the
scans' times (:mod:`imu_ground.evaluation.lidar`).
"""
from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from imu_ground.cli._common import say, warn_line
from imu_ground.datasets.options import OptionError
from imu_ground.errors import ImuGroundError

__all__ = ["add_lidar_flags", "check_lidar", "run_lidar"]


def add_lidar_flags(v: argparse.ArgumentParser) -> None:
    """The ``--lidar`` options of ``evaluate``."""
    g = v.add_argument_group("LiDAR ground truth (the paper's protocol)")
    g.add_argument("--lidar", nargs="+", metavar=("LOG", "SCANS"),
                   help="compare the methods on LOG with road planes fitted to the LiDAR scans in SCANS (a folder of "
                        "KITTI .bin, .pcd or .ply scans, e.g. a KITTI raw velodyne_points/data), or given by "
                        "--lidar-planes DIR")
    g.add_argument("--times", metavar="FILE", help="with --lidar: one time a line (s, on the log's clock), one per "
                                                   "scan (or planes file) in name order")
    g.add_argument("--lidar-extrinsic", metavar="SPEC",
                   help="with --lidar: the LiDAR's mounting, a KITTI raw calibration folder (calib_imu_to_velo.txt) or "
                        "an extrinsic file (R: ground <- LiDAR); with --lidar-planes: the planes' camera (kitti_cam2, "
                        "a camera file, DIR:2) or a folder of KITTI object calibration files named as the planes")
    g.add_argument("--lidar-planes", metavar="DIR",
                   help="with --lidar LOG: compare with the KITTI planes files in DIR (a b c d, camera axes; e.g. AVOD's "
                        "or 'estimate --planes' output) instead of fitting scans")
    g.add_argument("--lidar-region", nargs=4, type=float, metavar=("X0", "X1", "Y0", "Y1"),
                   help="road region of the fit in the LiDAR's axes: X0..X1 m ahead, Y0..Y1 m to the left (default "
                        "5 30 -4 4)")
    g.add_argument("--lidar-seed", type=int, default=0, metavar="N", help="RANSAC's random seed (default 0)")
    g.add_argument("--extrinsic", metavar="NAME_OR_FILE",
                   help="with --lidar: the log's static sensor-to-ground extrinsic (as for 'imu-ground estimate')")
    g.add_argument("-o", "--plot", metavar="FILE", help="with --lidar: PNG of pitch and roll over time")


def check_lidar(a: argparse.Namespace) -> None:
    """Option checks before any work (one line each, naming the flag)."""
    from imu_ground.cli._common import input_paths
    from imu_ground.pipeline.output import check_output_path, check_run_paths
    if a.real is not None or a.synthetic:
        raise OptionError("--lidar goes alone: not with --real or --synthetic", "lidar")
    other = [f for f, v in (("--plots", a.plots), ("--per-drive", a.per_drive)) if v]
    if other:
        raise OptionError(f"{other[0]} goes with --real or --synthetic; with --lidar: -o FILE.png plots, --csv "
                          "writes the frames", "lidar")
    if len(a.lidar) > 2:
        raise OptionError(f"{{opt}} takes LOG and SCANS, got {len(a.lidar)} paths", "lidar")
    if (len(a.lidar) == 1) == (not a.lidar_planes):
        raise OptionError(f"{a.lidar[0]}: {{opt}} LOG needs one truth: --lidar LOG SCANS, or --lidar LOG "
                          "--lidar-planes DIR (not both)", "lidar")
    if not a.times:
        raise OptionError("{opt} FILE is needed with --lidar: one time a line on the log's clock, one per scan",
                          "times")
    if not a.lidar_extrinsic:
        raise OptionError("{opt} SPEC is needed with --lidar: a KITTI raw calibration folder or an extrinsic file "
                          "(with --lidar-planes: the planes' camera or KITTI object calibration folder)",
                          "lidar_extrinsic")
    if a.plot:
        if Path(a.plot).suffix.lower() != ".png":
            raise OptionError(f"{a.plot}: the plot is a PNG; end the {{opt}} file name with .png", "plot", flag="-o")
        check_output_path(a.plot, [a.lidar[0]], "-o", kind=".png")
    for option, path in (("--csv", a.csv), ("--markdown", a.markdown)):
        if path:
            check_output_path(path, [a.lidar[0]], option=option, kind="text")
    inputs = [("--lidar LOG", a.lidar[0]), *(("--lidar SCANS", s) for s in a.lidar[1:]), *input_paths(a)]
    check_run_paths([("-o", a.plot), ("--csv", a.csv), ("--markdown", a.markdown)], inputs)


def _truth(a: argparse.Namespace, ext) -> tuple[list, np.ndarray, np.ndarray, str]:
    """The truth's files, its pitch and roll (rad) and what it is: the fitted scans, or the given planes files."""
    from imu_ground.evaluation import lidar as L
    from imu_ground.pipeline.planes import read_kitti_planes
    if len(a.lidar) == 2:
        files = L.scan_files(a.lidar[1])
        region = L.RoadRegion(*a.lidar_region) if a.lidar_region else L.ROAD_REGION
        rot = L.lidar_rotation(a.lidar_extrinsic, ext)
        fits = L.fit_scans(files, region, seed=a.lidar_seed)
        lp, lr = L.lidar_pitch_roll(fits[["normal_x", "normal_y", "normal_z"]].to_numpy(), rot)
        return files, lp, lr, (f"planes fitted to {len(files)} scans of {a.lidar[1]} (region {region}, RANSAC "
                               f"seed {a.lidar_seed})")
    d = Path(a.lidar_planes)
    if not d.is_dir():
        raise OptionError(f"{d}: no such folder ({{opt}} DIR: KITTI planes files)", "lidar_planes")
    files = sorted(p for p in d.iterdir() if p.suffix == ".txt")
    if not files:
        raise OptionError(f"{d}: no planes file (*.txt) in the folder ({{opt}})", "lidar_planes")
    abcd = []
    for f in files:
        try:
            abcd.append(read_kitti_planes(f))
        except ImuGroundError as e:
            raise OptionError(f"{' '.join(str(e).split())} ({{opt}})", "lidar_planes") from None
    lp, lr = L.planes_pitch_roll(np.array(abcd), L.planes_rotations(a.lidar_extrinsic, [f.name for f in files],
                                                                     ext))
    return files, lp, lr, f"{len(files)} planes files of {d}"


def run_lidar(a: argparse.Namespace) -> int:
    """Fit (or read) the LiDAR planes, run the methods, print the table; write the plot and files asked for."""
    from imu_ground.evaluation import lidar as L
    from imu_ground.evaluation.runner import METHODS, format_table, methods_from_list
    from imu_ground.filters import Extrinsic
    from imu_ground.pipeline.estimate import estimate_log
    from imu_ground.pipeline.output import atomic_path

    check_lidar(a)
    methods = methods_from_list(a.methods)
    log = a.lidar[0]
    ext = Extrinsic.coerce(a.extrinsic)
    files, lp, lr, truth = _truth(a, ext)
    t_scan = L.read_scan_times(a.times, len(files), "scans" if len(a.lidar) == 2 else "planes files")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = estimate_log(log, extrinsic=a.extrinsic)
    for w in res.meta["warnings"]:
        warn_line(w, log)
    tr = res.track
    estimates = {f"estimate ({res.meta['method']})": (tr.t, tr.pitch, tr.roll, tr.valid)}
    for name in methods:
        m = METHODS[name]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            track = m.factory(extrinsic=ext).run(res.egomotion, smooth=m.smooth)
        estimates[name] = (track.t, track.pitch, track.roll, track.valid)
    keep = np.isfinite(lp) & np.isfinite(lr)
    if not keep.all():
        warn_line(f"{int((~keep).sum())} planes are nan (frames across a gap): left out", a.lidar_planes)
    frames, summary = L.lidar_table(estimates, t_scan[keep], lp[keep], lr[keep], source=log)
    say(f"{Path(log).name} against {truth}; deg, estimate minus LiDAR")
    cols = ["n", "angle_mean", "pitch_offset", "roll_offset", "angle_centred", "pitch_spread", "lo95", "hi95",
            "p_best", "vs_best_lo95", "vs_best_hi95", "roll_change_spread", "roll_change_corr"]
    say(format_table(summary[[c for c in cols if c in summary.columns]], "text"))
    say("(angle_mean: mean angle between the normals, the paper's metric; *_offset: mean differences (a mounting "
        "calibration removes them); angle_centred: the angle with both centred; pitch_spread: standard deviation "
        "of the pitch difference, lo95..hi95 its moving-block bootstrap interval, p_best: share of the draws in "
        "which the method ranks first, vs_best_*: the interval of its spread minus the best method's; roll as changes only: the region sees the lane's crown)")
    if a.csv:
        with atomic_path(a.csv) as tmp:
            tmp.write_text(frames.to_csv(index=False, float_format="%.5f"), encoding="utf-8")
        say(f"wrote {a.csv}")
    if a.markdown:
        with atomic_path(a.markdown) as tmp:
            tmp.write_text(format_table(summary, "markdown") + "\n", encoding="utf-8")
        say(f"wrote {a.markdown}")
    if a.plot:
        with atomic_path(a.plot) as tmp:
            L.plot_lidar(frames, tmp, title=f"{Path(log).name}: pitch and roll relative to the road, LiDAR planes "
                                             "and estimates (means removed)")
        say(f"wrote {a.plot}")
    return 0
