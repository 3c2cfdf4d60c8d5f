"""A camera: pinhole intrinsics, image size and its static extrinsic (ground <- camera).

Camera axes x right, y down, z forward; pixel ``(u, v)`` (centres at whole numbers) sees the ray ``K^-1 (u, v, 1)``;
images are rectified. A camera file is an extrinsic file (``calib/README.md``) with two more lines, so it still
loads as an extrinsic::

    K: fx 0 cx 0 fy cy 0 0 1        # 3x3 intrinsics, row-major, pixels
    image_size: 1242 375            # width height, pixels

:func:`load_camera` reads a shipped name (``kitti_cam0`` ... ``kitti_cam3``), a file, or a KITTI raw calibration
folder with a camera index (``PATH/2011_09_26:2``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import ImuGroundError
from imu_ground.filters.extrinsics import Extrinsic, available_extrinsics, load_extrinsic, save_extrinsic

__all__ = ["Camera", "available_cameras", "load_camera", "save_camera"]

_KITTI_DIR = re.compile(r"^(?P<dir>.+):(?P<index>[^:/\\]*)$")


@dataclass
class Camera:
    """A rectified pinhole camera on the vehicle.

    Attributes
    ----------
    K : ndarray (3, 3)
        Intrinsics, pixels: ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
    image_size : tuple of int
        ``(width, height)``, pixels.
    extrinsic : Extrinsic
        Static ground <- camera: rotation (ground frame FLU, z up along the road normal at rest) and the camera
        origin in the ground frame, m (its ``z`` is the camera's height above the road at rest).
    name : str
        What it was loaded from.
    """
    K: np.ndarray
    image_size: tuple[int, int]
    extrinsic: Extrinsic = field(default_factory=Extrinsic)
    name: str = ""

    def __post_init__(self) -> None:
        self.K = np.array(self.K, dtype=float)
        if self.K.shape != (3, 3):
            raise ValueError(f"camera intrinsics K must be a 3x3 matrix, got shape {self.K.shape}")
        if not np.all(np.isfinite(self.K)):
            raise ValueError(f"camera intrinsics K has a value that is not finite "
                             f"({' '.join(f'{v:g}' for v in self.K.ravel())})")
        if self.K[0, 0] <= 0 or self.K[1, 1] <= 0 or np.any(self.K[1:, :1] != 0) or self.K[2, 1] != 0 \
                or self.K[2, 2] != 1:
            raise ValueError("camera intrinsics K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
        size = tuple(int(s) for s in self.image_size)
        if len(size) != 2 or min(size) <= 0 or tuple(self.image_size) != size:
            raise ValueError(f"camera image_size must be two whole numbers > 0 (width height), "
                             f"got {self.image_size!r}")
        self.image_size = size
        self.extrinsic = Extrinsic.coerce(self.extrinsic)

    @property
    def height(self) -> float:
        """The camera's height above the road at rest, m (``t_z`` of the extrinsic)."""
        return float(self.extrinsic.translation[2])

    def to_dict(self) -> dict[str, Any]:
        """Plain-number form (for output metadata): ``K``, ``image_size``, ``rotation`` (ground <- camera),
        ``translation`` (m), ``name``."""
        return {"name": self.name, "K": self.K.tolist(), "image_size": list(self.image_size),
                "rotation": self.extrinsic.rotation.tolist(), "translation": self.extrinsic.translation.tolist()}


def available_cameras() -> list[str]:
    """Shipped names that are cameras (extrinsic files with ``K`` and ``image_size``)."""
    return [n for n in available_extrinsics() if "K" in load_extrinsic(n).meta]


def _numbers(source: str, key: str, text: Any, count: int) -> np.ndarray:
    parts = str(text).split()
    try:
        values = np.array([float(p) for p in parts])
    except ValueError:
        raise ImuGroundError(f"{source}: '{key}' has a value that is not a number: {text!r}") from None
    if values.size != count:
        raise ImuGroundError(f"{source}: '{key}' needs {count} numbers, got {values.size}")
    return values


def load_camera(spec: str | Path | Camera) -> Camera:
    """A camera from a shipped name, a camera file, or a KITTI raw calibration folder and index.

    Parameters
    ----------
    spec : str, Path or Camera
        ``"kitti_cam2"`` (see :func:`available_cameras`); a file in the format of ``calib/README.md`` with ``K`` and
        ``image_size`` lines; ``"DIR:I"`` for rectified camera ``I`` (0-3) of the KITTI raw calibration folder
        ``DIR`` (derived as :mod:`imu_ground.perception.kitti_calib` says); a Camera is returned as it is.

    Raises
    ------
    FileNotFoundError
        No such file, folder or shipped name (the message lists the shipped cameras).
    ImuGroundError
        The file is not a camera (no ``K`` or ``image_size`` line) or a value is malformed; the message names the
        file.
    """
    if isinstance(spec, Camera):
        return spec
    text = str(spec)
    m = _KITTI_DIR.match(text)
    if m and not Path(text).exists() and (m["index"].isdigit() or Path(m["dir"]).is_dir()):
        from imu_ground.perception.kitti_calib import kitti_rectified_cameras
        if not (m["index"].isdigit() and int(m["index"]) <= 3):
            raise ImuGroundError(f"{text}: camera index {m['index']!r} is not one of KITTI's rectified cameras 0 "
                                 f"to 3 (e.g. {m['dir']}:2)")
        ext, k, size = kitti_rectified_cameras(Path(m["dir"]))[int(m["index"])]
        return Camera(k, size, ext, name=text)
    if Path(text).is_dir():
        from imu_ground.perception.kitti_calib import KITTI_CALIB_FILES
        if any((Path(text) / f).is_file() for f in KITTI_CALIB_FILES):
            raise ImuGroundError(f"{text}: a KITTI raw calibration folder needs the camera index, 0 to 3: use "
                                 f"{text}:2 (rectified camera 2, the left colour camera)")
        raise ImuGroundError(f"{text}: a folder, not a camera file (a camera file, calib/README.md, or a KITTI raw "
                             "calibration folder and camera index as DIR:2)")
    try:
        ext = load_extrinsic(spec)
    except FileNotFoundError as e:
        if Path(text).suffix or len(Path(text).parts) > 1 or Path(text).exists():
            raise FileNotFoundError(f"camera file not found: {text}") from None
        raise FileNotFoundError(f"no shipped camera named {text!r}; available: {', '.join(available_cameras())} "
                                "(or give a camera file, or a KITTI raw calibration folder as DIR:2)") from e
    source = ext.meta.get("source", text)
    missing = [k for k in ("K", "image_size") if k not in ext.meta]
    if missing:
        raise ImuGroundError(f"{source}: not a camera file: no {' or '.join(repr(k + ':') for k in missing)} line "
                             "(a camera file is an extrinsic file with 'K: 9 numbers' and 'image_size: W H'; "
                             "see calib/README.md)")
    k = _numbers(source, "K", ext.meta["K"], 9).reshape(3, 3)
    wh = _numbers(source, "image_size", ext.meta["image_size"], 2)
    if np.any(wh != np.round(wh)):
        raise ImuGroundError(f"{source}: 'image_size' must be two whole numbers (width height), got "
                             f"{ext.meta['image_size']!r}")
    meta = {k_: v for k_, v in ext.meta.items() if k_ not in ("K", "image_size")}
    try:
        return Camera(k, (int(wh[0]), int(wh[1])), Extrinsic(ext.rotation, ext.translation, meta), name=text)
    except ValueError as e:
        raise ImuGroundError(f"{source}: {e}") from None


def save_camera(camera: Camera, path: str | Path, comment: str = "") -> None:
    """Write a camera file (the extrinsic format with ``K`` and ``image_size`` lines, 17 significant digits)."""
    meta = {k: v for k, v in camera.extrinsic.meta.items() if k not in ("K", "image_size", "source")}
    meta["K"] = " ".join(f"{v:.17g}" for v in camera.K.ravel())
    meta["image_size"] = f"{camera.image_size[0]} {camera.image_size[1]}"
    save_extrinsic(Extrinsic(camera.extrinsic.rotation, camera.extrinsic.translation, meta), path, comment=comment)
