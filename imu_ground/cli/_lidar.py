"""``imu-ground evaluate --lidar``: every method against road planes fitted to LiDAR scans.

Two forms, told apart by the first path: ``--lidar DRIVE_DIR ...``, KITTI raw sync folders per drive and pooled,
per fit (:func:`lidar_drives_report`); ``--lidar LOG SCANS --times FILE --lidar-extrinsic SPEC`` (or ``--lidar LOG
--lidar-planes DIR``), one log, any scans. The log is estimated once with ``estimate``'s defaults; the methods of
``evaluate --real`` run on its frames, each compared with the planes at the scans' times.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.cli._common import estimate_said, first_given, no_warnings, say, warn_line, write_said
from imu_ground.errors import ImuGroundError, OptionError
from imu_ground.filters.methods import reference_methods

__all__ = ["DEFAULT_ROW", "FITS", "add_lidar_flags", "check_lidar", "lidar_drives_report", "run_lidar"]

#: The name of ``estimate``'s default (method auto, speed auto) among the methods of the drive form.
DEFAULT_ROW = "default"
#: ``--lidar-fit`` choices: ``auto`` is Patchwork++ where ``pypatchworkpp`` is installed, RANSAC otherwise;
#: ``all`` every ground choice in the box and along the driven path (the ranking across fits).
FITS = ("auto", "ransac", "patchwork", "all")
#: ``--lidar-min-speed`` default of the drive form, m/s (scans of a standing vehicle are left out).
MIN_SPEED = 0.5


def add_lidar_flags(v: argparse.ArgumentParser) -> None:
    """The ``--lidar`` options of ``evaluate``."""
    g = v.add_argument_group("LiDAR ground truth (the paper's protocol)")
    g.add_argument("--lidar", nargs="+", metavar="PATH",
                   help="DRIVE_DIR [DRIVE_DIR ...]: KITTI raw sync folders as they come (oxts/ the IMU log, "
                        "velodyne_points/data/*.bin the scans, their times from velodyne_points/timestamps.txt or "
                        "else the OXTS stamps, the calibration from the parent folder); or LOG SCANS: compare the "
                        "methods on LOG with road planes fitted to the LiDAR scans in SCANS (a folder of KITTI .bin, "
                        ".pcd or .ply scans) at --times, or given by --lidar-planes DIR")
    g.add_argument("--log", action="append", metavar="FILE",
                   help="with --lidar DRIVE_DIR: a log of the same drive to use instead of its oxts/: the 100 Hz "
                        "kitti_imu100 CSV (its clock from t0_seconds_of_day of drives.csv beside it) or a KITTI OXTS "
                        "folder (its stamps); paired with the DRIVE_DIR of the same drive name, once per drive")
    g.add_argument("--lidar-fit", choices=FITS, default="auto",
                   help="the road's points: Patchwork++ ground points (pypatchworkpp) or RANSAC, then least squares; "
                        "auto (default): Patchwork++ where installed, else RANSAC; all: RANSAC and Patchwork++, each "
                        "in the box and along the driven path, and how the ranking holds across them (drive form)")
    g.add_argument("--lidar-min-speed", type=float, metavar="M/S",
                   help=f"with --lidar DRIVE_DIR: leave out the scans where the log's speed is below this "
                        f"(default {MIN_SPEED:g} m/s; the LOG SCANS form compares every scan)")
    g.add_argument("--lidar-scans", type=int, metavar="N",
                   help="with --lidar DRIVE_DIR: the first N scans of each drive only (a quick look)")
    g.add_argument("--json", metavar="FILE",
                   help="with --lidar DRIVE_DIR: write every drive's and the pooled spreads per method as JSON")
    g.add_argument("--times", metavar="FILE", help="with --lidar: one time a line (s, on the log's clock), one per "
                                                   "scan (or planes file) in name order")
    g.add_argument("--lidar-extrinsic", metavar="SPEC",
                   help="with --lidar: the LiDAR's mounting, a KITTI raw calibration folder (calib_imu_to_velo.txt) or "
                        "an extrinsic file (R: ground <- LiDAR); with --lidar-planes: the planes' camera (kitti_cam2, "
                        "a camera file, DIR:2) or a folder of KITTI object calibration files named as the planes")
    g.add_argument("--lidar-planes", metavar="DIR",
                   help="with --lidar LOG: compare with the KITTI planes files in DIR (a b c d, camera axes; e.g. AVOD's "
                        "or 'estimate --planes' output) instead of fitting scans")
    g.add_argument("--lidar-region", nargs="+", metavar="REGION",
                   help="road region of the fit: X0 X1 Y0 Y1, the box X0..X1 m ahead, Y0..Y1 m to the left in the "
                        "LiDAR's axes (default "
                        "5 30 -4 4, a straight box); 'path' (drive form): the points within 1.5 m of the vehicle's "
                        "future OXTS track, 3-32 m ahead, so turns do not fit the kerb")
    g.add_argument("--lidar-seed", type=int, default=0, metavar="N", help="RANSAC's random seed (default 0)")
    g.add_argument("--extrinsic", metavar="NAME_OR_FILE",
                   help="with --lidar: the log's static sensor-to-ground extrinsic (as for 'imu-ground estimate')")
    g.add_argument("-o", "--plot", metavar="FILE", help="with --lidar: PNG of pitch and roll over time (several "
                                                         "DRIVE_DIRs: one a drive, FILE's name + _DRIVE.png)")


def _drive_form(a: argparse.Namespace) -> bool:
    """The first path is a KITTI raw sync folder, or (no ``--times``, ``--lidar-planes``) every path holds ``oxts/``."""
    from imu_ground.evaluation.lidar_kitti import is_kitti_sync_folder
    if is_kitti_sync_folder(a.lidar[0]):
        return True
    return not a.times and not a.lidar_planes and all((Path(p) / "oxts").is_dir() for p in a.lidar)


def _region_arg(a: argparse.Namespace):
    """``--lidar-region``: ``"path"`` or a :class:`RoadRegion` (default the box)."""
    from imu_ground.evaluation import lidar as L
    if not a.lidar_region:
        return L.ROAD_REGION
    if a.lidar_region in (["path"], ["box"]):
        return "path" if a.lidar_region == ["path"] else L.ROAD_REGION
    try:
        values = [float(v) for v in a.lidar_region]
    except ValueError:
        values = []
    if len(values) != 4:
        raise OptionError(f"{{opt}} {' '.join(a.lidar_region)}: give four numbers X0 X1 Y0 Y1 (m, LiDAR axes) or "
                          "'path' (the driven path, --lidar DRIVE_DIR)", "region", flag="--lidar-region")
    return L.RoadRegion(*values)


def _check_common(a: argparse.Namespace) -> None:
    if a.real is not None or a.synthetic:
        raise OptionError("--lidar goes alone: not with --real or --synthetic", "lidar")
    other = first_given(("--plots", a.plots), ("--per-drive", a.per_drive))
    if other:
        raise OptionError(f"{other} goes with --real or --synthetic; with --lidar: -o FILE.png plots, --csv "
                          "writes the frames", "lidar")
    if a.plot and Path(a.plot).suffix.lower() != ".png":
        raise OptionError(f"{a.plot}: the plot is a PNG; end the {{opt}} file name with .png", "plot", flag="-o")
    if a.lidar_min_speed is not None and not (a.lidar_min_speed >= 0 and np.isfinite(a.lidar_min_speed)):
        raise OptionError(f"{{opt}} {a.lidar_min_speed:g}: a speed >= 0 (m/s)", "lidar_min_speed")
    if a.lidar_scans is not None and a.lidar_scans < 2:
        raise OptionError(f"{{opt}} {a.lidar_scans}: at least 2 scans a drive", "lidar_scans")


def check_lidar(a: argparse.Namespace) -> None:
    """Option checks of the ``LOG SCANS`` form before any work (one line each, naming the flag)."""
    _check_common(a)
    drive_only = first_given(("--log", a.log), ("--json", a.json), ("--lidar-scans", a.lidar_scans),
                             ("--lidar-min-speed", a.lidar_min_speed), ("--lidar-fit all", a.lidar_fit == "all"),
                             ("--lidar-region path", a.lidar_region == ["path"]))
    if drive_only:
        raise OptionError(f"{a.lidar[0]}: {drive_only} goes with --lidar DRIVE_DIR (a KITTI raw sync folder with "
                          "oxts/ and velodyne_points/), not with --lidar LOG SCANS", "lidar")
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
    _region_arg(a)
    _check_outputs(a, [a.lidar[0]], [("--lidar LOG", a.lidar[0]), *(("--lidar SCANS", s) for s in a.lidar[1:])])


def _check_outputs(a: argparse.Namespace, inputs: list, named: list, extra: tuple = ()) -> None:
    """The output files (``-o``, ``--csv``, ``--markdown`` and ``extra``) writable and none an input."""
    from imu_ground.cli._common import input_paths
    from imu_ground.pipeline.output import check_output_path, check_run_paths
    if a.plot:
        check_output_path(a.plot, inputs, "-o", kind=".png")
    texts = [("--csv", a.csv), ("--markdown", a.markdown), *extra]
    for option, path in texts:
        if path:
            check_output_path(path, inputs, option=option, kind="text")
    check_run_paths([("-o", a.plot), *texts], [*named, *input_paths(a)])


def _plot(path: str | Path, frames: Any, name: str) -> None:
    """The pitch and roll plot of ``frames`` (:func:`~imu_ground.evaluation.lidar.plot_lidar`) written to ``path``."""
    from imu_ground.evaluation.lidar import plot_lidar
    write_said(path, lambda tmp: plot_lidar(frames, tmp, title=f"{name}: pitch and roll relative to the road, "
                                                                 "LiDAR planes and estimates (means removed)"))


def _truth(a: argparse.Namespace, ext) -> tuple[list, np.ndarray, np.ndarray, str]:
    """The truth's files, its pitch and roll (rad) and what it is: the fitted scans, or the given planes files."""
    from imu_ground.evaluation import lidar as L
    from imu_ground.pipeline.planes import read_kitti_planes
    if len(a.lidar) == 2:
        files = L.scan_files(a.lidar[1])
        region = _region_arg(a)
        rot = L.lidar_rotation(a.lidar_extrinsic, ext)
        ground, why = _ground(a.lidar_fit)
        fits = L.fit_scans(files, region, seed=a.lidar_seed, ground=ground)
        lp, lr = L.lidar_pitch_roll(fits[["normal_x", "normal_y", "normal_z"]].to_numpy(), rot)
        how = "Patchwork++ ground points" if ground == "patchwork" else f"RANSAC seed {a.lidar_seed}"
        return files, lp, lr, (f"planes fitted to {len(files)} scans of {a.lidar[1]} (region {region}, {how}, "
                               f"least squares{why})")
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


def _ground(fit: str) -> tuple[str, str]:
    """The ground-point choice of ``--lidar-fit`` (auto: Patchwork++ where installed) and why, for the output."""
    from imu_ground.evaluation import lidar as L
    if fit != "auto":
        return fit, ""
    if L.patchwork_available():
        return "patchwork", "; --lidar-fit auto: Patchwork++ is installed"
    return "ransac", "; --lidar-fit auto: pypatchworkpp is not installed (pip install -e \".[lidar]\"), RANSAC instead"


def _estimates(log: Any, methods: list, extrinsic: Any, default_name: str | None = None):
    """``estimate``'s defaults on the log, then every method on its frames: the result, ``{name: (t, pitch, roll,
    valid)}`` (the default first)."""
    from imu_ground.evaluation.runner import METHODS
    from imu_ground.filters import Extrinsic
    res = estimate_said(log, extrinsic=extrinsic)
    tr = res.track
    ext = Extrinsic.coerce(extrinsic)
    estimates = {default_name or f"estimate ({res.meta['method']})": (tr.t, tr.pitch, tr.roll, tr.valid)}
    for name in methods:
        m = METHODS[name]
        with no_warnings():
            track = m.factory(extrinsic=ext).run(res.egomotion, smooth=m.smooth)
        estimates[name] = (track.t, track.pitch, track.roll, track.valid)
    return res, estimates


def run_lidar(a: argparse.Namespace) -> int:
    """Fit (or read) the LiDAR planes, run the methods, print the table; write the plot and files asked for."""
    from imu_ground.evaluation import lidar as L
    from imu_ground.evaluation.runner import format_table, methods_from_list
    from imu_ground.filters import Extrinsic

    if _drive_form(a):
        return run_lidar_drives(a)
    check_lidar(a)
    methods = methods_from_list(a.methods)
    log = a.lidar[0]
    ext = Extrinsic.coerce(a.extrinsic)
    files, lp, lr, truth = _truth(a, ext)
    t_scan = L.read_scan_times(a.times, len(files), "scans" if len(a.lidar) == 2 else "planes files")
    _, estimates = _estimates(log, methods, a.extrinsic)
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
        "which the method ranks first, vs_best_*: the interval of its spread minus the best method's; roll as "
        "changes only: the region sees the lane's crown)")
    if a.csv:
        write_said(a.csv, frames.to_csv(index=False, float_format="%.5f"))
    if a.markdown:
        write_said(a.markdown, format_table(summary, "markdown") + "\n")
    if a.plot:
        _plot(a.plot, frames, Path(log).name)
    return 0


# ----------------------------------------------------------------------------- the drive form
def _fits(fit: str, region: Any) -> list[tuple[str, Any]]:
    """The (ground, region) pairs: one, or with ``all`` RANSAC and Patchwork++ each in the box and on the path."""
    from imu_ground.evaluation import lidar as L
    box = region if isinstance(region, L.RoadRegion) else L.ROAD_REGION
    if fit == "all":
        grounds = ["ransac"] + (["patchwork"] if L.patchwork_available() else [])
        return [(g, r) for g in grounds for r in (box, "path")]
    return [(_ground(fit)[0], region)]


def _fit_name(ground: str, region: Any) -> str:
    return f"{ground} {'path' if region == 'path' else 'box'}"


def _pair_logs(folders: list, logs: list | None) -> dict:
    """``--log`` files by drive name (``2011_09_26_drive_0009``), each of a given DRIVE_DIR."""
    from imu_ground.datasets.kitti_imu100 import drive_name
    names = [Path(f).name[:-5] if Path(f).name.endswith("_sync") else Path(f).name for f in folders]
    out: dict = {}
    for log in logs or []:
        p = Path(log)
        if not p.exists():
            raise OptionError(f"{p}: no such file ({{opt}} FILE: a log of one of the --lidar drives)", "log")
        name = drive_name(p) if p.is_file() else p.name[:-5] if p.name.endswith("_sync") else p.name
        if name not in names:
            raise OptionError(f"{p}: drive {name} is none of the --lidar DRIVE_DIRs ({', '.join(names)}); {{opt}} is "
                              "paired with the DRIVE_DIR of the same drive name", "log")
        if name in out:
            raise OptionError(f"{p}: a second {{opt}} for drive {name} (one log a drive)", "log")
        if p.is_file():                                  # its clock before any work (a folder has its OXTS stamps)
            from imu_ground.evaluation.lidar_kitti import log_clock
            log_clock(p)
        out[name] = p
    return out


def _lidar_from_imu(ground_from_lidar, ground_from_imu):
    """LiDAR <- IMU from ground <- LiDAR and ground <- IMU: ``x_l = R^T (R_g<-imu x + t_imu - t_l)``."""
    from imu_ground.filters import Extrinsic
    r_l, t_l = ground_from_lidar.rotation, ground_from_lidar.translation
    return Extrinsic(r_l.T @ ground_from_imu.rotation, r_l.T @ (ground_from_imu.translation - t_l))


def _scans_used(t_scan: np.ndarray, tr, min_speed: float) -> tuple[np.ndarray, list[str]]:
    """The scans inside the log's valid frames and at speed, and what was left out (for the output)."""
    t, valid = np.asarray(tr.t, dtype=float), np.asarray(tr.valid, dtype=bool) & np.isfinite(tr.t)
    tv = t[valid]
    step = float(np.median(np.diff(tv))) if len(tv) > 1 else 0.0
    inside = (t_scan >= tv[0] - step) & (t_scan <= tv[-1]) if len(tv) else np.zeros(len(t_scan), dtype=bool)
    notes = []
    if (~inside).any():
        notes.append(f"{int((~inside).sum())} scan(s) outside the log's frames ({tv[0] - step:.2f}..{tv[-1]:.2f} s "
                     "on its clock)" if len(tv) else f"{len(t_scan)} scan(s): the log has no valid frame")
    keep = inside
    speed = getattr(tr, "speed", None)
    if min_speed > 0:
        if speed is not None and len(speed) == len(t) and np.isfinite(speed[valid]).any():
            ok = np.isfinite(speed) & valid
            slow = inside & (np.interp(t_scan, t[ok], np.asarray(speed)[ok]) < min_speed)
            if slow.any():
                notes.append(f"{int(slow.sum())} scan(s) below --lidar-min-speed {min_speed:g} m/s")
            keep = inside & ~slow
        else:
            notes.append(f"the default has no speed: --lidar-min-speed {min_speed:g} not applied")
    return keep, notes


def _drive_checked(folder: Any, lidar_extrinsic: Any = None):
    """The folder's :class:`~imu_ground.evaluation.lidar_kitti.KittiLidarDrive` and its calibration, checked."""
    from imu_ground.evaluation import lidar_kitti as K
    drive = K.read_kitti_lidar_drive(folder)
    calib = lidar_extrinsic or drive.calibration
    if calib is None:
        raise OptionError(f"{drive.folder.parent}: no calib_imu_to_velo.txt beside {drive.folder.name}; give "
                          "{opt} SPEC (a KITTI raw calibration folder or an extrinsic file)", "lidar_extrinsic")
    if len(drive.files) < 2:
        raise OptionError(f"{drive.folder}: {len(drive.files)} scan in velodyne_points/data; {{opt}} DRIVE_DIR "
                          "compares 2 or more a drive (their spreads)", "lidar")
    return drive, calib


def lidar_drives_report(folders: list, logs: dict | None = None, methods: list | None = None, fit: str = "auto",
                        region: Any = None, extrinsic: Any = None, lidar_extrinsic: Any = None,
                        min_speed: float = MIN_SPEED, max_scans: int | None = None, seed: int = 0,
                        on_note: Any = None) -> tuple[dict, "Any"]:
    """Every method against the LiDAR planes of KITTI raw sync folders, per drive and pooled, per fit.

    Parameters
    ----------
    folders : list of str or Path
        KITTI raw sync folders; ``logs`` (dict, optional) drive name -> a log to estimate instead of its ``oxts/``.
    methods : list of str, optional
        Methods of ``evaluate --real`` beside the default (row :data:`DEFAULT_ROW`); default all.
    fit, region, extrinsic, lidar_extrinsic, min_speed (m/s), max_scans, seed
        As ``--lidar-fit``, ``--lidar-region`` (a RoadRegion or ``"path"``), ``--extrinsic``, ``--lidar-extrinsic``
        (default each folder's parent), ``--lidar-min-speed``, ``--lidar-scans``, ``--lidar-seed``.
    on_note : callable, optional
        ``on_note(drive, text)`` for what is left out or chosen.

    Returns
    -------
    report : dict
        ``{"fit", "region", "fits": {NAME: {"drives": [...], "pooled": {...}}}, "drives", "pooled", "ranking"}``:
        ``drives`` and ``pooled`` are those of the first fit (the one ``--lidar-fit`` names); each drive
        ``{"drive", "input", "times", "scans", "scans_total", "left_out", "fit_noise_pitch_deg",
        "fit_noise_roll_deg", "methods": {NAME: {"pitch_spread_deg", "roll_spread_deg", ...}}}``
        (:func:`~imu_ground.evaluation.lidar_kitti.drive_summary`); ``ranking`` per drive (and pooled) the methods
        in order of pitch and of roll spread under each fit, and whether the order holds across fits.
    frames : pandas.DataFrame
        Every scan's comparison, with ``drive`` and ``fit`` columns.
    """
    import pandas as pd
    from imu_ground.evaluation import lidar as L
    from imu_ground.evaluation import lidar_kitti as K
    from imu_ground.evaluation.runner import methods_from_list
    from imu_ground.filters import Extrinsic
    note = on_note or (lambda drive, text: None)
    methods = methods_from_list(None) if methods is None else methods
    region = L.ROAD_REGION if region is None else region
    logs = logs or {}
    pairs = _fits(fit, region)
    ext = Extrinsic.coerce(extrinsic)
    per_fit: dict = {_fit_name(g, r): {"drives": [], "frames": []} for g, r in pairs}
    all_frames = []
    for folder in folders:
        drive, calib = _drive_checked(folder, lidar_extrinsic)
        log = logs.get(drive.name, drive.folder)
        total = len(drive.files)
        cut = max_scans is not None and max_scans < total
        if cut:
            drive.files, drive.frames, drive.stamps_ns = (drive.files[:max_scans], drive.frames[:max_scans],
                                                          drive.stamps_ns[:max_scans])
        res, estimates = _estimates(log, methods, extrinsic, DEFAULT_ROW)
        t_scan = K.scan_times_on_log(drive, K.log_clock(log, res.meta.get("t0_ns")))
        keep, left_out = _scans_used(t_scan, res.track, min_speed)
        left_out[:0] = [f"the first {max_scans} of {total} scans (--lidar-scans)"] if cut else []
        ground_from_lidar = L.lidar_transform(calib, ext)
        lidar_from_imu = _lidar_from_imu(ground_from_lidar, ext)
        files = [f for f, k in zip(drive.files, keep, strict=True) if k]
        kept = np.flatnonzero(keep)
        path_regions = None
        for ground, reg in pairs:
            name = _fit_name(ground, reg)
            if reg == "path" and path_regions is None:
                regs = K.drive_path_regions(drive, lidar_from_imu)
                path_regions = [regs[i] for i in kept]
            regions = path_regions if reg == "path" else [reg] * len(files)
            assert regions is not None                         # the path's regions are made above
            normals = []
            for f, r in zip(files, regions, strict=True):
                try:
                    normals.append(L.fit_ground_plane(L.read_scan(f), r, seed=seed, source=str(f), ground=ground)[0])
                except OptionError as e:                       # no road in this scan's region: left out, said so
                    note(drive.name, f"{name}: {' '.join(str(e).split())}: left out")
                    normals.append(None)
            ok = np.array([n is not None for n in normals], dtype=bool)
            if ok.sum() < 2:
                raise OptionError(f"{drive.folder}: {int(ok.sum())} scan(s) to compare "
                                  f"({'; '.join(left_out) or 'none left out'}); {{opt}} needs 2 or more a drive", "lidar")
            lp, lr = L.lidar_pitch_roll(np.array([n for n in normals if n is not None]), ground_from_lidar.rotation)
            frames, _ = L.lidar_table(estimates, t_scan[kept][ok], lp, lr, source=str(log))
            frames = frames.assign(drive=drive.name, fit=name)
            all_frames.append(frames)
            row = {"drive": drive.name, "input": str(log), "times": drive.times_source,
                   "scans": int(ok.sum()), "scans_total": total, "left_out": left_out,
                   **K.fit_noise(np.degrees(lp), np.degrees(lr)), "methods": K.drive_summary(frames)}
            per_fit[name]["drives"].append(row)
            per_fit[name]["frames"].append(frames)
        for text in left_out:
            note(drive.name, text)
    fits_out = {k: {"drives": v["drives"], "pooled": {"drives": len(v["drives"]),
                                                     "scans": int(sum(d["scans"] for d in v["drives"])),
                                                     "methods": K.pooled_summary(v["frames"])}}
                for k, v in per_fit.items()}
    first = next(iter(fits_out.values()))
    report = {"fit": next(iter(fits_out)), "region": str(region), "default": DEFAULT_ROW,
              "min_speed_mps": min_speed, "drives": first["drives"], "pooled": first["pooled"],
              "fits": fits_out, "ranking": _ranking(fits_out)}
    return report, pd.concat(all_frames, ignore_index=True)


def _order(methods: dict, key: str) -> list[str]:
    return sorted(methods, key=lambda m: (methods[m][key], m))


def _ranking(fits: dict) -> dict:
    """Per drive and pooled, the methods by pitch and by roll spread under each fit: whether the order of all
    (``holds``) and of the default, paper and naive (``holds_default_paper_naive``) holds across the fits."""
    out: dict = {}
    names = list(fits)
    keys = [d["drive"] for d in fits[names[0]]["drives"]] + ["pooled"]
    for i, key in enumerate(keys):
        entry: dict = {}
        for what in ("pitch", "roll"):
            orders = {}
            for fit in names:
                methods = fits[fit]["pooled"]["methods"] if key == "pooled" else fits[fit]["drives"][i]["methods"]
                orders[fit] = _order(methods, f"{what}_spread_deg")
            three = {fit: [m for m in o if m in (DEFAULT_ROW, *reference_methods())] for fit, o in orders.items()}
            entry[what] = {"order": orders, "holds": len({tuple(o) for o in orders.values()}) == 1,
                           "holds_default_paper_naive": len({tuple(o) for o in three.values()}) == 1}
        out[key] = entry
    return out


#: Columns printed per method (the JSON keys, shortened headers).
_COLUMNS = {"scans": "n", "pitch_spread_deg": "pitch_spread", "pitch_spread_lo95": "lo95", "pitch_spread_hi95": "hi95",
            "roll_spread_deg": "roll_spread", "roll_spread_lo95": "r_lo95", "roll_spread_hi95": "r_hi95",
            "angle_mean_deg": "angle_mean", "angle_centred_deg": "angle_centred", "pitch_offset_deg": "pitch_offset",
            "roll_offset_deg": "roll_offset", "p_best_pitch": "p_best"}


def _table(methods: dict):
    import pandas as pd
    df = pd.DataFrame.from_dict(methods, orient="index")
    df.index.name = "method"
    cols = [c for c in _COLUMNS if c in df.columns]
    return df[cols].rename(columns=_COLUMNS)


def check_lidar_drives(a: argparse.Namespace) -> dict:
    """Option checks of the ``DRIVE_DIR`` form before any work; the ``--log`` files by drive name."""
    from imu_ground.evaluation.lidar_kitti import check_sync_folder
    _check_common(a)
    f = first_given(("--times", a.times), ("--lidar-planes", a.lidar_planes))
    if f:
        raise OptionError(f"{a.lidar[0]}: {f} goes with --lidar LOG SCANS; a KITTI raw DRIVE_DIR has its scans' "
                          "times (velodyne_points/timestamps.txt, else the OXTS stamps)", "lidar")
    for d in a.lidar:
        check_sync_folder(d)
        _drive_checked(d, a.lidar_extrinsic)
    if len(set(map(str, map(Path, a.lidar)))) != len(a.lidar):
        raise OptionError("{opt}: a DRIVE_DIR given twice (its scans would count twice in the pooled spreads)",
                          "lidar")
    _region_arg(a)
    if a.lidar_fit == "patchwork":
        from imu_ground.errors import require_extra
        from imu_ground.evaluation.lidar import PATCHWORK_MODULE
        require_extra(PATCHWORK_MODULE, "lidar", "Patchwork++ ground points (--lidar-fit patchwork)")
    if a.json and Path(a.json).is_dir():
        raise OptionError(f"{a.json}: is a folder; give {{opt}} a file name, e.g. {Path(a.json) / 'lidar.json'}",
                          "json")
    _check_outputs(a, [*a.lidar, *(a.log or [])],
                   [*(("--lidar DRIVE_DIR", d) for d in a.lidar), *(("--log", f) for f in a.log or [])],
                   (("--json", a.json),))
    return _pair_logs(a.lidar, a.log)


def run_lidar_drives(a: argparse.Namespace) -> int:
    """``--lidar DRIVE_DIR ...``: per drive and pooled tables, the ranking across fits; JSON, CSV, plots."""
    from imu_ground.evaluation.runner import format_table, methods_from_list
    logs = check_lidar_drives(a)
    methods = methods_from_list(a.methods)
    region = _region_arg(a)
    min_speed = MIN_SPEED if a.lidar_min_speed is None else a.lidar_min_speed
    _, why = _ground(a.lidar_fit)
    if why:
        say(why[2:])
    report, frames = lidar_drives_report(
        a.lidar, logs, methods, a.lidar_fit, region, a.extrinsic, a.lidar_extrinsic, min_speed, a.lidar_scans,
        a.lidar_seed, on_note=lambda drive, text: warn_line(text, drive))
    markdown = []
    for fit, block in report["fits"].items():
        for d in block["drives"]:
            say(f"\n{d['drive']} [{fit}, region {'the driven path' if fit.endswith('path') else region}]: "
                f"{Path(d['input']).name}, {d['scans']} of {d['scans_total']} scans, times from {d['times']}; deg, "
                "estimate minus LiDAR")
            table = _table(d["methods"])
            say(format_table(table, "text"))
            say(f"fit's own repeatability (frame to frame): pitch {d['fit_noise_pitch_deg']:.3f}, roll "
                f"{d['fit_noise_roll_deg']:.3f} deg")
            markdown.append(f"{d['drive']} ({fit}, {d['scans']} scans):\n\n" + format_table(table, "markdown"))
        pooled = _table(block["pooled"]["methods"])
        markdown.append(f"pooled ({fit}):\n\n" + format_table(pooled, "markdown"))
        if len(block["drives"]) > 1:
            say(f"\npooled over {block['pooled']['drives']} drives [{fit}] ({block['pooled']['scans']} scans; each "
                "drive's offset removed):")
            say(format_table(pooled, "text"))
    say(f"\n({DEFAULT_ROW}: what 'imu-ground estimate' runs with its defaults on the log; pitch_spread, roll_spread: "
        "standard deviation of estimate minus LiDAR, each method's offset removed, lo95..hi95 their moving-block "
        "bootstrap interval; angle_mean: the angle between the normals, angle_centred: with both centred; p_best: "
        "share of the draws in which the method's pitch spread ranks first)")
    if len(report["fits"]) > 1:
        say("\nranking across the fits (" + ", ".join(report["fits"]) + "):")
        for key, entry in report["ranking"].items():
            parts = []
            for what in ("pitch", "roll"):
                e = entry[what]
                three = next(iter({tuple(m for m in o if m in (DEFAULT_ROW, *reference_methods()))
                                   for o in e["order"].values()}))
                parts.append(f"{what} {' < '.join(three) if e['holds_default_paper_naive'] else 'order differs'}"
                             f" ({'same' if e['holds'] else 'not the same'} order of all methods)")
            say(f"  {key}: " + "; ".join(parts))
    if a.json:
        plain = json.loads(json.dumps(report), parse_constant=lambda _: None)     # NaN: null (standard JSON)
        write_said(a.json, json.dumps(plain, indent=1, allow_nan=False) + "\n")
    if a.csv:
        write_said(a.csv, frames.to_csv(index=False, float_format="%.5f"))
    if a.markdown:
        write_said(a.markdown, "\n\n".join(markdown) + "\n")
    if a.plot:
        first = report["fit"]
        drives = list(dict.fromkeys(frames["drive"]))
        for drive in drives:
            out = Path(a.plot) if len(drives) == 1 else Path(a.plot).with_name(f"{Path(a.plot).stem}_{drive}.png")
            _plot(out, frames[(frames["drive"] == drive) & (frames["fit"] == first)], f"{drive} [{first}]")
    return 0
