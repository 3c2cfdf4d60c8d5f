"""Generic IMU tables: a CSV file or a pandas DataFrame with named columns.

You say which columns hold time, angular rate and specific force and in which
units; the reader converts to the :class:`~imu_ground.imu.data.ImuData`
conventions (s, rad/s, m/s^2) and keeps every other column in ``extra``.

Example
-------
>>> imu = read_table("log.csv", time="timestamp", time_unit="ns",
...                  gyro=("gx", "gy", "gz"), gyro_unit="deg/s",
...                  accel=("ax", "ay", "az"), accel_unit="g")   # doctest: +SKIP
"""
from __future__ import annotations

import gzip
import io
import math
import re
import zlib
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from imu_ground.imu.data import ImuData
from imu_ground.datasets.validation import STANDARD_GRAVITY, MalformedFileError
from imu_ground.datasets.validation import validate as _validate

__all__ = [
    "TIME_UNITS",
    "GYRO_UNITS",
    "ACCEL_UNITS",
    "unit_scale",
    "read_table",
    "from_dataframe",
]

#: Time units accepted by :func:`read_table`, to seconds.
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
#: Angular-rate units accepted by :func:`read_table`, to rad/s.
GYRO_UNITS: dict[str, float] = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
#: Specific-force units accepted by :func:`read_table`, to m/s^2 (g = 9.80665 m/s^2).
ACCEL_UNITS: dict[str, float] = {"m/s^2": 1.0, "m/s2": 1.0, "g": STANDARD_GRAVITY}

_UNIT_TABLES = {"time": TIME_UNITS, "gyro": GYRO_UNITS, "accel": ACCEL_UNITS}


def unit_scale(kind: str, unit: str) -> float:
    """Factor converting ``unit`` to the ImuData unit of ``kind``.

    Parameters
    ----------
    kind : {"time", "gyro", "accel"}
        Quantity: time (to s), angular rate (to rad/s), specific force (to m/s^2).
    unit : str
        Unit of the source, one of :data:`TIME_UNITS`, :data:`GYRO_UNITS` or
        :data:`ACCEL_UNITS`.

    Returns
    -------
    float
        Multiply source values by this.

    Raises
    ------
    ValueError
        Unknown ``kind`` or ``unit``; the message lists the allowed units.
    """
    if kind not in _UNIT_TABLES:
        raise ValueError(f"unknown quantity {kind!r}; allowed: {list(_UNIT_TABLES)}")
    table = _UNIT_TABLES[kind]
    if unit not in table:
        raise ValueError(f"unknown {kind} unit {unit!r}; allowed: {list(table)}")
    return table[unit]


# --------------------------------------------------------------------------- text helpers
def _read_text(path: Path) -> str:
    """Whole text of a file (gzip when it ends in .gz), with file errors named."""
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if not path.is_file():
        raise MalformedFileError(path, "is not a file")
    try:
        if path.suffix == ".gz":
            with gzip.open(path, "rt", encoding="utf-8", newline="") as f:
                return f.read()
        return path.read_text(encoding="utf-8")
    except (EOFError, gzip.BadGzipFile, zlib.error) as e:
        raise MalformedFileError(path, f"truncated or corrupt gzip file ({e})") from e
    except UnicodeDecodeError as e:
        raise MalformedFileError(path, f"not UTF-8 text ({e})") from e


def _line_field_counts(text: str, sep: str) -> tuple[np.ndarray, np.ndarray]:
    """(1-based numbers of non-blank lines, field count of each), without a Python loop."""
    b = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    nl = np.flatnonzero(b == 10)
    n_lines = nl.size + (1 if b.size and b[-1] != 10 else 0)
    starts = np.concatenate(([0], nl + 1))[:n_lines]
    ends = np.concatenate((nl, [b.size]))[:n_lines]  # exclusive
    # blank: nothing but spaces, tabs and \r
    space = (b == 32) | (b == 9) | (b == 13)
    cs = np.concatenate(([0], np.cumsum(~space)))
    nonblank = (cs[ends] - cs[starts]) > 0
    seps = np.flatnonzero(b == ord(sep))
    counts = np.bincount(np.searchsorted(nl, seps), minlength=n_lines)[:n_lines] + 1
    lines = np.flatnonzero(nonblank)
    return lines + 1, counts[lines]


def _read_csv_text(path: Path, sep: str = ",") -> tuple[pd.DataFrame, np.ndarray]:
    """Parse a delimited text file; every line must have as many fields as the header.

    Returns the DataFrame and, for each row, its 1-based line number in the file.
    """
    text = _read_text(path)
    if not text.strip():
        raise MalformedFileError(path, "file is empty")
    line_no, counts = _line_field_counts(text, sep)
    if '"' not in text:  # quoted fields may contain the separator: let pandas judge
        bad = np.flatnonzero(counts != counts[0])
        if bad.size:
            k = int(bad[0])
            last = " (last line: truncated file?)" if k == counts.size - 1 else ""
            raise MalformedFileError(
                path, f"{counts[k]} fields, expected {counts[0]} as in the header{last}; "
                      f"{bad.size} such line(s), first line numbers {line_no[bad[:5]].tolist()}",
                line=int(line_no[k]))
    try:
        df = pd.read_csv(io.StringIO(text), sep=sep, skip_blank_lines=True)
    except pd.errors.EmptyDataError as e:
        raise MalformedFileError(path, "file is empty") from e
    except pd.errors.ParserError as e:
        m = re.search(r"line (\d+)", str(e))
        raise MalformedFileError(path, f"cannot parse: {e}", line=int(m.group(1)) if m else None) from e
    if len(df) == 0:
        raise MalformedFileError(path, "header only, no data rows", line=int(line_no[0]))
    rows_lines = line_no[1:] if len(line_no) == len(df) + 1 else np.arange(len(df)) + 2
    return df, rows_lines


def _numeric_columns(df: pd.DataFrame, columns: Sequence[str], where: str | Path,
                     row_lines: np.ndarray | None = None) -> np.ndarray:
    """Columns as a float array (N, k); a non-number raises naming column and line/row."""
    out = np.empty((len(df), len(columns)), dtype=float)
    for j, c in enumerate(columns):
        col = df[c]
        if pd.api.types.is_bool_dtype(col) or not pd.api.types.is_numeric_dtype(col):
            num = pd.to_numeric(col, errors="coerce")
            bad = np.flatnonzero(num.isna().to_numpy() & col.notna().to_numpy())
            if bad.size:
                r = int(bad[0])
                if row_lines is not None:
                    raise MalformedFileError(
                        where, f"column {c!r}: {col.iloc[r]!r} is not a number "
                               f"({bad.size} such value(s) in this column)", line=int(row_lines[r]))
                raise ValueError(f"{where}: column {c!r}, row {r}: {col.iloc[r]!r} is not a number "
                                 f"({bad.size} such value(s) in this column)")
            out[:, j] = num.to_numpy(dtype=float)
        else:
            out[:, j] = col.to_numpy(dtype=float)
    return out


def _finish(imu: ImuData, validate: bool, policy: str, validate_kw: dict[str, Any]) -> ImuData:
    """Run :func:`imu_ground.datasets.validation.validate` as the readers do.

    ``validate_kw["_depth"]`` (default 1) is the number of library frames between
    the user's call and this function's caller, so that warnings point at the user.
    """
    depth = int(validate_kw.pop("_depth", 1))
    if not validate:
        if validate_kw:
            raise TypeError(f"validation options {sorted(validate_kw)} given with validate=False")
        return imu
    kw = {"_stacklevel": 3 + depth, **validate_kw}
    out, _ = _validate(imu, policy, **kw)  # type: ignore[arg-type]
    return out


# --------------------------------------------------------------------------- reader
def from_dataframe(df: pd.DataFrame, *, time: str = "t",
                   gyro: Sequence[str] = ("wx", "wy", "wz"),
                   accel: Sequence[str] = ("ax", "ay", "az"),
                   time_unit: str = "s", gyro_unit: str = "rad/s", accel_unit: str = "m/s^2",
                   frame: str = "FLU", extra_units: Mapping[str, str] | None = None,
                   relative_time: bool = True, source: str = "<DataFrame>",
                   validate: bool = True, policy: str = "drop",
                   _row_lines: np.ndarray | None = None, **validate_kw: Any) -> ImuData:
    """Build an :class:`ImuData` from a DataFrame; see :func:`read_table` for the parameters."""
    t_scale = unit_scale("time", time_unit)
    w_scale = unit_scale("gyro", gyro_unit)
    a_scale = unit_scale("accel", accel_unit)
    gyro, accel = tuple(gyro), tuple(accel)
    for name, cols in (("gyro", gyro), ("accel", accel)):
        if len(cols) != 3:
            raise ValueError(f"{name} must name 3 columns (x, y, z), got {cols!r}")
    needed = [time, *gyro, *accel]
    missing = [c for c in needed if c not in df.columns]
    if missing:
        raise ValueError(f"{source}: column(s) {missing} not found; available: {list(map(str, df.columns))}")
    if len(df) == 0:
        raise MalformedFileError(source, "no data rows")

    # time: subtract the first value in the source's own representation (exact for ints)
    tcol = df[time]
    meta: dict[str, Any] = {}
    if pd.api.types.is_datetime64_any_dtype(tcol):
        raw = tcol.to_numpy(dtype="datetime64[ns]").astype(np.int64)
        t_scale = 1e-9
        meta["time_unit_used"] = "ns (datetime column)"
        tval: np.ndarray = raw
    elif pd.api.types.is_integer_dtype(tcol):
        tval = tcol.to_numpy(dtype=np.int64)
    else:
        tval = _numeric_columns(df, [time], source, _row_lines)[:, 0]
    first = tval[0]
    if relative_time and (np.issubdtype(tval.dtype, np.integer) or np.isfinite(first)):
        t = (tval - first).astype(float) * t_scale
        t0 = float(first) * t_scale
    else:
        t = tval.astype(float) * t_scale
        t0 = 0.0
    w = _numeric_columns(df, gyro, source, _row_lines) * w_scale
    a = _numeric_columns(df, accel, source, _row_lines) * a_scale

    extra_cols = [c for c in df.columns if c not in needed]
    extra = df[extra_cols].reset_index(drop=True) if extra_cols else pd.DataFrame()
    extra_units = dict(extra_units or {})
    units = {str(c): extra_units.get(str(c), "unknown") for c in extra_cols}
    meta.update({
        "format": "table",
        "t0": t0,
        "t0_clock": f"the source's {time!r} column" if relative_time else "t not shifted",
        "columns": {"time": time, "gyro": list(gyro), "accel": list(accel)},
        "source_units": {"time": time_unit, "gyro": gyro_unit, "accel": accel_unit},
    })
    imu = ImuData(t, w, a, frame, extra, units, source, meta)
    return _finish(imu, validate, policy, validate_kw)


def read_table(source: str | Path | pd.DataFrame, *, time: str = "t",
               gyro: Sequence[str] = ("wx", "wy", "wz"),
               accel: Sequence[str] = ("ax", "ay", "az"),
               time_unit: str = "s", gyro_unit: str = "rad/s", accel_unit: str = "m/s^2",
               frame: str = "FLU", extra_units: Mapping[str, str] | None = None,
               relative_time: bool = True, sep: str = ",",
               validate: bool = True, policy: str = "drop", **validate_kw: Any) -> ImuData:
    """Read a generic IMU table (CSV file, optionally gzip, or DataFrame).

    Parameters
    ----------
    source : str, Path or pandas.DataFrame
        A delimited text file with a header line (``.gz`` is decompressed), or a
        DataFrame.
    time : str
        Name of the time column (numbers in ``time_unit``, or a datetime column).
    gyro : tuple of 3 str
        Names of the angular-rate columns about the body x, y, z axes.
    accel : tuple of 3 str
        Names of the specific-force columns along the body x, y, z axes (what the
        accelerometer measures: +1 g on the up axis at rest).
    time_unit : {"s", "ms", "us", "µs", "ns"}
        Unit of the time column.
    gyro_unit : {"rad/s", "deg/s"}
        Unit of the angular-rate columns; converted to rad/s.
    accel_unit : {"m/s^2", "m/s2", "g"}
        Unit of the specific-force columns; converted to m/s^2 with
        g = 9.80665 m/s^2.
    frame : str
        Name of the body frame the columns are expressed in (default ``"FLU"``:
        x forward, y left, z up).  The reader does not rotate anything.
    extra_units : dict, optional
        Units of the other columns (kept in ``extra``), default ``"unknown"``.
    relative_time : bool
        Shift ``t`` to start at 0 (default) and keep the first time, in s, in
        ``meta["t0"]``; integer times are shifted before conversion so that
        nanosecond timestamps keep their precision.
    sep : str
        Field separator of the text file.
    validate : bool
        Run :func:`imu_ground.datasets.validation.validate` (default True).
    policy : {"drop", "sort", "strict"}
        Time-order policy of the validation.
    **validate_kw
        Other options of :func:`~imu_ground.datasets.validation.validate` (``nonfinite``,
        ``gap_factor``, ...).

    Returns
    -------
    ImuData
        ``t`` s, ``gyro`` rad/s, ``accel`` m/s^2 in ``frame``; other columns in
        ``extra``; ``meta["source_units"]`` records the conversion.

    Raises
    ------
    FileNotFoundError
        The file does not exist.
    MalformedFileError
        Empty file, a line with the wrong number of fields, or a non-number in a
        time/gyro/accel column (the message names the file and line).
    ValueError
        Unknown unit (the message lists the allowed ones) or missing column.
    """
    for kind, unit in (("time", time_unit), ("gyro", gyro_unit), ("accel", accel_unit)):
        unit_scale(kind, unit)  # fail on a bad unit before reading anything
    common = dict(time=time, gyro=gyro, accel=accel, time_unit=time_unit, gyro_unit=gyro_unit,
                  accel_unit=accel_unit, frame=frame, extra_units=extra_units,
                  relative_time=relative_time, validate=validate, policy=policy)
    validate_kw["_depth"] = int(validate_kw.get("_depth", 1)) + 1
    if isinstance(source, pd.DataFrame):
        return from_dataframe(source, **common, **validate_kw)
    path = Path(source)
    df, row_lines = _read_csv_text(path, sep)
    return from_dataframe(df, source=str(path), _row_lines=row_lines, **common, **validate_kw)
