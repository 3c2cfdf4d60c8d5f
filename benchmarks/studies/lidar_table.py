"""LiDAR ground truth (the paper's protocol) on the shared KITTI scans: every method, and the fit's repeatability.

    python benchmarks/studies/lidar_table.py       # prints the tables; make_results.py puts them in RESULTS.md

``table = LiDAR drives``: what ``imu-ground evaluate --lidar DRIVE_DIR ... --lidar-fit all`` measures
(:func:`imu_ground.cli._lidar.lidar_drives_report`, the product's own code), on every KITTI raw sync folder
under ``kitti_raw`` that has ``velodyne_points`` and ``oxts`` (found from the folders; one that cannot be
compared, e.g. a single scan, is a row saying why), each read from its own 10 Hz ``oxts/`` and, where
``kitti_imu100`` has the same drive, also from that 100 Hz CSV (``--log``, same scans); per fit (RANSAC or
Patchwork++ ground points, in the straight box or along the driven path), each method's pitch and roll
spreads (deg, ``pitch / roll``: standard deviation of estimate minus LiDAR, each method's offset removed;
``default`` is ``estimate``'s default on that input), the fit's frame-to-frame noise, and rows pooled over
the 10 Hz drives (each drive's offset removed). ``table = LiDAR ranking``: per drive, input and pooled, the
order of ``naive``, ``paper`` and ``default`` by pitch and by roll spread under each fit, and whether the
order of every method is the same under all fits.

Drive 2011_09_26_drive_0009, its first 31 Velodyne scans (``kitti_raw/.../velodyne_points``), times
from ``frames_estimated_times.txt`` (on the IMU log's clock, +-0.05 s): the road plane of each scan
(:func:`imu_ground.evaluation.fit_ground_plane`, default region and seed) turned into the body's pitch and
roll relative to the road with ``calib_imu_to_velo.txt``, against each method of ``evaluate --real`` and
the ``estimate`` command's default (suspension filter with the INS speed) run on the whole log, and the
INS reference (pitch + 10 m grade, as ``evaluate --real`` uses it). Rows ``table = drive 0009``: what
``imu-ground evaluate --lidar`` prints, the pitch spread with its moving-block bootstrap interval
(blocks of 5 frames, 2000 draws), ``p_best``, the share of the draws in which the method ranks first among
the methods (the INS reference is not ranked), and ``vs_best``, the interval of its spread minus the best
method's in the same draws (a method is behind only where that interval excludes 0).

``table = object frames``: the four KITTI object-benchmark frames on shared drives
(``kitti_object_samples``, their own calibration files). The fit against the AVOD planes (pitch and roll,
deg) and, per method, the pitch difference estimate minus LiDAR with drive 0009's offset (the same car
and calibration day) removed: an absolute check on frames the offset was not taken from. The frames'
times on the IMU clock are not published: they are taken as ``0.35 + 0.1036 k`` s for sync frame ``k``
(drive 0009's fit); ``far_fit_minus_avod_pitch_deg``: the fit in x 10..40 m instead (a road whose slope
changes ahead is not one plane: AVOD's follow the farther road); ``timing_deg`` is how much the default estimate's pitch moves over +-0.3 s of that.

``table = fit repeatability``: on drive 0009, the fit's pitch and roll over RANSAC seeds 0-9 (mean over
scans of the standard deviation across seeds), the frame-to-frame noise (standard deviation of the second
difference / sqrt(6), which removes what moves linearly over 0.2 s), the mean pitch and roll of the planes
and the default estimate's pitch spread against them, per road region and inlier threshold.
"""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from imu_ground.evaluation import lidar as L
from imu_ground.evaluation.drives import load_real_drive
from imu_ground.evaluation.runner import METHODS
from imu_ground.pipeline.estimate import estimate_log
from imu_ground.perception.kitti_calib import read_kitti_calib
from imu_ground.pipeline.planes import read_kitti_planes

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
DAY = DATA / "kitti_raw" / "2011_09_26"
SYNC = DAY / "2011_09_26_drive_0009_sync"
LOG = DATA / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
OBJECTS = DATA / "kitti_object_samples"
#: Sync frame k on the IMU log's clock (drive 0009's ICP-against-INS fit, ../shared/data/README.md).
FRAME_T0, FRAME_DT = 0.35, 0.1036
#: A farther region for the object frames (AVOD's planes follow the road farther ahead).
FAR = L.RoadRegion(10, 40, -4, 4)
#: Regions and thresholds of the repeatability rows.
VARIANTS = {"default (x 5..30, |y| < 4, 0.10 m)": (L.ROAD_REGION, 0.10),
            "|y| < 6 (the issue's box)": (L.RoadRegion(5, 30, -6, 6), 0.10),
            "x 5..20": (L.RoadRegion(5, 20, -4, 4), 0.10),
            "x 10..40": (L.RoadRegion(10, 40, -4, 4), 0.10),
            "threshold 0.05 m": (L.ROAD_REGION, 0.05),
            "threshold 0.20 m": (L.ROAD_REGION, 0.20)}
DEG = 180.0 / math.pi


def _estimates(log: Path) -> tuple[dict, object]:
    """Every method's ``(t, pitch, roll, valid)`` on a log, the CLI default first; and the real drive."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = estimate_log(log)
        drive = load_real_drive(log)
        out = {f"estimate ({res.meta['method']}, speed)": (res.track.t, res.track.pitch, res.track.roll,
                                                           res.track.valid)}
        for name, m in METHODS.items():
            tr = m.factory(extrinsic=drive.extrinsic).run(res.egomotion, smooth=m.smooth)
            out[name] = (tr.t, tr.pitch, tr.roll, tr.valid)
    return out, drive


def _fit(files, region=L.ROAD_REGION, threshold=0.1, seed=0, rotation=None):
    fits = L.fit_scans(files, region, seed=seed, threshold=threshold)
    rot = L.lidar_rotation(DAY) if rotation is None else rotation
    return L.lidar_pitch_roll(fits[["normal_x", "normal_y", "normal_z"]].to_numpy(), rot)


def drive_rows() -> tuple[list[dict], dict]:
    """The drive 0009 table, and each method's pitch offset (deg) there."""
    files = L.scan_files(SYNC / "velodyne_points" / "data")
    t_scan = L.read_scan_times(SYNC / "frames_estimated_times.txt", len(files))
    lp, lr = _fit(files)
    estimates, drive = _estimates(LOG)
    ins = drive.truth
    _, summary = L.lidar_table(estimates, t_scan, lp, lr, source=str(LOG))
    _, ref = L.lidar_table({"INS pitch + grade (reference)": (ins["t"].to_numpy(), ins["pitch"].to_numpy(),
                                                              np.zeros(len(ins)), ins["speed"].to_numpy() > 3.0)},
                           t_scan, lp, lr, source=str(LOG))
    rows = []
    for name, s in pd.concat([summary, ref]).iterrows():
        is_ref = name.startswith("INS")
        row = {"table": "drive 0009", "method": name, "scans": int(s["n"])}
        if not is_ref:
            row.update(angle_deg=s["angle_mean"], angle_centred_deg=s["angle_centred"])
        row.update(pitch_offset_deg=s["pitch_offset"], pitch_spread_deg=s["pitch_spread"], spread_lo95=s["lo95"],
                   spread_hi95=s["hi95"])
        if not is_ref:
            row.update(p_best=s["p_best"], vs_best_lo95=s["vs_best_lo95"], vs_best_hi95=s["vs_best_hi95"],
                       roll_change_spread_deg=s["roll_change_spread"], roll_change_corr=s["roll_change_corr"])
        rows.append(row)
    return rows, summary["pitch_offset"].to_dict()


def object_rows(offsets: dict) -> list[dict]:
    """The object frames: the fit against AVOD, and each method's pitch against the fit (0009's offset removed)."""
    mapping = pd.read_csv(OBJECTS / "mapping.csv", dtype={"object_index": str})
    rows = []
    for _, m in mapping.iterrows():
        idx, drive, k = m["object_index"], m["raw_drive"], int(m["raw_sync_frame"])
        calib = OBJECTS / "training" / "calib" / f"{idx}.txt"
        r_cam = L.kitti_object_rotation(calib)
        tr_iv = read_kitti_calib(calib)["Tr_imu_to_velo"].reshape(3, 4)[:, :3]
        u, _, vt = np.linalg.svd(tr_iv)
        r_velo = (u @ vt).T                                   # ground (= IMU axes) <- Velodyne
        normal, _, count = L.fit_ground_plane(L.read_bin_scan(OBJECTS / "training" / "velodyne" / f"{idx}.bin"),
                                              return_inliers=True)
        fp, fr = L.lidar_pitch_roll(normal, r_velo)
        ap, ar = L.planes_pitch_roll(read_kitti_planes(OBJECTS / "training" / "planes" / f"{idx}.txt"), r_cam)
        far_p, _ = L.lidar_pitch_roll(L.fit_ground_plane(L.read_bin_scan(OBJECTS / "training" / "velodyne"
                                                                          / f"{idx}.bin"), FAR)[0], r_velo)
        row = {"table": "object frames", "frame": idx, "drive": f"{drive} #{k}", "inliers": count,
               "fit_pitch_deg": float(fp) * DEG, "fit_minus_avod_pitch_deg": float(fp - ap[0]) * DEG,
               "fit_minus_avod_roll_deg": float(fr - ar[0]) * DEG,
               "far_fit_minus_avod_pitch_deg": float(far_p - ap[0]) * DEG}
        log = DATA / "kitti_imu100" / f"{drive}.csv.gz"
        if log.is_file():
            estimates, _ = _estimates(log)
            t = FRAME_T0 + FRAME_DT * k
            for name, (te, pe, re, ve) in estimates.items():
                f = L.compare_to_lidar([t], [float(fp)], [float(fr)], te, pe, re, ve, source=str(log))
                row[f"{name} pitch - offset"] = float(f["d_pitch_deg"].iloc[0]) - offsets.get(name, np.nan)
            te, pe = estimates[next(iter(estimates))][:2]
            near = pe[np.abs(te - t) <= 0.3] * DEG
            row["timing_deg"] = float(near.max() - near.min()) if near.size else np.nan
        rows.append(row)
    return rows


def repeatability_rows() -> list[dict]:
    """The fit's repeatability on drive 0009: seeds, frame to frame, regions and thresholds."""
    files = L.scan_files(SYNC / "velodyne_points" / "data")
    t_scan = L.read_scan_times(SYNC / "frames_estimated_times.txt", len(files))
    estimates, _ = _estimates(LOG)
    default = {k: v for k, v in list(estimates.items())[:1]}
    rows = []
    for label, (region, threshold) in VARIANTS.items():
        seeds = np.array([_fit(files, region, threshold, seed) for seed in range(10)])      # (10, 2, scans)
        lp, lr = seeds[0]
        second = lambda x: float(np.std(np.diff(x, 2), ddof=1) / math.sqrt(6.0)) * DEG   # noqa: E731
        _, summary = L.lidar_table(default, t_scan, lp, lr)
        rows.append({"table": "fit repeatability", "variant": label,
                     "seed_pitch_deg": float(seeds[:, 0].std(axis=0).mean()) * DEG,
                     "seed_roll_deg": float(seeds[:, 1].std(axis=0).mean()) * DEG,
                     "frame_pitch_deg": second(lp), "frame_roll_deg": second(lr),
                     "mean_pitch_deg": float(lp.mean()) * DEG, "mean_roll_deg": float(lr.mean()) * DEG,
                     "default_pitch_spread_deg": float(summary["pitch_spread"].iloc[0])})
    return rows


#: The methods whose spreads the LiDAR drives table shows first (the rest follow in the registry's order).
KEY_METHODS = ("naive", "paper", "default")


def _cell(pair: tuple[float, float]) -> str:
    if not any(np.isfinite(v) for v in pair):
        return ""
    return " / ".join("" if not np.isfinite(v) else f"{v:.3f}" for v in pair)


def _drive_row(d: dict, fit: str, label: str) -> dict:
    methods = d["methods"]
    names = [m for m in KEY_METHODS if m in methods] + [m for m in methods if m not in KEY_METHODS]
    row = {"table": "LiDAR drives", "drive": d["drive"].replace("2011_09_26_drive_", ""), "input": label,
           "fit": fit, "scans": d["scans"]}
    row.update({m: _cell((methods[m]["pitch_spread_deg"], methods[m]["roll_spread_deg"])) for m in names})
    row["fit_noise"] = _cell((d["fit_noise_pitch_deg"], d["fit_noise_roll_deg"]))
    return row


def _order(methods: dict, what: str) -> str:
    key = [m for m in sorted(methods, key=lambda m: methods[m][f"{what}_spread_deg"]) if m in KEY_METHODS]
    return " < ".join(key)


def lidar_drive_rows() -> list[dict]:
    """Every shared LiDAR drive (both inputs of a drive with a 100 Hz CSV), per fit, and pooled; the ranking."""
    from imu_ground.cli._lidar import lidar_drives_report
    from imu_ground.errors import ImuGroundError
    from imu_ground.evaluation import lidar_kitti as K
    folders = K.find_lidar_drives(DATA / "kitti_raw")
    out, ranking, pooled_frames = [], [], {}
    for folder in folders:
        name = folder.name[:-5] if folder.name.endswith("_sync") else folder.name
        csv = DATA / "kitti_imu100" / f"{name}.csv.gz"
        inputs = [("10 Hz oxts/", None)] + ([("100 Hz CSV (--log)", csv)] if csv.is_file() else [])
        for label, log in inputs:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    report, frames = lidar_drives_report([folder], {name: log} if log else None, fit="all")
            except ImuGroundError as e:
                out.append({"table": "LiDAR drives", "drive": name.replace("2011_09_26_drive_", ""), "input": label,
                            "fit": "skipped", "scans": len(L.scan_files(folder / "velodyne_points" / "data")),
                            "naive": "skipped: " + " ".join((e.cli_message() if hasattr(e, "cli_message")
                                                             else str(e)).split()).replace(str(DATA),
                                                                                           "../shared/data")})
                continue
            for fit, block in report["fits"].items():
                d = block["drives"][0]
                out.append(_drive_row(d, fit, label))
                if log is None:
                    pooled_frames.setdefault(fit, []).append(frames[frames["fit"] == fit])
            for fit, block in report["fits"].items():
                m = block["drives"][0]["methods"]
                ranking.append({"table": "LiDAR ranking", "drive": name.replace("2011_09_26_drive_", ""),
                                "input": label, "fit": fit, "pitch": _order(m, "pitch"), "roll": _order(m, "roll")})
            r = report["ranking"][name]
            ranking.append({"table": "LiDAR ranking", "drive": name.replace("2011_09_26_drive_", ""), "input": label,
                            "fit": "same order under every fit", "pitch": r["pitch"]["holds_default_paper_naive"],
                            "roll": r["roll"]["holds_default_paper_naive"], "all methods, pitch": r["pitch"]["holds"],
                            "all methods, roll": r["roll"]["holds"]})
    orders = {"pitch": set(), "roll": set()}
    for fit, parts in pooled_frames.items():
        if len(parts) < 2:
            continue
        methods = K.pooled_summary(parts)
        d = {"drive": f"pooled ({len(parts)} drives)", "scans": int(sum(len(p[p['method'] == 'default'])
                                                                        for p in parts)),
             "fit_noise_pitch_deg": float("nan"), "fit_noise_roll_deg": float("nan"), "methods": methods}
        out.append(_drive_row(d, fit, "10 Hz oxts/"))
        ranking.append({"table": "LiDAR ranking", "drive": d["drive"], "input": "10 Hz oxts/", "fit": fit,
                        "pitch": _order(methods, "pitch"), "roll": _order(methods, "roll")})
        for what in orders:
            orders[what].add(_order(methods, what))
    if orders["pitch"]:
        ranking.append({"table": "LiDAR ranking", "drive": "pooled", "input": "10 Hz oxts/",
                        "fit": "same order under every fit", "pitch": len(orders["pitch"]) == 1,
                        "roll": len(orders["roll"]) == 1})
    return out + ranking


def rows() -> list[dict]:
    """The tables of the module docstring (column ``table``)."""
    if not SYNC.is_dir():
        return [{"table": "drive 0009", "method": f"skipped: {SYNC} not found"}]
    drive, offsets = drive_rows()
    return lidar_drive_rows() + drive + object_rows(offsets) + repeatability_rows()


def main() -> None:
    for r in rows():
        print("; ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()))


if __name__ == "__main__":
    main()
