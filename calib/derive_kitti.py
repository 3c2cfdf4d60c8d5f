"""Derive KITTI's static sensor-to-ground extrinsics from the raw calibration files.

Run ``python -m imu_ground.calib.derive_kitti PATH/TO/2011_09_26`` to rewrite
``kitti_imu.txt`` and ``kitti_cam0.txt`` in this folder. The derivation is in
``README.md`` beside this file.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from imu_ground.filters.extrinsics import Extrinsic, save_extrinsic

__all__ = ["IMU_HEIGHT", "read_kitti_calib", "derive_kitti_extrinsics", "main"]

#: Height of the OXTS RT3003 above the road, metres (KITTI sensor set-up, Geiger et al. 2013, fig. 3).
IMU_HEIGHT = 0.93


def read_kitti_calib(path: Path) -> dict[str, np.ndarray]:
    """``key: numbers`` lines of a KITTI calibration file as arrays (text values skipped)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"KITTI calibration file not found: {path}")
    out = {}
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        if ":" not in line:
            continue
        key, value = line.split(":", 1)
        try:
            out[key.strip()] = np.array([float(v) for v in value.split()])
        except ValueError:
            continue        # calib_time and other text fields
    return out


def _rigid(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = r.reshape(3, 3)
    m[:3, 3] = t
    return m


def derive_kitti_extrinsics(calib_dir: Path) -> dict[str, Extrinsic]:
    """KITTI IMU and rectified camera-0 extrinsics (ground <- sensor).

    Parameters
    ----------
    calib_dir : Path
        Folder with ``calib_imu_to_velo.txt``, ``calib_velo_to_cam.txt`` and
        ``calib_cam_to_cam.txt`` (e.g. ``kitti_raw/2011_09_26``).

    Returns
    -------
    dict
        ``{"kitti_imu": Extrinsic, "kitti_cam0": Extrinsic}``; rotations are
        projected onto SO(3) (the files carry 7 digits).
    """
    calib_dir = Path(calib_dir)
    iv = read_kitti_calib(calib_dir / "calib_imu_to_velo.txt")
    vc = read_kitti_calib(calib_dir / "calib_velo_to_cam.txt")
    cc = read_kitti_calib(calib_dir / "calib_cam_to_cam.txt")
    T_velo_imu = _rigid(iv["R"], iv["T"])
    T_cam0_velo = _rigid(vc["R"], vc["T"])
    T_rect0_cam0 = _rigid(cc["R_rect_00"], np.zeros(3))
    T_rect0_imu = T_rect0_cam0 @ T_cam0_velo @ T_velo_imu
    T_g_imu = _rigid(np.eye(3), np.array([0.0, 0.0, IMU_HEIGHT]))
    T_g_cam0 = T_g_imu @ np.linalg.inv(T_rect0_imu)

    def ext(m, sensor):
        u, _, vt = np.linalg.svd(m[:3, :3])
        r = u @ vt
        return Extrinsic(r, m[:3, 3], {"platform": "kitti", "sensor": sensor,
                                        "derived_from": f"{calib_dir.name}/calib_*.txt"})
    return {"kitti_imu": ext(T_g_imu, "oxts_imu (FLU)"),
            "kitti_cam0": ext(T_g_cam0, "cam0_rect (x right, y down, z forward)")}


def main(argv=None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        raise SystemExit("usage: python -m imu_ground.calib.derive_kitti KITTI_RAW_DATE_FOLDER")
    here = Path(__file__).resolve().parent
    for name, e in derive_kitti_extrinsics(Path(argv[0])).items():
        save_extrinsic(e, here / f"{name}.txt",
                       comment=f"{name}: static sensor-to-ground extrinsic (ground <- sensor).\n"
                               "Derived by calib/derive_kitti.py; see calib/README.md.")
        print(f"wrote {here / (name + '.txt')}")


if __name__ == "__main__":
    main()
