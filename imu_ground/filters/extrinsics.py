"""Static sensor-to-ground extrinsics: the value type and the text-file loader.

An extrinsic is calibrated once, with the vehicle at rest on flat ground. The
ground frame is FLU (x forward, y left, z up along the ground normal) with
its origin on the road surface; ``rotation`` maps sensor-frame vectors into
the ground frame (ground <- sensor) and ``translation`` is the sensor origin
in ground coordinates, metres.

File format (``calib/*.txt``, described in ``calib/README.md``)::

    # comments start with '#'
    platform: kitti
    sensor: cam0_rect
    R: r00 r01 r02 r10 r11 r12 r20 r21 r22    # row-major, ground <- sensor
    t: tx ty tz                                # metres, sensor origin in the ground frame

``R`` is required; ``t`` defaults to zero; other ``key: value`` lines are kept
as metadata.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Union

import numpy as np

__all__ = ["Extrinsic", "load_extrinsic", "save_extrinsic", "available_extrinsics"]

_ORTHO_TOL = 1e-6


@dataclass
class Extrinsic:
    """A static sensor-to-ground extrinsic.

    Attributes
    ----------
    rotation : ndarray (3, 3)
        ground <- sensor rotation (ground frame FLU, z = ground normal).
    translation : ndarray (3,)
        Sensor origin in the ground frame, metres.
    meta : dict
        Platform, sensor name, source, derivation notes.
    """
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.rotation = np.array(self.rotation, dtype=float)
        self.translation = np.array(self.translation, dtype=float)
        if self.rotation.shape != (3, 3):
            raise ValueError(f"extrinsic rotation must be 3x3, got shape {self.rotation.shape}")
        if self.translation.shape != (3,):
            raise ValueError(f"extrinsic translation must have 3 elements, got shape {self.translation.shape}")
        err = np.abs(self.rotation.T @ self.rotation - np.eye(3)).max()
        if err > _ORTHO_TOL or np.linalg.det(self.rotation) < 0:
            raise ValueError(f"extrinsic rotation is not a rotation (|R^T R - I| = {err:.2e}, "
                             f"det = {np.linalg.det(self.rotation):.6f})")

    @classmethod
    def coerce(cls, value: Union["Extrinsic", np.ndarray, None]) -> "Extrinsic":
        """An Extrinsic from None (identity), an Extrinsic (itself) or a 3x3 rotation (ground <- sensor)."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        return cls(rotation=np.asarray(value, dtype=float))

    @property
    def normal(self) -> np.ndarray:
        """Static ground normal in the sensor frame, ``R^T e_z``."""
        return self.rotation[2].copy()

    @property
    def matrix(self) -> np.ndarray:
        """4x4 homogeneous transform ground <- sensor."""
        m = np.eye(4)
        m[:3, :3] = self.rotation
        m[:3, 3] = self.translation
        return m


def available_extrinsics() -> list[str]:
    """Names of the extrinsics shipped in ``calib/`` (usable with :func:`load_extrinsic`)."""
    root = resources.files("imu_ground.calib")
    return sorted(p.name[:-4] for p in root.iterdir() if p.name.endswith(".txt"))


def _resolve(name_or_path: Union[str, Path]) -> Path:
    p = Path(name_or_path)
    if p.suffix == ".txt" or p.exists() or len(p.parts) > 1:
        if not p.is_file():
            raise FileNotFoundError(f"extrinsic file not found: {p}")
        return p
    shipped = resources.files("imu_ground.calib") / f"{name_or_path}.txt"
    if not shipped.is_file():
        raise FileNotFoundError(f"no shipped extrinsic named {str(name_or_path)!r}; "
                                f"available: {', '.join(available_extrinsics())} (or give a file path)")
    return Path(str(shipped))


def _numbers(path: Path, lineno: int, key: str, text: str, count: int) -> np.ndarray:
    parts = text.split()
    if len(parts) != count:
        raise ValueError(f"{path}:{lineno}: '{key}' needs {count} numbers, got {len(parts)}")
    try:
        return np.array([float(v) for v in parts])
    except ValueError as e:
        raise ValueError(f"{path}:{lineno}: '{key}' has a value that is not a number: {e}") from None


def load_extrinsic(name_or_path: Union[str, Path]) -> Extrinsic:
    """Read a static extrinsic from a shipped name (``"kitti_cam0"``) or a file path.

    Parameters
    ----------
    name_or_path : str or Path
        A name from :func:`available_extrinsics` or the path of a file in the
        format of ``calib/README.md``.

    Returns
    -------
    Extrinsic
        ``rotation`` is ground <- sensor; ``translation`` the sensor origin in
        the ground frame, metres.

    Raises
    ------
    FileNotFoundError
        No such file or shipped name (the message lists the shipped names).
    ValueError
        Malformed line (file and line number), missing ``R``, or a matrix that
        is not a rotation.
    """
    path = _resolve(name_or_path)
    rot = None
    trans = np.zeros(3)
    meta: dict = {"source": str(path)}
    for lineno, raw in enumerate(path.read_text().splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if ":" not in line:
            raise ValueError(f"{path}:{lineno}: expected 'key: value', got {raw.strip()!r}")
        key, value = (s.strip() for s in line.split(":", 1))
        if key == "R":
            rot = _numbers(path, lineno, key, value, 9).reshape(3, 3)
            rot_line = lineno
        elif key == "t":
            trans = _numbers(path, lineno, key, value, 3)
        else:
            meta[key] = value
    if rot is None:
        raise ValueError(f"{path}: no 'R:' line (the ground <- sensor rotation, 9 numbers row-major)")
    try:
        return Extrinsic(rot, trans, meta)
    except ValueError as e:
        raise ValueError(f"{path}:{rot_line}: {e}") from None


def save_extrinsic(ext: Extrinsic, path: Union[str, Path], comment: str = "") -> None:
    """Write an extrinsic in the ``calib/`` text format (17 significant digits)."""
    lines = [f"# {c}" for c in comment.splitlines()] if comment else []
    for k, v in ext.meta.items():
        if k != "source":
            lines.append(f"{k}: {v}")
    lines.append("R: " + " ".join(f"{v:.17g}" for v in ext.rotation.ravel()))
    lines.append("t: " + " ".join(f"{v:.17g}" for v in ext.translation))
    Path(path).write_text("\n".join(lines) + "\n")
