"""IMU handling: the log container, standstills, preintegration, per-frame ego-motion, dead reckoning."""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    "ImuData": "imu_ground.imu.data",
    "GRAVITY": "imu_ground.imu.standstill",
    "GyroBiasEstimate": "imu_ground.imu.standstill",
    "detect_standstill": "imu_ground.imu.standstill",
    "estimate_gyro_bias": "imu_ground.imu.standstill",
    "PreintegratedImu": "imu_ground.imu.preintegration",
    "FrameDeltas": "imu_ground.imu.preintegration",
    "StreamingPreintegrator": "imu_ground.imu.preintegration",
    "preintegrate": "imu_ground.imu.preintegration",
    "make_frame_times": "imu_ground.imu.preintegration",
    "EgoFrame": "imu_ground.imu.egomotion",
    "EgoMotion": "imu_ground.imu.egomotion",
    "imu_to_egomotion": "imu_ground.imu.egomotion",
    "NavSolution": "imu_ground.imu.dead_reckoning",
    "attitude_from_accel": "imu_ground.imu.dead_reckoning",
    "dead_reckon": "imu_ground.imu.dead_reckoning",
    "dead_reckon_imu": "imu_ground.imu.dead_reckoning",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
