"""imu-ground: ground plane normal (pitch and roll relative to the road) from ego-motion.

Layers (each imports only from the ones above it in this list)
----------------------------------------------------------------
- :mod:`imu_ground.so3`, :mod:`imu_ground.units`: rotations (and the glossary of
  frames and signs), constants and units.
- :mod:`imu_ground.imu`: the IMU log container, standstills, preintegration,
  per-frame ego-motion.
- :mod:`imu_ground.datasets`: readers of IMU logs and pose files, validation.
- :mod:`imu_ground.filters`: the invariant EKF on SO(3), the ground-normal
  estimators, extrinsics and calibration.
- :mod:`imu_ground.pipeline` and :mod:`imu_ground.evaluation` (siblings): a log or a
  fleet to files; reference, metrics, baselines, simulator, plots.
- :mod:`imu_ground.cli`: the ``imu-ground`` command.

The names below are imported lazily, on first use, so ``import imu_ground``
costs no more than numpy.
"""
from imu_ground._lazy import lazy_exports

__version__ = "0.2.0"

_EXPORTS = {
    "ImuData": "imu_ground.imu.data",
    "EgoFrame": "imu_ground.imu.egomotion",
    "EgoMotion": "imu_ground.imu.egomotion",
    "imu_to_egomotion": "imu_ground.imu.egomotion",
    "preintegrate": "imu_ground.imu.preintegration",
    "PreintegrationParams": "imu_ground.imu.preintegration",
    "read_imu": "imu_ground.datasets",
    "read_poses": "imu_ground.datasets",
    "InvariantEKF": "imu_ground.filters.invariant_ekf",
    "GroundEstimator": "imu_ground.filters.estimator",
    "track_table": "imu_ground.filters.estimator",
    "GroundEstimate": "imu_ground.filters.estimator",
    "GroundNormalFilter": "imu_ground.filters.ground",
    "GroundTrack": "imu_ground.filters.estimator",
    "pitch_roll_from_normal": "imu_ground.filters.estimator",
    "SuspensionAwareFilter": "imu_ground.filters.suspension",
    "Extrinsic": "imu_ground.filters.extrinsics",
    "available_extrinsics": "imu_ground.filters.extrinsics",
    "load_extrinsic": "imu_ground.filters.extrinsics",
    "estimate_log": "imu_ground.pipeline.estimate",
}
__all__ = ["__version__", *_EXPORTS]
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
