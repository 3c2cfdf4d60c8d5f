"""KITTI raw calibration: the static extrinsics and the rectified cameras of one recording day.

A KITTI raw calibration folder (``2011_09_26/``) holds ``calib_imu_to_velo.txt``, ``calib_velo_to_cam.txt`` and
``calib_cam_to_cam.txt``. From them:

1. The OXTS RT3003 frame is FLU and mounted level in the car; the ground frame's axes are the IMU's
   (``R_g_imu = I``) and its origin is on the road below the IMU, which is :data:`IMU_HEIGHT` up (KITTI sensor
   set-up, Geiger et al., IJRR 2013).
2. ``T_velo_imu`` (imu_to_velo) and ``T_cam0_velo`` (velo_to_cam) map points of the first frame into the second;
   ``R_rect_00`` rotates camera 0 into the rectified frame shared by the four rectified cameras. Rectified camera
   ``i`` differs from rectified camera 0 by a translation only: ``P_rect_0i = K_i [I | K_i^-1 p_i]`` (``p_i`` its
   last column), so ``T_recti_rect0 = [I | K_i^-1 p_i]``.
3. ``T_g_cami = T_g_imu · (T_recti_rect0 · R_rect_00 · T_cam0_velo · T_velo_imu)^-1``; rotations are projected onto
   SO(3) (the files carry 7 digits).

Camera axes: x right, y down, z forward (optical axis). Intrinsics ``K_i`` are ``P_rect_0i[:, :3]``, the image size
``S_rect_0i`` (width, height, pixels).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imu_ground.errors import MalformedFileError
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.so3 import project

__all__ = ["IMU_HEIGHT", "KITTI_CALIB_FILES", "KITTI_ROTATION_TOL", "read_kitti_calib", "kitti_extrinsics",
           "kitti_rectified_cameras"]

#: Height of the OXTS RT3003 above the road, metres (KITTI sensor set-up, Geiger et al. 2013, fig. 3).
IMU_HEIGHT = 0.93
#: The three files of a KITTI raw calibration folder.
KITTI_CALIB_FILES = ("calib_imu_to_velo.txt", "calib_velo_to_cam.txt", "calib_cam_to_cam.txt")
#: Largest ``|R^T R - I|`` of a rotation in the files: their 7 significant digits leave about 1e-7
#: (KITTI's own files); a typo (one wrong digit, a scaled matrix) leaves 1e-3 or more.
KITTI_ROTATION_TOL = 1e-5


def read_kitti_calib(path: str | Path) -> dict[str, np.ndarray]:
    """``key: numbers`` lines of a KITTI calibration file as arrays (text values such as ``calib_time`` skipped).

    Raises
    ------
    FileNotFoundError
        No such file.
    MalformedFileError
        Not a text file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"KITTI calibration file not found: {path}")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise MalformedFileError(path, f"not a text file (byte {e.start} is not UTF-8 text); a KITTI raw "
                                       "calibration file holds 'key: numbers' lines") from None
    out = {}
    for line in text.splitlines():
        if ":" not in line:
            continue
        key, value = line.split(":", 1)
        try:
            out[key.strip()] = np.array([float(v) for v in value.split()])
        except ValueError:
            continue
    return out


def _rigid(r: np.ndarray, t: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = np.reshape(r, (3, 3))
    m[:3, 3] = t
    return m


def _entry(calib: dict, key: str, size: int, path: Path) -> np.ndarray:
    if key not in calib or calib[key].size != size:
        raise MalformedFileError(path, f"no '{key}:' line with {size} numbers (is this a KITTI raw calibration "
                                       "file?)")
    value = calib[key]
    if not np.all(np.isfinite(value)):
        raise MalformedFileError(path, f"'{key}' has a value that is not finite ({' '.join(f'{v:g}' for v in value)})")
    return value


def _rotation(calib: dict, key: str, path: Path) -> np.ndarray:
    """The 3x3 rotation of entry ``key``, checked as camera and extrinsic files are (to the files' 7 digits)."""
    r = _entry(calib, key, 9, path).reshape(3, 3)
    err = float(np.abs(r.T @ r - np.eye(3)).max())
    det = float(np.linalg.det(r))
    if err > KITTI_ROTATION_TOL or det < 0:
        raise MalformedFileError(path, f"'{key}' is not a rotation (|R^T R - I| = {err:.2e}, det = {det:.6f}; "
                                       f"7-digit rotations are within {KITTI_ROTATION_TOL:g}): a typo in the file?")
    return r


def _intrinsics(p: np.ndarray, key: str, path: Path) -> np.ndarray:
    """``K`` of a rectified projection ``P_rect_0i`` (3x4), checked to be ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``."""
    k = p[:, :3].copy()
    if k[0, 0] <= 0 or k[1, 1] <= 0 or np.any(k[1:, :1] != 0) or k[2, 1] != 0 or k[2, 2] != 1:
        raise MalformedFileError(path, f"'{key}' does not start with intrinsics [[fx, s, cx], [0, fy, cy], "
                                       f"[0, 0, 1]], fx, fy > 0 (got {' '.join(f'{v:g}' for v in k.ravel())})")
    return k


def kitti_extrinsics(calib_dir: str | Path) -> dict[str, Extrinsic]:
    """The IMU's and the four rectified cameras' static extrinsics (ground <- sensor) of a KITTI raw folder.

    Parameters
    ----------
    calib_dir : str or Path
        KITTI raw calibration folder (e.g. ``kitti_raw/2011_09_26``).

    Returns
    -------
    dict
        ``{"kitti_imu": ..., "kitti_cam0": ..., ..., "kitti_cam3": ...}``; rotation ground <- sensor, translation
        the sensor origin in the ground frame (FLU, origin on the road below the IMU), m.
    """
    cams = kitti_rectified_cameras(calib_dir)
    src = f"{Path(calib_dir).name}/calib_*.txt"
    out = {"kitti_imu": Extrinsic(np.eye(3), np.array([0.0, 0.0, IMU_HEIGHT]),
                                  {"platform": "kitti", "sensor": "oxts_imu (FLU)", "derived_from": src})}
    out.update({f"kitti_cam{i}": ext for i, (ext, _, _) in cams.items()})
    return out


def kitti_rectified_cameras(calib_dir: str | Path) -> dict[int, tuple[Extrinsic, np.ndarray, tuple[int, int]]]:
    """Rectified cameras 0-3 of a KITTI raw calibration folder.

    Returns
    -------
    dict
        Camera index -> ``(extrinsic, K, (width, height))``: extrinsic ground <- rectified camera (camera axes x
        right, y down, z forward), ``K`` the 3x3 intrinsics (pixels), image size in pixels.

    Raises
    ------
    FileNotFoundError
        No such folder or file.
    MalformedFileError
        A file lacks an entry the derivation needs, or holds one that is not finite, a rotation that is not one (to
        :data:`KITTI_ROTATION_TOL`) or intrinsics that are not; not a text file (the message names file and key).
    """
    calib_dir = Path(calib_dir)
    if not calib_dir.is_dir():
        raise FileNotFoundError(f"{calib_dir}: no such KITTI raw calibration folder (it holds "
                                f"{', '.join(KITTI_CALIB_FILES)})")
    iv_path, vc_path, cc_path = (calib_dir / f for f in KITTI_CALIB_FILES)
    iv, vc, cc = (read_kitti_calib(p) for p in (iv_path, vc_path, cc_path))
    t_velo_imu = _rigid(_rotation(iv, "R", iv_path), _entry(iv, "T", 3, iv_path))
    t_cam0_velo = _rigid(_rotation(vc, "R", vc_path), _entry(vc, "T", 3, vc_path))
    t_rect0_imu = _rigid(_rotation(cc, "R_rect_00", cc_path), np.zeros(3)) @ t_cam0_velo @ t_velo_imu
    t_g_imu = _rigid(np.eye(3), np.array([0.0, 0.0, IMU_HEIGHT]))
    out = {}
    for i in range(4):
        p = _entry(cc, f"P_rect_0{i}", 12, cc_path).reshape(3, 4)
        w, h = _entry(cc, f"S_rect_0{i}", 2, cc_path)
        k = _intrinsics(p, f"P_rect_0{i}", cc_path)
        t_recti_rect0 = _rigid(np.eye(3), np.linalg.solve(k, p[:, 3]))
        t_g_cam = t_g_imu @ np.linalg.inv(t_recti_rect0 @ t_rect0_imu)
        meta = {"platform": "kitti", "sensor": f"cam{i}_rect (x right, y down, z forward)",
                "derived_from": f"{calib_dir.name}/calib_*.txt"}
        out[i] = (Extrinsic(project(t_g_cam[:3, :3]), t_g_cam[:3, 3], meta), k, (int(round(w)), int(round(h))))
    return out
