"""A camera's road plane per output frame: the table's plane columns and the KITTI object ``planes`` files.

With a camera (``camera=``, ``--camera``), every frame's residual rotation road <- body gives the road
plane in the camera's axes; frames that span a gap (``valid`` false) get NaN.

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

import contextlib
import json
import os
import re
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground._version import __version__
from imu_ground.errors import ImuGroundError, OptionError
from imu_ground.datasets.storage import is_url, local_name
from imu_ground.perception import load_camera
from imu_ground.perception.camera import Camera
from imu_ground.perception.plane import BevGrid, GroundPlane
from imu_ground.pipeline.input_checks import check_creatable, process_running

__all__ = ["BEV_COLUMNS", "PLANES_MARKER", "PLANE_COLUMNS", "PLANE_UNITS", "camera_plane", "check_camera",
           "check_planes_dir", "plane_columns", "read_kitti_planes", "write_kitti_planes"]

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
    """The road plane of ``camera`` per frame from the residuals' road normal (their yaw cannot turn a bird's-eye
    view), NaN where ``valid`` is false.

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
    cols = dict(zip(PLANE_COLUMNS, plane.coefficients.T, strict=True))
    if grid is not None:
        cols.update(zip(BEV_COLUMNS, plane.to_bev(grid).reshape(-1, 9).T, strict=True))
    return cols


#: Marker file in every planes folder this tool writes (written with the planes files): only a folder that holds
#: it (and nothing but planes files and this run's own outputs) is ever replaced.
PLANES_MARKER = ".imu-ground-planes"
_PLANES_NAME = re.compile(r"[0-9]{6}\.txt")


def _is_inside(path: str | Path, folder: Path) -> bool:
    p, f = Path(os.path.abspath(path)).resolve(), Path(os.path.abspath(folder)).resolve()
    return p == f or f in p.parents


def check_planes_dir(path: str | Path, option: str = "--planes", inputs: Sequence[str | Path] = (),
                     outputs: Sequence[str | Path] = ()) -> Path:
    """Check, before any work, that ``path`` can be the planes folder: absent, empty, or a folder this tool wrote
    (holding :data:`PLANES_MARKER`) with nothing but planes files and this run's own outputs, and no input.

    Parameters
    ----------
    path : str or Path
    option : str
        How the user named the folder (for messages).
    inputs, outputs : sequence of str or Path
        The input logs (never inside the folder) and outputs of the same run (allowed inside it).

    Raises
    ------
    OptionError
        One line naming the path, the file and the option.
    """
    path, name = local_name(path), option.lstrip("-")
    if is_url(path):
        raise OptionError(f"{path}: the planes folder is replaced as a whole, by a rename object storage does not "
                          "have; give {opt} a local folder (and copy it up afterwards)", name, flag=option)
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OptionError(f"{p}: is a file; give {{opt}} a folder for the planes files", name, flag=option)
    for src in inputs:
        if _is_inside(src, p):
            raise OptionError(f"{p}: holds the input {src}, and the planes folder is replaced as a whole; give "
                              "{opt} another folder", name, flag=option)
    foreign = _foreign_files(p, outputs)
    if foreign:
        if (p / PLANES_MARKER).is_file():
            why = f"holds {foreign[0].name}, which imu-ground did not write beside its planes files"
        else:
            why = (f"holds files that imu-ground did not write ({foreign[0].name}; a planes folder it wrote holds "
                   f"its marker {PLANES_MARKER})")
        raise OptionError(f"{p}: {why}; give {{opt}} a new or empty folder, or one an earlier {option} run "
                          "wrote (it is replaced); nothing was changed", name, flag=option)
    check_creatable(p, option, start=p if p.exists() else p.parent)
    return p


def _foreign_files(folder: Path, outputs: Sequence[str | Path] = ()) -> list[Path]:
    """What of a folder's content may not be replaced: all of it without the marker, else what is neither a planes
    file, nor one of ``outputs``, nor an interrupted write of one (``.NAME.*.tmp``)."""
    if not folder.is_dir():
        return []
    ours = (folder / PLANES_MARKER).is_file()
    allowed = {Path(os.path.abspath(o)).resolve() for o in outputs}
    staged = tuple(f".{Path(o).name}." for o in outputs)
    return sorted(e for e in folder.iterdir()
                  if not (ours and (e.name == PLANES_MARKER or (_PLANES_NAME.fullmatch(e.name) and e.is_file())
                                    or (e.name.startswith(staged) and e.name.endswith(".tmp") and e.is_dir()))
                          or e.resolve() in allowed))


@contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM until the block ends, then act on the first one received (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    held = (signal.SIGINT, signal.SIGTERM)
    old = {s: signal.signal(s, lambda signum, frame: received.append(signum)) for s in held}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, signal.SIG_DFL if h is None else h)
        if received:
            first = signal.Signals(received[0])
            handler = old[first]
            if callable(handler):
                handler(first, None)
            elif handler != signal.SIG_IGN:
                signal.raise_signal(first)


def _remove_planes_folder(folder: Path) -> None:
    """Remove a planes folder this tool wrote, its marker last (what is left is still recognised as ours)."""
    if not folder.is_dir():
        return
    for e in folder.iterdir():
        if e.name != PLANES_MARKER:
            shutil.rmtree(e, ignore_errors=True) if e.is_dir() and not e.is_symlink() else e.unlink(missing_ok=True)
    (folder / PLANES_MARKER).unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        folder.rmdir()


def _marker_pid(folder: Path) -> int | None:
    try:
        return int(json.loads((folder / PLANES_MARKER).read_text(encoding="utf-8")).get("pid"))
    except (OSError, ValueError, TypeError, AttributeError):
        return None


def _remove_stale_leftovers(out: Path) -> None:
    """Remove what an interrupted run left beside ``out`` (``.NAME.*.tmp`` of a process no longer running,
    ``.NAME.*.tmp.old``), each only when it holds :data:`PLANES_MARKER`."""
    prefix = f".{out.name}."
    for d in out.parent.iterdir():
        if not (d.name.startswith(prefix) and d.name.endswith((".tmp", ".tmp.old")) and d.is_dir()
                and (d / PLANES_MARKER).is_file()):
            continue
        pid = _marker_pid(d)
        if d.name.endswith(".old") or pid is None or not process_running(pid):
            _remove_planes_folder(d)


def _folder_mode(out: Path) -> int:
    """The replaced folder's permissions, or those the umask gives a new folder."""
    if out.is_dir():
        return stat.S_IMODE(out.stat().st_mode)
    mask = os.umask(0)
    os.umask(mask)
    return 0o777 & ~mask


def write_kitti_planes(folder: str | Path, coefficients: Any, first_index: int = 0, *,
                       inputs: Sequence[str | Path] = (), keep: Sequence[str | Path] = ()) -> list[Path]:
    """Write one KITTI ``planes`` file per frame, ``%06d.txt`` from ``first_index``; NaN rows as ``nan``.

    The files and :data:`PLANES_MARKER` go to a temporary folder beside ``folder``, which then takes its place
    (signals held over the renames): no partial file, no stale frames of a longer earlier run. Only a folder
    :func:`check_planes_dir` accepts is replaced; the permissions are the replaced folder's, or the umask's.

    Parameters
    ----------
    folder : str or Path
    coefficients : array_like (N, 4)
        ``a b c d`` per frame (:attr:`GroundPlane.coefficients`).
    first_index : int
    inputs : sequence of str or Path
        Input logs, which must not lie inside ``folder``.
    keep : sequence of str or Path
        This run's outputs inside ``folder``, carried over into the new folder.

    Returns
    -------
    list of Path
        The files, in frame order.

    Raises
    ------
    OptionError
        The folder is refused (:func:`check_planes_dir`) or cannot be written (naming ``folder``).
    """
    abcd = np.asarray(coefficients, dtype=float).reshape(-1, 4)
    out = Path(folder)
    check_planes_dir(out, "folder", inputs, keep)
    names = [f"{first_index + i:06d}.txt" for i in range(len(abcd))]
    tmp: Path | None = None
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        _remove_stale_leftovers(out)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
        os.chmod(tmp, _folder_mode(out))
        marker = {"written_by": f"imu-ground {__version__}", "what": "KITTI object planes files, one per frame",
                  "frames": len(names), "pid": os.getpid()}
        (tmp / PLANES_MARKER).write_text(json.dumps(marker) + "\n", encoding="utf-8")
        for name, row in zip(names, abcd, strict=True):
            (tmp / name).write_text("# Matrix\nWIDTH 4\nHEIGHT 1\n" + " ".join(PLANES_FORMAT % v for v in row) + "\n",
                                    encoding="ascii")
        for k in keep:
            k = Path(k)
            if k.is_file() and k.parent.resolve() == out.resolve():
                try:
                    os.link(k, tmp / k.name)
                except OSError:
                    shutil.copy2(k, tmp / k.name)
        with _signals_deferred():
            old = tmp.with_name(tmp.name + ".old")
            replaced = out.exists()
            if replaced:
                os.replace(out, old)
            try:
                os.replace(tmp, out)
            except OSError:
                if replaced:
                    os.replace(old, out)            # the old folder back: never neither
                raise
            _remove_planes_folder(old)
    except OSError as e:
        raise OptionError(f"{out}: cannot write the planes files ({e.strerror or e}); choose another {{opt}}",
                          "planes", flag="--planes") from None
    finally:
        if tmp is not None:
            with _signals_deferred():
                _remove_planes_folder(tmp)
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
        A camera that cannot be loaded, a grid that is not 5 numbers, or a grid without a camera.
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
