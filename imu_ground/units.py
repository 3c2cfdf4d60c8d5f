"""Units and physical constants: the one owner of each.

Angles are radians and times seconds everywhere in the library; degrees appear only at the edges (CLI output columns
``*_deg``, documentation).
"""
from __future__ import annotations

import math

__all__ = ["GRAVITY", "DEG", "DEFAULT_FRAME_RATE", "MAX_GAP_FRAMES", "RENORM_EVERY"]

#: Standard gravity, m/s^2 (ISO 80000-3; the magnitude of "1 g").
GRAVITY: float = 9.80665

#: One degree in radians: ``x_deg * DEG`` is radians, ``x_rad / DEG`` degrees.
DEG: float = math.pi / 180.0

#: Default ego-motion frame rate, Hz (the paper's 10 Hz camera rate), used by the front end
#: (:func:`imu_ground.imu.egomotion.imu_to_egomotion`); estimators read the rate from their ego-motion.
DEFAULT_FRAME_RATE: float = 10.0

#: A forward step of the stamps longer than this many frame periods starts the frames again (a new segment)
#: instead of being integrated through as gap frames, whose number and memory would grow with the gap
#: (a clock set forward by a day: 864,000 frames at 10 Hz). An hour at 10 Hz.
MAX_GAP_FRAMES: int = 36_000

#: Frames between re-orthonormalisations of a cumulative rotation product (the rounding of 64 products
#: stays near 1e-14, and hours of data stay on SO(3)).
RENORM_EVERY: int = 64
