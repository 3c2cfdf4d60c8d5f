r"""Where the error is: driving conditions per frame, moving segments, and the reference's own uncertainty.

Conditions (:func:`frame_signals`, :func:`condition_masks`)
-----------------------------------------------------------
From signals real and synthetic drives both have, per frame: ``speed`` (m/s, the
reference's horizontal speed); ``acc_long`` (m/s^2, its central difference over
``+-ACC_WINDOW_S / 2``); ``yaw_rate`` (rad/s, from the ego-motion,
``log(R_gs delta_R R_gs^T)_z / delta_t``); ``pitch_rate_hf`` (rad/s, the RMS over a
centred ``ROUGH_WINDOW_S`` window of the body pitch rate minus its moving mean: road
roughness). A frame can be in several; all are restricted to the evaluated frames:

==================  ==============================================================
``speed_3_6``        ``3 < speed <= 6``
``speed_6_12``       ``6 < speed <= 12``
``speed_over_12``    ``speed > 12``
``turning``          ``|yaw_rate| > TURN_YAW_RATE``
``braking``          ``acc_long < -BRAKE_DECEL``
``near_stop``        within ``NEAR_STOP_S`` of a frame with ``speed < STOP_SPEED``
``rough``            ``pitch_rate_hf > ROUGH_PITCH_RATE``
==================  ==============================================================

Moving segments (:func:`moving_segments`, :func:`segment_centred`)
------------------------------------------------------------------
Runs of frames between stops (``speed < STOP_SPEED``), gaps included; the per-segment
metric removes the means per segment instead of per drive.

Reference uncertainty (:func:`reference_sigma`)
-----------------------------------------------
``sigma_ref = sqrt((INS_VU_NOISE / v)^2 + INS_PITCH_NOISE^2)`` (a slow vertical-velocity
error ``e_vu`` is a grade error ``e_vu / v``). A perfect estimator would score
``sqrt(2 / pi) * sigma_ref`` in mean absolute error (``ref_floor``); ``mean(sigma_ref^2) /
mean(error^2)`` is the share of the squared error the reference explains (``ref_share``);
per drive both capped at the method's own error. Synthetic drives: ``sigma_ref = 0``.
"""
from __future__ import annotations

import math

import numpy as np

from imu_ground import so3
from imu_ground.evaluation.reference import sample_gap
from imu_ground.units import DEG

__all__ = [
    "ACC_WINDOW_S", "BRAKE_DECEL", "CONDITIONS", "INS_PITCH_NOISE", "INS_VU_NOISE", "MIN_SEGMENT_FRAMES", "NEAR_STOP_S",
    "ROUGH_PITCH_RATE", "ROUGH_WINDOW_S", "SPEED_BINS", "STOP_SPEED", "TURN_YAW_RATE", "condition_masks",
    "frame_signals", "moving_segments", "reference_sigma", "segment_centred"
]

#: Speed bins, m/s: (key, low, high), low exclusive, high inclusive.
SPEED_BINS = (("speed_3_6", 3.0, 6.0), ("speed_6_12", 6.0, 12.0), ("speed_over_12", 12.0, math.inf))
#: Yaw rate above which a frame is turning, rad/s.
TURN_YAW_RATE = 0.1
#: Deceleration above which a frame is braking, m/s^2.
BRAKE_DECEL = 1.0
#: Speed below which the vehicle is stopped, m/s.
STOP_SPEED = 0.5
#: Frames within this many seconds of a stop are "near stop", s.
NEAR_STOP_S = 3.0
#: RMS of the high-passed body pitch rate above which the road is rough, rad/s.
ROUGH_PITCH_RATE = 1.1 * DEG
#: Window of the roughness measure, s.
ROUGH_WINDOW_S = 1.0
#: Span of the central difference for the longitudinal acceleration, s.
ACC_WINDOW_S = 1.0
#: Fewest evaluated frames of a moving segment in the per-segment metric.
MIN_SEGMENT_FRAMES = 30
#: INS vertical-velocity noise, m/s (slow, correlated), and pitch noise, rad.
INS_VU_NOISE = 0.03
INS_PITCH_NOISE = 0.03 * DEG
#: Condition keys and their labels in the reports, in report order.
CONDITIONS = {"speed_3_6": "3-6 m/s", "speed_6_12": "6-12 m/s", "speed_over_12": ">12 m/s",
              "turning": "turning", "braking": "braking", "near_stop": "within 3 s of a stop",
              "rough": "rough road"}


def _centred_mean(x: np.ndarray, half: int) -> np.ndarray:
    """Centred moving mean over ``2 half + 1`` samples, windows truncated at the ends, NaN ignored."""
    import pandas as pd
    return pd.Series(x).rolling(2 * half + 1, center=True, min_periods=1).mean().to_numpy()


def frame_signals(egomotion, extrinsic_rotation: np.ndarray, speed: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame signals that define the conditions (module docstring).

    Parameters
    ----------
    egomotion : EgoMotion
        Frames in the sensor frame (``delta_R`` sensor_{k-1} <- sensor_k, ``delta_t`` s, ``t`` s).
    extrinsic_rotation : ndarray (3, 3)
        Body/ground <- sensor.
    speed : ndarray (F,)
        Horizontal speed at the frames, m/s (NaN where unknown).

    Returns
    -------
    dict of ndarray (F,)
        ``speed`` m/s, ``acc_long`` m/s^2, ``yaw_rate`` rad/s, ``pitch_rate_hf`` rad/s.
    """
    r = np.asarray(extrinsic_rotation, dtype=float)
    d = r @ np.asarray(egomotion.delta_R, dtype=float) @ r.T
    dt = np.asarray(egomotion.delta_t, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        rate = so3.log(d) / np.where(dt > 0, dt, np.nan)[:, None] if len(d) else np.zeros((0, 3))
    t = np.asarray(egomotion.t, dtype=float)
    v = np.asarray(speed, dtype=float)
    fr = float(egomotion.rate)
    k = max(int(round(0.5 * ACC_WINDOW_S * fr)), 1)
    acc = np.full(v.shape, np.nan)
    if v.size > 2 * k:
        acc[k:-k] = (v[2 * k:] - v[:-2 * k]) / (t[2 * k:] - t[:-2 * k])
    half = max(int(round(0.5 * ROUGH_WINDOW_S * fr)), 1)
    hf = rate[:, 1] - _centred_mean(rate[:, 1], half)              # rate is (F, 3), also without frames
    return {"speed": v, "acc_long": acc, "yaw_rate": rate[:, 2], "pitch_rate_hf": np.sqrt(_centred_mean(hf * hf, half))}


def condition_masks(signals: dict[str, np.ndarray], t: np.ndarray) -> dict[str, np.ndarray]:
    """Boolean masks per condition (:data:`CONDITIONS`).

    Parameters
    ----------
    signals, t : dict, ndarray (F,)
        :func:`frame_signals`' signals and the frame times, s.
    """
    v = signals["speed"]
    with np.errstate(invalid="ignore"):
        out = {name: (v > lo) & (v <= hi) for name, lo, hi in SPEED_BINS}
        out["turning"] = np.abs(signals["yaw_rate"]) > TURN_YAW_RATE
        out["braking"] = signals["acc_long"] < -BRAKE_DECEL
        stopped = v < STOP_SPEED
        out["rough"] = signals["pitch_rate_hf"] > ROUGH_PITCH_RATE
    t = np.asarray(t, dtype=float)
    ts = t[stopped]                                   # increasing, as t is
    out["near_stop"] = sample_gap(ts, t) <= NEAR_STOP_S if ts.size else np.zeros(v.shape, dtype=bool)
    return {name: np.asarray(out[name], dtype=bool) for name in CONDITIONS}


def moving_segments(speed: np.ndarray) -> np.ndarray:
    """Segment index per frame: runs between stops get 0, 1, 2, ...; stopped frames -1.

    Parameters
    ----------
    speed : ndarray (F,)
        m/s; NaN (unknown) does not end a segment.
    """
    v = np.asarray(speed, dtype=float)
    with np.errstate(invalid="ignore"):
        stopped = v < STOP_SPEED
    starts = ~stopped & np.concatenate([[True], stopped[:-1]]) if v.size else stopped
    seg = np.cumsum(starts) - 1
    return np.where(stopped, -1, seg)


def segment_centred(est: np.ndarray, ref: np.ndarray, mask: np.ndarray, segments: np.ndarray):
    """Estimate minus reference with each one's mean removed per moving segment.

    Parameters
    ----------
    est, ref : ndarray (F,)
        Angles (any unit; the result has it).
    mask : ndarray of bool (F,)
        Evaluated frames.
    segments : ndarray of int (F,)
        From :func:`moving_segments`.

    Returns
    -------
    errors : ndarray (F,)
        NaN outside the evaluated frames of segments with :data:`MIN_SEGMENT_FRAMES` of them or more.
    """
    use = np.asarray(mask, dtype=bool) & np.isfinite(est) & np.isfinite(ref) & (segments >= 0)
    out = np.full(np.shape(est), np.nan)
    for s in np.unique(segments[use]):
        m = use & (segments == s)
        if np.count_nonzero(m) >= MIN_SEGMENT_FRAMES:
            out[m] = (est[m] - est[m].mean()) - (ref[m] - ref[m].mean())
    return out


def reference_sigma(speed: np.ndarray, vu_noise: float = INS_VU_NOISE,
                    pitch_noise: float = INS_PITCH_NOISE) -> np.ndarray:
    """Uncertainty (1 sigma, rad) of the INS pitch-relative-to-road reference per frame (module docstring).

    Parameters
    ----------
    speed : ndarray (F,)
        Horizontal speed, m/s (at or below 0: inf).
    vu_noise, pitch_noise : float
        INS vertical-velocity (m/s) and pitch (rad) noise.
    """
    v = np.asarray(speed, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        grade = np.where(v > 0, vu_noise / v, np.inf)
    return np.sqrt(grade * grade + pitch_noise * pitch_noise)
