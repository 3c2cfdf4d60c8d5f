r"""Revisit consistency: the road's attitude must repeat where a drive passes the same place twice.

Passing the same place twice in the same direction, ``road = INS attitude - estimated
attitude relative to the road`` (pitch and roll) must repeat; a difference is the estimator's
error (the mounting offset cancels; no grade reference needed). The INS and the estimators
share signs (pitch + nose down, roll + left side up); angles in rad unless a name ends in
``_deg``. The metric (:func:`revisit_consistency`) is ``mean |difference| / sqrt(2)``: the
per-pass error of two independent, alike passes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imu_ground.evaluation.metrics import wrap_pi
from imu_ground.evaluation.reference import MIN_SPEED, drop_out_of_order, sample_gap

__all__ = ["RevisitPairs", "drive_revisit_pairs", "ins_at_frames", "revisit_consistency", "revisit_differences",
           "revisit_pairs", "revisit_table"]

#: Pairing thresholds: metres, radians, seconds.
MAX_DISTANCE = 1.0
MAX_HEADING = math.radians(15.0)
MIN_SEPARATION = 30.0


@dataclass(frozen=True)
class RevisitPairs:
    """Frame pairs ``i < j`` (int (P,)) on the same place, same direction, and the INS ``ins_pitch``, ``ins_roll``
    at every frame (F,), rad."""
    i: np.ndarray
    j: np.ndarray
    ins_pitch: np.ndarray
    ins_roll: np.ndarray

    def __len__(self) -> int:
        return int(len(self.i))


def revisit_pairs(t: np.ndarray, x: np.ndarray, y: np.ndarray, heading: np.ndarray, speed: np.ndarray,
                  usable: np.ndarray | None = None, *, max_distance: float = MAX_DISTANCE,
                  max_heading: float = MAX_HEADING, min_separation: float = MIN_SEPARATION,
                  min_speed: float = MIN_SPEED) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of frames on the same place in the same direction, on different passes.

    Parameters
    ----------
    t, x, y, heading, speed : ndarray (F,)
        Frame times (s), horizontal position (m, any local level frame), heading (rad, modulo 2 pi),
        horizontal speed (m/s).
    usable : ndarray of bool (F,), optional
        Frames allowed to pair.
    max_distance, max_heading, min_separation, min_speed : float
        Largest distance (m) and heading difference (rad) of a pair, smallest time between its
        frames (s); both frames faster than ``min_speed`` (m/s).

    Returns
    -------
    i, j : ndarray of int (P,)
        The pairs, ``i < j``, sorted: each frame's closest partner (ties: the earliest), each pair once.
    """
    from scipy.spatial import cKDTree
    t, x, y, heading, speed = (np.asarray(a, dtype=float) for a in (t, x, y, heading, speed))
    ok = (speed > min_speed) & np.isfinite(x) & np.isfinite(y) & np.isfinite(heading) & np.isfinite(t)
    if usable is not None:
        ok &= np.asarray(usable, dtype=bool)
    idx = np.flatnonzero(ok)
    empty = np.zeros(0, dtype=int)
    if len(idx) < 2:
        return empty, empty
    # a < b, indices into idx
    near = cKDTree(np.column_stack([x[idx], y[idx]])).query_pairs(max_distance, output_type="ndarray")
    if len(near) == 0:
        return empty, empty
    a, b = idx[near[:, 0]], idx[near[:, 1]]
    keep = (np.abs(t[a] - t[b]) >= min_separation) & (np.abs(wrap_pi(heading[a] - heading[b])) <= max_heading)
    a, b = a[keep], b[keep]
    if len(a) == 0:
        return empty, empty
    dist = np.hypot(x[a] - x[b], y[a] - y[b])
    # each frame's closest partner: candidates from both ends, sorted by (frame, distance, partner)
    frame = np.concatenate([a, b])
    partner = np.concatenate([b, a])
    d2 = np.concatenate([dist, dist])
    order = np.lexsort((partner, d2, frame))
    frame, partner = frame[order], partner[order]
    first = np.r_[True, frame[1:] != frame[:-1]]
    lo, hi = np.minimum(frame[first], partner[first]), np.maximum(frame[first], partner[first])
    pairs = np.unique(np.column_stack([lo, hi]), axis=0)
    return pairs[:, 0].astype(int), pairs[:, 1].astype(int)


def ins_at_frames(df, times: np.ndarray) -> dict[str, np.ndarray]:
    """The INS attitude, position and speed of a ``kitti_imu100`` log at the frame times.

    Parameters
    ----------
    df : pandas.DataFrame
        The log (columns ``t, roll, pitch, yaw, ve, vn, px, py``; rad, m/s, m).
    times : ndarray (F,)
        Frame times, s, on the log's time base.

    Returns
    -------
    dict
        ``pitch, roll, yaw`` (rad), ``x, y`` (m), ``speed`` (m/s), interpolated (the yaw unwrapped);
        ``near`` (bool): a sample within 0.1 s of the frame.
    """
    d = drop_out_of_order(df)
    ts = d["t"].to_numpy(float)
    times = np.asarray(times, dtype=float)

    c = {k: d[k].to_numpy(float) for k in ("pitch", "roll", "yaw", "px", "py", "ve", "vn")}
    signals = {"pitch": c["pitch"], "roll": c["roll"], "yaw": np.unwrap(c["yaw"]), "x": c["px"], "y": c["py"],
               "speed": np.hypot(c["ve"], c["vn"])}
    return {**{k: np.interp(times, ts, v) for k, v in signals.items()}, "near": sample_gap(ts, times) <= 0.1}


def drive_revisit_pairs(drive, **thresholds) -> RevisitPairs:
    """The revisit pairs of a real drive with its raw log: valid frames near a sample (``thresholds``: as
    :func:`revisit_pairs`)."""
    em = drive.egomotion
    ins = ins_at_frames(drive.imu.to_dataframe(), em.t)
    usable = np.asarray(em.valid, dtype=bool) & ins["near"]
    i, j = revisit_pairs(em.t, ins["x"], ins["y"], ins["yaw"], ins["speed"], usable, **thresholds)
    return RevisitPairs(i, j, ins["pitch"], ins["roll"])


def revisit_differences(pairs: RevisitPairs, pitch: np.ndarray, roll: np.ndarray,
                        valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Differences of the road attitude between the passes, rad, over the pairs both of whose frames are valid.

    Parameters
    ----------
    pairs : RevisitPairs
    pitch, roll : ndarray (F,)
        Estimated body attitude relative to the road, rad.
    valid : ndarray of bool (F,), optional

    Returns
    -------
    d_pitch, d_roll : ndarray (P',)
        ``road(j) - road(i)`` with ``road = INS - estimate``.
    """
    road_p = pairs.ins_pitch - np.asarray(pitch, dtype=float)
    road_r = pairs.ins_roll - np.asarray(roll, dtype=float)
    v = np.ones(len(road_p), dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    keep = v[pairs.i] & v[pairs.j]
    i, j = pairs.i[keep], pairs.j[keep]
    return road_p[j] - road_p[i], road_r[j] - road_r[i]


def revisit_consistency(d_pitch: np.ndarray, d_roll: np.ndarray) -> dict[str, float]:
    """The metric: ``mean |difference| / sqrt(2)`` per angle, deg, and the pair count ``n``."""
    n = int(len(d_pitch))
    if n == 0:
        return {"n": 0, "pitch_deg": math.nan, "roll_deg": math.nan}
    s = math.degrees(1.0) / math.sqrt(2.0)
    return {"n": n, "pitch_deg": float(np.mean(np.abs(d_pitch)) * s), "roll_deg": float(np.mean(np.abs(d_roll)) * s)}


def revisit_table(results):
    """Revisit consistency per drive and pooled over drives (pairs), per method, from :func:`~.runner.evaluate`.

    Parameters
    ----------
    results : pandas.DataFrame
        The evaluation's rows (``revisit_n``, ``revisit_pitch_sum``, ``revisit_roll_sum``, deg).

    Returns
    -------
    pandas.DataFrame
        Index (drive, method; drive ``pooled`` over the drives); ``pairs``, ``pitch_deg``, ``roll_deg``. Empty
        without pairs.
    """
    import pandas as pd
    empty = pd.DataFrame(columns=["pairs", "pitch_deg", "roll_deg"])
    if "revisit_n" not in results.columns:
        return empty
    ok = results[results["valid"] & (results["revisit_n"].fillna(0) > 0)]
    rows = []
    s = 1.0 / math.sqrt(2.0)
    for key, g in list(ok.groupby(["drive", "method"], sort=False)) + [
            (("pooled", m), g) for m, g in ok.groupby("method", sort=False)]:
        n = int(g["revisit_n"].sum())
        rows.append({"drive": key[0], "method": key[1], "pairs": n,
                     "pitch_deg": g["revisit_pitch_sum"].sum() / n * s,
                     "roll_deg": g["revisit_roll_sum"].sum() / n * s})
    return pd.DataFrame(rows).set_index(["drive", "method"]) if rows else empty
