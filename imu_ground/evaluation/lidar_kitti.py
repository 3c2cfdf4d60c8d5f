r"""KITTI raw sync folders as LiDAR ground truth: the scans, their times, the driven path, per-drive summaries.

A sync folder (:func:`read_kitti_lidar_drive`) holds ``oxts/`` (the 10 Hz OXTS log and
the track), ``velodyne_points/data/*.bin`` (the scans, named by frame number) and
``velodyne_points/timestamps.txt`` (else the OXTS stamps, said in
:attr:`KittiLidarDrive.times_source`); ``calib_imu_to_velo.txt`` in the parent folder.

Clocks (:func:`log_clock`, :func:`scan_times_on_log`)
    With absolute stamps (``t0_ns``) a scan is at ``(stamp - t0_ns) * 1e-9`` s; on a
    ``kitti_imu100`` CSV at its stamp's seconds of the day minus ``t0_seconds_of_day``
    of the ``drives.csv`` beside it.

Driven path (:func:`drive_path_regions`)
    OXTS latitude and longitude on KITTI's Mercator projection (the devkit's), altitude
    up, ``R_{w<-imu} = R_z(yaw) R_y(pitch) R_x(roll)``; each scan's future track in the
    LiDAR's axes: :class:`~imu_ground.evaluation.lidar.PathRegion`.

Summaries (:func:`drive_summary`, :func:`pooled_summary`)
    Per method, deg, estimate minus LiDAR: pitch and roll spreads (sample std, offset
    removed) with moving-block bootstrap intervals, the angles, the offsets; pooled, each
    drive centred on its own mean. :func:`fit_noise`: the fit's own frame-to-frame noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from imu_ground.errors import OptionError
from imu_ground.evaluation.lidar import (PathRegion, bootstrap_spread, lidar_summary, method_summaries, path_region,
                                         scan_files)
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.so3 import rotx, roty, rotz

__all__ = ["EARTH_RADIUS_M", "KittiLidarDrive", "check_sync_folder", "drive_path_regions", "drive_summary", "find_lidar_drives",
           "fit_noise", "is_kitti_sync_folder", "log_clock", "oxts_track", "pooled_summary",
           "read_kitti_lidar_drive", "scan_times_on_log"]

#: KITTI devkit's earth radius for the Mercator projection, m.
EARTH_RADIUS_M = 6378137.0
#: :func:`drive_summary`'s keys from :func:`~imu_ground.evaluation.lidar.method_summaries`' columns.
_FROM_SUMMARY = {"pitch_spread": "pitch_spread_deg", "roll_change_spread": "roll_spread_deg",
                 "angle_mean": "angle_mean_deg", "angle_centred": "angle_centred_deg",
                 "pitch_offset": "pitch_offset_deg", "roll_offset": "roll_offset_deg", "lo95": "pitch_spread_lo95",
                 "hi95": "pitch_spread_hi95", "p_best": "p_best_pitch"}


@dataclass
class KittiLidarDrive:
    """One KITTI raw sync folder's scans and their times.

    Attributes
    ----------
    name : str
        The drive (the folder's name without ``_sync``).
    folder : Path
    files : list of Path
        The scans, in name order; ``frames`` (int (S,)) their sync frame numbers.
    stamps_ns, oxts_ns : ndarray of int64
        Each scan's and each OXTS packet's time, ns since 1970 of KITTI's written (local) clock.
    times_source : str
    calibration : Path or None
        The folder holding ``calib_imu_to_velo.txt``.
    """
    name: str
    folder: Path
    files: list
    frames: np.ndarray
    stamps_ns: np.ndarray
    times_source: str
    calibration: Path | None
    oxts_ns: np.ndarray = field(repr=False)


def is_kitti_sync_folder(path: str | Path) -> bool:
    """Whether ``path`` is a KITTI raw drive folder with ``oxts/`` and ``velodyne_points/``."""
    p = Path(path)
    return p.is_dir() and (p / "oxts").is_dir() and (p / "velodyne_points").is_dir()


def check_sync_folder(path: str | Path) -> Path:
    """``path`` as a KITTI raw sync folder, or an :class:`OptionError` naming what is missing and ``--lidar``."""
    d = Path(path)
    if not d.is_dir():
        raise OptionError(f"{d}: {'is a file' if d.exists() else 'no such folder'} ({{opt}} DRIVE_DIR: a KITTI raw "
                          "sync folder with oxts/ and velodyne_points/)", "lidar")
    for sub in ("oxts", "velodyne_points"):
        if not (d / sub).is_dir():
            raise OptionError(f"{d}: no {sub}/ folder; give {{opt}} DRIVE_DIR a KITTI raw sync folder (oxts/, "
                              "velodyne_points/data/*.bin), or --lidar LOG SCANS --times FILE", "lidar")
    return d


def find_lidar_drives(root: str | Path) -> list[Path]:
    """The KITTI raw sync folders under ``root`` (any depth) that have ``velodyne_points`` and ``oxts``, by name."""
    return sorted({p.parent for p in Path(root).rglob("velodyne_points") if is_kitti_sync_folder(p.parent)})


def _read_stamps(path: Path, flag: str) -> np.ndarray:
    from imu_ground.datasets.kitti_oxts import read_oxts_timestamps
    from imu_ground.errors import ImuGroundError
    try:
        return read_oxts_timestamps(path).astype(np.int64)
    except (ImuGroundError, FileNotFoundError, ValueError) as e:
        raise OptionError(f"{' '.join(str(e).split())} ({{opt}} DRIVE_DIR: a KITTI raw sync folder)", flag) from None


def read_kitti_lidar_drive(folder: str | Path) -> KittiLidarDrive:
    """Read a KITTI raw sync folder's scans and their times (see the module's docstring).

    Raises
    ------
    OptionError
        Not a sync folder, no scans, scans not named by frame numbers, or fewer stamps than frames.
    """
    d = check_sync_folder(folder)
    files = scan_files(d / "velodyne_points" / "data")
    bad = [f for f in files if not f.stem.isdigit()]
    if bad:
        raise OptionError(f"{bad[0]}: a KITTI raw scan is named by its frame number (0000000000.bin ...) ({{opt}})",
                          "lidar")
    frames = np.array([int(f.stem) for f in files], dtype=np.int64)
    oxts_ns = _read_stamps(d / "oxts" / "timestamps.txt", "lidar")
    velo = d / "velodyne_points" / "timestamps.txt"
    if velo.is_file():
        stamps, source = _read_stamps(velo, "lidar"), f"the Velodyne's stamps ({velo.relative_to(d.parent)})"
    else:
        stamps, source = oxts_ns, ("the OXTS stamps of the same frames (no velodyne_points/timestamps.txt; about "
                                   "0.015 s from the scans')")
    if frames.max() >= len(stamps):
        raise OptionError(f"{d}: scan {files[int(np.argmax(frames))].name} has no stamp ({len(stamps)} in "
                          f"{'velodyne_points' if velo.is_file() else 'oxts'}/timestamps.txt) ({{opt}})", "lidar")
    calib = d.parent if (d.parent / "calib_imu_to_velo.txt").is_file() else None
    name = d.name[:-5] if d.name.endswith("_sync") else d.name
    return KittiLidarDrive(name, d, files, frames, stamps[frames], source, calib, oxts_ns)


def log_clock(path: str | Path, t0_ns: int | None = None) -> tuple[str, int | float]:
    """Where a log's clock starts: ``("epoch_ns", t0_ns)`` (an int, exact) or ``("day_s", seconds of the day)``.

    Parameters
    ----------
    path : str or Path
        The log (a KITTI OXTS folder, a ``kitti_imu100`` CSV, ...).
    t0_ns : int, optional
        The first stamp its reader gave (``meta["t0_ns"]``), ns.

    Raises
    ------
    OptionError
        A log whose start on the stamps' clock is unknown (naming ``--log``).
    """
    if t0_ns is not None:
        return "epoch_ns", int(t0_ns)
    p = Path(path)
    from imu_ground.datasets.kitti_imu100 import drive_name, read_drives_index
    index = p.parent / "drives.csv"
    if index.is_file():
        drives = read_drives_index(index)
        name = drive_name(p)
        if name in drives.index:
            return "day_s", float(drives["t0_seconds_of_day"].loc[name])
    raise OptionError(f"{p}: the log's start on the scans' clock is unknown (no absolute stamps, and no drives.csv "
                      "beside it listing the drive's t0_seconds_of_day); give {opt} a kitti_imu100 CSV of the drive "
                      "with its drives.csv, or leave it out to read the folder's oxts/", "log")


def scan_times_on_log(drive: KittiLidarDrive, clock: tuple[str, float]) -> np.ndarray:
    """The scans' times on a log's clock (:func:`log_clock`), s."""
    kind, start = clock
    if kind == "epoch_ns":
        return (drive.stamps_ns - np.int64(int(start))).astype(float) * 1e-9      # integer ns first: exact
    day = np.int64(86_400 * 10**9)
    return (drive.stamps_ns % day).astype(float) * 1e-9 - start


def oxts_track(drive: KittiLidarDrive) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The vehicle's track from the folder's OXTS packets, on the OXTS clock (s from the first stamp).

    Returns
    -------
    t, positions, rotations : ndarray (N,), (N, 3), (N, 3, 3)
        s from the first stamp; the IMU's east, north (Mercator at the first latitude) and up, m from the
        first packet; world (ENU) <- IMU (FLU), ``R_z(yaw) R_y(pitch) R_x(roll)``.
    """
    from imu_ground.datasets.kitti_oxts import read_kitti_oxts
    imu = read_kitti_oxts(drive.folder, validate=False)
    x = imu.extra
    lat, lon = np.radians(x["lat"].to_numpy()), np.radians(x["lon"].to_numpy())
    scale = math.cos(lat[0])
    east = scale * EARTH_RADIUS_M * lon
    north = scale * EARTH_RADIUS_M * np.log(np.tan(math.pi / 4 + lat / 2))
    pos = np.column_stack([east - east[0], north - north[0], x["alt"].to_numpy() - x["alt"].to_numpy()[0]])
    rot = rotz(x["yaw"].to_numpy()) @ roty(x["pitch"].to_numpy()) @ rotx(x["roll"].to_numpy())
    return np.asarray(imu.t, dtype=float), pos, rot


def drive_path_regions(drive: KittiLidarDrive, lidar_from_imu: Extrinsic, half_width: float = 1.5,
                       ahead: tuple[float, float] = (3.0, 32.0)) -> list[PathRegion]:
    """Each scan's driven-path region (:func:`~imu_ground.evaluation.lidar.path_region`) from the folder's OXTS.

    Parameters
    ----------
    drive : KittiLidarDrive
    lidar_from_imu : Extrinsic
        LiDAR <- IMU (``calib_imu_to_velo.txt``: ``x_velo = R x_imu + T``).
    half_width, ahead
        As :class:`~imu_ground.evaluation.lidar.PathRegion`.
    """
    t, pos, rot = oxts_track(drive)
    t_scan = (drive.stamps_ns - drive.oxts_ns[0]).astype(float) * 1e-9
    return [path_region(ts, t, pos, rot, lidar_from_imu, half_width, ahead) for ts in t_scan]


def fit_noise(lidar_pitch_deg: Any, lidar_roll_deg: Any) -> dict[str, float]:
    """The fit's frame-to-frame noise, deg: std of the second difference / sqrt(6) (white noise of std s gives s;
    NaN with fewer than 4 scans)."""
    out = {}
    for key, v in (("fit_noise_pitch_deg", lidar_pitch_deg), ("fit_noise_roll_deg", lidar_roll_deg)):
        v = np.asarray(v, dtype=float)
        out[key] = float(np.std(np.diff(v, 2), ddof=1) / math.sqrt(6.0)) if len(v) >= 4 else float("nan")
    return out


def _bootstrap(diffs: dict[str, np.ndarray], prefix: str, rows: dict[str, dict]) -> None:
    if len(next(iter(diffs.values()))) < 3:
        return
    b = bootstrap_spread(diffs)
    for name, r in b.iterrows():
        rows[str(name)].update({f"{prefix}_spread_lo95": float(r["lo95"]), f"{prefix}_spread_hi95": float(r["hi95"]),
                                f"p_best_{prefix}": float(r["p_best"])})


def drive_summary(frames: pd.DataFrame) -> dict[str, dict[str, float]]:
    """Per method, one drive's spreads against the LiDAR (deg; see the module's docstring).

    Parameters
    ----------
    frames : pandas.DataFrame
        :func:`~imu_ground.evaluation.lidar.lidar_table`'s frames.

    Returns
    -------
    dict of str to dict
        Method -> ``scans``, ``pitch_spread_deg`` and ``roll_spread_deg`` (with ``_lo95`` / ``_hi95``
        and ``p_best_pitch`` / ``p_best_roll`` from 3 scans), ``angle_mean_deg``, ``angle_centred_deg``,
        ``pitch_offset_deg``, ``roll_offset_deg``.
    """
    rows = {str(k): {"scans": int(r["n"]), **{new: float(r[old]) for old, new in _FROM_SUMMARY.items() if old in r}}
            for k, r in method_summaries(frames).iterrows()}
    _bootstrap({str(k): g["d_roll_deg"].to_numpy() for k, g in frames.groupby("method", sort=False)}, "roll", rows)
    return rows


def pooled_summary(per_drive: list[pd.DataFrame]) -> dict[str, dict[str, float]]:
    """Per method, the spreads pooled over drives, each drive's differences centred on its own mean (deg).

    Spread ``sqrt(sum of squared centred differences / (scans - drives))``, bootstrapped over the
    concatenated centred differences; the angles are scan-weighted means of the drives'.
    """
    parts: dict[str, list[pd.DataFrame]] = {}
    rows: dict[str, dict] = {}
    count = {}
    for frames in per_drive:
        for name, g in frames.groupby("method", sort=False):
            parts.setdefault(str(name), []).append(g)
    for name, groups in parts.items():
        n = sum(len(g) for g in groups)
        dof = n - len(groups)
        row: dict[str, Any] = {"scans": n, "drives": len(groups)}
        for what in ("pitch", "roll"):
            c = np.concatenate([g[f"d_{what}_deg"].to_numpy() - g[f"d_{what}_deg"].mean() for g in groups])
            row[f"{what}_spread_deg"] = float(np.sqrt(np.sum(c ** 2) / dof)) if dof > 0 else float("nan")
            count[(name, what)] = c
        row["angle_mean_deg"] = float(np.mean(np.concatenate([g["angle_deg"].to_numpy() for g in groups])))
        row["angle_centred_deg"] = float(np.average([lidar_summary(g)["angle_centred"] for g in groups],
                                                    weights=[len(g) for g in groups]))
        rows[name] = row
    if rows and len({r["scans"] for r in rows.values()}) == 1:
        for what in ("pitch", "roll"):
            _bootstrap({k: count[(k, what)] for k in rows}, what, rows)
    return rows
