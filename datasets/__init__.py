"""Readers of IMU logs; each returns an :class:`~imu_ground.imu.data.ImuData`.

=================  ===========================================  ===================
format             what                                         reader
=================  ===========================================  ===================
``kitti_oxts``     KITTI raw drive / ``oxts`` folder (10, 100   :func:`read_kitti_oxts`
                   Hz)
``kitti_imu100``   KITTI 100 Hz CSV(.gz) ``t,wx,...,pz``         :func:`read_kitti_imu100`
``table``          any CSV(.gz) / DataFrame with a column map   :func:`read_table`
``nuscenes``       nuScenes CAN bus ``*_ms_imu.json``           :func:`read_nuscenes_imu`
``comma2k19``      comma2k19 segment folder                     :func:`read_comma2k19`
=================  ===========================================  ===================

:func:`read_imu` picks the reader from the path (:func:`detect_format`).
Every reader validates its output by default (``validate=True``,
``policy="drop"``; see :func:`imu_ground.datasets.validation.validate`) and stores the
report in ``meta["validation"]``.
"""
from __future__ import annotations

import gzip
from pathlib import Path
from typing import Any, Callable

import pandas as pd

from imu_ground.imu.data import ImuData

from .comma2k19 import read_comma2k19
from .kitti_imu100 import COLUMNS as KITTI_IMU100_COLUMNS
from .kitti_imu100 import read_drives_index, read_kitti_imu100
from .kitti_oxts import read_kitti_oxts
from .nuscenes import read_nuscenes_imu
from .poses import PoseSequence, read_kitti_poses, read_poses, read_tum_poses, relative_rotations, write_tum_poses
from .table import from_dataframe, read_table

__all__ = [
    "FORMATS",
    "UnknownFormatError",
    "detect_format",
    "read_imu",
    "read_kitti_oxts",
    "read_kitti_imu100",
    "read_drives_index",
    "read_table",
    "from_dataframe",
    "read_nuscenes_imu",
    "read_comma2k19",
    "PoseSequence",
    "read_poses",
    "read_kitti_poses",
    "read_tum_poses",
    "relative_rotations",
    "write_tum_poses",
]

#: Format name to reader.
FORMATS: dict[str, Callable[..., ImuData]] = {
    "kitti_oxts": read_kitti_oxts,
    "kitti_imu100": read_kitti_imu100,
    "table": read_table,
    "nuscenes": read_nuscenes_imu,
    "comma2k19": read_comma2k19,
}
_ALIASES = {"csv": "table", "oxts": "kitti_oxts", "kitti": "kitti_oxts", "nuscenes_can_bus": "nuscenes",
            "ms_imu": "nuscenes", "comma": "comma2k19"}
_TABLE_SUFFIXES = (".csv", ".csv.gz", ".txt", ".tsv", ".csv.bz2")


class UnknownFormatError(ValueError):
    """:func:`detect_format` cannot tell which reader a path needs."""


def _header(path: Path) -> list[str]:
    opener = gzip.open if path.name.endswith(".gz") else open
    try:
        with opener(path, "rt", encoding="utf-8") as f:  # type: ignore[operator]
            line = f.readline()
    except (OSError, EOFError, UnicodeDecodeError):
        return []
    return [c.strip() for c in line.strip().split(",")]


def detect_format(path: str | Path | pd.DataFrame) -> str:
    """Name of the format of ``path`` (a key of :data:`FORMATS`).

    Parameters
    ----------
    path : str, Path or pandas.DataFrame
        A folder (KITTI drive or ``oxts`` folder, comma2k19 segment, folder with
        one ``*_ms_imu.json``), a file (``*_ms_imu.json``; ``.csv``/``.csv.gz``:
        ``kitti_imu100`` when the header is exactly its columns, else ``table``),
        or a DataFrame (``table``).

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    UnknownFormatError
        Nothing recognised; the message names the path and what was looked for.
    """
    if isinstance(path, pd.DataFrame):
        return "table"
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if p.is_dir():
        if (p / "oxts" / "timestamps.txt").is_file() or (
                (p / "timestamps.txt").is_file() and (p / "data").is_dir()):
            return "kitti_oxts"
        if ((p / "processed_log" / "IMU").is_dir() or (p / "IMU" / "gyro").is_dir()
                or ((p / "gyro").is_dir() and (p / "accelerometer").is_dir())):
            return "comma2k19"
        if any(p.glob("*_ms_imu.json")):
            return "nuscenes"
        raise UnknownFormatError(
            f"{p}: cannot tell the IMU log format of this folder: no oxts/timestamps.txt (KITTI), "
            f"processed_log/IMU (comma2k19) or *_ms_imu.json (nuScenes)")
    name = p.name.lower()
    if name.endswith(".json"):
        if "ms_imu" in name:
            return "nuscenes"
        raise UnknownFormatError(f"{p}: a JSON file but not a nuScenes *_ms_imu.json")
    if name.endswith(_TABLE_SUFFIXES):
        return "kitti_imu100" if _header(p) == list(KITTI_IMU100_COLUMNS) else "table"
    raise UnknownFormatError(
        f"{p}: cannot tell the IMU log format from this file name; supported: a KITTI drive or "
        f"oxts folder, *.csv / *.csv.gz, *_ms_imu.json, a comma2k19 segment folder "
        f"(or pass format= one of {sorted(FORMATS)})")


def read_imu(path: str | Path | pd.DataFrame, format: str | None = None, **kw: Any) -> ImuData:
    """Read an IMU log of any supported format.

    Parameters
    ----------
    path : str, Path or pandas.DataFrame
        File or folder (see :func:`detect_format`), or a DataFrame.
    format : str, optional
        One of :data:`FORMATS` (``"kitti_oxts"``, ``"kitti_imu100"``, ``"table"``,
        ``"nuscenes"``, ``"comma2k19"``; ``"csv"`` means ``"table"``); detected
        from ``path`` when omitted.
    **kw
        Passed to the reader (e.g. the column map and units of
        :func:`read_table`, ``validate``, ``policy``, ``nonfinite``).

    Returns
    -------
    ImuData
        ``t`` s, ``gyro`` rad/s, ``accel`` m/s^2 (specific force) in the frame
        named by ``frame``; see the individual readers.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    UnknownFormatError
        The format cannot be detected, or ``format`` is not known.
    """
    fmt = detect_format(path) if format is None else _ALIASES.get(format, format)
    if fmt not in FORMATS:
        raise UnknownFormatError(f"unknown format {format!r} for {path}; "
                                 f"known: {sorted(FORMATS)} (aliases {sorted(_ALIASES)})")
    kw["_depth"] = int(kw.get("_depth", 1)) + 1
    return FORMATS[fmt](path, **kw)
