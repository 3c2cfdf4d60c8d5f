"""A vehicle speed signal (wheel / CAN speed) for the speed-aided estimators, and its resampling to frames.

Sources (:func:`read_speed`): a CSV file ``t,speed``, a column of the IMU log's table, or the log's own
signal (:data:`SPEED_SOURCES`: KITTI's INS horizontal speed, nuScenes ``pose.json`` ``vel``, comma2k19
``CAN/speed``, a ROS twist or odometry topic). Times are s on the IMU's time base (``ImuData.t``).
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import ImuGroundError, ImuInputError, MalformedFileError

from .csvio import RowLines, numeric, read_delimited
from .rosbag_files import is_rosbag

__all__ = ["MAX_REVERSE", "MAX_SPEED", "SPEED_NAMES", "SPEED_SOURCES", "TIME_NAMES", "check_speed", "frame_speed",
           "log_speed", "read_speed", "read_speed_file", "speed_unit"]

#: Log formats with a speed signal of their own, and what it is.
SPEED_SOURCES = {
    "kitti_imu100": "INS horizontal speed hypot(ve, vn)",
    "kitti_oxts": "INS horizontal speed hypot(ve, vn)",
    "nuscenes": "CAN bus pose.json forward speed",
    "comma2k19": "CAN speed",
    "rosbag": "twist / odometry topic speed",
}


def _checked(t, v, source: str) -> tuple[np.ndarray, np.ndarray]:
    """Samples with a finite time, sorted, duplicate times dropped; a NaN speed stays (a hole)."""
    t = np.asarray(t, dtype=float).ravel()
    v = np.asarray(v, dtype=float).ravel()
    if t.shape != v.shape or t.size == 0:
        raise ImuGroundError(f"{source}: {t.size} times but {v.size} speeds (need the same number, at least one)")
    v = np.where(np.isinf(v), np.nan, v)
    ok = np.isfinite(t)
    t, v = t[ok], v[ok]
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.zeros(0, bool)
    t, v = t[keep], v[keep]
    if not np.isfinite(v).any():
        raise ImuGroundError(f"{source}: no finite speed sample")
    return t, v


#: Fastest plausible reversing, m/s: a car backs up at walking pace, a few m/s.
MAX_REVERSE = 5.0
#: Fastest plausible forward speed, m/s (360 km/h).
MAX_SPEED = 100.0
#: Window over which speed changes are compared with the accelerometer, s.
UNIT_WINDOW_S = 1.0


def speed_unit(n: int, sums: Any) -> tuple[str | None, float]:
    """The speed's unit from ``n`` windows of its changes ``y`` against the accelerometer's ``x`` (m/s), given the
    sums ``(x, y, xx, yy, xy)``: the least-squares slope of ``y`` on ``x``, means removed.

    Returns ``(unit, slope)``: ``"km/h"`` for a slope of 2.9-4.5, ``"m/s"`` for 0.6-1.6, ``"other"`` for another,
    each with a correlation over 0.6; ``(None, nan)`` when the windows cannot tell (under 20, no correlation).
    Summed over a whole signal by :func:`check_speed`, frame by frame by the live ``SpeedUnit``.
    """
    if n < 20:
        return None, math.nan
    sx, sy, sxx, syy, sxy = sums
    cxx, cyy, cxy = sxx - sx * sx / n, syy - sy * sy / n, sxy - sx * sy / n
    if not (cxx > 0 and cyy > 0 and cxy / math.sqrt(cxx * cyy) > 0.6):
        return None, math.nan
    k = cxy / cxx
    return ("km/h" if 2.9 < k < 4.5 else "m/s" if 0.6 < k < 1.6 else "other"), k


def _scale_against_accel(t: np.ndarray, v: np.ndarray, imu) -> tuple[str | None, float, int]:
    """:func:`speed_unit` over windows of :data:`UNIT_WINDOW_S` above 1 m/s at both ends: ``(unit, slope, windows)``."""
    fin = np.isfinite(v)
    t, v = t[fin], v[fin]
    ti = np.asarray(imu.t, dtype=float)
    ax = np.asarray(imu.accel, dtype=float)[:, 0]
    ok = np.isfinite(ti) & np.isfinite(ax)
    ti, ax = ti[ok], ax[ok]
    lo, hi = max(t[0], ti[0] if ti.size else np.inf), min(t[-1], ti[-1] if ti.size else -np.inf)
    if ti.size < 2 or hi - lo < 20 * UNIT_WINDOW_S:
        return None, math.nan, 0
    edges = np.arange(lo, hi, UNIT_WINDOW_S)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (ax[1:] + ax[:-1]) * np.diff(ti))])
    dv_imu = np.diff(np.interp(edges, ti, cum))
    ve = np.interp(edges, t, v)
    dv_speed = np.diff(ve)
    moving = (np.abs(ve[:-1]) > 1.0) & (np.abs(ve[1:]) > 1.0)
    x, y = dv_imu[moving], dv_speed[moving]
    n = int(x.size)
    return (*speed_unit(n, [float(x.sum()), float(y.sum()), float(x @ x), float(y @ y), float(x @ y)]), n)


def check_speed(t: np.ndarray, v: np.ndarray, source: str, imu=None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Check a measured speed signal against what a car does and against the IMU; fix what is certain.

    Times in ms (spanning about 1000 times the log) and speeds in km/h (:func:`speed_unit`) are converted,
    another scale said; negative speeds are reversing, said; faster than :data:`MAX_REVERSE` backwards, mostly
    negative (a flipped sign) or faster than :data:`MAX_SPEED`: refused.

    Parameters
    ----------
    t, v : ndarray (M,)
        Times (s on the IMU's time base, increasing) and speeds (m/s, NaN where unknown), as read.
    source : str
        What the signal is (file or column), for messages.
    imu : ImuData, optional
        The log (its times and forward specific force); without it only the values are checked.

    Returns
    -------
    t, v : ndarray
        Converted where a conversion was certain.
    notes : list of str
        One line per finding (for warnings).

    Raises
    ------
    ImuGroundError
        Implausible speeds: the message gives the values and what the file must hold.
    """
    notes: list[str] = []
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    if imu is not None and len(imu.t) > 1 and t.size > 1:
        span_log = float(imu.t[-1] - imu.t[0])
        span = float(t[-1] - t[0])
        if span_log > 0 and 300.0 < span / span_log < 3000.0 and t[0] / 1000.0 <= imu.t[-1]:
            t = t / 1000.0
            notes.append(f"{source}: its times span {span:.0f} against the log's {span_log:.1f} s: taken as "
                         "milliseconds and converted to seconds")
    # the unit first, so that a km/h file at highway speed is converted before the plausibility checks
    if imu is not None and getattr(imu, "accel", None) is not None:
        unit, k, n = _scale_against_accel(t, v, imu)
        if unit == "km/h":
            v = v / 3.6
            notes.append(f"{source}: the speed changes {k:.2f} times as fast as the accelerometer says over "
                         f"{n} s of driving: taken as km/h and converted to m/s")
        elif unit == "other":
            notes.append(f"{source}: the speed changes {k:.2f} times as fast as the accelerometer says over "
                         f"{n} s of driving; a speed file holds m/s: check its unit")
    fast = float(np.nanmax(v))
    if fast > MAX_SPEED:
        raise ImuGroundError(f"{source}: speeds up to {fast:.1f}, implausible for m/s (over {MAX_SPEED:g} m/s); a speed "
                             "file holds the forward speed in m/s (divide km/h by 3.6)")
    neg = v < 0
    if neg.any():
        slow = float(np.nanmin(v))
        finite = int(np.isfinite(v).sum())
        share = float(neg.sum() / finite)
        if share > 0.5 or slow < -MAX_REVERSE:
            raise ImuGroundError(f"{source}: {100 * share:.0f}% of the speeds are negative, down to {slow:.1f} m/s; a "
                                 f"car reverses rarely and at a few m/s (at most {MAX_REVERSE:g}): is the sign flipped? "
                                 "a speed file holds the forward speed, m/s, negative only when reversing")
        notes.append(f"{source}: {int(neg.sum())} of {finite} speeds are negative (down to {slow:.2f} m/s): "
                     "taken as reversing")
    return t, v, notes


#: Accepted column names of a speed file (matched regardless of case): time, speed.
TIME_NAMES = ("t", "time")
SPEED_NAMES = ("speed", "v")


def _named_column(p: Path, cols: list[str], names: tuple[str, ...], what: str) -> str:
    """The one column of ``cols`` whose name is in ``names`` (regardless of case)."""
    found = [c for c in cols if c.lower() in names]
    accepted = " or ".join(repr(n) for n in names)
    if len(found) == 1:
        return found[0]
    if found:
        raise MalformedFileError(p, f"{len(found)} {what} columns ({', '.join(found)}); a speed file has one, "
                                    f"named {accepted}")
    raise MalformedFileError(p, f"no {what} column: the header is {','.join(cols)}; a speed file names its "
                                f"columns {' or '.join(map(repr, TIME_NAMES))} (s) and "
                                f"{' or '.join(map(repr, SPEED_NAMES))} (m/s), in any order and case, "
                                "e.g. the header 't,speed'")


def read_speed_file(path: str | Path, column: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A speed table: a CSV file whose header names a time (``t``, ``time``; s on the IMU log's time base) and a
    speed (``speed``, ``v``, or ``column``; m/s) column, in any case and order; an empty speed field is NaN, a row
    with another number of fields than the header is refused.

    Returns
    -------
    t, v : ndarray (M,)
        s, increasing; m/s, NaN where a row's speed field is empty.

    Raises
    ------
    FileNotFoundError
        No such file.
    MalformedFileError
        Not a CSV table; no time or speed column by those names, or two of one kind (the message gives the
        header and the accepted names); non-numeric values; a row without a time, or times that step back or
        repeat (the message gives the first such line: nothing is sorted or dropped).
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no such speed file")
    data, row_lines = read_delimited(p)
    cols = {str(c).strip(): x for c, x in data.items()}
    if column is not None and column not in cols:
        raise MalformedFileError(p, f"no speed column {column!r}; columns: {', '.join(cols)}")
    name = column or _named_column(p, list(cols), SPEED_NAMES, "speed")
    tcol = _named_column(p, list(cols), TIME_NAMES, "time")
    t, v = (numeric(cols[c], c, p, row_lines) for c in (tcol, name))
    _check_time_order(p, t, tcol, row_lines)
    return _checked(t, v, str(p))


def _check_time_order(p: Path, t: np.ndarray, tcol: str, row_lines: RowLines) -> None:
    """Refuse a speed file with a row without a finite time, or times that do not increase, naming the first line."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise MalformedFileError(p, f"no time in column {tcol!r} ({bad.size} row(s) without one); every row of a "
                                 "speed file has a time, s", line=int(row_lines(bad[:1])[0]))
    steps = np.diff(t)
    back = np.flatnonzero(steps <= 0)
    if not back.size:
        return
    k = int(back[0]) + 1
    before, line = (int(x) for x in row_lines(np.array([k - 1, k])))
    n_back, n_rep = int(np.count_nonzero(steps < 0)), int(np.count_nonzero(steps == 0))
    what = "repeats" if steps[k - 1] == 0 else "goes back from"
    counts = " and ".join(x for x in (f"{n_back} step(s) back" if n_back else "",
                                      f"{n_rep} repeated time(s)" if n_rep else "") if x)
    raise MalformedFileError(p, f"the time {t[k]:.6g} s {what} {t[k - 1]:.6g} s on line {before} "
                             f"({counts} in {t.size} rows); a speed file's times increase from row to row: "
                             "sort it by time and remove repeated rows", line=line)


def _nuscenes_speed(imu, path: Path) -> tuple[np.ndarray, np.ndarray]:
    from imu_ground.datasets.nuscenes import find_ms_imu
    ms = find_ms_imu(path)
    pose = ms.with_name(ms.name.replace("_ms_imu.json", "_pose.json"))
    if not pose.is_file():
        raise FileNotFoundError(f"{pose}: no CAN bus pose file beside {ms.name} (its 'vel' is the speed)")
    with open(pose, encoding="utf-8") as f:
        msgs = json.load(f)
    utime = np.array([m["utime"] for m in msgs], dtype=np.int64)
    vel = np.array([m["vel"] for m in msgs], dtype=float)
    t0_us = int(imu.meta["t0_ns"]) // 1000 if imu.meta.get("t0_ns") is not None else utime[0]
    return _checked((utime - t0_us) * 1e-6, np.linalg.norm(vel, axis=1), str(pose))


def _comma_speed(imu, path: Path) -> tuple[np.ndarray, np.ndarray]:
    from imu_ground.datasets.comma2k19 import find_imu_dir
    can = find_imu_dir(path).parent / "CAN" / "speed"
    if not (can / "t").is_file():
        raise FileNotFoundError(f"{can}: no CAN speed in this comma2k19 segment")
    t = np.load(can / "t", allow_pickle=False)
    v = np.load(can / "value", allow_pickle=False)
    return _checked(t - float(imu.meta.get("t0", 0.0)), np.asarray(v, dtype=float).reshape(len(t), -1)[:, 0], str(can))


def log_speed(path: str | Path, format: str, imu=None, topic: str | None = None
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """The log's own speed signal ``(t, speed)`` on the IMU's time base, or None when its format has none.

    Parameters
    ----------
    path : str or Path
        The IMU log.
    format : str
        Its format (a :func:`~imu_ground.datasets.detect_format` name).
    imu : ImuData, optional
        The log as read (read when needed and not given).
    topic : str, optional
        ROS: the twist / odometry topic.

    Raises
    ------
    ImuInputError
        A ROS log with several speed topics (naming ``--speed``).
    """
    p = Path(path)
    if format not in SPEED_SOURCES:
        return None
    if imu is None:
        from imu_ground.datasets import read_imu
        imu = read_imu(p, format=format)
    if format == "nuscenes":
        return _nuscenes_speed(imu, p)
    if format == "comma2k19":
        return _comma_speed(imu, p)
    if format == "rosbag":
        from imu_ground.datasets.rosbag import read_rosbag_speed, speed_topics
        if topic is None:
            names = speed_topics(p)
            if not names:
                return None          # an IMU-only recording: no twist / odometry topic
            if len(names) > 1:
                raise ImuInputError(f"{p}: {len(names)} speed topics ({', '.join(names)}); choose one with {{hint}}",
                                    option="speed", value=names[0], flag="--speed")
        return _checked(*read_rosbag_speed(p, topic, t0_ns=imu.meta.get("t0_ns")), str(p))
    if not {"ve", "vn"} <= set(imu.extra.columns):
        return None
    return _checked(imu.t, np.hypot(imu.extra["ve"].to_numpy(float), imu.extra["vn"].to_numpy(float)), str(p))


def read_speed(source: Any, *, log: str | Path | None = None, format: str | None = None, imu=None,
               topic: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A speed signal ``(t, speed)``: t in s on the IMU's time base (increasing), speed in m/s (NaN where unknown).

    Parameters
    ----------
    source : str or Path
        A speed file (CSV ``t,speed``: :func:`read_speed_file`), a column name of the log's table (a ROS
        log: a twist / odometry topic), or the log itself (its own speed, :func:`log_speed`).
    log : str or Path, optional
        The IMU log (for a column name); default ``source``.
    format : str, optional
        The log's format (detected when None).
    imu : ImuData, optional
        The log as read (saves reading it again).
    topic : str, optional
        ROS: the speed topic.

    Raises
    ------
    ImuGroundError
        No such column, or a log without a speed signal (the message says what to pass).
    """
    src = Path(str(source))
    log = src if log is None else Path(log)
    if src.is_file() and src != log:
        return read_speed_file(src)
    if src == log:
        from imu_ground.datasets import detect_format
        fmt = detect_format(log) if format is None else format
        out = log_speed(log, fmt, imu, topic)
        if out is None:
            raise ImuGroundError(f"{log}: a {fmt} log carries no speed signal; give a speed file (CSV t,speed) or "
                                 f"the name of the log's speed column (formats with their own: {', '.join(SPEED_SOURCES)})")
        return out
    name = str(source)
    if format == "rosbag" or (format is None and log.exists() and is_rosbag(log)):
        got = log_speed(log, "rosbag", imu, topic=name)          # a ROS log: the name is a topic
        assert got is not None                                    # (a ROS log has speeds: a missing topic raises)
        return got
    if imu is None:
        from imu_ground.datasets import read_imu
        imu = read_imu(log, format=format)
    if name not in imu.extra.columns:
        raise ImuGroundError(f"{log}: no column {name!r} for the speed (and no such file); columns besides the IMU's: "
                             f"{', '.join(map(str, imu.extra.columns)) or 'none'}")
    return _checked(imu.t, imu.extra[name].to_numpy(float), f"{log} column {name}")


def frame_speed(t: np.ndarray, speed: np.ndarray, frame_t: np.ndarray, frame_dt: np.ndarray) -> np.ndarray:
    """Mean speed over each frame ``(t_k - dt_k, t_k]``, m/s: the exact mean of the piecewise-linear speed; NaN for a
    frame outside the signal's span or reached by a hole (a run of NaN speeds, between its finite neighbours).

    Parameters
    ----------
    t, speed : ndarray (M,)
        Speed samples (s, increasing; m/s, NaN where unknown).
    frame_t, frame_dt : ndarray (F,)
        Frame end times and durations, s (an EgoMotion's ``t`` and ``delta_t``).
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(speed, dtype=float)
    te = np.asarray(frame_t, dtype=float)
    ts = te - np.asarray(frame_dt, dtype=float)
    fin = np.isfinite(v)
    if not fin.any():
        return np.full(te.shape, np.nan)
    if not fin.all():
        lo, hi = _holes(t, fin)
        k = np.searchsorted(lo, te, side="left") - 1       # the last hole starting before the frame ends
        hit = (k >= 0) & (hi[np.maximum(k, 0)] > ts)       # holes are disjoint: only that one can reach it
        return np.where(hit, np.nan, frame_speed(t[fin], v[fin], te, te - ts))
    if t.size == 1:
        return np.where((te >= t[0]) & (ts <= t[0]), v[0], np.nan)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])

    def integral(x):
        xc = np.clip(x, t[0], t[-1])
        j = np.clip(np.searchsorted(t, xc, side="right") - 1, 0, t.size - 2)
        h = xc - t[j]
        slope = (v[j + 1] - v[j]) / (t[j + 1] - t[j])
        return cum[j] + h * (v[j] + 0.5 * slope * h)

    with np.errstate(invalid="ignore", divide="ignore"):
        out = (integral(te) - integral(ts)) / (te - ts)
    inside = (ts >= t[0] - 1e-9) & (te <= t[-1] + 1e-9)
    return np.where(inside, out, np.nan)


def _holes(t: np.ndarray, fin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Open intervals ``(lo, hi)``, s, between the finite neighbours of each run of NaN speeds."""
    good = np.flatnonzero(fin)
    pos = np.unique(np.searchsorted(good, np.flatnonzero(~fin)))    # one per run: the next finite sample's rank
    lo = np.where(pos > 0, t[good[np.maximum(pos - 1, 0)]], -np.inf)
    hi = np.where(pos < good.size, t[good[np.minimum(pos, good.size - 1)]], np.inf)
    return lo, hi
