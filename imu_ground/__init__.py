"""imu-ground: ground plane normal (pitch and roll relative to the road) from ego-motion.

Main entry points
-----------------
- :class:`GroundNormalFilter`: relative rotations in, per-frame normal, pitch,
  roll and dynamic extrinsic out (streaming ``step`` or batch ``run``).
- :class:`InvariantEKF`: the filterpy-style invariant EKF on SO(3) under it.
- :mod:`imu_ground.datasets`: readers of IMU logs and odometry pose files.
- :mod:`imu_ground.so3`: rotations, batch-first.
"""
from .extrinsics import Extrinsic, available_extrinsics, load_extrinsic
from .ground import GroundEstimate, GroundNormalFilter, GroundTrack, pitch_roll_from_normal
from .imu_data import ImuData
from .invariant_ekf import InvariantEKF

__version__ = "0.1.0"
__all__ = [
    "__version__",
    "Extrinsic", "available_extrinsics", "load_extrinsic",
    "GroundEstimate", "GroundNormalFilter", "GroundTrack", "pitch_roll_from_normal",
    "ImuData", "InvariantEKF",
]
