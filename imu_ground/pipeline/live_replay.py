"""A log replayed through the live object (:class:`~imu_ground.pipeline.streaming.StreamingEstimator`) sample by
sample, and the track of its frames (:meth:`StreamingEstimator.run`, ``estimate --causal``, ``stream --replay``)."""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from imu_ground.imu.egomotion import EgoMotion

__all__ = ["frames_track", "replay"]


def replay(est: Any, t, gyro, accel, speed=None, *, start: tuple[int, int] = (0, 0),
           before: Callable[[int], None] | None = None,
           after: Callable[[list, int, int], None] | None = None) -> list:
    """Feed a log to ``est`` sample by sample as a stream would bring it, then flush: the one loop of ``estimate
    --causal`` and ``stream --replay``. Before each IMU sample come the speed samples up to the largest IMU stamp so
    far (after a stamp steps back those already due stay pushed: a stream's arrival clock does not step back).

    Parameters
    ----------
    est : StreamingEstimator
        The live object (:mod:`imu_ground.pipeline.streaming`, which imports this module).
    t, gyro, accel : array_like
        IMU stamps (s, as recorded), rates (rad/s), specific forces (m/s^2) in the sensor's axes; (n,), (n, 3).
    speed : tuple of array_like, optional
        ``(t, v)``, s and m/s, sorted by time (ignored by a method that takes no speed).
    start : tuple of int
        IMU and speed samples already fed (a resumed replay).
    before, after : callable, optional
        ``before(i)`` before IMU sample ``i`` and its speeds are pushed; ``after(frames, samples, speeds)`` after
        each (its frames, the IMU and speed samples fed so far) and after each speed sample that follows the last.

    Returns
    -------
    list of FrameEstimate
        Every frame in order; with ``after``, the flush's only.
    """
    t = np.asarray(t, dtype=float).tolist()
    g, a = np.asarray(gyro, float).tolist(), np.asarray(accel, float).tolist()
    out: list = []
    if speed is not None and est.speed_aided:
        ts_sp, v_sp = (np.asarray(x, dtype=float).tolist() for x in speed)
    else:
        ts_sp, v_sp = [], []
    first, j = start
    M = len(ts_sp)
    top = -math.inf
    push_speed, push_imu = est.push_speed, est.push_imu
    for i in range(first, len(t)):
        ti = t[i]
        if before is not None:
            before(i)
        if ti > top:
            top = ti
        while j < M and ts_sp[j] <= top:
            push_speed(ts_sp[j], v_sp[j])
            j += 1
        frames = push_imu(ti, g[i], a[i])
        if after is None:
            out += frames
        else:
            after(frames, i + 1, j)
    while j < M:
        push_speed(ts_sp[j], v_sp[j])
        j += 1
        if after is not None:
            after([], len(t), j)
    return out + est.flush()


def frames_track(frames: list, est: Any, egos: list | None = None) -> tuple:
    """A GroundTrack of streamed estimates (``est``'s extrinsic: road <- sensor), and the EgoMotion of their frames
    ``egos`` (:class:`~imu_ground.imu.egomotion.EgoFrame`; None: times, durations and flags alone, identities)."""
    from imu_ground.filters.estimator import GroundTrack
    n = len(frames)
    E = np.array([f.residual for f in frames]).reshape(n, 3, 3)
    P = np.array([f.P for f in frames]).reshape(n, 3, 3)
    t = np.array([f.t for f in frames])
    ts = np.array([f.t_start for f in frames])
    Rgs = None if est.extrinsic is None else est.extrinsic.rotation
    track = GroundTrack.from_residuals(E, np.tile(np.eye(3), (n, 1, 1)), P, np.tile(np.eye(3), (n, 1, 1)), Rgs,
                                       est.extrinsic.translation, t=t, valid=[f.valid for f in frames],
                                       pitch_std=[f.pitch_std for f in frames], roll_std=[f.roll_std for f in frames],
                                       status=[f.status_code for f in frames],
                                       status_reason=[f.status_reason for f in frames],
                                       road_grade=[f.road_grade for f in frames],
                                       road_bank=[f.road_bank for f in frames],
                                       road_grade_std=[f.road_grade_std for f in frames],
                                       road_bank_std=[f.road_bank_std for f in frames])
    if egos is None:
        dR, dv, dt, still, valid = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), t - ts, np.zeros(n, bool), \
            np.array([f.valid for f in frames], bool)
    else:
        dR, dv = np.array([e.delta_R for e in egos]).reshape(n, 3, 3), np.array([e.delta_v for e in egos]).reshape(n, 3)
        dt, still = np.array([e.delta_t for e in egos], float), np.array([e.stationary for e in egos], bool)
        valid = np.array([e.valid for e in egos], bool)
    em = EgoMotion(t, dR, dv, dt, still, valid, est.bias_gyro, "FLU", {"causal": True}, est.rate, True)
    return track, em
