r"""The road plane seen by a camera, frame by frame: :class:`GroundPlane`, and the bird's-eye grid :class:`BevGrid`.

Frames and signs
----------------
- **Camera** axes: x right, y down, z forward; pixel ``(u, v)`` sees the ray ``K^-1 (u, v, 1)`` (z component 1:
  a point's depth is the ray's scale).
- **Road** frame ``r``: x forward, y left, z up along the road normal, origin on the road. With
  :meth:`GroundPlane.from_camera`: ``R_rc = E · R_gc``, ``t_rc = E · t_gc`` with ``E`` the estimate's residual
  rotation road <- body and ``(R_gc, t_gc)`` the camera's static extrinsic (ground <- camera); the static extrinsic
  is ``E = I``.
- **Plane** in camera axes: ``n · X + d = 0``, ``n`` the unit road normal pointing up, ``d`` the camera's height
  above the road, m (KITTI ``planes`` files' ``a b c d``).

Batch-first: a :class:`GroundPlane` holds ``N`` frames, every query a leading axis of ``N``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from imu_ground.so3 import rotx, roty

__all__ = ["BevGrid", "GroundPlane", "range_error"]


@dataclass(frozen=True)
class BevGrid:
    """A bird's-eye (inverse perspective) grid on the road: ``x0..x1`` ahead, ``y0..y1`` to the left, ``res`` m a pixel.

    Forward is up, left is left: pixel ``(col, row)``'s centre is the road point ``X = x1 - (row + 0.5) res``,
    ``Y = y1 - (col + 0.5) res`` (m, road frame).
    """
    x0: float
    x1: float
    y0: float
    y1: float
    res: float

    def __post_init__(self) -> None:
        vals = (self.x0, self.x1, self.y0, self.y1, self.res)
        if not all(np.isfinite(vals)):
            raise ValueError(f"bird's-eye grid needs finite numbers, got {vals}")
        if self.res <= 0 or self.x1 <= self.x0 or self.y1 <= self.y0:
            raise ValueError(f"bird's-eye grid needs X0 < X1, Y0 < Y1 and RES > 0 (m), got {vals}")
        if self.shape[0] < 1 or self.shape[1] < 1:
            raise ValueError(f"bird's-eye grid of {vals} has no pixel: RES is larger than the extent")
        if self.shape[0] * self.shape[1] > 50_000_000:
            raise ValueError(f"bird's-eye grid of {vals} has {self.shape[0]} x {self.shape[1]} pixels; "
                             "choose a coarser RES")

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, cols)`` of the bird's-eye image."""
        return int(round((self.x1 - self.x0) / self.res)), int(round((self.y1 - self.y0) / self.res))

    @property
    def road_from_bev(self) -> np.ndarray:
        """3x3 homography road ``(X, Y, 1)`` <- bird's-eye pixel ``(col, row, 1)``."""
        r = self.res
        return np.array([[0.0, -r, self.x1 - 0.5 * r], [-r, 0.0, self.y1 - 0.5 * r], [0.0, 0.0, 1.0]])

    def bev_from_road(self, x: Any, y: Any) -> np.ndarray:
        """Bird's-eye pixel ``(..., 2)`` (col, row) of road points ``(x, y)`` (m)."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        return np.stack([(self.y1 - y) / self.res - 0.5, (self.x1 - x) / self.res - 0.5], axis=-1)


def _batch(a: Any, tail: tuple[int, ...], what: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.shape == tail:
        a = a[None]
    if a.ndim != len(tail) + 1 or a.shape[1:] != tail:
        raise ValueError(f"{what} must have shape (N, {', '.join(map(str, tail))}) or {tail}, got {a.shape}")
    return a


def _rotations_about(normal: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations road <- camera with z = ``normal`` and x = ``forward`` projected onto the plane."""
    z = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    x = forward - np.einsum("ni,ni->n", forward, z)[:, None] * z
    norm = np.linalg.norm(x, axis=1, keepdims=True)
    if np.any(norm < 1e-9):
        raise ValueError("forward direction is parallel to the plane normal")
    x = x / norm
    return np.stack([x, np.cross(z, x), z], axis=1)


def range_error(distance: Any, dpitch: Any, droll: Any = 0.0, height: Any = 1.65, lateral: Any = 0.0,
                first_order: bool = False) -> np.ndarray:
    r"""How far a ground point's estimated range moves when the road plane is off by ``dpitch``, ``droll``.

    The ray to the road point ``distance`` m ahead and ``lateral`` m left of the point below a camera ``height`` m
    up, intersected with the plane through that point tilted by the errors (estimated minus true pitch, + nose down,
    and roll, + left side up, rad): its ground range in the tilted plane minus the true one, m; NaN above the
    horizon.

    Parameters
    ----------
    distance, lateral : array_like
        Road point ahead and to the left of the point below the camera, m.
    dpitch, droll : array_like
        Plane errors, rad.
    height : array_like
        Camera height above the road, m.
    first_order : bool
        The linearisation ``-(rho^2 + height^2) (distance dpitch - lateral droll) / (rho height)`` (``rho`` the true
        ground range; far ahead ``-distance^2 dpitch / height``).

    Returns
    -------
    ndarray
        Broadcast shape of the inputs, m; negative: the point looks closer than it is.
    """
    d, y, dp, dr, h = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in
                                            (distance, lateral, dpitch, droll, height)))
    rho = np.hypot(d, y)
    if first_order:
        return -(rho ** 2 + h ** 2) * (d * dp - y * dr) / (rho * h)
    n = np.stack([-np.sin(dp), np.sin(dr) * np.cos(dp), np.cos(dp) * np.cos(dr)], axis=-1)
    p = np.stack([d, y, -h], axis=-1)
    denom = np.einsum("...i,...i->...", n, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom < 0, -h / denom, np.nan)
        q = s[..., None] * p + h[..., None] * n              # from the point below the camera on the tilted plane
    return np.linalg.norm(q, axis=-1) - rho


class GroundPlane:
    """The road plane in a camera's axes for ``N`` frames, with its pixel and bird's-eye queries.

    Parameters
    ----------
    K : array_like (3, 3)
        Camera intrinsics, pixels.
    rotation : array_like (N, 3, 3) or (3, 3)
        Road <- camera rotation per frame.
    translation : array_like (N, 3) or (3,)
        The camera origin in the road frame, m (its z: the camera's height above the road).
    image_size : tuple of int, optional
        ``(width, height)``, pixels (queries do not clip to it). Frames with NaN give NaN.
    """

    def __init__(self, K: Any, rotation: Any, translation: Any, image_size: tuple[int, int] | None = None) -> None:
        self.K = np.array(K, dtype=float)
        if self.K.shape != (3, 3):
            raise ValueError(f"K must be 3x3, got shape {self.K.shape}")
        self.rotation = _batch(rotation, (3, 3), "rotation")
        self.translation = _batch(translation, (3,), "translation")
        if len(self.rotation) != len(self.translation):
            raise ValueError(f"{len(self.rotation)} rotations but {len(self.translation)} translations")
        self.image_size = None if image_size is None else (int(image_size[0]), int(image_size[1]))
        self._K_inv = np.linalg.inv(self.K)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_camera(cls, camera: Any, residual: Any = None) -> GroundPlane:
        """The planes of ``camera`` for residual rotations road <- body (``None``: the static extrinsic).

        Parameters
        ----------
        camera : Camera
            Intrinsics and static extrinsic ground <- camera (:class:`~imu_ground.perception.Camera`).
        residual : array_like (N, 3, 3) or (3, 3), optional
            Per-frame rotation road <- body of an estimate (its track's ``residual``); identity when None.
        """
        e = np.eye(3)[None] if residual is None else _batch(residual, (3, 3), "residual")
        ext = camera.extrinsic
        return cls(camera.K, e @ ext.rotation, e @ ext.translation, camera.image_size)

    @classmethod
    def from_pitch_roll(cls, camera: Any, pitch: Any, roll: Any) -> GroundPlane:
        """The planes of ``camera`` for the body's pitch and roll relative to the road (rad; + nose down,
        + left side up): :meth:`from_camera` with the yaw-free residual ``Ry(pitch) Rx(roll)``."""
        p, r = np.broadcast_arrays(np.atleast_1d(np.asarray(pitch, dtype=float)),
                                   np.atleast_1d(np.asarray(roll, dtype=float)))
        return cls.from_camera(camera, roty(p) @ rotx(r))

    @classmethod
    def from_normal(cls, K: Any, normal: Any, height: Any, rotation: Any = None, forward: Any = (0.0, 0.0, 1.0),
                    image_size: tuple[int, int] | None = None) -> GroundPlane:
        """Planes from a unit road normal (pointing up) in any frame and the camera's height above the road.

        Parameters
        ----------
        K : array_like (3, 3)
            Intrinsics, pixels.
        normal : array_like (N, 3) or (3,)
            Road normal, pointing up, in frame ``F`` (normalised here).
        height : array_like (N,) or scalar
            Camera height above the road, m (> 0).
        rotation : array_like (3, 3) or (N, 3, 3), optional
            Camera <- ``F`` rotation; None when the normal is already in camera axes.
        forward : array_like (3,)
            Camera-axes direction projected onto the road as its x (origin below the camera).
        image_size : tuple of int, optional
        """
        n = _batch(normal, (3,), "normal")
        if rotation is not None:
            n = np.einsum("...ij,nj->ni", np.asarray(rotation, dtype=float), n)
        h = np.broadcast_to(np.asarray(height, dtype=float), (len(n),))
        fwd = np.broadcast_to(np.asarray(forward, dtype=float), n.shape)
        r_rc = _rotations_about(n, fwd)
        t_rc = np.zeros((len(n), 3))
        t_rc[:, 2] = h
        return cls(K, r_rc, t_rc, image_size)

    # ------------------------------------------------------------------ the plane
    def __len__(self) -> int:
        return len(self.rotation)

    def __getitem__(self, index: Any) -> GroundPlane:
        """The frames ``index`` selects (an int keeps a frame axis of 1)."""
        if isinstance(index, (int, np.integer)):
            index = slice(index, index + 1 if index != -1 else None)
        return GroundPlane(self.K, self.rotation[index], self.translation[index], self.image_size)

    def __repr__(self) -> str:
        return f"GroundPlane({len(self)} frames, height {np.nanmedian(self.height) if len(self) else np.nan:.3f} m)"

    @property
    def normal(self) -> np.ndarray:
        """(N, 3) unit road normal in camera axes, pointing up."""
        return self.rotation[:, 2, :].copy()

    @property
    def height(self) -> np.ndarray:
        """(N,) camera height above the road, m (the plane's ``d``)."""
        return self.translation[:, 2].copy()

    @property
    def coefficients(self) -> np.ndarray:
        """(N, 4) ``a b c d``: ``a x + b y + c z + d = 0`` for road points in camera axes (KITTI ``planes``)."""
        return np.column_stack([self.normal, self.height])

    @property
    def matrix(self) -> np.ndarray:
        """(N, 4, 4) homogeneous transform road <- camera."""
        m = np.zeros((len(self), 4, 4))
        m[:, :3, :3] = self.rotation
        m[:, :3, 3] = self.translation
        m[:, 3, 3] = 1.0
        return m

    # ------------------------------------------------------------------ pixels
    def _rays(self, u: Any, v: Any) -> np.ndarray:
        u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
        return np.stack([u, v, np.ones_like(u)], axis=-1) @ self._K_inv.T          # (..., 3), z = 1

    def _frame_rays(self, u: Any, v: Any, per_frame: bool) -> np.ndarray:
        rays = self._rays(u, v)
        if not per_frame:
            return np.broadcast_to(rays, (len(self),) + rays.shape)
        if rays.ndim < 2 or rays.shape[0] != len(self):
            raise ValueError(f"per_frame pixels need a leading axis of {len(self)} frames, got shape {rays.shape[:-1]}")
        return rays

    def depth(self, u: Any, v: Any, per_frame: bool = False) -> np.ndarray:
        """(N, ...) depth (camera z, m) of the road point pixel ``(u, v)`` sees; NaN at or above the horizon
        (``per_frame``: ``u`` and ``v`` lead with ``N``, frame ``i``'s pixels for frame ``i``)."""
        rays = self._frame_rays(u, v, per_frame)
        denom = np.einsum("ni,n...i->n...", self.normal, rays)
        h = self.height.reshape((-1,) + (1,) * (denom.ndim - 1))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(denom < 0, -h / denom, np.nan)

    def point_from_pixel(self, u: Any, v: Any, per_frame: bool = False) -> np.ndarray:
        """(N, ..., 3) road point (camera axes, m) that pixel ``(u, v)`` sees; NaN at or above the horizon."""
        return self.depth(u, v, per_frame)[..., None] * self._frame_rays(u, v, per_frame)

    def road_from_pixel(self, u: Any, v: Any, per_frame: bool = False) -> np.ndarray:
        """(N, ..., 2) road-frame ``(X, Y)`` (m; forward, left) of the road point pixel ``(u, v)`` sees."""
        p = self.point_from_pixel(u, v, per_frame)
        shape = p.shape
        q = np.einsum("nij,nkj->nki", self.rotation[:, :2], p.reshape(len(self), -1, 3))
        q = q + self.translation[:, None, :2]
        return q.reshape(shape[:-1] + (2,))

    def pixel_from_road(self, x: Any, y: Any) -> np.ndarray:
        """(N, ..., 2) pixel ``(u, v)`` of road points ``(x, y)`` (road frame, m); NaN behind the camera."""
        x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
        pts = np.stack([x, y, np.zeros_like(x)], axis=-1).reshape(-1, 3)
        cam = np.einsum("nji,nkj->nki", self.rotation, pts[None] - self.translation[:, None, :])  # R^T (p - t)
        img = cam @ self.K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.where(cam[..., 2:] > 0, img[..., :2] / img[..., 2:], np.nan)
        return uv.reshape((len(self),) + x.shape + (2,))

    # ------------------------------------------------------------------ homographies
    @property
    def image_from_road(self) -> np.ndarray:
        """(N, 3, 3) homography pixel ``(u, v, 1)`` <- road ``(X, Y, 1)``: ``K [r1 r2 t]`` of camera <- road."""
        r_cr = np.swapaxes(self.rotation, 1, 2)
        t_cr = -np.einsum("nij,nj->ni", r_cr, self.translation)
        return np.einsum("ij,njk->nik", self.K, np.stack([r_cr[:, :, 0], r_cr[:, :, 1], t_cr], axis=2))

    def from_bev(self, grid: BevGrid) -> np.ndarray:
        """(N, 3, 3) homography image pixel <- bird's-eye pixel ``(col, row, 1)`` of ``grid`` (sampling map of a warp)."""
        return self.image_from_road @ grid.road_from_bev

    def to_bev(self, grid: BevGrid) -> np.ndarray:
        """(N, 3, 3) homography bird's-eye pixel <- image pixel (OpenCV ``warpPerspective``'s matrix), ``h22 = 1``."""
        h = np.linalg.inv(self.from_bev(grid))
        with np.errstate(divide="ignore", invalid="ignore"):
            return h / h[:, 2:, 2:]

    def range_error(self, distance: Any, dpitch: Any, droll: Any = 0.0, lateral: Any = 0.0,
                    first_order: bool = False) -> np.ndarray:
        """:func:`range_error` with this plane's camera heights: shape ``(N,) + broadcast(inputs)``, m."""
        shape = np.broadcast_shapes(*(np.shape(a) for a in (distance, dpitch, droll, lateral)))
        h = self.height.reshape((-1,) + (1,) * len(shape))
        return range_error(distance, dpitch, droll, h, lateral, first_order)
