"""Generic IMU tables: CSV (optionally compressed), Parquet, or a pandas DataFrame with named columns.

The columns of time, angular rate and specific force are named (``columns``); units not given are told from
the data (:mod:`imu_ground.datasets.unit_checks`); the result is in s, rad/s, m/s^2, other columns in ``extra``.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imu_ground.errors import ImuInputError, MalformedFileError, require_extra
from imu_ground.imu.data import ImuData

from .csvio import Columns, numeric, read_delimited
from .skeleton import finish, register_format, with_finish_parameters
from .unit_checks import (ACCEL_UNITS, GYRO_UNITS, TIME_UNITS, UNIT_OPTIONS, check_units, detect_time_unit,
                          motion_in_si, raw_times, settle_unit, unit_scale)

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ACCEL_UNITS", "GYRO_UNITS", "PARQUET_SUFFIXES", "TABLE_SUFFIXES", "TIME_UNITS", "from_dataframe",
           "map_columns", "parse_columns", "read_parquet_table", "read_table", "unit_scale"]

#: File names read as delimited text tables.
TABLE_SUFFIXES = (".csv", ".csv.gz", ".txt", ".tsv", ".csv.bz2", ".txt.gz", ".tsv.gz")
#: File names read as Parquet tables.
PARQUET_SUFFIXES = (".parquet", ".pq")


#: The quantities a table needs: time, angular rate x y z, specific force x y z.
QUANTITIES = ("t", "wx", "wy", "wz", "ax", "ay", "az")


def parse_columns(columns: str | Mapping[str, str]) -> dict[str, Any]:
    """``columns`` (``"t=timestamp,wx=gyro_x,..."`` or a mapping; others keep their names) as keywords.

    Raises
    ------
    ImuInputError
        Not ``key=name`` pairs, or a key that is not one of :data:`QUANTITIES` (names ``columns``).
    """
    if isinstance(columns, str):
        pairs = [p.strip() for p in columns.split(",") if p.strip()]
        if not pairs or any(p.count("=") != 1 or not all(x.strip() for x in p.split("=")) for p in pairs):
            raise ImuInputError(f"columns {columns!r}: expected QUANTITY=COLUMN pairs separated by commas, e.g. "
                                f"{{hint}}", option="columns", value="t=timestamp,wx=gyro_x")
        given = {k.strip(): v.strip() for k, v in (p.split("=") for p in pairs)}
    else:
        given = {str(k): str(v) for k, v in dict(columns).items()}
    unknown = sorted(set(given) - set(QUANTITIES))
    if unknown:
        raise ImuInputError(f"columns: unknown quantit{'y' if len(unknown) == 1 else 'ies'} {unknown}; the "
                            f"quantities are {', '.join(QUANTITIES)} ({{hint}})", option="columns",
                            value="t=timestamp,wx=gyro_x")
    name = {q: given.get(q, q) for q in QUANTITIES}
    return {"time": name["t"], "gyro": (name["wx"], name["wy"], name["wz"]),
            "accel": (name["ax"], name["ay"], name["az"])}


def _match_case(cols: Mapping[str, np.ndarray], wanted: str) -> str:
    """``wanted``, or the one column equal to it regardless of case and surrounding spaces."""
    if wanted in cols:
        return wanted
    found = [c for c in cols if str(c).strip().lower() == wanted.strip().lower()]
    return found[0] if len(found) == 1 else wanted


def map_columns(cols: Mapping[str, np.ndarray], *, time: str = "t",
                gyro: Sequence[str] = ("wx", "wy", "wz"), accel: Sequence[str] = ("ax", "ay", "az"),
                time_unit: str | None = None, gyro_unit: str | None = None,
                accel_unit: str | None = None, frame: str = "FLU",
                extra_units: Mapping[str, str] | None = None, relative_time: bool = True,
                source: str = "<DataFrame>", row_lines: Callable | None = None,
                extra: pd.DataFrame | None = None) -> ImuData:
    """Named columns (``cols``: name -> array in file order) to an unvalidated :class:`ImuData`; parameters as
    :func:`read_table`, ``row_lines`` rows to 1-based file lines, ``extra`` the source DataFrame if any."""
    import pandas as pd
    gyro, accel = tuple(gyro), tuple(accel)
    for name, c3 in (("gyro", gyro), ("accel", accel)):
        if len(c3) != 3:
            raise ValueError(f"{name} must name 3 columns (x, y, z), got {c3!r}")
    time = _match_case(cols, time)
    gyro = tuple(_match_case(cols, c) for c in gyro)
    accel = tuple(_match_case(cols, c) for c in accel)
    needed = [time, *gyro, *accel]
    missing = [c for c in needed if c not in cols]
    if missing:
        hint = ",".join(f"{q}=NAME" for q, c in zip(QUANTITIES, needed, strict=True) if c not in cols)
        raise ImuInputError(f"{source}: column(s) {missing} not found; available: {list(map(str, cols))}; say "
                            f"which column holds what with {{hint}}", option="columns", value=hint)
    n = len(cols[time])
    if n == 0:
        raise MalformedFileError(source, "no data rows")
    tval, forced = raw_times(np.asarray(cols[time]), time, source, row_lines)
    w = np.column_stack([numeric(np.asarray(cols[c]), c, source, row_lines) for c in gyro])
    a = np.column_stack([numeric(np.asarray(cols[c]), c, source, row_lines) for c in accel])
    t_unit = forced or settle_unit("time", time_unit, detect_time_unit, tval, source, time)
    w, a, g_unit, a_unit = motion_in_si(w, a, gyro_unit, accel_unit, source)
    t_scale = unit_scale("time", t_unit)
    first = tval[0]
    if relative_time and (tval.dtype.kind == "i" or np.isfinite(first)):
        t, t0 = (tval - first).astype(float) * t_scale, float(first) * t_scale
    else:
        t, t0 = tval.astype(float) * t_scale, 0.0
    extra_cols = [c for c in cols if c not in needed]
    if extra is None:
        extra = pd.DataFrame({c: cols[c] for c in extra_cols}, copy=False) if extra_cols else pd.DataFrame()
    else:                                           # a DataFrame source keeps its own columns
        rest = [c for c in extra.columns if str(c) in extra_cols]
        extra = extra[rest].reset_index(drop=True) if rest else pd.DataFrame()
    units = {str(c): dict(extra_units or {}).get(str(c), "unknown") for c in extra_cols}
    meta: dict[str, Any] = {
        "format": "table", "t0": t0,
        "t0_clock": f"the source's {time!r} column" if relative_time else "t not shifted",
        "columns": {"time": time, "gyro": list(gyro), "accel": list(accel)},
        "source_units": {"time": time_unit or t_unit, "gyro": gyro_unit or g_unit,
                         "accel": accel_unit or a_unit},
        "detected_units": {k: u for k, u, given in (("time", t_unit, time_unit or forced),
                                                     ("gyro", g_unit, gyro_unit),
                                                     ("accel", a_unit, accel_unit)) if given is None},
    }
    if forced:
        meta["time_unit_used"] = "ns (datetime column)"
    if row_lines is not None:
        meta["row_lines"] = row_lines
    return ImuData(t, w, a, frame, extra, units, source, meta)


def from_dataframe(df: pd.DataFrame, *, source: str = "<DataFrame>", validate: bool = True,
                   policy: str = "retime", **kw: Any) -> ImuData:
    """Build an :class:`ImuData` from a DataFrame; see :func:`read_table` for the parameters."""
    mapping, options = _split(kw)
    imu = map_columns({str(c): df[c].to_numpy() for c in df.columns}, source=source, extra=df, **mapping)
    return finish(imu, validate=validate, policy=policy, **options)


_MAPPING_KEYS = ("time", "gyro", "accel", "time_unit", "gyro_unit", "accel_unit", "frame", "extra_units",
                 "relative_time")


def _split(kw: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(column-mapping options, validation options); ``columns`` becomes ``time``/``gyro``/``accel``."""
    columns = kw.pop("columns", None)
    mapping = {k: kw.pop(k) for k in _MAPPING_KEYS if k in kw}
    if columns is not None:
        mapping.update(parse_columns(columns))
    check_units(**{k: mapping.get(k) for k in UNIT_OPTIONS})
    return mapping, kw


@with_finish_parameters
def read_table(source: str | Path | pd.DataFrame, *, sep: str | None = None, decimal: str | None = None,
               validate: bool = True, policy: str = "retime", **validate_kw: Any) -> ImuData:
    """Read a generic IMU table (CSV file, optionally ``.gz`` / ``.bz2``, or DataFrame).

    Parameters
    ----------
    source : str, Path or pandas.DataFrame
        A delimited text file with a header line, or a DataFrame.
    sep, decimal : str, optional
        Field separator and decimal mark; None: told from the file (:func:`~imu_ground.datasets.csvio.detect_dialect`).
    {finish_parameters}

    Other Parameters
    ----------------
    columns : str or dict, optional
        Which column holds what, ``"t=timestamp,wx=gyro_x,..."`` or ``{"t": "timestamp", ...}`` (keys of
        :data:`QUANTITIES`, others keep their names; ``--columns``), matched regardless of case.
    time : str
        Time column (numbers, or datetimes), default ``"t"``.
    gyro, accel : tuple of 3 str
        Angular rate about, and specific force along, the body x, y, z axes (default ``wx, wy, wz``, ``ax, ay, az``).
    time_unit : {"s", "ms", "us", "µs", "ns"}, optional
    gyro_unit : {"rad/s", "deg/s"}, optional
    accel_unit : {"m/s^2", "m/s2", "g"}, optional
        Units of those columns (g = 9.80665 m/s^2); told from the data when omitted.
    frame : str
        Name of the body frame of the columns (default ``"FLU"``); nothing is rotated.
    extra_units : dict, optional
        Units of the other columns (kept in ``extra``), default ``"unknown"``.
    relative_time : bool
        Shift ``t`` to start at 0 (default; the first time, s, in ``meta["t0"]``; integers shifted first).

    Returns
    -------
    ImuData
        ``t`` s, ``gyro`` rad/s, ``accel`` m/s^2 in ``frame``; other columns in ``extra``;
        ``meta["source_units"]`` and ``meta["detected_units"]`` record the conversion.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    MalformedFileError
        Empty file, a line with the wrong field count, or a non-number in a time/gyro/accel column (naming
        the file and 1-based line).
    ImuInputError
        Unknown unit, units the data cannot decide, or a missing column (naming the option).
    """
    import pandas as pd
    mapping, options = _split(validate_kw)
    if isinstance(source, pd.DataFrame):
        return from_dataframe(source, validate=validate, policy=policy, **mapping, **options)
    path = Path(source)
    cols, row_lines = read_delimited(path, sep, decimal=decimal)
    imu = map_columns(cols, source=str(path), row_lines=row_lines, **mapping)
    del cols
    return finish(imu, validate=validate, policy=policy, **options)


@with_finish_parameters
def read_parquet_table(path: str | Path, *, validate: bool = True, policy: str = "retime",
                       **validate_kw: Any) -> ImuData:
    """Read a Parquet IMU table (pyarrow) through the same column mapping as :func:`read_table`.

    Parameters
    ----------
    path : str or Path
        The ``.parquet`` file. Rows are numbered from 0 in messages (Parquet has no lines).
    {finish_parameters}
        (and ``time``, ``gyro``, ``accel``, the units, ``frame``, ... as in :func:`read_table`)

    Raises
    ------
    FileNotFoundError
        No such file.
    MalformedFileError
        Not a readable Parquet file.
    """
    path = Path(path)
    pq = require_extra("pyarrow.parquet", "parquet", f"{path}: reading Parquet")
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        table = pq.read_table(path)
    except Exception as e:  # pyarrow raises ArrowInvalid / OSError for broken files
        raise MalformedFileError(path, f"not a readable Parquet file ({e})") from e
    cols: Columns = {name: table.column(name).to_numpy() for name in table.column_names}
    del table
    mapping, options = _split(validate_kw)
    imu = map_columns(cols, source=str(path), **mapping)
    imu.meta["format"] = "parquet"
    return finish(imu, validate=validate, policy=policy, **options)


def _is_table(path: Path) -> bool:
    return path.is_file() and path.name.lower().endswith(TABLE_SUFFIXES)


def _is_parquet(path: Path) -> bool:
    return path.is_file() and path.name.lower().endswith(PARQUET_SUFFIXES)


register_format("parquet", _is_parquet, read_parquet_table, "Parquet IMU table (pyarrow), same columns as CSV",
                priority=40, options=(*UNIT_OPTIONS, "columns"))
register_format("table", _is_table, read_table, "any CSV(.gz) / DataFrame with a column map", priority=90,
                options=(*UNIT_OPTIONS, "columns"))
