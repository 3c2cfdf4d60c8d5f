r"""Error metrics for ground-normal estimates, per frame and per drive: pitch and roll in rad, errors in deg.

Pitch and roll are the body's relative to the road (pitch + nose down, roll + left side up,
attitude ``Ry(pitch) @ Rx(roll)``); the road normal in the body frame (FLU) is
``n = (-sin p, sin r cos p, cos r cos p)``. Per frame (:func:`frame_errors`): the ``angle``
between the normals (deg, [0, 180]) and ``pitch``, ``roll`` estimate minus truth (deg, wrapped
to (-180, 180]). Per drive (:func:`summarize`): ``n``, ``mean``, ``median``, ``rms``, ``p95`` of
the absolute errors and ``bias`` (mean signed error). Mean removal (``remove_mean=True``, the
real-data protocol): estimate and reference each centred on their own mean over the evaluated
frames (the static mounting offsets a calibration removes).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import pandas as pd

__all__ = [
    "normal_from_pitch_roll", "normal_angle", "wrap_angle", "wrap_pi", "frame_errors", "summarize", "evaluate_drive",
    "per_drive_table"
]


def normal_from_pitch_roll(pitch, roll) -> np.ndarray:
    """Road normal in the body frame (FLU) for a body pitch and roll relative to the road.

    Parameters
    ----------
    pitch, roll : array_like, rad
        Broadcast together; pitch positive nose down, roll positive left up.

    Returns
    -------
    ndarray (..., 3)
        Unit vectors ``(-sin p, sin r cos p, cos r cos p)``.
    """
    p, r = np.broadcast_arrays(np.asarray(pitch, dtype=float), np.asarray(roll, dtype=float))
    cp = np.cos(p)
    return np.stack([-np.sin(p), np.sin(r) * cp, np.cos(r) * cp], axis=-1)


def normal_angle(n_est, n_true) -> np.ndarray:
    """Angle between two (not necessarily unit) vectors: ``atan2(|a x b|, a . b)``, exact at any angle.

    Parameters
    ----------
    n_est, n_true : array_like (..., 3)

    Returns
    -------
    ndarray (...)
        deg, in [0, 180].
    """
    a = np.asarray(n_est, dtype=float)
    b = np.asarray(n_true, dtype=float)
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    return np.degrees(np.arctan2(cross, dot))


def wrap_angle(a_deg) -> np.ndarray:
    """Wrap angles in degrees to (-180, 180]."""
    a = np.asarray(a_deg, dtype=float)
    return 180.0 - np.mod(180.0 - a, 360.0)


def wrap_pi(a_rad: np.ndarray) -> np.ndarray:
    """Wrap angles in rad to [-pi, pi)."""
    return (a_rad + np.pi) % (2.0 * np.pi) - np.pi


def frame_errors(est_pitch, true_pitch, est_roll=None, true_roll=None) -> pd.DataFrame:
    """Per-frame errors of an estimate against the truth.

    Parameters
    ----------
    est_pitch, true_pitch : array_like (N,), rad
    est_roll, true_roll : array_like (N,), rad, optional
        Both or neither.

    Returns
    -------
    pandas.DataFrame
        ``pitch`` and, with roll, ``roll`` and ``angle`` (module docstring), deg; NaN in, NaN out.
    """
    ep = np.asarray(est_pitch, dtype=float)
    tp = np.asarray(true_pitch, dtype=float)
    if ep.shape != tp.shape:
        raise ValueError(f"estimate and truth differ in shape: {ep.shape} vs {tp.shape}")
    out = {"pitch": wrap_angle(np.degrees(ep - tp))}
    if (est_roll is None) != (true_roll is None):
        raise ValueError("give both est_roll and true_roll, or neither")
    if est_roll is not None:
        er = np.asarray(est_roll, dtype=float)
        tr = np.asarray(true_roll, dtype=float)
        if er.shape != ep.shape or tr.shape != ep.shape:
            raise ValueError("roll arrays must have the shape of the pitch arrays")
        out["roll"] = wrap_angle(np.degrees(er - tr))
        out["angle"] = normal_angle(normal_from_pitch_roll(ep, er), normal_from_pitch_roll(tp, tr))
    return pd.DataFrame(out)


def summarize(errors, mask=None) -> dict[str, float]:
    """Summary statistics of one error series over the frames of a mask.

    Parameters
    ----------
    errors : array_like (N,)
        Errors, deg.
    mask : array_like of bool (N,), optional
        Frames to use (default all); non-finite errors are left out and counted in ``n_nonfinite``.

    Returns
    -------
    dict
        ``n``, ``mean``, ``median``, ``rms``, ``p95`` of ``|errors|``, ``bias``, ``n_nonfinite``; NaN without frames.
    """
    e = np.asarray(errors, dtype=float)
    m = np.ones(e.shape, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != e.shape:
        raise ValueError(f"mask shape {m.shape} differs from errors shape {e.shape}")
    finite = np.isfinite(e)
    n_nonfinite = int(np.count_nonzero(m & ~finite))
    x = e[m & finite]
    if x.size == 0:
        return {"n": 0, **dict.fromkeys(("mean", "median", "rms", "p95", "bias"), float("nan")),
                "n_nonfinite": n_nonfinite}
    a = np.abs(x)
    return {"n": int(x.size), "mean": float(a.mean()), "median": float(np.median(a)),
            "rms": float(np.sqrt(np.mean(x * x))), "p95": float(np.percentile(a, 95.0)),
            "bias": float(x.mean()), "n_nonfinite": n_nonfinite}


def evaluate_drive(est_pitch, true_pitch, est_roll=None, true_roll=None, mask=None,
                   remove_mean: bool = False) -> dict[str, dict[str, float]]:
    """Per-drive error summaries of pitch (and roll and normal angle when given).

    Parameters
    ----------
    est_pitch, true_pitch, est_roll, true_roll : array_like (N,), rad
        As :func:`frame_errors`.
    mask : array_like of bool (N,), optional
        Frames evaluated (e.g. ``Reference.valid``); frames with a non-finite input are left out too.
    remove_mean : bool
        The real-data protocol (module docstring).

    Returns
    -------
    dict
        ``{"pitch": ..., "roll": ..., "angle": ...}`` (the last two only with roll), each :func:`summarize`'s.
    """
    rolls = [np.asarray(a, dtype=float) for a in (est_roll, true_roll) if a is not None]
    if len(rolls) == 1:
        raise ValueError("give both est_roll and true_roll, or neither")
    arrays = [np.asarray(est_pitch, dtype=float), np.asarray(true_pitch, dtype=float), *rolls]
    n = arrays[0].shape
    for a in arrays:
        if a.shape != n or a.ndim != 1:
            raise ValueError("all angle arrays must be 1-D and of the same length")
    m = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != n:
        raise ValueError(f"mask shape {m.shape} differs from the data's {n}")
    use = m & np.logical_and.reduce([np.isfinite(a) for a in arrays])
    if remove_mean and np.any(use):
        arrays = [a - a[use].mean() for a in arrays]
    err = frame_errors(*arrays)
    return {k: summarize(err[k].to_numpy(), use) for k in err.columns}


def per_drive_table(per_drive: Mapping[str, Mapping[str, Any]], quantity: str = "pitch",
                  stat: str | None = None) -> pd.DataFrame:
    """Per-drive summaries of one quantity as a table, with the mean over drives.

    Parameters
    ----------
    per_drive : mapping
        Drive name to :func:`evaluate_drive`'s dict.
    quantity : {"pitch", "roll", "angle"}
    stat : str, optional
        Keep only this column (e.g. ``"mean"``).

    Returns
    -------
    pandas.DataFrame
        One row per drive plus ``"mean over drives"`` (each drive once; ``n`` summed).
    """
    rows = {name: dict(res[quantity]) for name, res in per_drive.items()}
    table = pd.DataFrame.from_dict(rows, orient="index")
    if len(table):
        agg = table.drop(columns=["n", "n_nonfinite"], errors="ignore").mean(skipna=True)
        agg["n"] = table["n"].sum()
        if "n_nonfinite" in table:
            agg["n_nonfinite"] = table["n_nonfinite"].sum()
        table.loc["mean over drives"] = agg
    return table if stat is None else table[[stat]]
