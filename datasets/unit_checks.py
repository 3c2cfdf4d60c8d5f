"""Units and time scales told from the data, for tables whose units are not given.

Each check returns the unit it settles on and, when that is not the
ImuData unit, the one warning text saying what was converted; where the data
cannot decide, it raises :class:`~imu_ground.datasets.options.ImuInputError`
naming the option to pass (``time_unit``, ``gyro_unit``, ``accel_unit``).

- time: the median step must give an IMU rate of 1-2000 Hz, and times of epoch
  size (1980-2100 since 1970) fix the unit by their magnitude;
- gyro: a car does not turn at more than ~2 rad/s for 1 % of a drive; numbers
  that large are deg/s (a gentle drive in deg/s can stay below this and is
  then not caught);
- accel: the specific force's median magnitude is about 9.8 in m/s^2 and about
  1 in g.

The medians these checks and the validation take of whole logs come from
:func:`median` (the value ``np.median`` gives, without partitioning the whole
log); the retiming's running median of the clock offset near its jumps from
:func:`_medians_near`.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from imu_ground.units import DEG, GRAVITY

from .options import ImuInputError

__all__ = [
    "ACCEL_UNITS",
    "GYRO_UNITS",
    "TIME_UNITS",
    "detect_accel_unit",
    "detect_gyro_unit",
    "detect_time_unit",
    "median",
    "unit_scale",
]

#: Time units, to seconds.
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "ns": 1e-9}
#: Angular-rate units, to rad/s.
GYRO_UNITS: dict[str, float] = {"rad/s": 1.0, "deg/s": DEG}
#: Specific-force units, to m/s^2 (g = 9.80665 m/s^2).
ACCEL_UNITS: dict[str, float] = {"m/s^2": 1.0, "m/s2": 1.0, "g": GRAVITY}
_TABLES = {"time": TIME_UNITS, "gyro": GYRO_UNITS, "accel": ACCEL_UNITS}
_OPTION = {"time": "time_unit", "gyro": "gyro_unit", "accel": "accel_unit"}
_NAMES = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}

RATE_RANGE = (1.0, 2000.0)          # plausible IMU rates, Hz
EPOCH_RANGE = (3.15e8, 4.1e9)       # 1980 .. 2100, s since 1970
GYRO_DEG_SURE = 2.0                 # 99th percentile |w| above this (rad/s): deg/s
GYRO_RAD_SURE = 1.0                 # ... below this: rad/s; between: ask
_BLOCK = 1 << 15                    # values per block of a pass over a whole log (stays in the CPU cache)
_GROUP = 12                         # consecutive windows sharing one partition in _window_medians


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
    fin = v[np.isfinite(v)] if v.dtype.kind == "f" else v
    if fin.size < 2:
        return "s", None
    steps = np.diff(fin)
    steps = steps[steps > 0]
    if not steps.size:
        return "s", None
    step = median(steps)
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
    """``"rad/s"`` or ``"deg/s"`` from the 99th percentile of the rate magnitude; see the module docstring.

    Raises
    ------
    ImuInputError
        The magnitude is between what a car does in rad/s and what deg/s shows (``option="gyro_unit"``).
    """
    w = np.asarray(gyro, dtype=float)
    w = w[np.isfinite(w).all(axis=1)]
    if not w.size:
        return "rad/s", None
    q = float(np.percentile(np.linalg.norm(w, axis=1), 99))
    if q <= GYRO_RAD_SURE:
        return "rad/s", None
    if q > GYRO_DEG_SURE:
        return "deg/s", (f"{source}: gyro read as deg/s from the data: 1 % of the samples turn faster than "
                         f"{q:.3g} in the file's unit, which no car does in rad/s (pass {{hint}} to say so)")
    raise ImuInputError(f"{source}: cannot tell the gyro unit: 1 % of the samples turn faster than {q:.3g} "
                        f"(fast for a car in rad/s, slow in deg/s); pass {{hint}} or gyro_unit='rad/s'",
                        option="gyro_unit", value="deg/s")


def detect_accel_unit(accel: np.ndarray, source: str) -> tuple[str, str | None]:
    """``"m/s^2"`` or ``"g"`` from the median specific-force magnitude (about 9.8 or about 1).

    Anything else is left to the validation's units check (gravity removed, mg, ...).
    """
    a = np.asarray(accel, dtype=float)
    a = a[np.isfinite(a).all(axis=1)]
    if not a.size:
        return "m/s^2", None
    med = median(np.linalg.norm(a, axis=1))
    if abs(med - 1.0) < 0.25:
        return "g", (f"{source}: accelerometer read as units of g from the data: median specific-force "
                     f"magnitude {med:.4g} (pass {{hint}} to say so)")
    return "m/s^2", None


# --------------------------------------------------------------------------- order statistics
def median(x: np.ndarray, sqrt: bool = False) -> float:
    """``float(np.median(x))`` of a 1-D float64 array, found without partitioning all of it.

    The same order statistic(s) (the mean of the middle two for an even count)
    as NumPy's median, so the same value: a random sample brackets the middle
    ranks between two sample values, one pass counts the values below and
    gathers those between, and only these are sorted. NumPy's partition is
    slow on some data (many repeated values, or the extra maximum it
    partitions out for its NaN check). Falls back to ``np.median`` for short
    arrays, a NaN or when the bracket misses (a rare sample).

    ``sqrt=True``: the median of ``np.sqrt(x)`` (``x >= 0``, e.g. squared
    norms), from the square roots of the middle values of ``x`` (a monotone
    map keeps the order, so these are the middle values of ``np.sqrt(x)``).
    """
    x = np.asarray(x)
    n = x.size
    if x.ndim != 1 or x.dtype != np.float64 or n < 1 << 16:
        return float(np.median(np.sqrt(x) if sqrt else x))
    h = n // 2
    r0 = h if n % 2 else h - 1                           # the middle rank(s): r0 and h
    smp = np.sort(x[np.random.default_rng(0).integers(0, n, 1 << 14)])
    if np.isnan(smp[-1]):
        return float(np.median(np.sqrt(x) if sqrt else x))
    lo = smp[max(int(r0 / n * smp.size) - 400, 0)]       # ~6 standard deviations of a sample rank
    hi = smp[min(int(h / n * smp.size) + 400, smp.size - 1)]
    n_ge = n_le = n_mid = 0
    mids: list[np.ndarray] | None = [] if lo < hi else None  # lo == hi: no values to sort, only counts
    for i in range(0, n, _BLOCK):
        c = x[i:i + _BLOCK]
        ge, le = c >= lo, c <= hi
        n_ge += int(np.count_nonzero(ge))
        n_le += int(np.count_nonzero(le))
        if mids is not None:
            mids.append(c[np.logical_and(ge, le, out=ge)])
            n_mid += mids[-1].size
            if n_mid > n >> 3:           # a wide band (many repeats around the middle): not worth it
                return float(np.median(np.sqrt(x) if sqrt else x))
        else:
            n_mid += int(np.count_nonzero(np.logical_and(ge, le, out=ge)))
    below = n_le - n_mid                                 # values < lo (values > hi: n_ge - n_mid)
    if n_ge + below != n or not below <= r0 <= h < n_le:  # a NaN, or the middle not bracketed
        return float(np.median(np.sqrt(x) if sqrt else x))
    if mids is None:
        pair = np.array([lo, lo])
    else:
        mid = np.concatenate(mids)
        mid.sort()
        pair = mid[[r0 - below, h - below]]
    if sqrt:
        pair = np.sqrt(pair)
    return float(pair[1]) if n % 2 else float(np.mean(pair))


def _near(events: np.ndarray, h: int, n: int) -> np.ndarray:
    """The positions within ``[e - h - 1, e + h + 2)`` of an event ``e``: the union of these (sorted) ranges."""
    starts = np.clip(events - h - 1, 0, n)
    stops = np.clip(events + h + 2, 0, n)
    new = np.concatenate([[True], starts[1:] > stops[:-1]])      # a range not overlapping the one before
    lo = starts[new]
    hi = np.maximum.reduceat(stops, np.flatnonzero(new))
    lens = hi - lo
    return np.repeat(lo - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens) + np.arange(int(lens.sum()))


def _window_medians(xs: np.ndarray, q: np.ndarray, w: int) -> np.ndarray:
    """Medians of ``xs[p:p + w]`` (``w`` odd) for the window starts ``q`` (increasing).

    Consecutive starts share a partition: for ``S`` windows ``q0 .. q0+S-1`` the
    ``w - S + 1`` samples common to all (the core ``C``) hold the median of each
    window between their ranks ``h+1-S`` and ``h`` (0-based, ``h = w // 2``): the
    window adds only ``S - 1`` samples ``E`` to ``C``. Clamping every value to
    that band (a monotone map, which commutes with order statistics) shows the
    window's median is the ``S``-th smallest of ``band + E``, ``2S - 1``
    values. The result is the same order statistic ``np.median`` returns.
    """
    h = w // 2
    out = np.empty(q.size)
    if not q.size:
        return out
    brk = np.flatnonzero(np.diff(q) != 1) + 1
    run_lo = q[np.concatenate([[0], brk])]
    run_len = np.diff(np.concatenate([[0], brk, [q.size]]))
    s = min(_GROUP, h + 1, int(run_len.min()))
    if s < 2 or np.isnan(xs).any():             # short runs (or NaN, which np.median returns): window by window
        win = np.lib.stride_tricks.sliding_window_view(xs, w)
        for i in range(0, q.size, 4096):        # cache-sized batches, whatever the log's length
            out[i:i + 4096] = np.median(win[q[i:i + 4096]], axis=1, overwrite_input=True)
        return out
    ng = -(-run_len // s)                       # groups of s windows per run, the last one ending the run
    first = np.repeat(np.cumsum(ng) - ng, ng)
    g0 = np.minimum(np.repeat(run_lo, ng) + s * (np.arange(int(ng.sum())) - first),
                    np.repeat(run_lo + run_len - s, ng))
    view = np.lib.stride_tricks.sliding_window_view
    core = view(xs, w - s + 1)[g0 + s - 1]      # a gathered copy, (G, w - s + 1)
    core.partition(h, axis=1)                   # (one rank at a time: much faster than two at once)
    band = core[:, :h + 1]
    band.partition(h + 1 - s, axis=1)
    band = band[:, h + 1 - s:]                  # ranks h+1-s .. h of the core, any order
    pool = np.concatenate([view(xs, s - 1)[g0], view(xs, s - 1)[g0 + w]], axis=1)  # E of window i: pool[i:i+s-1]
    z = np.concatenate([np.broadcast_to(band[:, None, :], (g0.size, s, s)),
                        view(pool, s - 1, axis=1)[:, :s]], axis=2)
    z.partition(s - 1, axis=2)
    out[np.searchsorted(q, (g0[:, None] + np.arange(s)).ravel())] = z[:, :, s - 1].ravel()
    return out


def _medians_near(values: Callable[[np.ndarray], np.ndarray], n: int, near: np.ndarray, w: int) -> np.ndarray:
    """Centred running medians over ``w`` samples at positions ``near`` (edges padded with the end values).

    ``values(idx)`` gives the series at positions ``idx``; only the samples
    within ``w // 2`` of a position in ``near`` are asked for.
    """
    h = w // 2
    brk = np.flatnonzero(np.diff(near) != 1) + 1
    lo = near[np.concatenate([[0], brk])]
    length = np.diff(np.concatenate([[0], brk, [near.size]]))
    piece = length + 2 * h                      # each run of positions with its windows' margins
    offset = np.concatenate([[0], np.cumsum(piece)[:-1]])
    idx = np.repeat(lo - h - offset, piece) + np.arange(int(piece.sum()))
    xs = values(np.clip(idx, 0, n - 1))         # clipping pads the ends with the end values
    return _window_medians(xs, near + np.repeat(offset - lo, length), w)


def _running_median(x: np.ndarray, w: int, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centred running median over ``w`` (odd) samples (edges padded with the end values), and where it differs.

    Evaluated only within ``w // 2`` samples of an ``events`` position (a step
    that is not one sample period); elsewhere the window holds one undisturbed
    stretch and the value is taken as it is, so the cost follows the events,
    not the log's length. Returns the medians and the positions evaluated.
    """
    out = x.copy()
    if not events.size:
        return out, events
    near = _near(events, w // 2, x.size)
    out[near] = _medians_near(x.__getitem__, x.size, near, w)
    return out, near
