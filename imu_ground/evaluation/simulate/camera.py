"""A camera's view of the simulated road: lane markings and a metric grid on the true, moving road plane.

:func:`render_road` ray-casts every pixel onto one frame's true road plane and paints asphalt,
solid lane lines at ``Y = +- lane_width/2``, dashed ones a lane further out, grass beyond, a grid
scrolling with the distance travelled, and sky above the horizon or beyond ``max_range``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imu_ground.perception.plane import GroundPlane

__all__ = ["RoadMarkings", "render_road"]

_ASPHALT = np.array([92.0, 92.0, 96.0])
_LINE = np.array([245.0, 245.0, 240.0])
_GRID = np.array([235.0, 190.0, 60.0])
_GRASS = np.array([70.0, 120.0, 60.0])
_SKY_TOP, _SKY_LOW = np.array([120.0, 165.0, 225.0]), np.array([205.0, 220.0, 235.0])


@dataclass(frozen=True)
class RoadMarkings:
    """What is painted on the simulated road (m): lane width and line width, dash pattern, grid spacing."""
    lane_width: float = 3.5
    line_width: float = 0.15
    dash: float = 3.0
    gap: float = 6.0
    grid_across: float = 5.0
    grid_along: float = 1.0
    grid_line: float = 0.06
    max_range: float = 120.0


def _colour(x: np.ndarray, y: np.ndarray, m: RoadMarkings) -> np.ndarray:
    """RGB (float) of road points ``(x, y)``: road frame, ``x`` already shifted by the distance travelled."""
    out = np.broadcast_to(_ASPHALT, x.shape + (3,)).copy()
    grid = ((np.abs((x + 0.5 * m.grid_across) % m.grid_across - 0.5 * m.grid_across) < 2 * m.grid_line)
            | (np.abs((y + 0.5 * m.grid_along) % m.grid_along - 0.5 * m.grid_along) < 0.5 * m.grid_line))
    out[grid] = _GRID
    half = 0.5 * m.line_width
    solid = np.abs(np.abs(y) - 0.5 * m.lane_width) < half
    dashed = (np.abs(np.abs(y) - 1.5 * m.lane_width) < half) & ((x % (m.dash + m.gap)) < m.dash)
    out[solid | dashed] = _LINE
    out[np.abs(y) > 2.0 * m.lane_width + 1.0] = _GRASS
    return out


def render_road(plane: GroundPlane, image_size: tuple[int, int], travelled: float = 0.0,
                markings: RoadMarkings = RoadMarkings(), supersample: int = 2) -> np.ndarray:
    """The camera image of one frame's road, uint8 (height, width, 3).

    Parameters
    ----------
    plane : GroundPlane
        One frame: the true road plane in the camera's axes (its road frame: x forward, y left).
    image_size : tuple of int
        ``(width, height)``, pixels.
    travelled : float
        Distance driven, m: the markings move by it.
    markings : RoadMarkings
    supersample : int
        Rays per pixel along each axis.
    """
    if len(plane) != 1:
        raise ValueError(f"render_road draws one frame, got a plane of {len(plane)} frames")
    w, h = int(image_size[0]), int(image_size[1])
    k = max(1, int(supersample))
    offs = (np.arange(k) + 0.5) / k - 0.5
    u = (np.arange(w)[:, None] + offs[None, :]).ravel()
    v = (np.arange(h)[:, None] + offs[None, :]).ravel()
    road = plane.road_from_pixel(u[None, :], v[:, None])[0]                     # (h k, w k, 2)
    x, y = road[..., 0], road[..., 1]
    dist = np.hypot(x - plane.translation[0, 0], y - plane.translation[0, 1])
    ground = np.isfinite(x) & (dist < markings.max_range)
    img = np.empty(x.shape + (3,))
    share = np.clip(v / max(h - 1, 1), 0.0, 1.0)[:, None, None]
    img[:] = _SKY_TOP * (1 - share) + _SKY_LOW * share
    colour = _colour(np.where(ground, x + travelled, 0.0), np.where(ground, y, 0.0), markings)
    haze = np.clip(dist / markings.max_range, 0.0, 1.0)[..., None] ** 2
    img = np.where(ground[..., None], colour * (1 - haze) + _SKY_LOW * haze, img)
    img = img.reshape(h, k, w, k, 3).mean(axis=(1, 3))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
