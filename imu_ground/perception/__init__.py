"""Perception geometry: cameras, the per-frame road plane in a camera's axes, bird's-eye (IPM) homographies.

:mod:`~imu_ground.perception.camera` (:class:`Camera`, :func:`load_camera`), :mod:`~imu_ground.perception.kitti_calib`
(the KITTI raw calibration chain), :mod:`~imu_ground.perception.plane` (:class:`GroundPlane`, :class:`BevGrid`,
:func:`range_error`), :mod:`~imu_ground.perception.warp` (:func:`warp_to_bev`). Layer: above
:mod:`imu_ground.filters` (it reads extrinsic files), below :mod:`imu_ground.pipeline`. Names are imported lazily.
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    ".camera": "Camera available_cameras load_camera save_camera",
    ".plane": "BevGrid GroundPlane range_error",
    ".warp": "warp_to_bev",
    ".kitti_calib": "kitti_rectified_cameras kitti_extrinsics read_kitti_calib",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
