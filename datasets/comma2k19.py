"""comma2k19 segments: the phone-grade IMU of ``processed_log/IMU``.

Layout (NumPy ``.npy`` arrays stored without extension)::

    <segment>/processed_log/IMU/gyro/t               (N,)   s, log clock
    <segment>/processed_log/IMU/gyro/value           (N, 3) rad/s
    <segment>/processed_log/IMU/accelerometer/t      (M,)   s, log clock
    <segment>/processed_log/IMU/accelerometer/value  (M, 3) m/s^2

Both are in the phone's own axes (frame ``"device"``, not rotated). The accelerometer is linearly
interpolated onto the gyro's times; ``meta["accel_alignment"]`` says how far apart the two bases were.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import ImuValidationWarning, MalformedFileError, warn_user
from imu_ground.imu.data import ImuData

from .skeleton import finish, register_format, with_finish_parameters
from .timestamps import check_timestamps

__all__ = ["find_imu_dir", "read_comma2k19"]


def find_imu_dir(path: str | Path) -> Path:
    """The ``IMU`` folder of a comma2k19 segment, given the segment, ``processed_log`` or ``IMU`` folder.

    Raises
    ------
    FileNotFoundError
        ``path`` missing or without ``processed_log/IMU`` (the message names it).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such folder")
    for cand in (p / "processed_log" / "IMU", p / "IMU", p):
        if (cand / "gyro").is_dir() or (cand / "accelerometer").is_dir():
            return cand
    raise FileNotFoundError(f"{p / 'processed_log' / 'IMU'}: no such folder "
                            f"({p} is not a comma2k19 segment)")


def _load(path: Path, ndim: int) -> np.ndarray:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as e:
        raise MalformedFileError(path, f"not a readable NumPy array file ({e}; empty or truncated?)") from e
    if arr.ndim != ndim or (ndim == 2 and arr.shape[1] != 3):
        want = "(N,)" if ndim == 1 else "(N, 3)"
        raise MalformedFileError(path, f"shape {arr.shape}, expected {want}")
    if arr.shape[0] == 0:
        raise MalformedFileError(path, "no samples (empty array)")
    return np.asarray(arr, dtype=float)


@with_finish_parameters
def read_comma2k19(path: str | Path, *, validate: bool = True, policy: str = "retime",
                   **validate_kw: Any) -> ImuData:
    """Read the IMU of a comma2k19 segment, accelerometer aligned onto gyro times.

    Parameters
    ----------
    path : str or Path
        The segment folder (holding ``processed_log``), or its ``processed_log`` or ``processed_log/IMU``
        folder.
    {finish_parameters}
        (the accelerometer's own times, only interpolated from, get ``"drop"`` under ``"retime"``)

    Returns
    -------
    ImuData
        ``t`` s from the first gyro sample, ``gyro`` rad/s, ``accel`` m/s^2 interpolated onto the gyro
        times, frame ``"device"``. ``meta``: ``format``, ``t0`` (first gyro time on the log clock, s),
        ``t0_clock``, ``accel_alignment`` (``method``, ``identical_time_bases``, ``max_offset_s``: largest
        distance from a gyro time to the nearest accelerometer time, ``n_gyro_outside_accel``: gyro samples
        dropped outside the accelerometer's span, ``n_accel_dropped``, ``accel_rate_hz``), ``validation``.

    Raises
    ------
    FileNotFoundError
        Missing folder or array file (named).
    MalformedFileError
        Unreadable array, wrong shape, t and value lengths that differ.
    """
    imu_dir = find_imu_dir(path)
    tg = _load(imu_dir / "gyro" / "t", 1)
    wg = _load(imu_dir / "gyro" / "value", 2)
    ta = _load(imu_dir / "accelerometer" / "t", 1)
    va = _load(imu_dir / "accelerometer" / "value", 2)
    for name, t_, v_ in (("gyro", tg, wg), ("accelerometer", ta, va)):
        if t_.shape[0] != v_.shape[0]:
            raise MalformedFileError(imu_dir / name / "value",
                                     f"{v_.shape[0]} samples but {imu_dir / name / 't'} has {t_.shape[0]}")
    identical = tg.shape == ta.shape and bool(np.array_equal(tg, ta))
    # the accelerometer's own time base must be finite and increasing for np.interp
    fin = np.flatnonzero(np.isfinite(ta))
    if fin.size < ta.size:
        warn_user(f"{imu_dir / 'accelerometer' / 't'}: {ta.size - fin.size} non-finite time(s) "
                  f"(first at index {int(np.flatnonzero(~np.isfinite(ta))[0])}); those "
                  f"accelerometer samples are not used", ImuValidationWarning)
    keep, _, _ = check_timestamps(ta[fin], "drop" if policy == "retime" else policy,  # type: ignore[arg-type]
                                  gaps="ignore", source=str(imu_dir / "accelerometer" / "t"), index=fin)
    sel = fin[keep]
    ta_k, va_k = ta[sel], va[sel]
    # gyro samples outside the accelerometer's span cannot be interpolated
    inside = ((tg >= ta_k[0]) & (tg <= ta_k[-1])) | ~np.isfinite(tg)
    n_out = int((~inside).sum())
    if n_out:
        warn_user(f"{imu_dir / 'gyro' / 't'}: {n_out} gyro sample(s) outside the accelerometer's "
                  f"time span [{ta_k[0]:.6f}, {ta_k[-1]:.6f}] s dropped (no accelerometer "
                  f"data to align)", ImuValidationWarning)
    tg_in, wg_in = tg[inside], wg[inside]
    acc = np.column_stack([np.interp(tg_in, ta_k, va_k[:, j]) for j in range(3)])
    if ta_k.size > 1 and tg_in.size:
        pos = np.clip(np.searchsorted(ta_k, tg_in), 1, ta_k.size - 1)
        off = np.minimum(np.abs(tg_in - ta_k[pos - 1]), np.abs(ta_k[pos] - tg_in))
        max_off = float(np.nanmax(off)) if np.isfinite(off).any() else float("nan")
    else:
        max_off = 0.0 if identical else float("nan")

    t_first = float(tg_in[0]) if tg_in.size and np.isfinite(tg_in[0]) else 0.0
    align = {"method": "accelerometer linearly interpolated onto the gyro times (numpy.interp per axis)",
             "identical_time_bases": identical, "max_offset_s": max_off, "n_gyro_outside_accel": n_out,
             "n_accel_dropped": int(ta.size - sel.size),
             "accel_rate_hz": float(1.0 / np.median(np.diff(ta_k))) if ta_k.size > 1 else float("nan")}
    meta: dict[str, Any] = {"format": "comma2k19", "t0": t_first, "t0_clock": "comma2k19 log clock (s)",
                            "accel_alignment": align}
    imu = ImuData(tg_in - t_first, wg_in, acc, "device", source=str(imu_dir), meta=meta)
    return finish(imu, validate=validate, policy=policy, **validate_kw)


def _probe(p: Path) -> bool:
    """A comma2k19 segment, ``processed_log`` or ``IMU`` folder (gyro and accelerometer arrays)."""
    return p.is_dir() and ((p / "processed_log" / "IMU").is_dir() or (p / "IMU" / "gyro").is_dir()
                           or ((p / "gyro").is_dir() and (p / "accelerometer").is_dir()))


register_format("comma2k19", _probe, read_comma2k19, "comma2k19 segment folder (processed_log/IMU)",
                priority=20)
