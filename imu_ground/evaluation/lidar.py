r"""LiDAR ground truth, the paper's protocol: road planes fitted to scans, and the estimate against them.

Plane fit (:func:`fit_ground_plane`)
    The points of a road region (:class:`RoadRegion`, a box in the LiDAR's axes x forward,
    y left, z up; or :class:`PathRegion`, the driven path) chosen by RANSAC (scikit-learn)
    or Patchwork++, then refitted by total least squares, the inliers re-chosen by their
    distance until they settle. Result: the unit normal pointing up and ``d`` with
    ``n . x + d = 0`` on the road (m). The extra ``.[lidar]`` brings scikit-learn,
    pypatchworkpp and the ``.pcd``/``.ply`` readers.

Frames and signs
    ``R_{g<-l}`` (:func:`lidar_rotation`) turns LiDAR vectors into the ground frame of the
    log's static extrinsic (FLU): with KITTI's calibration ``R_{g<-imu} R_{velo<-imu}^T``,
    with the project's extrinsic file its ``R``. ``n_b = R_{g<-l} n_l`` gives the body's
    pitch (+ nose down) and roll (+ left side up) relative to the road. Camera planes
    (KITTI ``planes`` files, rectified camera axes) turn with ``R_{g<-cam}``.

Comparison (:func:`compare_to_lidar`, :func:`lidar_summary`, :func:`bootstrap_spread`)
    Per scan, the estimate interpolated to the scan's time against the plane: the angle
    between the normals and the pitch and roll differences (estimate minus LiDAR, deg),
    with the constant offset and without it; the roll as changes only (the lane's crown).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from imu_ground.errors import ImuGroundError, OptionError, require_extra
from imu_ground.evaluation.metrics import normal_angle, normal_from_pitch_roll
from imu_ground.filters.estimator import pitch_roll_from_normal
from imu_ground.filters.extrinsics import Extrinsic, load_extrinsic
from imu_ground.so3 import project

__all__ = ["GROUND_FITS", "LIDAR_EXTRA", "PATCHWORK_MODULE", "ROAD_REGION", "SCAN_SUFFIXES", "PathRegion", "RoadRegion",
           "bootstrap_spread", "compare_to_lidar", "fit_ground_plane", "fit_scans", "kitti_object_rotation",
           "lidar_figure", "lidar_pitch_roll", "lidar_rotation", "lidar_summary", "lidar_table", "lidar_transform",
           "method_summaries", "path_region",
           "patchwork_available", "patchwork_ground", "planes_pitch_roll", "planes_rotations", "plot_lidar",
           "read_bin_scan", "read_scan", "read_scan_times", "read_times", "scan_files"]

#: The optional extra that installs the plane fit's and the readers' dependencies (scikit-learn, plyfile, pypcd4).
LIDAR_EXTRA = ".[lidar]"
#: Scan files read: KITTI Velodyne ``.bin`` (float32 x, y, z, reflectance; numpy), PCD (pypcd4), PLY (plyfile).
SCAN_SUFFIXES = (".bin", ".pcd", ".ply")


@dataclass(frozen=True)
class RoadRegion:
    """A box of the LiDAR's own axes (x forward, y left, z up) where the road is fitted.

    Attributes
    ----------
    x_min, x_max : float
        Ahead of the LiDAR, m.
    y_min, y_max : float
        To the left (negative: right), m.
    """
    x_min: float = 5.0
    x_max: float = 30.0
    y_min: float = -4.0
    y_max: float = 4.0

    def __post_init__(self) -> None:
        values = (self.x_min, self.x_max, self.y_min, self.y_max)
        if not all(math.isfinite(v) for v in values) or self.x_min >= self.x_max or self.y_min >= self.y_max:
            raise OptionError(f"{{opt}} {' '.join(f'{v:g}' for v in values)}: the road region needs finite X0 < X1 "
                              "and Y0 < Y1 (m, LiDAR axes)", "region", flag="--lidar-region")

    def mask(self, points: np.ndarray) -> np.ndarray:
        """Which of the (N, 3) points lie in the box (bool (N,))."""
        x, y = points[:, 0], points[:, 1]
        return (x >= self.x_min) & (x <= self.x_max) & (y >= self.y_min) & (y <= self.y_max)

    def __str__(self) -> str:
        return f"x {self.x_min:g}..{self.x_max:g} m, y {self.y_min:g}..{self.y_max:g} m"


#: The default road region: 5-30 m ahead, 4 m either side of the LiDAR.
ROAD_REGION = RoadRegion()
#: Ground-point choices of the plane fit (:func:`fit_ground_plane`'s ``ground``).
GROUND_FITS = ("ransac", "patchwork")
#: The Patchwork++ package (the extra ``.[lidar]``).
PATCHWORK_MODULE = "pypatchworkpp"


class PathRegion:
    """The road along the driven path: points within ``half_width`` of the vehicle's future track, ahead of it.

    Parameters
    ----------
    xy : array_like (M, 2)
        The future track in the LiDAR's axes at the scan's time (x, y, m), in driving order.
    half_width, step : float
        Horizontal distance to the track, and the track's resampling step, m.
    ahead : tuple of float
        Distance along the track from its point nearest the LiDAR, m.
    """

    def __init__(self, xy: Any, half_width: float = 1.5, ahead: tuple[float, float] = (3.0, 32.0),
                 step: float = 0.25) -> None:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if len(xy) < 2 or not (half_width > 0 and 0 <= ahead[0] < ahead[1]):
            raise OptionError("{opt} path: the driven path needs a track of 2 points or more, a positive width "
                              "and 0 <= ahead min < max", "region", flag="--lidar-region")
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        grid = np.arange(0.0, s[-1] + step / 2, step)
        self.xy = np.column_stack([np.interp(grid, s, xy[:, 0]), np.interp(grid, s, xy[:, 1])])
        self.along = grid - grid[int(np.argmin(np.hypot(*self.xy.T)))]
        self.half_width, self.ahead = float(half_width), (float(ahead[0]), float(ahead[1]))

    def mask(self, points: np.ndarray) -> np.ndarray:
        """Which of the (N, 3) points lie along the path (bool (N,))."""
        from scipy.spatial import cKDTree
        keep = (self.along >= self.ahead[0] - self.half_width) & (self.along <= self.ahead[1] + self.half_width)
        if not keep.any():
            return np.zeros(len(points), dtype=bool)
        dist, idx = cKDTree(self.xy[keep]).query(points[:, :2], distance_upper_bound=self.half_width)
        assert isinstance(idx, np.ndarray)          # one index per point of a 2-D query
        near = np.isfinite(dist)
        along = np.full(len(points), np.nan)
        along[near] = self.along[keep][idx[near]]
        with np.errstate(invalid="ignore"):
            return near & (along >= self.ahead[0]) & (along <= self.ahead[1])

    def __str__(self) -> str:
        return f"the driven path: within {self.half_width:g} m of the track, {self.ahead[0]:g}..{self.ahead[1]:g} m ahead"


def path_region(t_scan: float, t: Any, positions: Any, rotations: Any, lidar_from_body: Extrinsic,
                half_width: float = 1.5, ahead: tuple[float, float] = (3.0, 32.0)) -> PathRegion:
    """The :class:`PathRegion` of one scan from the vehicle's track.

    Parameters
    ----------
    t_scan : float
        The scan's time, s, on the track's clock.
    t, positions, rotations : array_like (N,), (N, 3), (N, 3, 3)
        The track: increasing times (s), the body's positions in a world frame (m) and world <- body.
    lidar_from_body : Extrinsic
        LiDAR <- body: ``x_lidar = R x_body + t``.
    half_width, ahead
        As :class:`PathRegion`; a shorter track is continued straight (at a standstill: along body x).
    """
    t = np.asarray(t, dtype=float)
    pos = np.asarray(positions, dtype=float)
    rot = np.asarray(rotations, dtype=float)
    i = int(np.clip(np.searchsorted(t, t_scan), 0, len(t) - 1))
    p0 = np.array([np.interp(t_scan, t, pos[:, k]) for k in range(3)])
    future = np.vstack([p0, pos[t > t_scan]])
    body = (future - p0) @ rot[i]                                   # rows: R_{w<-b}^T (p - p0)
    xy = (body @ lidar_from_body.rotation.T + lidar_from_body.translation)[:, :2]
    steps = np.hypot(*np.diff(xy, axis=0).T)
    length = float(steps.sum())
    if length < ahead[1] + half_width + 1.0:
        moving = np.flatnonzero(steps > 0.05)
        direction = (xy[moving[-1] + 1] - xy[moving[-1]]) if moving.size else (lidar_from_body.rotation @ [1, 0, 0])[:2]
        direction = direction / np.linalg.norm(direction)
        xy = np.vstack([xy, xy[-1] + direction * (ahead[1] + half_width + 1.0 - length)])
    return PathRegion(xy, half_width, ahead)


def _quiet(make, *args):
    """``make(*args)`` with file descriptor 1 closed to C++'s own prints."""
    import os
    import sys
    sys.stdout.flush()
    saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        return make(*args)
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


_PATCHWORK: dict = {}


def patchwork_ground(points: np.ndarray, sensor_height: float = 1.73) -> np.ndarray:
    """Patchwork++'s ground points of a whole scan (bool (N,); LiDAR axes, m), its defaults but the sensor height.

    Raises
    ------
    MissingExtraError
        ``pypatchworkpp`` is not installed (naming ``.[lidar]`` and ``--lidar-fit``).
    """
    key = float(sensor_height)
    if key not in _PATCHWORK:
        pw = require_extra(PATCHWORK_MODULE, "lidar", "Patchwork++ ground points (--lidar-fit patchwork)")
        params = pw.Parameters()
        params.verbose = False
        params.sensor_height = key
        _PATCHWORK[key] = _quiet(pw.patchworkpp, params)
    seg = _PATCHWORK[key]
    pts = np.asarray(points, dtype=float)
    cloud = np.column_stack([pts[:, :3], pts[:, 3] if pts.shape[1] > 3 else np.zeros(len(pts))])
    seg.estimateGround(np.ascontiguousarray(cloud, dtype=np.float32))          # (N, 4) x y z intensity
    mask = np.zeros(len(pts), dtype=bool)
    mask[np.asarray(seg.getGroundIndices(), dtype=int).ravel()] = True
    return mask


def patchwork_available() -> bool:
    """Whether ``pypatchworkpp`` imports (the ``auto`` fit uses Patchwork++ then, RANSAC otherwise)."""
    import importlib.util
    return importlib.util.find_spec(PATCHWORK_MODULE) is not None


def _tls_plane(points: np.ndarray) -> tuple[np.ndarray, float]:
    centre = points.mean(axis=0)
    normal = np.linalg.svd(points - centre, full_matrices=False)[2][2]
    normal = normal if normal[2] >= 0 else -normal
    return normal, float(-normal @ centre)


def fit_ground_plane(points: Any, region: Any = ROAD_REGION, threshold: float = 0.1, seed: int = 0,
                     max_trials: int = 200, min_inliers: int = 200, max_tilt_deg: float = 15.0,
                     source: str = "scan", return_inliers: bool = False, ground: str = "ransac"):
    """The road plane of one LiDAR scan: RANSAC (or Patchwork++) in the road region, then least squares on the inliers.

    Parameters
    ----------
    points : array_like (N, 3) or (N, 4)
        Points in the LiDAR's axes, m; a fourth column (reflectance) is ignored.
    region : RoadRegion or PathRegion
        Where the road is looked for; anything with ``mask(points)``.
    threshold : float
        Inlier distance to the plane, m (RANSAC's vertical residual, then the refit's perpendicular one).
    seed, max_trials : int
        RANSAC's random seed and iterations.
    min_inliers : int
        Fewer road points than this is "no road".
    max_tilt_deg : float
        A plane tilted more than this from the LiDAR's z axis is not the road.
    source : str
        The scan's name for messages.
    return_inliers : bool
    ground : {"ransac", "patchwork"}
        The road's first points: RANSAC on the region's, or :func:`patchwork_ground`'s in the region.

    Returns
    -------
    normal, d : ndarray (3,), float
        Unit normal pointing up, LiDAR axes, and ``d`` (m) with ``normal . x + d = 0`` on the road.
    inliers : int
        Only with ``return_inliers``.

    Raises
    ------
    OptionError
        An empty scan, no road in the region, or scikit-learn missing (the extra ``.[lidar]``).
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] not in (3, 4):
        raise OptionError(f"{source}: points must be an (N, 3) or (N, 4) array, got shape {pts.shape} ({{opt}})",
                          "lidar")
    if not len(pts):
        raise OptionError(f"{source}: the scan is empty; give {{opt}} scans with points", "lidar")
    full = pts[np.all(np.isfinite(pts[:, :3]), axis=1)]
    pts = full[:, :3]
    inside = region.mask(pts)
    road = pts[inside]
    need = max(min_inliers, 3)

    def no_road(why: str) -> OptionError:
        return OptionError(f"{source}: no road in the region ({region}): {why}; give {{opt}} scans whose LiDAR sees "
                           "the road ahead, or another region (--lidar-region)", "lidar")

    if len(road) < need:
        raise no_road(f"{len(road)} points there, {min_inliers} needed")
    if ground == "patchwork":
        road = pts[inside & patchwork_ground(full)]
        if len(road) < need:
            raise no_road(f"{len(road)} Patchwork++ ground points there, {min_inliers} needed")
        inl = np.ones(len(road), dtype=bool)
    elif ground == "ransac":
        lm = require_extra("sklearn.linear_model", "lidar", "the LiDAR plane fit (--lidar)")
        try:
            fit = lm.RANSACRegressor(lm.LinearRegression(), residual_threshold=threshold, max_trials=max_trials, min_samples=3,
                         random_state=seed).fit(road[:, :2], road[:, 2])
            inl = fit.inlier_mask_
        except ValueError:
            raise no_road("RANSAC found no plane") from None
    else:
        raise OptionError(f"{{opt}} {ground}: choose ransac or patchwork", "lidar_fit")
    for _ in range(5):
        if np.count_nonzero(inl) < need:
            break
        normal, d = _tls_plane(road[inl])
        again = np.abs(road @ normal + d) < threshold
        if np.array_equal(again, inl):
            break
        inl = again
    count = int(np.count_nonzero(inl))
    if count < need:
        raise no_road(f"{count} points on a plane, {min_inliers} needed")
    normal, d = _tls_plane(road[inl])
    tilt = math.degrees(math.acos(min(1.0, normal[2])))
    if tilt > max_tilt_deg:
        raise no_road(f"the best plane is tilted {tilt:.0f} deg from the LiDAR's z axis (at most {max_tilt_deg:g})")
    return (normal, d, count) if return_inliers else (normal, d)


# ----------------------------------------------------------------------------- reading
def read_bin_scan(path: str | Path) -> np.ndarray:
    """A KITTI Velodyne ``.bin`` scan: float32 ``x y z reflectance`` records as an (N, 4) float64 array.

    Raises
    ------
    OptionError
        No such file, or not a whole number of 16-byte records.
    """
    p = Path(path)
    if not p.is_file():
        raise OptionError(f"{p}: no such scan file ({{opt}} SCANS: a folder of KITTI .bin scans)", "lidar")
    raw = np.fromfile(p, dtype="<f4")
    if raw.size % 4:
        raise OptionError(f"{p}: {raw.size * 4} bytes is not a whole number of KITTI Velodyne records (16 bytes: "
                          "float32 x y z reflectance); give {opt} KITTI .bin scans", "lidar")
    return raw.reshape(-1, 4).astype(float)


def read_scan(path: str | Path) -> np.ndarray:
    """One scan's points, (N, 3) or (N, 4) float64, LiDAR axes, m: KITTI ``.bin``, ``.pcd`` or ``.ply``.

    Raises
    ------
    OptionError
        No such file, an unknown suffix, or a file its reader cannot read.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".bin":
        return read_bin_scan(p)
    if suffix not in SCAN_SUFFIXES:
        raise OptionError(f"{p}: unknown scan type {suffix or '(no suffix)'!r}; give {{opt}} "
                          f"{', '.join(SCAN_SUFFIXES)} scans", "lidar")
    if not p.is_file():
        raise OptionError(f"{p}: no such scan file ({{opt}})", "lidar")
    reader = require_extra("pypcd4" if suffix == ".pcd" else "plyfile", "lidar", f"{p}: reading this scan (--lidar)")
    try:
        if suffix == ".pcd":
            cloud = reader.PointCloud.from_path(p)
            return np.asarray(cloud.numpy(("x", "y", "z")), dtype=float).reshape(-1, 3)
        vertex = reader.PlyData.read(str(p))["vertex"]
        return np.column_stack([np.asarray(vertex[k], dtype=float) for k in "xyz"]).reshape(-1, 3)
    except Exception as e:                          # the third-party parsers' own errors: a file we cannot read
        raise OptionError(f"{p}: not a readable {suffix[1:].upper()} point cloud with x y z "
                          f"({type(e).__name__}: {' '.join(str(e).split())[:120]}); give {{opt}} another scan",
                          "lidar") from None


def scan_files(folder: str | Path) -> list[Path]:
    """The scans of a folder (:data:`SCAN_SUFFIXES`), in name order (a KITTI ``velodyne_points/data`` folder).

    Raises
    ------
    OptionError
        No such folder, or no scan in it.
    """
    d = Path(folder)
    if not d.is_dir():
        raise OptionError(f"{d}: no such folder ({{opt}} LOG SCANS: SCANS is a folder of scans, "
                          f"{', '.join(SCAN_SUFFIXES)})", "lidar")
    files = sorted(p for p in d.iterdir() if p.suffix.lower() in SCAN_SUFFIXES and p.is_file())
    if not files:
        raise OptionError(f"{d}: no scan ({', '.join(SCAN_SUFFIXES)}) in the folder; give {{opt}} LOG SCANS a "
                          "folder of scans", "lidar")
    return files


def read_times(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """One time a line (s, on the log's clock; ``#`` starts a comment) and each time's 1-based line number.

    Raises
    ------
    OptionError
        No such file, no time, or a line that is not a finite number (naming the line).
    """
    p = Path(path)
    if not p.is_file():
        raise OptionError(f"{p}: no such times file ({{opt}} FILE: one time a line, s on the log's clock)", "times")
    times, lines = [], []
    for lineno, line in enumerate(p.read_text(errors="replace").splitlines(), start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            value = float(text.split()[0].rstrip(","))
        except ValueError:
            raise OptionError(f"{p}:{lineno}: {text!r} is not one time (s) a line; give {{opt}} a file of times",
                              "times") from None
        if not math.isfinite(value):
            raise OptionError(f"{p}:{lineno}: {text!r}: a time that is not finite ({{opt}})", "times")
        times.append(value)
        lines.append(lineno)
    if not times:
        raise OptionError(f"{p}: no time in the file ({{opt}}: one time a line, s on the log's clock)", "times")
    return np.array(times), np.array(lines)


def read_scan_times(path: str | Path, count: int, what: str = "scans") -> np.ndarray:
    """:func:`read_times`, exactly ``count`` of them, increasing.

    Raises
    ------
    OptionError
        As :func:`read_times`, a count other than ``count``, or times that do not increase.
    """
    t, lines = read_times(path)
    if len(t) != count:
        raise OptionError(f"{path}: {len(t)} times for {count} {what}; give {{opt}} one time a line, one per "
                          f"{what[:-1]} in name order", "times")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        raise OptionError(f"{path}:{lines[back[0] + 1]}: times must increase ({{opt}})", "times")
    return t


# ----------------------------------------------------------------------------- frames
def lidar_transform(spec: str | Path, imu_extrinsic: Any = None) -> Extrinsic:
    """The LiDAR's extrinsic ground <- LiDAR (rotation ``R_{g<-l}``, translation: its origin in the ground frame, m).

    Parameters
    ----------
    spec : str or Path
        A KITTI raw calibration folder (holding ``calib_imu_to_velo.txt``), that file, or an
        extrinsic file of the project's format (``R``: ground <- LiDAR, ``t``).
    imu_extrinsic : optional
        The log's static extrinsic (ground <- IMU), for KITTI's files; default ``kitti_imu``.

    Raises
    ------
    OptionError
        Naming the file and ``--lidar-extrinsic``.
    """
    p = Path(spec)
    calib = p / "calib_imu_to_velo.txt" if p.is_dir() else p
    if not calib.is_file():
        raise OptionError(f"{p}: no such file or KITTI raw calibration folder (give {{opt}} a folder holding "
                          "calib_imu_to_velo.txt or an extrinsic file, R: ground <- LiDAR)", "lidar_extrinsic")
    text = calib.read_text(errors="replace")
    if calib.name == "calib_imu_to_velo.txt" or ("T:" in text and "calib_time" in text):
        from imu_ground.perception.kitti_calib import read_kitti_calib
        c = read_kitti_calib(calib)
        r, t = c.get("R"), c.get("T")
        if r is None or r.size != 9 or t is None or t.size != 3:
            raise OptionError(f"{calib}: no 'R:' line with 9 numbers and 'T:' with 3 (a KITTI calib_imu_to_velo.txt; "
                              "{opt})", "lidar_extrinsic")
        r_velo_imu = project(np.reshape(r, (3, 3)))
        g_imu = Extrinsic.coerce("kitti_imu" if imu_extrinsic is None else imu_extrinsic)
        r_imu_velo, t_imu_velo = r_velo_imu.T, -r_velo_imu.T @ t                # x_imu = R^T (x_velo - T)
        return Extrinsic(g_imu.rotation @ r_imu_velo, g_imu.rotation @ t_imu_velo + g_imu.translation,
                         {"sensor": "lidar", "derived_from": str(calib)})
    try:
        return load_extrinsic(calib)
    except (ImuGroundError, FileNotFoundError) as e:
        raise OptionError(f"{{opt}} {' '.join(str(e).split())}", "lidar_extrinsic") from None


def lidar_rotation(spec: str | Path, imu_extrinsic: Any = None) -> np.ndarray:
    """``R_{g<-l}`` (3, 3): the rotation of :func:`lidar_transform` (the same arguments)."""
    return lidar_transform(spec, imu_extrinsic).rotation


def kitti_object_rotation(calib_file: str | Path, imu_extrinsic: Any = None) -> np.ndarray:
    """``R_{g<-rect} = R_{g<-imu} (R0 R_vc R_vi)^T`` of a KITTI object calibration file (rectified camera axes)."""
    from imu_ground.perception.kitti_calib import read_kitti_calib
    p = Path(calib_file)
    if not p.is_file():
        raise OptionError(f"{p}: no such KITTI object calibration file ({{opt}})", "lidar_extrinsic")
    c = read_kitti_calib(p)
    need = {"R0_rect": 9, "Tr_velo_to_cam": 12, "Tr_imu_to_velo": 12}
    for key, size in need.items():
        if key not in c or c[key].size != size:
            raise OptionError(f"{p}: no '{key}:' line with {size} numbers (a KITTI object calibration file; "
                              "{opt})", "lidar_extrinsic")
    r_rect_imu = (c["R0_rect"].reshape(3, 3) @ c["Tr_velo_to_cam"].reshape(3, 4)[:, :3]
                  @ c["Tr_imu_to_velo"].reshape(3, 4)[:, :3])
    return Extrinsic.coerce(imu_extrinsic).rotation @ project(r_rect_imu).T


def lidar_pitch_roll(normals: Any, rotation: Any) -> tuple[np.ndarray, np.ndarray]:
    """The body's pitch and roll relative to the road (rad) from road normals in a sensor's axes.

    Parameters
    ----------
    normals, rotation : array_like (N, 3) or (3,); (3, 3) or (N, 3, 3)
        Road normals pointing up (any length), sensor axes; ground <- sensor (:func:`lidar_rotation`).
    """
    n = np.asarray(normals, dtype=float)
    nb = np.einsum("...ij,...j->...i", np.asarray(rotation, dtype=float), n)
    nb = nb / np.linalg.norm(nb, axis=-1, keepdims=True)
    return pitch_roll_from_normal(nb)


def planes_pitch_roll(coefficients: Any, rotation: Any) -> tuple[np.ndarray, np.ndarray]:
    """Pitch and roll (rad) of KITTI ``planes`` rows ``a b c d`` (camera axes, normal pointing up)."""
    abcd = np.asarray(coefficients, dtype=float).reshape(-1, 4)
    return lidar_pitch_roll(abcd[:, :3], rotation)


def fit_scans(files: list[Path], region: Any = ROAD_REGION, seed: int = 0, **fit_options) -> pd.DataFrame:
    """:func:`fit_ground_plane` of every scan file: one row a scan.

    Parameters
    ----------
    files : list of Path
        Scan files (:func:`read_scan`).
    region : RoadRegion, PathRegion or list of them
        One region for every scan, or one per scan.
    seed, **fit_options
        As :func:`fit_ground_plane`.

    Returns
    -------
    pandas.DataFrame
        ``scan`` (file name), ``normal_x normal_y normal_z`` (LiDAR axes), ``d`` (m), ``inliers``.
    """
    rows = []
    regions = region if isinstance(region, (list, tuple)) else [region] * len(files)
    for f, reg in zip(files, regions, strict=True):
        normal, d, count = fit_ground_plane(read_scan(f), reg, seed=seed, source=str(f),
                                            return_inliers=True, **fit_options)
        rows.append({"scan": Path(f).name, "normal_x": normal[0], "normal_y": normal[1], "normal_z": normal[2],
                     "d": d, "inliers": count})
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- comparison
def compare_to_lidar(t_scan: Any, lidar_pitch: Any, lidar_roll: Any, t: Any, pitch: Any, roll: Any,
                     valid: Any = None, source: str = "the log") -> pd.DataFrame:
    """Per scan: the estimate at the scan's time against the LiDAR plane.

    Parameters
    ----------
    t_scan, lidar_pitch, lidar_roll : array_like (S,)
        Scan times (s, the log's clock) and the LiDAR planes' body pitch and roll relative to the road, rad.
    t, pitch, roll, valid : array_like (N,)
        The estimate's frame times (s), angles (rad) and valid frames (default: finite ones).
    source : str
        The log's name for messages.

    Returns
    -------
    pandas.DataFrame
        ``t``, ``lidar_pitch_deg``, ``lidar_roll_deg``, ``pitch_deg``, ``roll_deg`` (the estimate, interpolated),
        ``d_pitch_deg``, ``d_roll_deg`` (estimate minus LiDAR), ``angle_deg``.

    Raises
    ------
    OptionError
        Fewer than 2 valid frames, or a scan time outside the log's frames.
    """
    ts = np.asarray(t_scan, dtype=float)
    t, p, r = (np.asarray(a, dtype=float) for a in (t, pitch, roll))
    use = np.isfinite(t) & np.isfinite(p) & np.isfinite(r)
    if valid is not None:
        use &= np.asarray(valid, dtype=bool)
    if np.count_nonzero(use) < 2:
        raise OptionError(f"{source}: fewer than 2 valid frames to compare with the scans", "lidar")
    t, p, r = t[use], p[use], r[use]
    step = float(np.median(np.diff(t)))
    out = np.flatnonzero((ts < t[0] - step) | (ts > t[-1]))
    if out.size:
        i = int(out[0])
        raise OptionError(f"{source}: scan {i + 1}'s time {ts[i]:g} s is outside the log's frames "
                          f"({t[0] - step:g} .. {t[-1]:g} s); give {{opt}} the scans' times on the log's clock",
                          "times")
    ep, er = np.interp(ts, t, p), np.interp(ts, t, r)
    lp, lr = np.asarray(lidar_pitch, dtype=float), np.asarray(lidar_roll, dtype=float)
    angle = normal_angle(normal_from_pitch_roll(ep, er), normal_from_pitch_roll(lp, lr))
    deg = np.degrees
    return pd.DataFrame({"t": ts, "lidar_pitch_deg": deg(lp), "lidar_roll_deg": deg(lr), "pitch_deg": deg(ep),
                         "roll_deg": deg(er), "d_pitch_deg": deg(ep - lp), "d_roll_deg": deg(er - lr),
                         "angle_deg": angle})


def lidar_summary(frames: pd.DataFrame) -> dict[str, float]:
    """One method's summary of :func:`compare_to_lidar`'s frames, deg.

    Returns
    -------
    dict
        ``n``, ``angle_mean``, ``pitch_offset``, ``roll_offset``; centred: ``angle_centred``, ``pitch_spread``
        (sample std), ``pitch_mae_centred``, ``roll_change_spread``, ``roll_change_corr``.
    """
    dp, dr = frames["d_pitch_deg"].to_numpy(), frames["d_roll_deg"].to_numpy()
    n = len(frames)
    ep, er = np.radians(frames["pitch_deg"].to_numpy()), np.radians(frames["roll_deg"].to_numpy())
    lp, lr = np.radians(frames["lidar_pitch_deg"].to_numpy()), np.radians(frames["lidar_roll_deg"].to_numpy())
    centred = normal_angle(normal_from_pitch_roll(ep - ep.mean(), er - er.mean()),
                           normal_from_pitch_roll(lp - lp.mean(), lr - lr.mean()))
    ddof = 1 if n > 1 else 0
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = float(np.corrcoef(er, lr)[0, 1]) if n > 2 and np.std(er) > 0 and np.std(lr) > 0 else float("nan")
    return {"n": n, "angle_mean": float(frames["angle_deg"].mean()), "pitch_offset": float(dp.mean()),
            "roll_offset": float(dr.mean()), "angle_centred": float(centred.mean()),
            "pitch_spread": float(dp.std(ddof=ddof)), "pitch_mae_centred": float(np.abs(dp - dp.mean()).mean()),
            "roll_change_spread": float(dr.std(ddof=ddof)), "roll_change_corr": corr}


def bootstrap_spread(differences: dict[str, Any], samples: int = 2000, block: int = 5,
                     seed: int = 0) -> pd.DataFrame:
    """Each method's spread with a paired moving-block bootstrap interval, and how often it ranks first.

    Parameters
    ----------
    differences : dict of str to array_like (S,)
        Per method, the difference estimate minus LiDAR per scan, deg.
    samples, block, seed : int
        Bootstrap draws, consecutive frames a block (they are correlated), the seed.

    Returns
    -------
    pandas.DataFrame
        Index ``method``: ``spread`` (sample std), ``lo95``, ``hi95``, ``p_best`` (share of the draws it ranks
        first), ``vs_best_lo95``, ``vs_best_hi95`` (its spread minus the best method's).
    """
    names = list(differences)
    d = np.array([np.asarray(differences[k], dtype=float) for k in names])
    s = d.shape[1]
    block = max(1, min(int(block), s))
    rng = np.random.default_rng(seed)
    starts = rng.integers(0, s - block + 1, size=(samples, -(-s // block)))
    idx = (starts[:, :, None] + np.arange(block)).reshape(samples, -1)[:, :s]
    spreads = d[:, idx].std(axis=2, ddof=1)                       # (methods, samples)
    point = d.std(axis=1, ddof=1)
    best = int(np.argmin(point))
    wins = np.bincount(np.argmin(spreads, axis=0), minlength=len(names)) / samples
    rel = spreads - spreads[best]
    return pd.DataFrame({"spread": point, "lo95": np.percentile(spreads, 2.5, axis=1),
                         "hi95": np.percentile(spreads, 97.5, axis=1), "p_best": wins,
                         "vs_best_lo95": np.percentile(rel, 2.5, axis=1),
                         "vs_best_hi95": np.percentile(rel, 97.5, axis=1)}, index=pd.Index(names, name="method"))


def lidar_table(estimates: dict[str, Any], t_scan: Any, lidar_pitch: Any, lidar_roll: Any,
                source: str = "the log") -> tuple[pd.DataFrame, pd.DataFrame]:
    """Every estimate against the LiDAR planes: the frames (long) and one summary row a method.

    Parameters
    ----------
    estimates : dict of str to tuple
        Method name to ``(t, pitch, roll, valid)`` of its track (s, rad, rad, bool; ``valid`` may be None).
    t_scan, lidar_pitch, lidar_roll, source
        As :func:`compare_to_lidar`.

    Returns
    -------
    frames : pandas.DataFrame
        :func:`compare_to_lidar`'s columns plus ``method`` and ``scan`` (0-based).
    summary : pandas.DataFrame
        :func:`method_summaries` of the pitch.
    """
    frames = pd.concat([compare_to_lidar(t_scan, lidar_pitch, lidar_roll, t, pitch, roll, valid, source)
                        .assign(method=name, scan=lambda f: np.arange(len(f)))
                        for name, (t, pitch, roll, valid) in estimates.items()], ignore_index=True)
    return frames, method_summaries(frames)


def method_summaries(frames: pd.DataFrame, what: str = "pitch") -> pd.DataFrame:
    """Index ``method``: :func:`lidar_summary` of each method's frames (:func:`lidar_table`'s) and, with 3 scans or
    more, :func:`bootstrap_spread` of its ``d_{what}_deg`` (``lo95 hi95 p_best vs_best_lo95 vs_best_hi95``)."""
    groups = frames.groupby("method", sort=False)
    summary = pd.DataFrame.from_dict({str(k): lidar_summary(g) for k, g in groups}, orient="index")
    summary.index.name = "method"
    if len(summary) and summary["n"].iloc[0] >= 3:
        boot = bootstrap_spread({str(k): g[f"d_{what}_deg"].to_numpy() for k, g in groups})
        summary = summary.join(boot.drop(columns="spread"))
    return summary


def planes_rotations(spec: str | Path, names: list[str], imu_extrinsic: Any = None) -> np.ndarray:
    """``R_{g<-cam}`` for each planes file: of a camera, or of the KITTI object calibration files.

    Parameters
    ----------
    spec : str or Path
        A folder of KITTI object calibration files named as the planes files (``names``,
        ``000005.txt``), one such file, or a camera (:func:`~imu_ground.perception.load_camera`).
    names : list of str
    imu_extrinsic : optional
        The log's static extrinsic (ground <- IMU), for the KITTI object files.

    Returns
    -------
    ndarray (len(names), 3, 3)
    """
    p = Path(spec)
    if p.is_dir() and (p / names[0]).is_file():
        missing = [n for n in names if not (p / n).is_file()]
        if missing:
            raise OptionError(f"{p}: no calibration file {missing[0]} for the planes file of that name ({{opt}})",
                              "lidar_extrinsic")
        return np.array([kitti_object_rotation(p / n, imu_extrinsic) for n in names])
    if p.is_file() and "R0_rect" in p.read_text(errors="replace"):
        return np.repeat(kitti_object_rotation(p, imu_extrinsic)[None], len(names), axis=0)
    from imu_ground.perception.camera import load_camera
    try:
        cam = load_camera(str(spec))
    except (ImuGroundError, FileNotFoundError) as e:
        raise OptionError(f"{{opt}} {spec}: not a camera nor KITTI object calibration ({' '.join(str(e).split())})",
                          "lidar_extrinsic") from None
    return np.repeat(cam.extrinsic.rotation[None], len(names), axis=0)


def plot_lidar(frames: pd.DataFrame, path: str | Path, title: str = "") -> Path:
    """Pitch and roll over time: the LiDAR planes and each method's estimate, each centred on its mean (PNG)."""
    path = Path(path)
    lidar_figure(frames, title).savefig(path, format="png")
    return path


def lidar_figure(frames: pd.DataFrame, title: str = ""):
    """The matplotlib ``Figure`` of :func:`plot_lidar` (:func:`lidar_table`'s frames; deg over the log's clock, s)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(10, 6.5), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, 1, sharex=True)
    first = frames[frames["method"] == frames["method"].iloc[0]]
    for ax, what in zip(axes, ("pitch", "roll"), strict=True):
        lidar = first[f"lidar_{what}_deg"].to_numpy()
        ax.plot(first["t"], lidar - lidar.mean(), "k.-", lw=2, label="LiDAR plane")
        for name, g in frames.groupby("method", sort=False):
            est = g[f"{what}_deg"].to_numpy()
            spread = [g[f"d_{w}_deg"].std(ddof=1) if len(g) > 1 else float("nan") for w in ("pitch", "roll")]
            ax.plot(g["t"], est - est.mean(), "-", lw=1,
                    label=f"{name} (spread: pitch {spread[0]:.2f}, roll {spread[1]:.2f} deg)")
        ax.set_ylabel(f"{what} - mean (deg)")
        ax.grid(True, alpha=0.3)
    axes[0].set_title(title or "body pitch and roll relative to the road: LiDAR planes and estimates (means removed)",
                      fontsize=9)
    axes[1].set_xlabel("t (s, the log's clock)")
    handles, labels = axes[0].get_legend_handles_labels()
    ncol = min(3, len(labels))
    rows = -(-len(labels) // ncol)
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0.0, 0.01 + 0.03 * rows, 1.0, 1.0))           # the legend below the axes, not on the curves
    return fig
