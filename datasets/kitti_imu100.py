"""KITTI raw 100 Hz OXTS logs ("extract" data) stored as one CSV per drive.

Each ``<drive>.csv`` or ``<drive>.csv.gz`` has the columns :data:`COLUMNS`: ``t`` (s since the drive's
first sample; ``drives.csv`` beside the files gives the start as seconds of the day and the sample count),
``wx,wy,wz`` (rad/s) and ``ax,ay,az`` (specific force, m/s^2) in FLU, and kept in ``extra`` ``roll,pitch,yaw``
(rad), ``ve,vn,vu`` (m/s, east/north/up), ``px,py,pz`` (m, east/north/up from the first sample). Other units
are told from the data as for CSV tables unless ``time_unit``, ``gyro_unit``, ``accel_unit`` say them. The
raw stamps jitter (about -0.05 s steps) at a steady 100 Hz, with real dropouts: ``"retime"`` fixes the first.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imu_ground.errors import ImuValidationWarning, MalformedFileError, warn_user
from imu_ground.imu.data import ImuData

from .csvio import numeric, open_binary, read_delimited
from .skeleton import finish, register_format, with_finish_parameters
from .unit_checks import UNIT_OPTIONS, check_units, detect_time_unit, motion_in_si, raw_times, settle_unit, unit_scale

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["COLUMNS", "EXTRA_UNITS", "drive_name", "read_drives_index", "read_kitti_imu100"]

#: Columns of a kitti_imu100 CSV, in order.
COLUMNS: tuple[str, ...] = ("t", "wx", "wy", "wz", "ax", "ay", "az", "roll", "pitch", "yaw",
                            "ve", "vn", "vu", "px", "py", "pz")
#: Columns read side by side into ImuData's (N, 3) arrays.
_STACKS = {"gyro": COLUMNS[1:4], "accel": COLUMNS[4:7]}
#: Units of the columns kept in ``ImuData.extra``.
EXTRA_UNITS: dict[str, str] = {"roll": "rad", "pitch": "rad", "yaw": "rad",
                               "ve": "m/s", "vn": "m/s", "vu": "m/s",
                               "px": "m", "py": "m", "pz": "m"}


def drive_name(path: str | Path) -> str:
    """Drive name of a kitti_imu100 file: ``.../2011_09_26_drive_0009.csv.gz`` -> ``2011_09_26_drive_0009``."""
    name = Path(path).name
    for suffix in (".csv.gz", ".csv"):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return Path(path).stem


def read_drives_index(path: str | Path) -> pd.DataFrame:
    """Read ``drives.csv`` (the file, or its folder): one row per drive, ``drive, t0_seconds_of_day, samples``.

    Returns
    -------
    pandas.DataFrame
        Indexed by drive name; ``t0_seconds_of_day`` in s (float), ``samples`` (int).

    Raises
    ------
    FileNotFoundError
        No such file.
    MalformedFileError
        Empty file, bad line, or missing columns.
    """
    p = Path(path)
    if p.is_dir():
        p = p / "drives.csv"
    import pandas as pd
    cols, lines = read_delimited(p)
    need = ["drive", "t0_seconds_of_day", "samples"]
    missing = [c for c in need if c not in cols]
    if missing:
        raise MalformedFileError(p, f"missing column(s) {missing}; header has {list(cols)}", line=1)
    return pd.DataFrame({"t0_seconds_of_day": numeric(cols[need[1]], need[1], p, lines),
                         "samples": numeric(cols[need[2]], need[2], p, lines).astype(int)},
                        index=pd.Index(cols["drive"].astype(str), name="drive"))


@with_finish_parameters
def read_kitti_imu100(path: str | Path, *, drives_csv: str | Path | bool | None = None,
                      time_unit: str | None = None, gyro_unit: str | None = None, accel_unit: str | None = None,
                      validate: bool = True, policy: str = "retime", **validate_kw: Any) -> ImuData:
    """Read one kitti_imu100 drive (100 Hz KITTI OXTS, CSV or CSV.gz).

    Parameters
    ----------
    path : str or Path
        The drive's ``.csv`` / ``.csv.gz`` file.
    drives_csv : str, Path, bool or None
        The ``drives.csv`` giving the drive's start; None (default): the one beside ``path`` if any; True:
        that one, required; False: ignored.
    time_unit : {"s", "ms", "us", "ns"}, optional
    gyro_unit : {"rad/s", "deg/s"}, optional
    accel_unit : {"m/s^2", "g"}, optional
        Units of ``t``, ``wx, wy, wz`` and ``ax, ay, az``; told from the data when omitted.
    {finish_parameters}

    Returns
    -------
    ImuData
        ``t`` s from the first sample, ``gyro`` rad/s and ``accel`` m/s^2 in ``"FLU"``; ``extra`` the other
        columns. ``meta``: ``format``, ``drive``, ``t0`` (seconds of the day when ``drives.csv`` lists the
        drive, else 0.0), ``t0_clock``, ``expected_samples``, ``source_units``, ``validation``.

    Raises
    ------
    FileNotFoundError
        ``path`` (or an explicitly given ``drives_csv``) does not exist.
    MalformedFileError
        Empty or truncated file, wrong columns, a line with the wrong field count or a non-number
        (naming the file and line).
    ImuInputError
        Unknown unit, or units the data cannot decide (naming the option).
    """
    import pandas as pd
    check_units(time_unit=time_unit, gyro_unit=gyro_unit, accel_unit=accel_unit)
    path = Path(path)
    cols, lines = read_delimited(path, stack=_STACKS)       # numbers straight into (N, 3) arrays
    names = [m for c in cols for m in _STACKS.get(c, (c,))]  # the header as in the file
    if names != list(COLUMNS):
        missing = [c for c in COLUMNS if c not in names]
        raise MalformedFileError(path, f"expected columns {','.join(COLUMNS)}, got {','.join(names)}"
                                       + (f" (missing {missing})" if missing else ""), line=1)
    tval = raw_times(cols.pop("t"), "t", str(path), lines)[0]
    gyro, accel = (cols.pop(k) if k in cols else np.column_stack([numeric(cols.pop(c), c, path, lines) for c in m])
                   for k, m in _STACKS.items())
    t_unit = settle_unit("time", time_unit, detect_time_unit, tval, str(path), "t")
    gyro, accel, g_unit, a_unit = motion_in_si(gyro, accel, gyro_unit, accel_unit, str(path))
    n = tval.size
    drive = drive_name(path)
    first = tval[0] if tval.dtype.kind == "i" or np.isfinite(tval[0]) else 0
    if t_unit == "s":                   # KITTI's own files (starting at 0: the parsed array, no copy)
        t = (tval if first == 0 and not np.signbit(first) else tval - first) if tval.dtype.kind == "f" \
            else (tval - first).astype(float)
    else:                               # shifted before scaling (exact for integer ns)
        t = (tval - first).astype(float) * unit_scale("time", t_unit)
    t_first = float(first) * unit_scale("time", t_unit)
    meta: dict[str, Any] = {"format": "kitti_imu100", "drive": drive, "t0": 0.0,
                            "t0_clock": "t of the file (no drives.csv entry)"}
    index_path: Path | None = None
    if isinstance(drives_csv, (str, Path)):
        index_path = Path(drives_csv)
        if not index_path.exists():
            raise FileNotFoundError(f"{index_path}: no such file")
    elif drives_csv is not False and (path.parent / "drives.csv").is_file():
        index_path = path.parent / "drives.csv"
    elif drives_csv is True:
        raise FileNotFoundError(f"{path.parent / 'drives.csv'}: no such file (drives_csv=True)")
    if index_path is not None:
        index = read_drives_index(index_path)
        meta["drives_csv"] = str(index_path)
        if drive in index.index:
            row = index.loc[drive]
            assert isinstance(row, pd.Series)   # drives.csv names each drive once
            meta["t0"] = float(row["t0_seconds_of_day"]) + t_first
            meta["t0_clock"] = "seconds of the day (drives.csv t0_seconds_of_day)"
            meta["expected_samples"] = int(row["samples"])
            if int(row["samples"]) != n:
                warn_user(f"{path}: {n} rows but {index_path} lists {int(row['samples'])} "
                          f"samples for {drive} (truncated or edited file?)", ImuValidationWarning)
        else:
            meta["notes"] = [f"{drive} not listed in {index_path}"]
    if t_first != 0.0:
        meta["t_offset_in_file"] = t_first
    meta["row_lines"] = lines
    meta["source_units"] = {"time": t_unit, "gyro": g_unit, "accel": a_unit}
    extra = pd.DataFrame({c: numeric(cols.pop(c), c, path, lines) for c in COLUMNS[7:]}, copy=False)
    imu = ImuData(t, gyro, accel, "FLU", extra, dict(EXTRA_UNITS), str(path), meta)
    return finish(imu, validate=validate, policy=policy, **validate_kw)


def _probe(path: Path) -> bool:
    """A ``.csv`` / ``.csv.gz`` file whose header is exactly :data:`COLUMNS`."""
    if not (path.is_file() and path.name.lower().endswith((".csv", ".csv.gz"))):
        return False
    try:
        with open_binary(path) as f:
            line = f.readline(4096).decode("utf-8")
    except (OSError, EOFError, UnicodeDecodeError, ValueError):
        return False
    return [c.strip() for c in line.strip().split(",")] == list(COLUMNS)


register_format("kitti_imu100", _probe, read_kitti_imu100, "KITTI 100 Hz CSV(.gz) with header t,wx,...,pz",
                priority=50, options=UNIT_OPTIONS)
