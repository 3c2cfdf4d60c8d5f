r"""Synthetic drives with exact ground truth: a vehicle on a rough road, and its IMU.

Modules: :mod:`~imu_ground.evaluation.simulate.road` (:class:`RoadParams`: layout and
ISO 8608 roughness), :mod:`~imu_ground.evaluation.simulate.vehicle` (:class:`VehicleParams`,
:class:`SpeedParams`: speed profile and suspension), :mod:`~imu_ground.evaluation.simulate.imu_errors`
(:class:`ImuErrorModel`), :mod:`~imu_ground.evaluation.simulate.kinematics` (exact sensor
motion), :mod:`~imu_ground.evaluation.simulate.drive` (:func:`simulate`, :class:`SimResult`),
:mod:`~imu_ground.evaluation.simulate.suite` (:func:`simulate_suite`),
:mod:`~imu_ground.evaluation.simulate.second_pass` (:func:`second_pass`: the same road again).

Conventions
-----------
Frames and signs as in the glossary of :mod:`imu_ground.so3`; specifically:

- **World** ``w``: local level, z up (ENU-like), treated as inertial (the Earth's
  rotation, 7.3e-5 rad/s, is not simulated); gravity ``g_w = (0, 0, -9.80665)``.
- **Body / ground frame** ``b`` (FLU): x forward, y left, z up, fixed to the
  vehicle body; its origin is on the road surface below the vehicle reference
  point (by default mid-wheelbase), displaced vertically by the body's heave.
- **Attitude** of a frame ``a`` relative to a frame ``c`` as ``R (c <- a) =
  Rz(yaw) @ Ry(pitch) @ Rx(roll)``; pitch positive = nose DOWN (right-handed
  about y-left), roll positive = left side UP (right-handed about x-forward),
  the KITTI OXTS convention.
- **Road frame** ``r`` at the vehicle: x along the road tangent in the heading
  direction, z the road-surface normal of the *macro* road (grade and
  cross-slope) plus the roughness smoothed over 10 m (the rest of the roughness
  is not part of the plane, it is what shakes the body). ``R_wr = Rz(heading) @
  Ry(-grade) @ Rx(bank)``: ``road_grade`` (rad) positive uphill; ``road_bank``
  (rad) positive when the left edge is higher.
- **Body relative to road**: ``E = R_rb = Ry(pitch) @ Rx(roll)`` (no side-slip).
  The ground normal in the body frame is ``n_b = E^T e_z = [-sin(pitch),
  sin(roll) cos(pitch), cos(pitch) cos(roll)]``.
- **Sensor** ``s``: ``R_gs`` (body/ground <- sensor) and ``t_gs`` (sensor origin in
  the body frame, m). ``R_ws = R_wr @ E @ R_gs``; ``p_ws = p_wb + R_wb @ t_gs``. The
  normal in the sensor frame is ``n_s = R_gs^T n_b``. The IMU measures, in the
  sensor frame, the angular rate of the sensor frame (``w_s = R_gs^T w_b``) and
  the specific force ``f_s = R_ws^T (a_w - g_w)`` (about ``+9.81`` up at rest).

Exactness
---------
Every rotation and its first two time derivatives are closed-form (septic smooth-step
profiles and their integrals, :mod:`~imu_ground.evaluation.simulate.smooth`); the
suspension is discretised exactly for a first-order-hold input on a fine grid; the
positions are the 3-point Gauss-Legendre integral of the analytic velocity. Noise-free
samples are the exact derivatives of the truth trajectory.
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
