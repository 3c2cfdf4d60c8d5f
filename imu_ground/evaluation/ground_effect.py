"""What a plane error does to perception: ground-point range and lane-width errors of a camera.

True road points go into the image through the true plane and back through the believed one: the
range error at ``X`` m is the believed forward distance of the point ahead at ``X`` minus ``X``; the
lane-width error the believed distance between the lines ``Y = +- lane_width / 2`` minus the width.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from imu_ground.perception.camera import Camera
from imu_ground.perception.plane import GroundPlane

__all__ = ["DISTANCES", "LANE_WIDTH", "drive_ground_errors", "ground_errors"]

#: Distances ahead (m) of the measured effect in RESULTS.md.
DISTANCES = (20.0, 40.0, 60.0)
#: Lane width of the synthetic road, m.
LANE_WIDTH = 3.5


def ground_errors(truth: GroundPlane, believed: GroundPlane, distances: Any = DISTANCES,
                  lane_width: float = LANE_WIDTH) -> dict[str, np.ndarray]:
    """Range and lane-width errors (m) of ``believed`` planes against ``truth`` planes, frame by frame.

    Parameters
    ----------
    truth, believed : GroundPlane
        The same camera's true and believed planes, ``N`` frames each (origins below the same point).
    distances : array_like (D,)
        Road distances ahead, m.
    lane_width : float
        m.

    Returns
    -------
    dict
        ``range`` and ``lane_width``: ndarray (N, D), m, NaN where a point is behind the camera.
    """
    x = np.asarray(distances, dtype=float)
    y = np.array([0.0, 0.5 * lane_width, -0.5 * lane_width])
    uv = truth.pixel_from_road(x[:, None], y[None, :])                           # (N, D, 3, 2)
    est = believed.road_from_pixel(uv[..., 0], uv[..., 1], per_frame=True)       # (N, D, 3, 2)
    return {"range": est[:, :, 0, 0] - x, "lane_width": (est[:, :, 1, 1] - est[:, :, 2, 1]) - lane_width}


def drive_ground_errors(camera: Camera, pitch: Any, roll: Any, true_pitch: Any, true_roll: Any,
                        distances: Any = DISTANCES, lane_width: float = LANE_WIDTH) -> dict[str, dict]:
    """:func:`ground_errors` of the static extrinsic, an estimate and the truth for one drive's frames.

    Parameters
    ----------
    camera : Camera
    pitch, roll : array_like (N,)
        Estimated body pitch and roll relative to the road, rad.
    true_pitch, true_roll : array_like (N,)
        The truth, rad.

    Returns
    -------
    dict
        ``{"static": errors, "dynamic": errors, "truth": errors}``, each :func:`ground_errors`' dict.
    """
    truth = GroundPlane.from_pitch_roll(camera, true_pitch, true_roll)
    planes = {"static": GroundPlane.from_pitch_roll(camera, np.zeros(len(truth)), np.zeros(len(truth))),
              "dynamic": GroundPlane.from_pitch_roll(camera, pitch, roll), "truth": truth}
    return {name: ground_errors(truth, plane, distances, lane_width) for name, plane in planes.items()}
