"""The LiDAR plane in a bird's-eye preview of real images, and a distance the LiDAR measured read off each view."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import OptionError
from imu_ground.evaluation import lidar as L
from imu_ground.evaluation.preview import Preview
from imu_ground.perception.plane import GroundPlane

__all__ = ["MEASURED_DISTANCE", "add_lidar_plane", "measured_point", "preview_frame"]

#: Distance ahead (m, ground frame) of the LiDAR road point read off each view.
MEASURED_DISTANCE = 30.0


def measured_point(points: np.ndarray, normal: np.ndarray, d: float, transform: Any, distance: float,
                   threshold: float = 0.02) -> np.ndarray:
    """The road point of a scan nearest to ``(distance, 0)`` ahead, ground frame (x forward, y left, z up), m.

    Parameters
    ----------
    points : ndarray (N, 3+)
        The scan, LiDAR axes.
    normal, d : ndarray (3,), float
        Its road plane (:func:`~imu_ground.evaluation.lidar.fit_ground_plane`).
    transform : Extrinsic
        Ground <- LiDAR (:func:`~imu_ground.evaluation.lidar.lidar_transform`).
    distance : float
    threshold : float
        Road points: within this of the plane, m.
    """
    pts = np.asarray(points, dtype=float)[:, :3]
    road = pts[np.abs(pts @ normal + d) < threshold]
    g = road @ transform.rotation.T + transform.translation
    if not len(g):
        return np.full(3, np.nan)
    return g[int(np.argmin(np.hypot(g[:, 0] - distance, 2.0 * g[:, 1])))]


def add_lidar_plane(preview: Preview, scans: str | Path, spec: str | Path, imu_extrinsic: Any = None,
                    region: L.RoadRegion = L.ROAD_REGION, seed: int = 0,
                    distance: float = MEASURED_DISTANCE) -> Preview:
    """``preview`` with the LiDAR plane of each image's scan and a measured distance read off every view.

    Parameters
    ----------
    preview : Preview
        An image preview; gains ``planes["lidar"]``, ``readings`` (each view's distance to the LiDAR's
        road point nearest ``distance`` m ahead) and ``marks`` (that point's ground x, y, m).
    scans : str or Path
        A folder of scans, one per image, in the images' order.
    spec, imu_extrinsic
        As :func:`~imu_ground.evaluation.lidar.lidar_transform`.
    region, seed
        Of the fit.
    distance : float
        m ahead.

    Raises
    ------
    OptionError
        Scans that do not match the images (count), or that have no road (naming ``--lidar``).
    """
    files = L.scan_files(scans)
    if len(files) != len(preview.times):
        raise OptionError(f"{scans}: {len(files)} scans for {len(preview.times)} images; give {{opt}} one scan per "
                          "image, in the images' order", "lidar")
    transform = L.lidar_transform(spec, imu_extrinsic)
    cam = preview.camera
    normals, heights, measured = [], [], []
    for f in files:
        pts = L.read_scan(f)
        normal, d = L.fit_ground_plane(pts, region, seed=seed, source=str(f))
        normals.append(normal)
        n_g = transform.rotation @ normal
        heights.append(d - n_g @ transform.translation)        # the ground origin's height above the measured road
        measured.append(measured_point(pts, normal, d, transform, distance))
    pitch, roll = L.lidar_pitch_roll(np.array(normals), transform.rotation)
    tilted = GroundPlane.from_pitch_roll(cam, pitch, roll)
    lifted = tilted.translation + np.outer(heights, [0.0, 0.0, 1.0])
    preview.planes["lidar"] = GroundPlane(cam.K, tilted.rotation, lifted, cam.image_size)
    marks = np.array(measured)
    ext = cam.extrinsic
    in_cam = (marks - ext.translation) @ ext.rotation                # R^T (x_g - t), row-wise
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = (in_cam @ cam.K.T)[:, :2] / in_cam[:, 2:]

    def reading(plane: GroundPlane, k: int) -> str:
        x = plane[k].road_from_pixel(uv[k, 0], uv[k, 1])[0, 0] if np.all(np.isfinite(uv[k])) else np.nan
        return (f"LiDAR point {marks[k, 0]:.1f} m ahead reads {x:.1f} m" if np.isfinite(x)
                else "LiDAR point: not on the road in this view")

    preview.readings = {name: [reading(p, k) for k in range(len(files))] for name, p in preview.planes.items()}
    preview.marks = marks[:, :2]
    preview.title += (f"; the LiDAR plane from {Path(scans).parent.name}/{Path(scans).name} (region {region}); "
                      f"cross: the LiDAR's road point nearest {distance:g} m ahead")
    return preview


def preview_frame(preview: Preview, k: int) -> Preview:
    """The preview reduced to its frame ``k`` (0-based), e.g. for a PNG of another frame than the first.

    Raises
    ------
    OptionError
        ``k`` outside the frames (naming ``--frame``).
    """
    n = len(preview.times)
    if not 0 <= k < n:
        raise OptionError(f"{{opt}} {k}: the preview has frames 0 to {n - 1}", "frame")
    return Preview(preview.camera, {name: plane[k] for name, plane in preview.planes.items()},
                   preview.times[k:k + 1], lambda _: preview.image(k), preview.lane_error, preview.title,
                   preview.labels[k:k + 1], preview.lanes,
                   {name: texts[k:k + 1] for name, texts in preview.readings.items()},
                   None if preview.marks is None else preview.marks[k:k + 1])
