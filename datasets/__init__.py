"""Readers of IMU logs; each returns a validated :class:`~imu_ground.imu.data.ImuData`.

Formats (:data:`FORMATS`, detected by :func:`read_imu`): ``kitti_oxts`` (:func:`read_kitti_oxts`), ``comma2k19``
(:func:`read_comma2k19`), ``nuscenes`` (:func:`read_nuscenes_imu`), ``rosbag`` (``rosbag.read_rosbag_imu``),
``parquet`` (:func:`read_parquet_table`), ``kitti_imu100`` (:func:`read_kitti_imu100`), ``table`` (any CSV or
DataFrame, :func:`read_table`); each registered with :func:`~imu_ground.datasets.skeleton.register_format` and
ending in :func:`~imu_ground.datasets.skeleton.finish` (validation, report in ``meta["validation"]``). Pose files
(KITTI odometry, TUM) are read by :func:`read_poses`; handed to :func:`read_imu` they get a :class:`PoseFileError`.
"""
from __future__ import annotations

from imu_ground.errors import ImuInputError, OptionError, PoseFileError, UnknownFormatError

from . import comma2k19 as _comma2k19  # noqa: F401  (each import registers its format)
from . import kitti_oxts as _kitti_oxts  # noqa: F401
from . import nuscenes as _nuscenes  # noqa: F401
from . import rosbag as _rosbag  # noqa: F401  (rosbags itself loads when a bag is read)
from .comma2k19 import read_comma2k19
from .kitti_imu100 import COLUMNS as KITTI_IMU100_COLUMNS
from .kitti_imu100 import read_drives_index, read_kitti_imu100
from .kitti_oxts import read_kitti_oxts
from .nuscenes import read_nuscenes_imu
from .options import READER_OPTIONS
from .poses import (PoseSequence, detect_pose_format, read_kitti_poses, read_poses, read_tum_poses, relative_rotations,
                    write_tum_poses)
from .skeleton import FORMATS, detect_format, finish, read_imu, register_format
from .table import from_dataframe, read_parquet_table, read_table

__all__ = ["FORMATS", "KITTI_IMU100_COLUMNS", "READER_OPTIONS", "ImuInputError", "OptionError", "PoseFileError",
           "PoseSequence", "UnknownFormatError", "detect_format", "detect_pose_format", "finish", "from_dataframe",
           "read_comma2k19", "read_drives_index", "read_imu", "read_kitti_imu100", "read_kitti_oxts",
           "read_kitti_poses", "read_nuscenes_imu", "read_parquet_table", "read_poses", "read_table", "read_tum_poses",
           "register_format", "relative_rotations", "write_tum_poses"]
