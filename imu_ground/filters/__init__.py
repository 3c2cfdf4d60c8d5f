"""Filters: the invariant EKF on SO(3), ground-normal estimators, extrinsics and calibration."""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    "InvariantEKF": "imu_ground.filters.invariant_ekf",
    "GroundNormalFilter": "imu_ground.filters.ground",
    "GroundEstimate": "imu_ground.filters.ground",
    "GroundTrack": "imu_ground.filters.ground",
    "pitch_roll_from_normal": "imu_ground.filters.ground",
    "DEFAULT_GAINS": "imu_ground.filters.suspension",
    "GAIN_BAND": "imu_ground.filters.suspension",
    "GravityEstimate": "imu_ground.filters.gravity_velocity",
    "GravityTrack": "imu_ground.filters.gravity_velocity",
    "GravityVelocityFilter": "imu_ground.filters.gravity_velocity",
    "SuspensionAwareFilter": "imu_ground.filters.suspension",
    "SuspensionTrack": "imu_ground.filters.suspension",
    "estimate_suspension_aware": "imu_ground.filters.suspension",
    "bandpass_gain_regression": "imu_ground.filters.suspension",
    "Extrinsic": "imu_ground.filters.extrinsics",
    "load_extrinsic": "imu_ground.filters.extrinsics",
    "save_extrinsic": "imu_ground.filters.extrinsics",
    "available_extrinsics": "imu_ground.filters.extrinsics",
    "Calibration": "imu_ground.filters.calibration",
    "calibrate": "imu_ground.filters.calibration",
    "load_calibration": "imu_ground.filters.calibration",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
