"""imu-ground: ground plane normal (pitch and roll relative to the road) from ego-motion.

Layers (each imports only from the ones above it in this list)
----------------------------------------------------------------
- :mod:`imu_ground.so3`, :mod:`imu_ground.units`, :mod:`imu_ground.errors`: rotations (and the glossary of
  frames and signs), constants and units, the errors and warnings under their roots (:class:`ImuGroundError`,
  :class:`ImuGroundWarning`).
- :mod:`imu_ground.imu`: the IMU log container, standstills, preintegration, per-frame ego-motion.
- :mod:`imu_ground.datasets` and :mod:`imu_ground.filters` (siblings): readers of IMU logs and pose files,
  validation; the invariant EKF on SO(3), the ground-normal estimators, extrinsics and calibration.
- :mod:`imu_ground.perception`: cameras, the per-frame road plane in a camera's axes, bird's-eye homographies.
- :mod:`imu_ground.pipeline` and :mod:`imu_ground.evaluation` (siblings): a log or a fleet to files; reference,
  metrics, baselines, simulator, plots.
- :mod:`imu_ground.cli`: the ``imu-ground`` command.

The names below are imported lazily, on first use, so ``import imu_ground`` costs no more than numpy.
"""
from imu_ground._lazy import lazy_exports
from imu_ground._version import __version__ as __version__

_EXPORTS = {
    ".errors": "ImuGroundError MissingExtraError OptionError ImuInputError ImuValidationError MalformedFileError "
               "UnknownFormatError PoseFileError StorageError MissingFilesystemError MissingPacketsError ImuGroundWarning",
    ".imu.warm_start": "StateError",
    ".filters.calibration": "TooLittleDataError",
    ".imu.data": "ImuData",
    ".imu.egomotion": "EgoFrame EgoMotion imu_to_egomotion",
    ".imu.preintegration": "preintegrate PreintegrationParams StreamingPreintegrator",
    ".datasets": "read_imu read_poses",
    ".filters.invariant_ekf": "InvariantEKF",
    ".filters.estimator": "GroundEstimator GroundEstimate GroundTrack pitch_roll_from_normal",
    ".filters.ground": "GroundNormalFilter",
    ".filters.suspension": "SuspensionAwareFilter",
    ".filters.extrinsics": "Extrinsic available_extrinsics load_extrinsic",
    ".perception": "Camera GroundPlane load_camera",
    ".pipeline.estimate": "estimate_log",
    ".pipeline.streaming": "StreamingEstimator",
    ".pipeline.output": "track_table",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, {"imu_ground._version": "__version__", **_EXPORTS})
