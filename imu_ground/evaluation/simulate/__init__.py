r"""Synthetic drives with exact ground truth: a vehicle on a rough road, and its IMU.

Road (:class:`RoadParams`), vehicle and speed (:class:`VehicleParams`, :class:`SpeedParams`), IMU errors
(:class:`ImuErrorModel`), one drive (:func:`simulate`), a suite (:func:`simulate_suite`), the same road again
(:func:`second_pass`).

Conventions (frames and signs as in :mod:`imu_ground.so3`)
----------------------------------------------------------
- **World** ``w``: local level, z up, inertial (no Earth rotation); gravity ``g_w = (0, 0, -9.80665)``.
- **Body / ground** ``b`` (FLU), fixed to the body; origin on the road below the reference point
  (mid-wheelbase by default), displaced vertically by the heave.
- **Attitude** ``R (c <- a) = Rz(yaw) @ Ry(pitch) @ Rx(roll)``; pitch + nose DOWN, roll + left side UP
  (KITTI OXTS).
- **Road** ``r``: x along the road in the heading direction, z the normal of the macro road (grade,
  cross-slope) plus the roughness smoothed over 10 m (the rest shakes the body).
  ``R_wr = Rz(heading) @ Ry(-grade) @ Rx(bank)``: ``road_grade`` + uphill, ``road_bank`` + left edge higher.
- **Body relative to road**: ``E = R_rb = Ry(pitch) @ Rx(roll)`` (no side-slip); normal
  ``n_b = E^T e_z = [-sin(pitch), sin(roll) cos(pitch), cos(pitch) cos(roll)]``.
- **Sensor** ``s``: ``R_gs`` (body <- sensor), ``t_gs`` (its origin in the body frame, m);
  ``R_ws = R_wr @ E @ R_gs``, ``p_ws = p_wb + R_wb @ t_gs``, ``n_s = R_gs^T n_b``. The IMU measures
  ``w_s = R_gs^T w_b`` and ``f_s = R_ws^T (a_w - g_w)`` (about +9.81 up at rest).

Exactness: rotations and their first two derivatives are closed-form (septic smooth steps,
:mod:`~imu_ground.evaluation.simulate.smooth`); the suspension is discretised exactly for a
first-order-hold input on a fine grid; positions are the 3-point Gauss-Legendre integral of the
analytic velocity.
"""
from imu_ground.evaluation.simulate.drive import TRUTH_ANGLES, TRUTH_COLUMNS, SimResult, simulate
from imu_ground.evaluation.simulate.imu_errors import IMU_PRESETS, ImuErrorModel, imu_error_model
from imu_ground.evaluation.simulate.remount import remounted
from imu_ground.evaluation.simulate.road import (
    ISO8608_CLASSES, ISO8608_N0, ROAD_PLANE_WINDOW, RoadParams, iso8608_psd, road_profile
)
from imu_ground.evaluation.simulate.second_pass import second_pass
from imu_ground.evaluation.simulate.suite import simulate_suite
from imu_ground.evaluation.simulate.vehicle import SpeedParams, VehicleParams, suspension_response
from imu_ground.units import GRAVITY

__all__ = [
    "GRAVITY", "IMU_PRESETS", "ISO8608_CLASSES", "ISO8608_N0", "ROAD_PLANE_WINDOW", "TRUTH_ANGLES", "TRUTH_COLUMNS",
    "ImuErrorModel", "RoadParams", "SimResult", "SpeedParams", "VehicleParams", "imu_error_model",
    "iso8608_psd", "remounted", "road_profile", "second_pass", "simulate", "simulate_suite", "suspension_response",
]
