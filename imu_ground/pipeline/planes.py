"""A camera's road plane per output frame: the table's plane columns and the KITTI object ``planes`` files.

With a camera (:func:`~imu_ground.pipeline.estimate_log`'s ``camera=``, the CLI's
``--camera``), every frame's residual rotation road <- body gives the road plane
in the camera's axes (:meth:`GroundPlane.from_camera
<imu_ground.perception.GroundPlane.from_camera>`); frames that span a gap
(``valid`` false) get NaN, so nothing extrapolated reaches a detector.

- Table columns :data:`PLANE_COLUMNS` (``plane_a`` ... ``plane_d``: unit normal
  pointing up in camera axes, x right, y down, z forward, and the camera's height
  above the road, m) and, with a bird's-eye grid, :data:`BEV_COLUMNS`
  (``bev_h00`` ... ``bev_h22``: the homography bird's-eye pixel <- image pixel,
  row-major, ``h22 = 1``; OpenCV's ``warpPerspective`` matrix).
- :func:`write_kitti_planes`: one ``%06d.txt`` per output frame, the KITTI object
  ``planes`` format that monocular 3D detectors read::

      # Matrix
      WIDTH 4
      HEIGHT 1
      a b c d

  (a level road seen by KITTI's camera 2 is about ``0 -1 0 1.65``); gap frames hold
  ``nan nan nan nan`` so file indices stay aligned with frames.
"""
from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.datasets.options import OptionError
from imu_ground.errors import ImuGroundError
from imu_ground.perception import load_camera
from imu_ground.perception.camera import Camera
from imu_ground.perception.plane import BevGrid, GroundPlane
from imu_ground.pipeline.input_checks import check_creatable

__all__ = ["BEV_COLUMNS", "PLANE_COLUMNS", "PLANE_UNITS", "camera_plane", "check_camera", "check_planes_dir",
           "plane_columns", "read_kitti_planes", "write_kitti_planes"]

#: Plane columns of the output table with a camera.
PLANE_COLUMNS = ("plane_a", "plane_b", "plane_c", "plane_d")
#: Homography columns (bird's-eye pixel <- image pixel, row-major) with a camera and a bird's-eye grid.
BEV_COLUMNS = tuple(f"bev_h{i}{j}" for i in range(3) for j in range(3))
#: Unit (and meaning) of each of those columns.
PLANE_UNITS = {**{c: "1 (unit road normal pointing up, camera axes x right y down z forward; nan across gaps)"
                  for c in PLANE_COLUMNS[:3]},
               "plane_d": "m (camera height above the road: a x + b y + c z + d = 0 on the road; nan across gaps)",
               **{c: "1 (homography bird's-eye pixel <- image pixel, row-major, h22 = 1)" for c in BEV_COLUMNS}}
#: Number format of the planes files (KITTI's own have 7 significant digits).
PLANES_FORMAT = "%.9e"


def camera_plane(residual: Any, valid: Any, camera: Camera) -> GroundPlane:
    """The road plane of ``camera`` per frame: residual rotations road <- body, NaN where ``valid`` is false.

    Only the residual's road normal counts (the road frame's x is the body's heading
    projected onto the road: :meth:`GroundPlane.from_pitch_roll`), so a residual's
    yaw, which the road plane does not have, cannot turn a bird's-eye view.

    Parameters
    ----------
    residual : ndarray (N, 3, 3)
        Road <- body per frame (a track's ``residual``).
    valid : ndarray of bool (N,)
    camera : Camera
    """
    n = np.array(residual, dtype=float).reshape(-1, 3, 3)[:, 2, :]          # road normal in the body frame
    n[~np.asarray(valid, dtype=bool)] = np.nan
    pitch, roll = np.arctan2(-n[:, 0], np.hypot(n[:, 1], n[:, 2])), np.arctan2(n[:, 1], n[:, 2])
    return GroundPlane.from_pitch_roll(camera, pitch, roll)


def plane_columns(plane: GroundPlane, grid: BevGrid | None = None) -> dict[str, np.ndarray]:
    """The table columns of a plane: :data:`PLANE_COLUMNS`, and :data:`BEV_COLUMNS` when ``grid`` is given."""
    cols = dict(zip(PLANE_COLUMNS, plane.coefficients.T))
    if grid is not None:
        cols.update(zip(BEV_COLUMNS, plane.to_bev(grid).reshape(-1, 9).T))
    return cols


def check_planes_dir(path: str | Path, option: str = "--planes") -> Path:
    """Check, before any work, that ``path`` can be the planes folder (absent, or a folder we may write in).

    Raises
    ------
    ImuGroundError
        One line naming the path and the option.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ImuGroundError(f"{p}: is a file; give {option} a folder for the planes files")
    foreign = _foreign_files(p)
    if foreign:
        raise ImuGroundError(f"{p}: holds other files than planes files ({foreign[0].name}); give {option} a new or "
                             "empty folder, or one of planes files only (they are replaced)")
    check_creatable(p, option, start=p if p.exists() else p.parent)
    return p


def _foreign_files(folder: Path) -> list[Path]:
    """What a folder holds besides planes files (``%06d.txt``); empty for a missing folder."""
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if not re.fullmatch(r"[0-9]{6}\.txt", p.name))


def _planes_text(abcd: np.ndarray) -> str:
    return "# Matrix\nWIDTH 4\nHEIGHT 1\n" + " ".join(PLANES_FORMAT % v for v in abcd) + "\n"


def write_kitti_planes(folder: str | Path, coefficients: Any, first_index: int = 0) -> list[Path]:
    """Write one KITTI ``planes`` file per frame, ``%06d.txt`` from ``first_index``; NaN rows as ``nan``.

    All files are written into a temporary folder beside ``folder`` first, which then
    takes the folder's place: a failure leaves no partial file, and a folder of an
    earlier, longer run keeps no stale frames. A ``folder`` that holds anything but
    planes files is refused (nothing of the user's is deleted).

    Parameters
    ----------
    folder : str or Path
    coefficients : array_like (N, 4)
        ``a b c d`` per frame (:attr:`GroundPlane.coefficients`).
    first_index : int

    Returns
    -------
    list of Path
        The files, in frame order.
    """
    abcd = np.asarray(coefficients, dtype=float).reshape(-1, 4)
    out = Path(folder)
    check_planes_dir(out, "folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    names = [f"{first_index + i:06d}.txt" for i in range(len(abcd))]
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    old = tmp.with_name(tmp.name + ".old")
    try:
        for name, row in zip(names, abcd):
            (tmp / name).write_text(_planes_text(row), encoding="ascii")
        if out.exists():
            os.replace(out, old)
        os.replace(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(old, ignore_errors=True)
    return [out / n for n in names]


def read_kitti_planes(path: str | Path) -> np.ndarray:
    """``a b c d`` of one KITTI ``planes`` file (the fourth line), as the KITTI object loaders read it.

    Raises
    ------
    ImuGroundError
        Not in the format (the message names the file).
    """
    p = Path(path)
    lines = p.read_text().splitlines()
    if len(lines) < 4 or lines[:3] != ["# Matrix", "WIDTH 4", "HEIGHT 1"]:
        raise ImuGroundError(f"{p}: not a KITTI planes file (expected '# Matrix', 'WIDTH 4', 'HEIGHT 1', 'a b c d')")
    try:
        values = np.array([float(v) for v in lines[3].split()])
    except ValueError:
        raise ImuGroundError(f"{p}:4: the plane has a value that is not a number") from None
    if values.size != 4:
        raise ImuGroundError(f"{p}:4: expected 4 numbers, got {values.size}")
    return values


def check_camera(camera: Any, bev: Any) -> tuple[Any, Any]:
    """The :class:`~imu_ground.perception.Camera` and :class:`~imu_ground.perception.BevGrid` of
    :func:`~imu_ground.pipeline.estimate_log`'s ``camera`` and ``bev`` options (None when not given).

    Raises
    ------
    OptionError
        A camera that cannot be loaded, a grid that is not 5 numbers, or a grid without a camera,
        naming the option (``--camera`` / ``--bev`` on the command line).
    """
    if camera is None:
        if bev is not None:
            raise OptionError("{opt} needs a camera: add --camera NAME_OR_FILE", "bev")
        return None, None
    try:
        cam = load_camera(camera)
    except (ImuGroundError, FileNotFoundError) as e:
        text = " ".join(str(e).split())
        raise OptionError(f"{{opt}} {text}" if text.startswith(str(camera)) else f"{{opt}} {camera}: {text}",
                          "camera") from e
    if bev is None:
        return cam, None
    if isinstance(bev, BevGrid):
        return cam, bev
    try:
        values = [float(v) for v in bev]
        if len(values) != 5:
            raise ValueError(f"needs 5 numbers X0 X1 Y0 Y1 RES (m), got {len(values)}")
        return cam, BevGrid(*values)
    except (TypeError, ValueError) as e:
        raise OptionError(f"{{opt}} {' '.join(map(str, bev)) if isinstance(bev, (list, tuple)) else bev!r}: {e}",
                          "bev") from e
