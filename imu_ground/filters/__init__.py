"""Filters: the invariant EKF on SO(3), the ground-normal estimators, extrinsics and calibration.

Module map (each imports only the ones above it, and the imu layer below):

- ``design``: discrete-time filter design; ``extrinsics``: static extrinsics and the calibration file format;
- ``status``: the calibrated 1-sigma of pitch and roll (``SigmaModel``) and the per-frame status with its reason;
- ``estimator``: the protocol, ``GroundEstimate``, ``GroundTrack``; ``frame_checks``: frame checks, ``on_invalid``;
- ``residual``: the invariant EKF on the residual both ground estimators run;
- ``invariant_ekf_kernel``, ``gravity_kernel``: the per-frame kernels of the invariant EKF and the gravity filter;
- ``invariant_ekf``, ``gravity_velocity``: the filters the estimators are built from;
- ``road``: road grade and bank relative to gravity; ``mount_monitor``: a sensor mount that moved;
  ``recalibration``: the estimate of a mount change (online re-estimation);
- ``gains``: suspension gains; ``suspension_model``: load, gains and body tilt;
- ``ground`` (``GroundNormalFilter``), ``suspension`` (``SuspensionAwareFilter``): the estimators, each one class
  with its state, step, batch run and saved state (:mod:`imu_ground.imu.warm_start`); ``constant_normal``
  (``ConstantNormal``, the static extrinsic alone);
- ``methods``: the one registry of the estimators by CLI name; ``calibration``: ``calibrate`` a platform.

The loops of ``frame_checks``, ``residual``, ``gravity_kernel`` and ``invariant_ekf_kernel`` are compiled by numba
(:mod:`imu_ground._jit`).
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    ".invariant_ekf": "InvariantEKF",
    ".estimator": "GroundEstimator GroundEstimate GroundTrack pitch_roll_from_normal as_egomotion",
    ".ground": "GroundNormalFilter",
    ".constant_normal": "ConstantNormal",
    ".gains": "DEFAULT_GAINS GAIN_BAND bandpass_gain_regression",
    ".gravity_velocity": "GravityEstimate GravityTrack GravityVelocityFilter",
    ".suspension": "SuspensionAwareFilter SuspensionTrack",
    ".extrinsics": ("Extrinsic load_extrinsic save_extrinsic available_extrinsics Calibration "
                    "load_calibration resolve_platform"),
    ".calibration": "calibrate",
    ".methods": "estimate_suspension_aware",
    ".status": "STATUSES",
    "imu_ground.so3": "euler_zyx twist_angle as_rotations",      # rotation helpers, re-exported from so3
    ".design": "butter_bandpass foh_filter",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
