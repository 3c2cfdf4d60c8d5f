"""The per-frame 'how sure' fields of a suspension-aware batch: 1-sigma, road, mount monitor, status and reason.

One function, :func:`suspension_confidence`, the batch twin of what
:meth:`~imu_ground.filters.suspension.SuspensionAwareFilter.step` adds to each
estimate (:mod:`imu_ground.filters.status` for the 1-sigma and the status,
:mod:`imu_ground.filters.road` for grade and bank,
:mod:`imu_ground.filters.mount_monitor` for a mount that moved); it advances the
filter's road filter, mount monitor, clock and convergence latch as the frames would.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from imu_ground.filters.mount_monitor import monitor_track
from imu_ground.filters.road import NO_SPEED_REASON
from imu_ground.filters.status import DEGRADED, OK, SUSPENSION_STD, track_reasons, track_statuses

__all__ = ["suspension_confidence"]


def suspension_confidence(f, em, sub, good: np.ndarray, a: np.ndarray, load: np.ndarray, gains: np.ndarray,
                          gravity_cov: np.ndarray, E: np.ndarray, speed: Optional[np.ndarray]) -> dict:
    """The fields of a :class:`~imu_ground.filters.suspension.SuspensionTrack` that say how sure it is.

    Parameters
    ----------
    f : SuspensionAwareFilter
        The filter (its road filter, mount monitor, ``_time`` and ``_converged`` advance).
    em, sub : EgoMotion
        All F frames of the batch, and its G good ones.
    good : ndarray of bool (F,)
        The frames processed (others were skipped).
    a : ndarray (G,)
        The residual filter's horizontal variance per good frame, rad^2.
    load, gains : ndarray (G, 2)
        The suspension model's load (m/s^2) and the gains used (rad per m/s^2) per good frame.
    gravity_cov : ndarray (G, 6, 6)
        The gravity/velocity filter's covariance per good frame.
    E : ndarray (G, 3, 3)
        The residuals road <- body.
    speed : ndarray (G,) or None
        Measured speed per good frame, m/s.

    Returns
    -------
    dict
        ``pitch_std``, ``roll_std`` (rad; NaN on skipped frames), ``status``, ``status_reason``,
        ``road_grade``, ``road_bank``, ``road_grade_std``, ``road_bank_std`` (rad), each (F,).
    """
    n, m = len(good), len(sub)
    sg2 = (1.0 - f.load_share) ** 2 * 0.5 * (gravity_cov[:, 3, 3] + gravity_cov[:, 4, 4])
    pm, rm = SUSPENSION_STD
    var = np.stack([pm.variance(a, load[:, 0], load[:, 1], sg2 * (gains[:, 0] ** 2 + f.cross_gain ** 2)),
                    rm.variance(a, load[:, 0], load[:, 1], sg2 * gains[:, 1] ** 2)], axis=1)
    var_max = np.full(n, np.inf)
    std = np.full((n, 2), np.nan)                   # (a skipped frame has none, as in step)
    var_max[good], std[good] = var.max(axis=1), np.sqrt(var)
    road = np.full((n, 4), np.nan)
    sp = np.full(m, np.nan) if speed is None else speed
    rg = np.full((m, 3), np.nan)
    if speed is not None or f.road_filter.gravity_filter is not None:
        road[good], rg, _ = f.road_filter.run(sub, sp, E, np.sqrt(var[:, 0]), np.sqrt(var[:, 1]))
    times = np.cumsum(np.concatenate([[f._time], np.asarray(sub.delta_t, dtype=float)]))[1:]   # (as step sums)
    if m:
        f._time = float(times[-1])
    mm = f.mount_monitor
    degraded = np.zeros(n, dtype=bool)
    degraded[good] = monitor_track(mm, times, rg, np.asarray(sub.valid, dtype=bool) & np.isfinite(sp))
    codes, f._converged = track_statuses(var_max, em.stationary, em.valid, good, f._converged, degraded)
    details = np.where(degraded, mm.alarm, np.where(np.isnan(road[:, 0]), NO_SPEED_REASON, None))
    reasons = track_reasons(codes, np.sqrt(var_max), em.delta_t,
                            np.where((codes == OK) | (codes == DEGRADED), details, None))
    return dict(pitch_std=std[:, 0], roll_std=std[:, 1], status=codes, status_reason=reasons, road_grade=road[:, 0],
                road_bank=road[:, 1], road_grade_std=road[:, 2], road_bank_std=road[:, 3])
