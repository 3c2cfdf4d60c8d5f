"""IMU handling: the log container, standstills, preintegration, per-frame ego-motion, dead reckoning.

Rotations follow the glossary of :mod:`imu_ground.so3`: ``R_{a<-b}`` maps vectors
from frame b into frame a; attitudes are ``R_{world<-body}``; a frame's
``delta_R`` is ``R_{body_{k-1}<-body_k}``.
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    ".data": "ImuData",
    "imu_ground.units": "GRAVITY",
    ".standstill": "GyroBiasEstimate detect_standstill estimate_gyro_bias",
    ".preintegration": ("PreintegrationParams PreintegratedImu FrameDeltas "
                        "StreamingPreintegrator preintegrate make_frame_times"),
    ".egomotion": "EgoFrame EgoMotion imu_to_egomotion",
    ".dead_reckoning": "NavSolution attitude_from_accel dead_reckon dead_reckon_imu",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
