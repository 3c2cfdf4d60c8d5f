"""KITTI raw OXTS folders (``sync`` at 10 Hz and ``extract`` at 100 Hz).

Layout of a drive::

    <drive>/oxts/timestamps.txt    one "YYYY-MM-DD HH:MM:SS.nnnnnnnnn" per packet
    <drive>/oxts/dataformat.txt    names and units of the 30 fields (optional)
    <drive>/oxts/data/0000000000.txt ...   one packet per file, 30 numbers

The angular rate is ``wx, wy, wz`` and the specific force ``ax, ay, az``: the body's axes (``"FLU"``).
``wf, wl, wu`` and ``af, al, au`` are in the heading frame parallel to the earth's surface (no gravity tilt:
they would hide the body's pitch and roll). All 30 fields are kept in ``extra`` with their units.
"""
from __future__ import annotations

import itertools
import re
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import ImuValidationWarning, MalformedFileError, MissingPacketsError, warn_user
from imu_ground.imu.data import ImuData

from .skeleton import finish, register_format, with_finish_parameters

__all__ = ["OXTS_FIELDS", "OXTS_UNITS", "MissingPacketsError", "find_oxts_dir", "read_kitti_oxts",
           "read_oxts_dataformat", "read_oxts_timestamps"]

#: The 30 OXTS fields of KITTI raw, in file order (KITTI devkit).
OXTS_FIELDS: tuple[str, ...] = (
    "lat", "lon", "alt", "roll", "pitch", "yaw", "vn", "ve", "vf", "vl", "vu",
    "ax", "ay", "az", "af", "al", "au", "wx", "wy", "wz", "wf", "wl", "wu",
    "pos_accuracy", "vel_accuracy", "navstat", "numsats", "posmode", "velmode", "orimode")
#: Units of the standard fields ("-": a code or a count).
OXTS_UNITS: dict[str, str] = {
    "lat": "deg", "lon": "deg", "alt": "m", "roll": "rad", "pitch": "rad", "yaw": "rad",
    "vn": "m/s", "ve": "m/s", "vf": "m/s", "vl": "m/s", "vu": "m/s",
    **{k: "m/s^2" for k in ("ax", "ay", "az", "af", "al", "au")},
    **{k: "rad/s" for k in ("wx", "wy", "wz", "wf", "wl", "wu")},
    "pos_accuracy": "m", "vel_accuracy": "m/s", "navstat": "-", "numsats": "-",
    "posmode": "-", "velmode": "-", "orimode": "-"}

_GYRO, _ACCEL = ("wx", "wy", "wz"), ("ax", "ay", "az")            # body axes (module docstring)
_LINE = re.compile(r"^\s*([A-Za-z_]\w*)\s*:\s*(.*?)\s*$")


def find_oxts_dir(path: str | Path) -> Path:
    """The ``oxts`` folder of a KITTI drive, given the drive folder or the ``oxts`` folder.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist, or holds neither ``timestamps.txt`` nor ``oxts/timestamps.txt`` (named).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such folder")
    if not p.is_dir():
        raise FileNotFoundError(f"{p}: not a folder (expected a KITTI drive or its oxts folder)")
    for cand in (p, p / "oxts"):
        if (cand / "timestamps.txt").is_file():
            return cand
    raise FileNotFoundError(f"{p / 'oxts' / 'timestamps.txt'}: no such file "
                            f"({p} is neither a KITTI drive folder nor its oxts folder)")


def read_oxts_timestamps(path: str | Path) -> np.ndarray:
    """Parse a KITTI ``timestamps.txt`` into integer nanoseconds (datetime64[ns]).

    Parameters
    ----------
    path : str or Path
        Lines like ``2011-09-26 13:02:25.964389445`` (local time, no zone); trailing blank lines ignored.

    Returns
    -------
    ndarray of datetime64[ns], shape (N,)

    Raises
    ------
    FileNotFoundError, MalformedFileError
        Missing file; empty file, blank line inside, or a line that is not a timestamp (named).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such file")
    text = p.read_text(encoding="utf-8").rstrip()
    if not text.strip():
        raise MalformedFileError(p, "file is empty")
    lines = np.char.strip(np.array(text.splitlines(), dtype=str))
    try:
        ts = lines.astype("datetime64[ns]")
    except ValueError:
        ts = None
    if ts is None or np.isnat(ts).any():
        for i, s in enumerate(lines.tolist()):  # error path only: find the bad line
            try:
                if not s or np.isnat(np.datetime64(s, "ns")):
                    raise ValueError
            except ValueError:
                raise MalformedFileError(p, f"not a timestamp: {s!r} (expected "
                                            f"'YYYY-MM-DD HH:MM:SS.fffffffff')", line=i + 1) from None
    return ts  # type: ignore[return-value]


def read_oxts_dataformat(path: str | Path) -> tuple[list[str], dict[str, str], list[str]]:
    """Field names and units from a KITTI ``dataformat.txt``.

    Units are each line's first parenthesised text (``"north/east in m"``: ``"m"``; none or a remark: ``"-"``).
    A repeated name (KITTI's field 14 ``ay`` means ``az``) or a wrong count falls back to :data:`OXTS_FIELDS`.

    Returns
    -------
    names, units, notes : list of str, dict, list of str
        30 field names, name to unit, what was corrected.
    """
    p = Path(path)
    notes: list[str] = []
    names: list[str] = []
    units: dict[str, str] = {}
    for raw in p.read_text(encoding="utf-8").splitlines():
        m = _LINE.match(raw)
        if not m:
            continue
        name, desc = m.group(1), m.group(2)
        u = re.search(r"\(([^)]*)\)", desc)
        unit = u.group(1).strip() if u else "-"
        if " in " in unit:
            unit = unit.rsplit(" in ", 1)[1].strip()
        elif " " in unit or not unit:  # "(see navstat_to_string)" is a remark, not a unit
            unit = "-"
        names.append(name)
        units.setdefault(name, unit)
    if len(names) != len(OXTS_FIELDS):
        notes.append(f"{p} names {len(names)} fields, expected {len(OXTS_FIELDS)}: "
                     f"using the standard KITTI field names")
        return list(OXTS_FIELDS), dict(OXTS_UNITS), notes
    seen: set[str] = set()
    for i, name in enumerate(names):
        if name in seen:
            std = OXTS_FIELDS[i]
            notes.append(f"{p}: field {i + 1} is named {name!r} a second time; "
                         f"using the standard name {std!r}")
            names[i] = std
            units[std] = OXTS_UNITS[std]
        seen.add(names[i])
    if len(set(names)) != len(names):
        notes.append(f"{p}: repeated field names remain; using the standard KITTI field names")
        return list(OXTS_FIELDS), dict(OXTS_UNITS), notes
    return names, {n: units[n] for n in names}, notes


def _read_packets(files: list[Path], n_fields: int) -> np.ndarray:
    """Parse one-line packet files into an (N, n_fields) array; errors name file and line."""
    texts = [f.read_text(encoding="utf-8") for f in files]  # one read per packet file
    tokens = [s.split() for s in texts]
    counts = np.fromiter(map(len, tokens), dtype=np.int64, count=len(tokens))
    multiline = np.fromiter((s.strip().count("\n") for s in texts), dtype=np.int64, count=len(texts))
    bad = np.flatnonzero((counts != n_fields) | (multiline > 0))
    if bad.size:
        k = int(bad[0])
        if counts[k] == 0:
            raise MalformedFileError(files[k], f"empty packet file ({bad.size} bad packet file(s))")
        if multiline[k]:
            raise MalformedFileError(files[k], f"{multiline[k] + 1} lines, expected one "
                                               f"({bad.size} bad packet file(s))", line=2)
        raise MalformedFileError(files[k], f"{counts[k]} fields, expected {n_fields} "
                                           f"({bad.size} bad packet file(s))", line=1)
    flat = list(itertools.chain.from_iterable(tokens))
    try:
        values = np.array(flat, dtype=float)
    except ValueError:
        for f, tok in zip(files, tokens, strict=True):  # error path only: find the file and field
            for j, x in enumerate(tok):
                try:
                    float(x)
                except ValueError:
                    raise MalformedFileError(f, f"field {j + 1}: {x!r} is not a number", line=1) from None
        raise
    return values.reshape(len(files), n_fields)


@with_finish_parameters
def read_kitti_oxts(path: str | Path, *, allow_missing: bool = False, validate: bool = True,
                    policy: str = "retime", **validate_kw: Any) -> ImuData:
    """Read a KITTI raw OXTS log (sync 10 Hz or extract 100 Hz).

    Parameters
    ----------
    path : str or Path
        The drive folder (holding ``oxts/``) or its ``oxts`` folder.
    allow_missing : bool
        Read the packet files present (matched to ``timestamps.txt`` by number) with a warning, not raise.
    {finish_parameters}

    Returns
    -------
    ImuData
        ``t`` s from the first timestamp (from integer ns), ``gyro`` (wx, wy, wz) rad/s and ``accel`` (ax, ay,
        az) m/s^2 in ``"FLU"``; ``extra`` all 30 fields with their ``units``. ``meta``: ``format``, ``drive``,
        ``t0`` (s since 1970 of the written clock), ``t0_ns``, ``t0_iso``, ``t0_clock``, ``fields_source``,
        ``notes``, ``validation``.

    Raises
    ------
    FileNotFoundError
        Missing folder, ``timestamps.txt``, ``data/`` or packet files (unless ``allow_missing``), named.
    MalformedFileError
        Bad timestamp line, packet with a wrong field count or a non-number, or more packet files than
        timestamps; the message names file and line.
    """
    oxts = find_oxts_dir(path)
    ts = read_oxts_timestamps(oxts / "timestamps.txt")
    data_dir = oxts / "data"
    if not data_dir.is_dir():
        raise FileNotFoundError(f"{data_dir}: no such folder")
    fmt = oxts / "dataformat.txt"
    if fmt.is_file():
        names, units, notes = read_oxts_dataformat(fmt)
        fields_source = str(fmt)
    else:
        names, units, notes = list(OXTS_FIELDS), dict(OXTS_UNITS), []
        fields_source = "standard KITTI OXTS field list (no dataformat.txt)"
    files = sorted(data_dir.glob("*.txt"))
    stems = [f.stem for f in files]
    if not all(s.isdigit() for s in stems):
        bad = next(f for f, s in zip(files, stems, strict=True) if not s.isdigit())
        raise MalformedFileError(bad, "unexpected file name in data/ (expected 0000000000.txt ...)")
    number = np.array([int(s) for s in stems], dtype=np.int64)
    n_ts = ts.size
    if number.size == 0:
        raise FileNotFoundError(f"{data_dir / '0000000000.txt'}: no such file (data/ has no packets)")
    beyond = np.flatnonzero(number >= n_ts)
    if beyond.size:
        raise MalformedFileError(oxts / "timestamps.txt",
                                 f"{n_ts} timestamps but packet file {files[beyond[0]].name} exists "
                                 f"({beyond.size} packet file(s) without a timestamp: truncated?)")
    missing = np.setdiff1d(np.arange(n_ts), number)
    if missing.size:
        first = data_dir / f"{int(missing[0]):010d}.txt"
        msg = (f"{first}: no such file; {missing.size} of {n_ts} packet files listed in "
               f"timestamps.txt are missing (first numbers {missing[:5].tolist()})")
        if not allow_missing:
            raise MissingPacketsError(msg + " ({hint} reads the others)", option="allow_missing", value=True)
        warn_user(msg + f"; reading the {number.size} present", ImuValidationWarning)
        notes.append(msg)
    import pandas as pd
    values = _read_packets(files, len(names))
    ns = ts.astype(np.int64)[number]
    t = (ns - ns[0]).astype(float) * 1e-9
    col = {n: i for i, n in enumerate(names)}
    gyro_idx = [col.get(n, OXTS_FIELDS.index(n)) for n in _GYRO]
    accel_idx = [col.get(n, OXTS_FIELDS.index(n)) for n in _ACCEL]
    extra = pd.DataFrame(values, columns=names)
    meta: dict[str, Any] = {
        "format": "kitti_oxts", "drive": oxts.parent.name, "t0": float(ns[0]) * 1e-9, "t0_ns": int(ns[0]),
        "t0_iso": str(ts[number[0]]),
        "t0_clock": "KITTI timestamps.txt as written (local time, no zone), s since 1970-01-01",
        "fields_source": fields_source, "notes": notes}
    if missing.size:
        meta["missing_packets"] = missing
    imu = ImuData(t, values[:, gyro_idx], values[:, accel_idx], "FLU", extra, units, str(oxts), meta)
    return finish(imu, validate=validate, policy=policy, **validate_kw)


def _probe(p: Path) -> bool:
    """A KITTI drive folder (``oxts/timestamps.txt``) or its ``oxts`` folder (``timestamps.txt`` + ``data/``)."""
    return p.is_dir() and ((p / "oxts" / "timestamps.txt").is_file()
                           or ((p / "timestamps.txt").is_file() and (p / "data").is_dir()))


register_format("kitti_oxts", _probe, read_kitti_oxts, "KITTI raw drive or oxts folder (oxts/timestamps.txt)",
                priority=10, options=("allow_missing",))
