"""Suspension gains: the defaults, and the band-pass regression that estimates them from a drive.

The body tilts relative to the road in proportion to the load on the
suspension: pitch (nose down +) ``k_pitch u_x`` and roll (left side up +)
``k_roll u_y`` for a load ``u`` (m/s^2, body frame FLU). Both the gyro tilt and
the acceleration pass the same band-pass (:data:`GAIN_BAND`): lower
frequencies are confounded by the road (cars speed up downhill, roads bank
into curves), higher ones by the suspension's resonance and noise. The defaults are chosen by
``benchmarks/studies/tune_suspension.py``.
"""
from __future__ import annotations

from typing import Optional, Sequence

import numpy as np

from imu_ground import so3
from imu_ground.filters.design import butter_bandpass
from imu_ground.units import DEG

__all__ = ["DEFAULT_GAINS", "DEFAULT_CROSS_GAIN", "GAIN_BAND", "TYPICAL_BAND_POWER", "tilt_angles", "bandpass_gain_regression"]

#: Suspension gains of the KITTI car ``(k_pitch, k_roll)``, rad per m/s^2: braking dives the nose
#: (``k_pitch < 0``), a car rolls out of a turn (``k_roll > 0``; chosen where a drive passes the same place
#: twice, ``benchmarks/studies/revisit_table.py``).
DEFAULT_GAINS = (-0.25 * DEG, 0.40 * DEG)
#: Pitch (nose down +) per m/s^2 of *lateral* load ``u_y``, rad (empirical: road crown, chassis asymmetry).
DEFAULT_CROSS_GAIN = -0.05 * DEG
#: Band of the gain regression, Hz.
GAIN_BAND = (0.3, 1.5)
#: Mean band-passed acceleration power ``(a_x, a_y)`` of typical (KITTI) driving, (m/s^2)^2;
#: scales the weight of the prior gains in the online estimate.
TYPICAL_BAND_POWER = (0.0417, 0.0264)


def tilt_angles(body_increments: np.ndarray) -> np.ndarray:
    """Body pitch (about y) and roll (about x) integrated from the increments, rad, (N, 2)."""
    return np.cumsum(so3.log(np.asarray(body_increments, dtype=float))[:, [1, 0]], axis=0)


def bandpass_gain_regression(body_increments: np.ndarray, acceleration: np.ndarray,
                             band: Sequence[float] = GAIN_BAND, frame_rate: float = 10.0,
                             mask: Optional[np.ndarray] = None):
    """Suspension gains: band-passed gyro tilt regressed on the band-passed acceleration.

    Parameters
    ----------
    body_increments : ndarray (N, 3, 3)
        Body-frame rotation increments, body_{k-1} <- body_k.
    acceleration : ndarray (N, 2) or (N, 3)
        Gravity-compensated body acceleration per frame (``a_x, a_y``), m/s^2.
    band, frame_rate : (float, float), float
        Pass band and frame rate, Hz.
    mask : ndarray of bool (N,), optional
        Frames that enter the sums (after filtering), e.g. moving frames.

    Returns
    -------
    gains : ndarray (2,)
        ``(k_pitch, k_roll)``, rad per m/s^2 (NaN without signal).
    sxy, sxx : ndarray (2,)
        The sums (tilt x acceleration and acceleration^2) per axis.
    """
    from scipy.signal import lfilter
    b, a = butter_bandpass(band, frame_rate)
    y = lfilter(b, a, tilt_angles(body_increments), axis=0)
    x = lfilter(b, a, np.asarray(acceleration, dtype=float)[:, :2], axis=0)
    if mask is not None:
        m = np.asarray(mask, dtype=bool)[:, None]
        x, y = x * m, y * m
    sxy = np.sum(x * y, axis=0)
    sxx = np.sum(x * x, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(sxx > 0, sxy / sxx, np.nan)
    return k, sxy, sxx
