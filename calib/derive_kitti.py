"""Derive KITTI's static sensor-to-ground extrinsics and rectified cameras from the raw calibration files.

Run ``python -m imu_ground.calib.derive_kitti PATH/TO/2011_09_26`` to rewrite ``kitti_imu.txt`` and
``kitti_cam0.txt`` ... ``kitti_cam3.txt`` in this folder (the cameras with their intrinsics ``K`` and
``image_size``). The derivation is in ``README.md`` beside this file and in
:mod:`imu_ground.perception.kitti_calib`, which also reads a calibration folder directly (``--camera DIR:2``).
"""
from __future__ import annotations

import sys
from pathlib import Path

from imu_ground.filters.extrinsics import Extrinsic, save_extrinsic
from imu_ground.perception.camera import Camera, save_camera
from imu_ground.perception.kitti_calib import IMU_HEIGHT, kitti_extrinsics, kitti_rectified_cameras, read_kitti_calib

__all__ = ["IMU_HEIGHT", "read_kitti_calib", "derive_kitti_extrinsics", "derive_kitti_cameras", "main"]


def derive_kitti_extrinsics(calib_dir: Path) -> dict[str, Extrinsic]:
    """KITTI IMU and rectified camera 0-3 extrinsics (ground <- sensor), by name (``kitti_imu``, ``kitti_cam0``, ...).

    Parameters
    ----------
    calib_dir : Path
        Folder with ``calib_imu_to_velo.txt``, ``calib_velo_to_cam.txt`` and ``calib_cam_to_cam.txt`` (e.g.
        ``kitti_raw/2011_09_26``).
    """
    return kitti_extrinsics(calib_dir)


def derive_kitti_cameras(calib_dir: Path) -> dict[str, Camera]:
    """The rectified cameras ``kitti_cam0`` ... ``kitti_cam3`` (intrinsics, image size, extrinsic ground <- camera)."""
    return {f"kitti_cam{i}": Camera(k, size, ext, name=f"kitti_cam{i}")
            for i, (ext, k, size) in kitti_rectified_cameras(calib_dir).items()}


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        raise SystemExit("usage: python -m imu_ground.calib.derive_kitti KITTI_RAW_DATE_FOLDER")
    here = Path(__file__).resolve().parent
    comment = ("{name}: static sensor-to-ground extrinsic (ground <- sensor){cam}.\n"
               "Derived by calib/derive_kitti.py; see calib/README.md.")
    save_extrinsic(derive_kitti_extrinsics(Path(argv[0]))["kitti_imu"], here / "kitti_imu.txt",
                   comment=comment.format(name="kitti_imu", cam=""))
    print(f"wrote {here / 'kitti_imu.txt'}")
    for name, cam in derive_kitti_cameras(Path(argv[0])).items():
        save_camera(cam, here / f"{name}.txt",
                    comment=comment.format(name=name, cam=", rectified camera: intrinsics K and image_size"))
        print(f"wrote {here / (name + '.txt')}")


if __name__ == "__main__":
    main()
