"""Bird's-eye (inverse perspective) images: an image resampled onto a :class:`~imu_ground.perception.BevGrid`
through the homography image pixel <- bird's-eye pixel (:meth:`GroundPlane.from_bev
<imu_ground.perception.GroundPlane.from_bev>`) with :func:`scipy.ndimage.map_coordinates`."""
from __future__ import annotations

from typing import Any, Literal

import numpy as np

from imu_ground.perception.plane import BevGrid

__all__ = ["warp_to_bev"]


def warp_to_bev(image: Any, from_bev: Any, grid: BevGrid, order: Literal[0, 1, 2, 3, 4, 5] = 1,
                fill: float = 0.0) -> np.ndarray:
    """Resample ``image`` onto the bird's-eye grid.

    Parameters
    ----------
    image : array_like (H, W) or (H, W, C)
        Camera image (row = v, column = u).
    from_bev : array_like (3, 3)
        Homography image pixel ``(u, v, 1)`` <- bird's-eye pixel ``(col, row, 1)``, one frame's.
    grid : BevGrid
    order : {0, 1, 2, 3, 4, 5}
        Spline order of :func:`scipy.ndimage.map_coordinates` (1: bilinear).
    fill : float
        Value outside the image or behind the camera.

    Returns
    -------
    ndarray (rows, cols) or (rows, cols, C)
        ``image``'s dtype.
    """
    from scipy import ndimage                       # heavy (~0.2 s): loaded when a picture is warped
    img = np.asarray(image)
    h = np.asarray(from_bev, dtype=float)
    if h.shape != (3, 3):
        raise ValueError(f"from_bev must be one 3x3 homography, got shape {h.shape}")
    rows, cols = grid.shape
    c, r = np.meshgrid(np.arange(cols, dtype=float), np.arange(rows, dtype=float))
    p = np.einsum("ij,jrc->irc", h, np.stack([c, r, np.ones_like(c)]))
    with np.errstate(divide="ignore", invalid="ignore"):
        ahead = p[2] > 0
        u = np.where(ahead, p[0] / p[2], -1e6)
        v = np.where(ahead, p[1] / p[2], -1e6)
    channels = img[..., None] if img.ndim == 2 else img
    out = np.empty((rows, cols, channels.shape[2]), dtype=float)
    for k in range(channels.shape[2]):
        out[..., k] = ndimage.map_coordinates(channels[..., k].astype(float), [v, u], order=order, mode="constant",
                                      cval=fill, prefilter=order > 1)
    if np.issubdtype(img.dtype, np.integer):
        info = np.iinfo(img.dtype)
        out = np.clip(np.rint(out), info.min, info.max)
    out = out.astype(img.dtype)
    return out[..., 0] if img.ndim == 2 else out
