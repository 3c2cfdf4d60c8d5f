"""IMU handling: the log container, standstills, preintegration, per-frame ego-motion, dead reckoning.

Rotations follow the glossary of :mod:`imu_ground.so3`: ``R_{a<-b}`` maps vectors
from frame b into frame a; attitudes are ``R_{world<-body}``; a frame's
``delta_R`` is ``R_{body_{k-1}<-body_k}``.
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    "ImuData": "imu_ground.imu.data",
    "GRAVITY": "imu_ground.units",
    "GyroBiasEstimate": "imu_ground.imu.standstill",
    "detect_standstill": "imu_ground.imu.standstill",
    "estimate_gyro_bias": "imu_ground.imu.standstill",
    "PreintegrationParams": "imu_ground.imu.preintegration",
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
