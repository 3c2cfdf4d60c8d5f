"""The one output table of an estimate and its writers, chosen by the file's suffix; every write is atomic.

Table (:func:`track_table` of a track, :func:`result_table` of an estimate): :data:`COLUMNS`, their
units and signs in :data:`UNITS` (pitch + nose down, roll + left side up, of the body relative to the
road; ``qw qx qy qz`` the residual rotation road <- body, scalar first); frames inside a gap longer
than :data:`GAP_NAN_FRAMES` frames hold NaN.

Writers: ``.csv`` (comment header with units, method, settings), ``.parquet`` (typed; units and
settings in the schema metadata), ``.tum`` (dynamic extrinsic ground <- sensor of the valid frames,
for evo), ``.bag``/``.mcap`` (:mod:`imu_ground.pipeline.ros_output`); a picture (``.png``, ``.pdf``,
``.svg``: :func:`imu_ground.pipeline.plot.plot_estimate`) when asked for by its kind.

Atomic: each file is written to a temporary folder beside its destination and renamed into place only
when every requested file has been written: never a partial file, nor a fresh one beside a missing one.
"""
from __future__ import annotations

import csv
import io
import json
import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imu_ground._version import __version__
from imu_ground.datasets import storage
from imu_ground.datasets.poses import write_tum_poses
from imu_ground.errors import ImuGroundError, MissingExtraError, require_extra
from imu_ground.filters.estimator import GroundTrack
from imu_ground.filters.status import GAP, gap_run_durations, status_names, status_reason
from imu_ground.pipeline.input_checks import OptionError, check_creatable
from imu_ground.pipeline.planes import PLANE_UNITS, plane_columns
from imu_ground.pipeline.plot import PLOT_SUFFIXES, plot_estimate
from imu_ground.pipeline.ros_output import write_ros_output
from imu_ground.so3 import quat_from_matrix

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["COLUMNS", "TEXT_COLUMNS", "GAP_NAN_FRAMES", "OUTPUT_SUFFIXES", "UNITS", "atomic_path", "check_output_path",
           "check_run_paths", "default_output_name", "package_version", "read_output_settings", "result_table",
           "same_file", "track_table", "summarize_table", "write_csv_rows", "write_output", "write_outputs"]

#: File suffixes :func:`write_output` knows.
OUTPUT_SUFFIXES = (".csv", ".parquet", ".tum", ".bag", ".mcap")
#: Columns of the output table, in order.
COLUMNS = ("t", "normal_x", "normal_y", "normal_z", "pitch_deg", "roll_deg", "qw", "qx", "qy", "qz", "valid",
           "pitch_std_deg", "roll_std_deg", "road_grade_deg", "road_bank_deg", "road_grade_std_deg",
           "road_bank_std_deg", "status", "status_reason")
#: Unit (and meaning) of each column.
UNITS = {"t": "s (frame end)", "normal_x": "1 (unit normal, sensor frame)", "normal_y": "1 (unit normal, sensor frame)",
         "normal_z": "1 (unit normal, sensor frame)", "pitch_deg": "deg, + nose down, body relative to road",
         "roll_deg": "deg, + left side up, body relative to road",
         **{q: "1 (unit quaternion road <- body, scalar first)" for q in ("qw", "qx", "qy", "qz")},
         "valid": "bool: true = from measured motion, false = frame spans a gap",
         "pitch_std_deg": "deg, calibrated 1-sigma of pitch_deg", "roll_std_deg": "deg, calibrated 1-sigma of roll_deg",
         "road_grade_deg": "deg, + uphill in the direction of travel, road relative to gravity (nan: not estimated)",
         "road_bank_deg": "deg, + left side up, road relative to gravity (nan: not estimated)",
         "road_grade_std_deg": "deg, 1-sigma of road_grade_deg", "road_bank_std_deg": "deg, 1-sigma of road_bank_deg",
         "status": "str: converging, ok, standstill, gap, degraded or invalid", "status_reason": "str: why (empty: ok)"}
#: Text columns of the table (every other column is a float, ``valid`` a bool).
TEXT_COLUMNS = ("status", "status_reason")
#: Runs of invalid frames longer than this are NaN in the table (shorter ones are kept, flagged).
GAP_NAN_FRAMES = 3
_PathLike = str | Path


# ------------------------------------------------------------------------------------------ table
def track_table(track: GroundTrack, max_gap_frames: int = GAP_NAN_FRAMES) -> "pd.DataFrame":
    """THE output table of an estimate, one row a frame: :data:`COLUMNS` (units and signs: the module docstring,
    :data:`UNITS`; ``qw >= 0``; ``status`` one of :data:`~imu_ground.filters.status.STATUSES`).

    Parameters
    ----------
    track : GroundTrack
    max_gap_frames : int
        Frames in a run of more than this many invalid frames get NaN values; shorter runs keep their
        (extrapolated) values. ``valid`` is False for all.

    Returns
    -------
    pandas.DataFrame
    """
    import pandas as pd                             # heavy: only when a table is made
    n = len(track)
    assert track.status is not None and track.status_reason is not None     # (filled in by GroundTrack)
    reasons = _gap_reasons(np.asarray(track.status), np.asarray(track.t, dtype=float), track.status_reason)
    q = quat_from_matrix(track.residual) if n else np.zeros((0, 4))
    valid = np.asarray(track.valid, dtype=bool)
    df = pd.DataFrame({"t": np.asarray(track.t, dtype=float),
                       "normal_x": track.normal[:, 0], "normal_y": track.normal[:, 1], "normal_z": track.normal[:, 2],
                       "pitch_deg": np.degrees(track.pitch), "roll_deg": np.degrees(track.roll),
                       "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3], "valid": valid,
                       **{f"{name}_deg": np.degrees(getattr(track, name)) for name in _EXTRA_ANGLES},
                       "status": status_names(track.status), "status_reason": reasons})
    blank = _long_runs(~valid, max_gap_frames)
    if blank.any():
        cols = [c for c in df.columns if c not in ("t", "valid", "status", "status_reason")]
        df.loc[blank, cols] = np.nan
    return df


def _gap_reasons(codes: np.ndarray, t: np.ndarray, reasons: np.ndarray) -> np.ndarray:
    """The reasons with every frame of a run of ``gap`` frames saying the whole gap's length."""
    gap = codes == GAP
    if not gap.any():
        return reasons
    dt = np.diff(t, prepend=t[0] - (np.nanmedian(np.diff(t)) if len(t) > 1 else 0.0))
    seconds = gap_run_durations(gap, dt)
    out = np.array(reasons, dtype=object)
    for sec in np.unique(seconds[gap]).tolist():          # one text per gap length (few)
        out[gap & (seconds == sec)] = status_reason(GAP, sec)
    return out


#: Angle fields of a track written to the table after ``valid``, as ``NAME_deg``.
_EXTRA_ANGLES = ("pitch_std", "roll_std", "road_grade", "road_bank", "road_grade_std", "road_bank_std")


def _long_runs(mask: np.ndarray, longer_than: int) -> np.ndarray:
    """Elements of ``mask`` that lie in runs of more than ``longer_than`` consecutive True."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    out = np.zeros(len(mask), dtype=bool)
    for a, b in zip(edges[::2], edges[1::2], strict=False):
        if b - a > longer_than:
            out[a:b] = True
    return out


def result_table(result) -> Any:
    """The output table (pandas.DataFrame, :data:`COLUMNS`) of an :class:`~imu_ground.pipeline.EstimateResult`;
    with a camera (``meta["plane"]``) then ``plane_a`` ... ``plane_d`` (and with a bird's-eye grid ``bev_h00`` ...
    ``bev_h22``: :mod:`imu_ground.pipeline.planes`)."""
    table = track_table(result.track, max_gap_frames=GAP_NAN_FRAMES)
    if result.meta.get("plane") is not None:
        for name, values in plane_columns(result.meta["plane"], result.meta.get("bev")).items():
            table[name] = values
    return table


def summarize_table(table) -> dict[str, Any]:
    """Frames, valid share and pitch/roll statistics (deg) over the valid, finite frames of a table."""
    valid = table["valid"].to_numpy(dtype=bool)
    p, r = table["pitch_deg"].to_numpy(), table["roll_deg"].to_numpy()
    ok = valid & np.isfinite(p) & np.isfinite(r)
    row: dict[str, Any] = {"frames": len(table), "valid_frames": int(valid.sum()),
                           "valid_share": float(valid.mean()) if len(table) else float("nan")}
    for name, x in (("pitch", p[ok]), ("roll", r[ok])):
        for stat in ("mean", "std", "min", "max"):
            row[f"{name}_{stat}_deg"] = float(getattr(x, stat)()) if x.size else float("nan")
    return row


# ------------------------------------------------------------------------------------------ paths
def default_output_name(log: _PathLike, suffix: str = ".csv") -> str:
    """``<log name without extensions>_ground<suffix>`` (``drive.csv.gz`` -> ``drive_ground.csv``)."""
    name = Path(str(log).rstrip("/\\")).name
    return name.split(".")[0] + "_ground" + suffix


def check_output_path(path: _PathLike, inputs: Sequence[_PathLike] = (), option: str = "-o",
                      kind: str | None = None) -> Path:
    """Check that ``path`` can be written as an output, before any work is done.

    Parameters
    ----------
    path : str or Path
        Output file; its suffix picks the writer (:data:`OUTPUT_SUFFIXES`). A URL
        (:mod:`imu_ground.datasets.storage`) is returned as it is (a string).
    inputs : sequence of str or Path
        Input logs, which an output must never overwrite.
    option : str
        How the user named the path (for messages).
    kind : str, optional
        Writer to use whatever the suffix (e.g. ``".tum"``); default: by suffix.

    Returns
    -------
    Path

    Raises
    ------
    ImuGroundError
        Unknown suffix; the path is a folder, an input, or lies under a file; no permission to write there.
    MissingExtraError
        The writer of its type needs an optional extra that is not installed.
    MissingFilesystemError
        A URL whose filesystem package (``s3fs`` ...) is not installed.
    """
    target: Any = storage.local_name(path)
    url = storage.is_url(target)
    p: Any = target if url else Path(target)
    located: tuple[Any, str] = storage.filesystem(target) if url else (None, "")
    fs, key = located
    if fs.isdir(key) if url else p.is_dir():
        raise ImuGroundError(f"{p}: is a folder; give {option} a file name, e.g. {storage.join(p, 'ground.csv')}")
    suffix = Path(storage.url_name(target) if url else p).suffix.lower()
    if kind is None and suffix not in OUTPUT_SUFFIXES:
        raise ImuGroundError(f"{p}: unknown output type {suffix or '(no suffix)'!r}; end the {option} file name "
                             f"with {', '.join(OUTPUT_SUFFIXES)}")
    for src in map(storage.local_name, inputs):
        if str(src).rstrip("/") == target.rstrip("/") if url else same_file(p, src):
            raise ImuGroundError(f"{p}: is the input log; writing it would overwrite the log: choose another {option}")
    if url:
        storage.check_bucket(target, option)
    else:
        check_creatable(p, option)
    _require_writer(p, kind or suffix)
    return p


def same_file(a: _PathLike, b: _PathLike) -> bool:
    """Whether paths ``a`` and ``b`` name one file: the same resolved path (symbolic links, ``..``), or, both
    existing, the same file (:func:`os.path.samefile`: hard links, other spellings)."""
    return bool(_file_keys(a) & _file_keys(b))


def _file_keys(path: _PathLike) -> set:
    """What names a file: its resolved path and, when it exists, its device and inode."""
    p = Path(path)
    keys: set = {str(p.resolve())}
    try:
        st = p.stat()
        keys.add((st.st_dev, st.st_ino))
    except OSError:
        pass
    return keys


def check_run_paths(outputs: Sequence[tuple[str, _PathLike | None]],
                    inputs: Sequence[tuple[str, _PathLike | None]] = ()) -> None:
    """The one check of a run's paths, before any work: no output is a file the user named as an input, and no
    two outputs share a path (:func:`same_file` decides).

    Parameters
    ----------
    outputs, inputs : sequence of (flag, path)
        Every file or folder the run writes, and every input the user named, with the flag naming it
        (``"-o"``, ``"LOG"``, ``"--speed"``, ...); None and empty left out.

    Raises
    ------
    ImuGroundError
        One line naming the path and both flags (exit 2 from the command line).
    """
    given: dict = {}
    for flag, src in inputs:
        if src is not None and str(src) != "":
            for key in _file_keys(src):
                given.setdefault(key, flag)
    written: dict = {}
    for flag, path in outputs:
        if path is None:
            continue
        keys = _file_keys(path)
        for key in keys:
            if key in given:
                raise ImuGroundError(f"{path}: given to both {given[key]} (an input) and {flag}; writing it would "
                                     f"replace the input: choose another {flag}")
            if key in written:
                raise ImuGroundError(f"{path}: given to both {written[key]} and {flag}; the two outputs need two "
                                     "file names")
        written.update(dict.fromkeys(keys, flag))


#: Output suffix -> (the modules its writer needs, the extra that installs them).
_WRITER_EXTRAS = {".parquet": (("pyarrow.parquet",), "parquet"), ".bag": (("rosbags.typesys",), "ros"),
                  ".mcap": (("rosbags.typesys", "mcap.writer"), "ros")}


def _require_writer(path: Path, kind: str) -> None:
    """Raise :class:`~imu_ground.errors.MissingExtraError` naming ``path`` when its writer's extra is missing."""
    modules, extra = _WRITER_EXTRAS.get(kind, ((), ""))
    for module in modules:
        require_extra(module, extra, f"{path}: writing {kind}")


@contextmanager
def atomic_path(path: _PathLike) -> Iterator[Path]:
    """Temporary path beside ``path``, renamed onto it when the block succeeds (parents created; on an exception
    nothing is left and ``path`` untouched). A URL's is local, uploaded in one piece
    (:func:`~imu_ground.datasets.storage.staged_outputs`)."""
    path = storage.local_name(path)
    if storage.is_url(path):
        with storage.staged_outputs([path]) as (tmp,):
            yield tmp
        return
    p = Path(path)
    with _staged(p) as tmp:
        yield tmp
        os.replace(tmp, p)


# ------------------------------------------------------------------------------------------ writers
def package_version() -> str:
    """The package's version (its one owner is ``imu_ground/_version.py``; pyproject reads it from there)."""
    return __version__


def _csv_header(meta: Mapping[str, Any]) -> str:
    settings = json.dumps(meta.get("settings", {}), sort_keys=True, default=str)
    lines = [
        (f"imu-ground {package_version()} estimate: format {meta.get('format')}, method {meta.get('method')} "
        f"({meta.get('method_description', '')})"),
        f"settings: {settings}",
        *([f"clock: t is on {meta['clock']}"] if meta.get("clock") else []),
        ("columns: t (s, frame end); normal_x, normal_y, normal_z (unit ground normal, sensor frame); "
        "pitch_deg (deg, + nose down) and roll_deg (deg, + left side up) of the body relative to the road; "
        "qw, qx, qy, qz (residual rotation road <- body, unit quaternion, scalar first)"),
        ("valid: 1 = estimated from measured motion, 0 = the frame spans a timestamp gap (integrated "
        f"through, extrapolated); inside gaps longer than {GAP_NAN_FRAMES} frames every column but t, "
        "valid, status and status_reason is nan"),
        ("pitch_std_deg, roll_std_deg: calibrated 1-sigma (deg) of pitch_deg and roll_deg; road_grade_deg "
        "(+ uphill in the direction of travel) and road_bank_deg (+ left side up): the road's attitude "
        "relative to gravity (deg), with road_grade_std_deg and road_bank_std_deg (1-sigma), nan where "
        "not estimated (the reason in status_reason)"),
        ("status: converging (until the 1-sigma is first below its threshold), ok, standstill, gap, "
        "degraded (the sensor's mount moved; needs a speed) or invalid (a bad frame skipped); "
        "status_reason: why, in words"),
    ]
    if meta.get("camera"):
        lines.append(f"camera {meta['camera'].get('name')}: plane_a, plane_b, plane_c (unit road normal pointing up, "
                     "camera axes x right, y down, z forward), plane_d (camera height above the road, m): "
                     "a x + b y + c z + d = 0 on the road; nan on frames that span a gap"
                     + ("; bev_h00 .. bev_h22: homography bird's-eye pixel <- image pixel, row-major"
                        if meta.get("bev") is not None else ""))
    return "".join(f"# {ln}\n" for ln in lines)


def write_csv_rows(fh, table) -> None:
    """Write ``table``'s header line and rows as CSV to ``fh`` (binary; the index not written).

    Through pyarrow's CSV writer (pandas' ``to_csv`` without it: the same values, numbers maybe spelt
    otherwise): every number the shortest text that reads back as the same double, NaN as ``nan``,
    infinities as ``inf``/``-inf``, bools as 0/1; text quoted where it needs it (``"`` doubled).
    """
    head = io.StringIO()
    csv.writer(head, lineterminator="\n").writerow([str(c) for c in table.columns])
    fh.write(head.getvalue().encode("utf-8"))
    if not len(table.columns):
        return
    df = table.reset_index(drop=True)
    for c in df.columns[[k == "b" for k in df.dtypes.map(lambda d: d.kind)]]:
        df[c] = df[c].astype(np.int8)
    try:
        import pyarrow as pa
        import pyarrow.csv as pacsv
        # column by column from numpy (NaN stays a number, written nan; pandas' conversion would make it empty)
        rows = pa.table([pa.array(df[c].to_numpy() if df[c].dtype.kind in "fiu" else df[c].to_numpy(dtype=object))
                         for c in df.columns], names=[f"c{j}" for j in range(len(df.columns))])
    except (ImportError, ValueError, TypeError):        # no pyarrow, or columns it cannot type (ArrowInvalid ...)
        df.to_csv(fh, header=False, index=False, na_rep="nan", lineterminator="\n", encoding="utf-8")
        return
    _write_row_blocks(pa, pacsv, rows, fh, pacsv.WriteOptions(include_header=False, quoting_style="needed"))


#: Tables of at least this many rows are formatted in :data:`CSV_PARTS` row blocks on as many threads.
CSV_PARALLEL_ROWS = 1 << 16
CSV_PARTS = max(1, min(4, os.cpu_count() or 1))


def _write_row_blocks(pa: Any, pacsv: Any, rows: Any, fh: Any, options: Any) -> None:
    """``pyarrow.csv.write_csv(rows, fh, options)`` (no header); a long table's row blocks formatted on several
    threads (pyarrow releases the GIL), each into a buffer of its own, written in order: the bytes of one call."""
    n = rows.num_rows
    parts = CSV_PARTS if n >= CSV_PARALLEL_ROWS else 1
    if parts == 1:
        pacsv.write_csv(rows, fh, options)
        return
    bounds = [n * k // parts for k in range(parts + 1)]

    def block(k: int) -> Any:
        sink = pa.BufferOutputStream()
        pacsv.write_csv(rows.slice(bounds[k], bounds[k + 1] - bounds[k]), sink, options)
        return sink.getvalue()

    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(parts) as pool:
        for buf in pool.map(block, range(parts)):
            fh.write(buf)
            del buf


def _write_csv(path: Path, table, meta: Mapping[str, Any]) -> None:
    with open(path, "wb") as fh:
        fh.write(_csv_header(meta).encode("utf-8"))
        write_csv_rows(fh, table)


def _write_parquet(path: Path, table, meta: Mapping[str, Any]) -> None:
    pa = require_extra("pyarrow", "parquet", f"{path}: writing Parquet")
    pq = require_extra("pyarrow.parquet", "parquet", f"{path}: writing Parquet")
    df = table.reset_index(drop=True)
    df["valid"] = df["valid"].astype(bool)
    units = {**UNITS, **PLANE_UNITS}
    fields = [pa.field(c, pa.bool_() if c == "valid" else pa.string() if c in TEXT_COLUMNS else pa.float64(),
                       metadata={"unit": units[c]}) for c in df.columns]
    info = {k: meta.get(k) for k in ("format", "method", "method_description", "settings", "extrinsic", "camera")}
    info["units"] = UNITS
    info["gap_nan_frames"] = GAP_NAN_FRAMES
    schema = pa.schema(fields, metadata={"imu_ground": json.dumps(info, sort_keys=True, default=str)})
    pq.write_table(pa.Table.from_pandas(df, schema=schema, preserve_index=False), path)


def _write_tum(path: Path, table, meta: Mapping[str, Any]) -> None:
    from scipy.spatial.transform import Rotation
    ext = meta.get("extrinsic") or {}
    q = table[["qw", "qx", "qy", "qz"]].to_numpy(dtype=float)
    keep = table["valid"].to_numpy(dtype=bool) & np.all(np.isfinite(q), axis=1)
    dyn = Rotation.from_quat(q[keep], scalar_first=True).as_matrix() @ np.asarray(ext.get("rotation", np.eye(3)),
                                                                                  dtype=float)
    settings = json.dumps(meta.get("settings", {}), sort_keys=True, default=str)
    write_tum_poses(path, table["t"].to_numpy(dtype=float)[keep], dyn,   # road-ground <- sensor
                    np.asarray(ext.get("translation", np.zeros(3)), dtype=float),
                    header=f"dynamic extrinsic ground <- sensor of the valid frames: t x y z qx qy qz qw\nsettings: {settings}")


def _write_ros(path: Path, table, meta: Mapping[str, Any]) -> None:
    settings = dict(meta.get("settings", {}))
    if meta.get("t0_ns") is not None:
        settings["t0_ns"] = int(meta["t0_ns"])                   # stamps line up with the recording
    try:
        plane = meta.get("plane")
        write_ros_output(path, table, frame_id=meta.get("frame_id") or "imu", settings=settings,
                         road_from_camera=None if plane is None else plane.matrix, extrinsic=meta.get("extrinsic"))
    except ImportError as e:                                     # rosbags / mcap load on first use
        if isinstance(e, MissingExtraError):
            raise
        raise MissingExtraError(f"{path}: writing {path.suffix}", (e.name or "rosbags").split(".")[0], "ros") from e


def read_output_settings(path: _PathLike) -> dict | None:
    """The ``settings`` an output of this package records (CSV and TUM header, Parquet schema, MCAP metadata
    record), or None (a ROS bag, whose settings topic is not read here, or a file written by something else)."""
    p = storage.local_name(path)
    suffix = Path(storage.url_name(p) if storage.is_url(p) else p).suffix.lower()
    try:
        if suffix == ".mcap":
            from imu_ground.pipeline.ros_output import read_mcap_settings
            return read_mcap_settings(p)
        if suffix == ".parquet":
            import pyarrow.parquet as pq
            with storage.open_file(p, "rb") as src:
                raw = (pq.read_schema(src).metadata or {}).get(b"imu_ground")
            return json.loads(raw).get("settings") if raw else None
        if suffix in (".csv", ".tum"):
            with storage.open_file(p, "r") as fh:
                for line in fh:
                    if not line.startswith("#"):
                        break
                    text = line.lstrip("# ").rstrip("\n")
                    if text.startswith("settings: "):
                        return json.loads(text[len("settings: "):])
    except (OSError, ValueError, ImportError):
        return None
    return None


def _write_plot(path: Path, table, meta: Mapping[str, Any]) -> None:
    source = Path(str(meta.get("source", "")).rstrip("/\\")).name
    t_label = f"t (s, frame end, on {meta['clock']})" if meta.get("clock") else "t (s, frame end, the log's time base)"
    plot_estimate(table, path, speed=meta.get("frame_speed"), speed_note=str(meta.get("speed") or ""),
                  title=f"{source or 'estimate'}: method {meta.get('method')}", time_label=t_label)


_WRITERS = {".csv": _write_csv, ".parquet": _write_parquet, ".tum": _write_tum, ".bag": _write_ros,
            ".mcap": _write_ros, **{suffix: _write_plot for suffix in PLOT_SUFFIXES}}


def write_outputs(paths: Sequence[_PathLike], table, meta: Mapping[str, Any],
                  kinds: Sequence[str | None] | None = None) -> Sequence[Path | str]:
    """Write ``table`` (:func:`result_table`'s columns) to every path; all appear together or none does.

    Parameters
    ----------
    paths : sequence of str or Path
        Destinations (best checked with :func:`check_output_path` first). A URL stays a string: written
        locally, then uploaded in one piece (:func:`~imu_ground.datasets.storage.staged_outputs`).
    table : pandas.DataFrame
    meta : mapping
        :class:`~imu_ground.pipeline.EstimateResult` ``meta`` (format, method, settings, extrinsic, frame_id;
        ``frame_speed`` for a picture).
    kinds : sequence of str or None, optional
        Writer per path, a suffix of :data:`OUTPUT_SUFFIXES` (``".tum"`` for a TUM file named ``.txt``) or of
        :data:`~imu_ground.pipeline.plot.PLOT_SUFFIXES`; None: from the path's suffix.

    Returns
    -------
    list of Path or str
    """
    paths = [storage.local_name(p) for p in paths]
    if any(storage.is_url(p) for p in paths):
        with storage.staged_outputs(paths) as local:
            write_outputs(local, table, meta, kinds)
        return [p if storage.is_url(p) else Path(p) for p in paths]
    out = [Path(p) for p in paths]
    suffixes = [k or p.suffix.lower() for p, k in zip(out, kinds or [None] * len(out), strict=True)]
    for p, k in zip(out, suffixes, strict=True):
        if k not in _WRITERS:
            raise ImuGroundError(f"{p}: unknown output type {k!r}; use {', '.join(OUTPUT_SUFFIXES)}")
        _require_writer(p, k)
    with ExitStack() as stack:
        temps = [stack.enter_context(_staged(p)) for p in out]
        for k, tmp in zip(suffixes, temps, strict=True):
            _WRITERS[k](tmp, table, meta)
        for p, tmp in zip(out, temps, strict=True):
            os.replace(tmp, p)
    return out


@contextmanager
def _staged(path: Path) -> Iterator[Path]:
    """Like :func:`atomic_path` but the caller renames (so several files can be committed together).

    An operating-system error names ``path``, never the temporary folder.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmpdir = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    except OSError as e:
        raise OptionError(f"{path}: cannot be written there ({e.strerror or e}); choose another path") from None
    try:
        yield tmpdir / path.name
    except OSError as e:
        if str(tmpdir) not in f"{e.filename} {e.filename2}":
            raise
        raise OptionError(f"{path}: could not be written ({e.strerror or e}); choose another path") from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def write_output(path: _PathLike, table, meta: Mapping[str, Any],
                 extra: Sequence[_PathLike] | None = None) -> Path | str:
    """Write one output (and optional ``extra`` ones, all or none); returns its path."""
    return write_outputs([path, *(extra or ())], table, meta)[0]
