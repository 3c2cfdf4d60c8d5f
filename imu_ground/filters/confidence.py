"""The per-frame 'how sure' fields of the suspension-aware filter: 1-sigma, road, mount monitor, status and reason.

:func:`suspension_confidence` for a batch; its streaming twins :func:`step_road_and_monitor`
(before the attitude update) and :func:`step_confidence` (after it), what
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
from imu_ground.filters.road import NO_SPEED_REASON, road_one
from imu_ground.filters.status import (CONVERGED_STD, DEGRADED, OK, SLOW_SPEED, SUSPENSION_STD, frame_status_code,
                                       ok_note, track_reasons, track_statuses)

__all__ = ["step_confidence", "step_road_and_monitor", "suspension_confidence"]

_CONVERGED_VAR = CONVERGED_STD * CONVERGED_STD
_I_GXX, _I_GYY = 21, 24                             # gravity kernel state: P[3, 3] and P[4, 4] (gravity_kernel)


def step_road_and_monitor(f, d, dv, dt: float, stationary: bool, valid: bool, speed: float) -> tuple:
    """One frame of the filter's road filter (from its first measured speed on) and mount monitor.

    Parameters
    ----------
    f : SuspensionAwareFilter
        Its ``road_filter``, ``mount_monitor`` and clock ``_time`` advance.
    d, dv, dt, stationary, valid
        The checked frame, as the gravity/velocity filter takes it (sensor_{k-1} <- sensor_k, m/s, s).
    speed : float
        Measured speed, m/s (NaN: none).

    Returns
    -------
    road : tuple or None
        The road filter's raw output (None before the first speed).
    alarm : str or None
        The mount monitor's reason once it has seen the mount move.
    """
    road = None
    if speed == speed or f.road_filter.gravity_filter is not None:
        road = f.road_filter.step(d, dv, dt, stationary, valid, speed)
    f._time += dt
    mm = f.mount_monitor
    alarm = mm.alarm
    if alarm is None and (road is not None or mm._hist or mm._armed_at == mm._armed_at):
        alarm = mm.update(f._time, None if road is None else road[0], valid and speed == speed)
    return road, alarm


def step_confidence(f, o, ux: float, uy: float, wp: float, wr: float, dt: float, stationary: bool, valid: bool,
                    road, alarm, psi: float, speed: float) -> tuple:
    """The status code, the 1-sigma inputs and the road of one processed frame (the batch twin:
    :func:`suspension_confidence`).

    Parameters
    ----------
    f : SuspensionAwareFilter
        Its gravity filter's covariance is read; its convergence latch ``_converged`` advances.
    o : sequence
        The residual kernel's output of the frame (``o[4]``: the slow state's level variance, rad^2).
    ux, uy : float
        The frame's load, m/s^2.
    wp, wr : float
        The suspension model's tilt weights of the gains used at this frame.
    dt : float
        Frame duration, s.
    stationary, valid : bool
        The frame's flags.
    road, alarm
        :func:`step_road_and_monitor`'s outputs.
    psi : float
        The frame's heading change about the ground's up axis, rad.
    speed : float
        The estimator's speed over the frame (measured, else estimated), m/s.

    Returns
    -------
    code : int
        :data:`~imu_ground.filters.status.STATUSES` index.
    info : tuple
        What :class:`~imu_ground.filters.estimator.GroundEstimate` derives the 1-sigma and the reason from.
    road : tuple or None
        Grade and bank with their variances (:func:`~imu_ground.filters.road.road_one`), or None.
    """
    g = f.gravity_filter._s                         # gravity's world-horizontal variances -> the modelled tilt
    sg2 = g.item(_I_GXX) + g.item(_I_GYY) if f._garray else g[_I_GXX] + g[_I_GYY]
    if road is not None:
        road = road_one(o, *road)
    yaw_rate = abs(psi) / dt
    recal = None if f.recalibrator is None else f.recalibrator.note     # (after an online re-estimation)
    note = alarm if alarm is not None else ok_note(abs(speed) < SLOW_SPEED,
                                                    recal if road is not None else NO_SPEED_REASON)
    info = (SUSPENSION_STD[0], SUSPENSION_STD[1], o[4], ux, uy, sg2 * wp, sg2 * wr, dt, note, CONVERGED_STD, yaw_rate)
    if not f._converged:
        pm, rm = SUSPENSION_STD
        f._converged = max(pm.variance(o[4], ux, uy, info[5], yaw_rate),
                           rm.variance(o[4], ux, uy, info[6], yaw_rate)) <= _CONVERGED_VAR
    return frame_status_code(f._converged, stationary, valid, alarm is not None), info, road


def suspension_confidence(f, em, sub, good: np.ndarray, a: np.ndarray, load: np.ndarray, gains: np.ndarray,
                          gravity_cov: np.ndarray, E: np.ndarray, speed: Optional[np.ndarray], yaw_rate: np.ndarray,
                          speed_used: np.ndarray) -> dict:
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
    yaw_rate : ndarray (G,)
        Heading change over frame duration per good frame, rad/s (signed).
    speed_used : ndarray (G,)
        The estimator's speed per good frame (measured, else estimated), m/s.

    Returns
    -------
    dict
        ``pitch_std``, ``roll_std`` (rad; NaN on skipped frames), ``status``, ``status_reason``,
        ``road_grade``, ``road_bank``, ``road_grade_std``, ``road_bank_std`` (rad), each (F,).
    """
    n, m = len(good), len(sub)
    sg2 = (1.0 - f.load_share) ** 2 * 0.5 * (gravity_cov[:, 3, 3] + gravity_cov[:, 4, 4])
    pm, rm = SUSPENSION_STD
    w = np.abs(yaw_rate)
    var = np.stack([pm.variance(a, load[:, 0], load[:, 1], sg2 * (gains[:, 0] ** 2 + f.cross_gain ** 2), w),
                    rm.variance(a, load[:, 0], load[:, 1], sg2 * gains[:, 1] ** 2, w)], axis=1)
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
    slow = np.zeros(n, dtype=bool)
    slow[good] = np.abs(speed_used) < SLOW_SPEED
    no_road = np.isnan(road[:, 0])
    notes = np.array([ok_note(s_, r_) for s_ in (False, True) for r_ in (None, NO_SPEED_REASON)], dtype=object)
    details = np.where(degraded, mm.alarm, notes[2 * slow + no_road])
    reasons = track_reasons(codes, np.sqrt(var_max), em.delta_t,
                            np.where((codes == OK) | (codes == DEGRADED), details, None))
    return dict(pitch_std=std[:, 0], roll_std=std[:, 1], status=codes, status_reason=reasons, road_grade=road[:, 0],
                road_bank=road[:, 1], road_grade_std=road[:, 2], road_bank_std=road[:, 3])
