"""nuScenes CAN bus expansion: the 100 Hz ``<scene>_ms_imu.json`` messages.

Each message is ``{"utime": µs since 1970, "linear_accel": [x, y, z] m/s^2 (specific force),
"rotation_rate": [x, y, z] rad/s, "q": [w, x, y, z]}`` in the ego vehicle frame ``"FLU"``.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imu_ground.errors import ImuInputError, MalformedFileError
from imu_ground.imu.data import ImuData

from .skeleton import finish, register_format, with_finish_parameters

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["find_ms_imu", "read_nuscenes_imu"]

_VECTORS = {"linear_accel": 3, "rotation_rate": 3, "q": 4}


def find_ms_imu(path: str | Path, scene: str | None = None) -> Path:
    """The ``*_ms_imu.json`` file for ``path``: the file, or a CAN bus folder holding it (``<scene>_ms_imu.json``).

    Raises
    ------
    FileNotFoundError
        Nothing found (the message names the path and pattern).
    ImuInputError
        A folder with several ``*_ms_imu.json`` files and no ``scene`` (the message names the option).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if p.is_file():
        return p
    if scene is not None:
        f = p / f"{scene}_ms_imu.json"
        if not f.is_file():
            raise FileNotFoundError(f"{f}: no such file")
        return f
    found = sorted(p.glob("*_ms_imu.json"))
    if not found:
        raise FileNotFoundError(f"{p}: no *_ms_imu.json file in this folder")
    if len(found) > 1:
        first = found[0].name[: -len("_ms_imu.json")]
        raise ImuInputError(f"{p}: {len(found)} *_ms_imu.json files ({found[0].name}, ...); pass the file "
                            f"or {{hint}}", option="scene", value=first)
    return found[0]


def _vectors(df: pd.DataFrame, key: str, width: int, path: Path) -> np.ndarray:
    col = df[key]
    try:
        arr = np.array(col.tolist(), dtype=float)
        if arr.shape == (len(df), width):
            return arr
    except (ValueError, TypeError):
        pass
    # error path only: find the first bad message
    for i, v in enumerate(col.tolist()):
        try:
            ok = np.asarray(v, dtype=float).shape == (width,)
        except (ValueError, TypeError):
            ok = False
        if not ok:
            raise MalformedFileError(path, f"message {i}: {key!r} = {v!r} is not {width} numbers")
    raise MalformedFileError(path, f"{key!r} has an unexpected shape")  # pragma: no cover


@with_finish_parameters
def read_nuscenes_imu(path: str | Path, *, scene: str | None = None, validate: bool = True,
                      policy: str = "retime", **validate_kw: Any) -> ImuData:
    """Read a nuScenes CAN bus ``*_ms_imu.json`` file.

    Parameters
    ----------
    path : str or Path
        The ``<scene>_ms_imu.json`` file, or a folder holding one (see ``scene``).
    scene : str, optional
        Scene name to pick in a folder with several scenes.
    {finish_parameters}

    Returns
    -------
    ImuData
        ``t`` s from the first message (from integer µs), ``gyro`` = ``rotation_rate`` rad/s, ``accel`` =
        ``linear_accel`` m/s^2, frame ``"FLU"``; ``extra``: ``utime`` (µs) and the attitude quaternion
        ``qw, qx, qy, qz``. ``meta``: ``format``, ``scene``, ``t0`` (s since 1970), ``t0_ns``, ``t0_clock``,
        ``validation``.

    Raises
    ------
    FileNotFoundError
        No such file / no ``*_ms_imu.json`` in the folder.
    MalformedFileError
        Not JSON (line and column given), not a list of messages, empty, a missing key or a vector of the
        wrong length (message index given).
    """
    import pandas as pd
    p = find_ms_imu(path, scene)
    try:
        with open(p, encoding="utf-8") as f:
            records = json.load(f)
    except json.JSONDecodeError as e:
        raise MalformedFileError(p, f"not valid JSON: {e.msg} (column {e.colno}; truncated file?)",
                                 line=e.lineno) from e
    except UnicodeDecodeError as e:
        raise MalformedFileError(p, f"not a JSON text file (not UTF-8: {e.reason} at byte {e.start})") from e
    if not isinstance(records, list):
        raise MalformedFileError(p, f"expected a JSON list of messages, got {type(records).__name__}")
    if not records:
        raise MalformedFileError(p, "no messages (empty list)")
    try:
        df = pd.DataFrame.from_records(records)
    except (TypeError, ValueError, AttributeError) as e:
        raise MalformedFileError(p, f"messages are not JSON objects ({e})") from e
    for key in ("utime", *_VECTORS):
        if key not in df.columns:
            raise MalformedFileError(p, f"no {key!r} in any message; keys: {list(df.columns)}")
        absent = np.flatnonzero(df[key].isna().to_numpy())
        if absent.size:
            raise MalformedFileError(p, f"message {int(absent[0])} has no {key!r} "
                                        f"({absent.size} message(s) without it)")
    try:
        utime = df["utime"].to_numpy(dtype=np.int64)
    except (ValueError, TypeError) as e:
        raise MalformedFileError(p, f"'utime' is not integer microseconds ({e})") from e
    vec = {k: _vectors(df, k, w, p) for k, w in _VECTORS.items()}
    t = (utime - utime[0]).astype(float) * 1e-6
    extra = pd.DataFrame({"utime": utime, **dict(zip(("qw", "qx", "qy", "qz"), vec["q"].T, strict=True))})
    units = {"utime": "us", "qw": "-", "qx": "-", "qy": "-", "qz": "-"}
    scene = p.name.removesuffix("_ms_imu.json") if p.name.endswith("_ms_imu.json") else p.stem
    meta: dict[str, Any] = {"format": "nuscenes", "scene": scene, "t0": float(utime[0]) * 1e-6,
                            "t0_ns": int(utime[0]) * 1000, "t0_clock": "nuScenes utime: s since 1970-01-01 (UTC)",
                            "quaternion": "extra qw, qx, qy, qz = the message's q (w, x, y, z) as given"}
    imu = ImuData(t, vec["rotation_rate"], vec["linear_accel"], "FLU", extra, units, str(p), meta)
    return finish(imu, validate=validate, policy=policy, **validate_kw)


def _probe(p: Path) -> bool:
    """A ``*ms_imu*.json`` file, or a folder holding a ``*_ms_imu.json``."""
    if p.is_dir():
        return any(p.glob("*_ms_imu.json"))
    name = p.name.lower()
    return name.endswith(".json") and "ms_imu" in name


register_format("nuscenes", _probe, read_nuscenes_imu, "nuScenes CAN bus *_ms_imu.json (or its folder)",
                priority=30, options=("scene",))
