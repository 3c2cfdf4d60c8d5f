"""Filters: the invariant EKF on SO(3), the ground-normal estimators, extrinsics and calibration.

Module map (each imports only the ones above it, and the imu layer below):

- ``rotations``: increments in any form, heading twist, ZYX Euler angles, quaternions;
- ``design``: discrete-time filter design (band-pass, second-order response, IIR runner);
- ``extrinsics``: static extrinsics and the calibration file format (``Calibration``);
- ``estimator``: the estimator protocol, ``GroundEstimate``, ``GroundTrack``, ``track_table``, frame checks;
- ``residual``: the scalar residual filter both invariant-EKF estimators run on;
- ``invariant_ekf``, ``gravity_velocity``: the filters the estimators are built from;
- ``gains``: suspension gains (defaults, band-pass regression);
- ``ground`` (``GroundNormalFilter``), ``suspension`` (``SuspensionAwareFilter``): the estimators;
- ``methods``: the estimators by CLI name; ``calibration``: ``calibrate`` a platform.
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    "InvariantEKF": "imu_ground.filters.invariant_ekf",
    "GroundEstimator": "imu_ground.filters.estimator",
    "GroundEstimate": "imu_ground.filters.estimator",
    "GroundTrack": "imu_ground.filters.estimator",
    "pitch_roll_from_normal": "imu_ground.filters.estimator",
    "track_table": "imu_ground.filters.estimator",
    "as_egomotion": "imu_ground.filters.estimator",
    "GroundNormalFilter": "imu_ground.filters.ground",
    "DEFAULT_GAINS": "imu_ground.filters.gains",
    "GAIN_BAND": "imu_ground.filters.gains",
    "bandpass_gain_regression": "imu_ground.filters.gains",
    "GravityEstimate": "imu_ground.filters.gravity_velocity",
    "GravityTrack": "imu_ground.filters.gravity_velocity",
    "GravityVelocityFilter": "imu_ground.filters.gravity_velocity",
    "SuspensionAwareFilter": "imu_ground.filters.suspension",
    "SuspensionTrack": "imu_ground.filters.suspension",
    "estimate_suspension_aware": "imu_ground.filters.suspension",
    "Extrinsic": "imu_ground.filters.extrinsics",
    "load_extrinsic": "imu_ground.filters.extrinsics",
    "save_extrinsic": "imu_ground.filters.extrinsics",
    "available_extrinsics": "imu_ground.filters.extrinsics",
    "Calibration": "imu_ground.filters.extrinsics",
    "load_calibration": "imu_ground.filters.extrinsics",
    "resolve_platform": "imu_ground.filters.extrinsics",
    "calibrate": "imu_ground.filters.calibration",
    "euler_zyx": "imu_ground.filters.rotations",
    "twist_angle": "imu_ground.filters.rotations",
    "as_rotations": "imu_ground.filters.rotations",
    "butter_bandpass": "imu_ground.filters.design",
    "foh_filter": "imu_ground.filters.design",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
