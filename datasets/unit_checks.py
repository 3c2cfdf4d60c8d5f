"""Units and time scales told from the data, for tables whose units are not given.

Each check returns the unit it settles on and, when it converts, one warning text; where the data cannot
decide, it raises :class:`~imu_ground.errors.ImuInputError` naming ``time_unit``, ``gyro_unit`` or ``accel_unit``.

- time: the median step must give an IMU rate of 1-2000 Hz; epoch-sized times (1980-2100) fix the unit;
- gyro: a car does not turn faster than ~2 rad/s for 1 % of a drive: numbers that large are deg/s (a
  gentle drive in deg/s can stay below and is then not caught);
- accel: the median specific-force magnitude is about 9.8 in m/s^2, about 1 in g.

Logs longer than :data:`DECIDE_SAMPLES` rows are decided on that many rows evenly spread.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from imu_ground.errors import ImuInputError, UnitsWarning, warn_user
from imu_ground.units import DEG, GRAVITY

from .csvio import numeric
from .order_stats import median

__all__ = ["ACCEL_UNITS", "GYRO_UNITS", "TIME_UNITS", "check_units", "detect_accel_unit", "detect_gyro_unit",
           "detect_time_unit", "motion_in_si", "raw_times", "settle_unit", "unit_scale"]

#: Time units, to seconds.
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
#: Angular-rate units, to rad/s.
GYRO_UNITS: dict[str, float] = {"rad/s": 1.0, "deg/s": DEG}
#: Specific-force units, to m/s^2 (g = 9.80665 m/s^2).
ACCEL_UNITS: dict[str, float] = {"m/s^2": 1.0, "m/s2": 1.0, "g": GRAVITY}
#: The reader options that give the units (a format that converts units accepts them).
UNIT_OPTIONS = ("time_unit", "gyro_unit", "accel_unit")
_TABLES = {"time": TIME_UNITS, "gyro": GYRO_UNITS, "accel": ACCEL_UNITS}
_OPTION = {"time": "time_unit", "gyro": "gyro_unit", "accel": "accel_unit"}
_NAMES = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}

#: Rows (evenly spread) on which a long log's units are decided.
DECIDE_SAMPLES = 200_000
#: Plausible IMU sample rates, Hz (the time unit's test here, the validation's rate check).
RATE_RANGE = (1.0, 2000.0)
EPOCH_RANGE = (3.15e8, 4.1e9)       # 1980 .. 2100, s since 1970
GYRO_DEG_SURE = 2.0                 # 99th percentile |w| above this (rad/s): deg/s
GYRO_RAD_SURE = 1.0                 # ... below this: rad/s; between: ask


def _spread(x: np.ndarray) -> np.ndarray:
    """At most about :data:`DECIDE_SAMPLES` rows of ``x``, evenly spread."""
    return x[::max(1, x.shape[0] // DECIDE_SAMPLES)]


def unit_scale(kind: str, unit: str) -> float:
    """Factor converting ``unit`` to the ImuData unit of ``kind`` (``"time"``, ``"gyro"``, ``"accel"``).

    Raises
    ------
    ImuInputError
        Unknown ``kind`` or ``unit``; the message lists the allowed units and names the option.
    """
    if kind not in _TABLES:
        raise ValueError(f"unknown quantity {kind!r}; allowed: {list(_TABLES)}")
    table = _TABLES[kind]
    if unit not in table:
        raise ImuInputError(f"unknown {kind} unit {unit!r}; allowed: {list(table)} ({{hint}})",
                            option=_OPTION[kind])
    return table[unit]


def check_units(**units: str | None) -> None:
    """Refuse a bad ``time_unit``, ``gyro_unit`` or ``accel_unit`` (None: not given) before anything is read."""
    for option, unit in units.items():
        if unit is not None:
            unit_scale(option.removesuffix("_unit"), unit)


def raw_times(col: np.ndarray, name: str, source: str, row_lines) -> tuple[np.ndarray, str | None]:
    """Raw time values (int64 kept exact, for epoch ns) and a forced unit for datetime columns (else None)."""
    if col.dtype.kind == "M":
        return col.astype("datetime64[ns]").astype(np.int64), "ns"
    if col.dtype.kind in "iu":
        return col.astype(np.int64, copy=False), None
    return numeric(col, name, source, row_lines), None


def settle_unit(kind: str, given: str | None, detect: Callable, values: np.ndarray, *args: Any) -> str:
    """The unit given (checked), or the one ``detect(values, *args)`` (a ``detect_*`` here) tells, warning once."""
    if given is not None:
        unit_scale(kind, given)
        _check_given(kind, given, detect, values, *args)
        return given
    unit, note = detect(values, *args)
    if note:
        warn_user(note, UnitsWarning, _OPTION[kind], unit)
    return unit


def _check_given(kind: str, given: str, detect: Callable, values: np.ndarray, source: str, *args: Any) -> None:
    """Refuse a given time unit that gives no IMU rate; warn about a gyro unit the data read otherwise."""
    opt = f"{{opt}} {given}"
    if kind == "time":
        step = _median_step(values)
        if step is None:
            return
        rate = 1.0 / (step * TIME_UNITS[given])
        if RATE_RANGE[0] <= rate <= RATE_RANGE[1]:
            return
        try:
            unit, _ = detect(values, source, *args)
            other = f"read from the data, the unit is {_NAMES.get(unit, unit)} ({1.0 / (step * TIME_UNITS[unit]):.6g} Hz): " \
                    f"pass {{opt}} {unit} or leave it out"
        except ImuInputError:
            other = "give the unit of the time column, or leave it out to tell it from the data"
        raise ImuInputError(f"{source}: {opt} makes the median time step {step * TIME_UNITS[given]:.6g} s, "
                            f"{rate:.3g} Hz, no IMU's rate ({RATE_RANGE[0]:g}-{RATE_RANGE[1]:g} Hz); {other}",
                            option="time_unit")
    if kind == "gyro":
        try:
            unit, _ = detect(values, source, *args)
        except ImuInputError:                   # the data cannot tell: the unit given decides
            return
        q = _gyro_p99(values)
        if unit != given and q == q:
            seen = ("no car turns that fast in rad/s" if unit == "deg/s" else
                    f"{q * DEG:.3g} rad/s in deg/s, a car that hardly turns")
            warn_user(f"{source}: {opt} given, but the data read as {unit}: 1 % of the samples turn faster than "
                      f"{q:.3g} in the file's unit ({seen}); check the unit (leave {{opt}} out to tell it from "
                      "the data)", UnitsWarning, "gyro_unit")


def motion_in_si(gyro: np.ndarray, accel: np.ndarray, gyro_unit: str | None, accel_unit: str | None,
                 source: str) -> tuple[np.ndarray, np.ndarray, str, str]:
    """Angular rate and specific force (N, 3), body frame, in rad/s and m/s^2 (units as :func:`settle_unit`).

    Returns
    -------
    gyro, accel : ndarray (N, 3)
        In rad/s and m/s^2 (the arrays given when already so).
    gyro_unit, accel_unit : str
        The units they were in.
    """
    g_unit = settle_unit("gyro", gyro_unit, detect_gyro_unit, gyro, source)
    a_unit = settle_unit("accel", accel_unit, detect_accel_unit, accel, source)
    g, a = unit_scale("gyro", g_unit), unit_scale("accel", a_unit)
    return (gyro if g == 1.0 else gyro * g), (accel if a == 1.0 else accel * a), g_unit, a_unit


def _median_step(values: np.ndarray) -> float | None:
    """The median positive step of raw times over evenly spread neighbour pairs (None: no such step)."""
    v = np.asarray(values)
    fin = v if v.dtype.kind != "f" or np.isfinite(v).all() else v[np.isfinite(v)]   # no copy when all finite
    if fin.size < 2:
        return None
    stride = max(1, (fin.size - 1) // DECIDE_SAMPLES)   # steps of evenly spread pairs of neighbours
    steps = fin[1::stride] - fin[:-1:stride]
    steps = steps[steps > 0]
    return median(steps) if steps.size else None


def detect_time_unit(values: np.ndarray, source: str, column: str) -> tuple[str, str | None]:
    """Unit of a time column from its median step and magnitude: ``(unit, warning or None)``.

    Parameters
    ----------
    values : ndarray (N,)
        Raw times (any numeric dtype), in file order.
    source, column : str
        Named in messages.

    Raises
    ------
    ImuInputError
        Several units or none give a plausible rate (``option="time_unit"``).
    """
    v = np.asarray(values)
    step = _median_step(v)
    if step is None:
        return "s", None
    fin = v if v.dtype.kind != "f" or np.isfinite(v).all() else v[np.isfinite(v)]   # no copy when all finite
    first = float(abs(fin[0]))
    units = ("s", "ms", "us", "ns")
    rate_ok = [u for u in units if RATE_RANGE[0] <= 1.0 / (step * TIME_UNITS[u]) <= RATE_RANGE[1]]
    epoch = [u for u in units if EPOCH_RANGE[0] <= first * TIME_UNITS[u] <= EPOCH_RANGE[1]]
    choice = [u for u in rate_ok if u in epoch] if epoch else rate_ok
    if len(choice) == 1:
        u = choice[0]
        if u == "s":
            return u, None
        why = f"epoch-sized values ({first:.6g}) and " if epoch else ""
        return u, (f"{source}: time column {column!r} read as {_NAMES[u]} from the data: {why}median step "
                   f"{step:.6g} = {1.0 / (step * TIME_UNITS[u]):.6g} Hz (pass {{hint}} to say so)")
    rates = ", ".join(f"{u}: {1.0 / (step * TIME_UNITS[u]):.6g} Hz" for u in units)
    if not choice:
        msg = (f"{source}: cannot tell the unit of time column {column!r}: its median step {step:.6g} gives "
               f"no IMU rate of {RATE_RANGE[0]:g}-{RATE_RANGE[1]:g} Hz ({rates}); pass {{hint}}")
    else:
        msg = (f"{source}: cannot tell the unit of time column {column!r}: median step {step:.6g} fits "
               f"{' or '.join(choice)} ({rates}); pass {{hint}}")
    raise ImuInputError(msg, option="time_unit")


def detect_gyro_unit(gyro: np.ndarray, source: str) -> tuple[str, str | None]:
    """``"rad/s"`` or ``"deg/s"`` from the 99th percentile of the rate magnitude: ``(unit, warning or None)``.

    Raises
    ------
    ImuInputError
        The magnitude is between what a car does in rad/s and what deg/s shows (``option="gyro_unit"``).
    """
    q = _gyro_p99(gyro)
    if q != q or q <= GYRO_RAD_SURE:
        return "rad/s", None
    if q > GYRO_DEG_SURE:
        return "deg/s", (f"{source}: gyro read as deg/s from the data: 1 % of the samples turn faster than "
                         f"{q:.3g} in the file's unit, which no car does in rad/s (pass {{hint}} to say so)")
    raise ImuInputError(f"{source}: cannot tell the gyro unit: 1 % of the samples turn faster than {q:.3g} "
                        f"(fast for a car in rad/s, slow in deg/s); pass {{hint}} or gyro_unit='rad/s'",
                        option="gyro_unit", value="deg/s")


def _gyro_p99(gyro: np.ndarray) -> float:
    """The 99th percentile of the rate magnitude, in the file's unit (NaN without a finite sample)."""
    w = _spread(np.asarray(gyro, dtype=float))
    with np.errstate(over="ignore"):
        norms = np.linalg.norm(w[np.isfinite(w).all(axis=1)], axis=1)
    norms = norms[np.isfinite(norms)]          # (a norm of huge values overflows: left to the validation)
    return float(np.percentile(norms, 99)) if norms.size else float("nan")


def detect_accel_unit(accel: np.ndarray, source: str) -> tuple[str, str | None]:
    """``"m/s^2"`` or ``"g"`` from the median specific-force magnitude: ``(unit, warning or None)``."""
    a = _spread(np.asarray(accel, dtype=float))
    a = a[np.isfinite(a).all(axis=1)]
    if not a.size:
        return "m/s^2", None
    med = median(np.linalg.norm(a, axis=1))
    if abs(med - 1.0) < 0.25:
        return "g", (f"{source}: accelerometer read as units of g from the data: median specific-force "
                     f"magnitude {med:.4g} (pass {{hint}} to say so)")
    return "m/s^2", None
