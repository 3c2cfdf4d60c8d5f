"""Static sensor-to-ground extrinsics: the value type and the text-file loader.

An extrinsic is calibrated once, the vehicle at rest on flat ground. The ground frame is FLU (z up along the ground
normal, origin on the road); ``rotation`` maps sensor-frame vectors into it (ground <- sensor) and ``translation``
is the sensor origin in ground coordinates, m. File format (``calib/*.txt``, ``calib/README.md``)::

    # comments start with '#'
    platform: kitti
    sensor: cam0_rect
    R: r00 r01 r02 r10 r11 r12 r20 r21 r22    # row-major, ground <- sensor
    t: tx ty tz                                # metres, sensor origin in the ground frame

``R`` is required, ``t`` defaults to zero, other ``key: value`` lines are metadata. A *calibration file*
(:meth:`Calibration.save`, :func:`load_calibration`) adds the platform's suspension gains::

    suspension_gains: -0.0043633 0.0087266      # k_pitch k_roll
    suspension_gains_unit: rad per m/s^2         # or: deg per m/s^2

:func:`resolve_platform` is the one reader of an ``extrinsic=`` argument.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Optional, Union

import numpy as np

from imu_ground.errors import ImuGroundError
from imu_ground.so3 import euler_zyx
from imu_ground.units import DEG

__all__ = ["Extrinsic", "load_extrinsic", "save_extrinsic", "available_extrinsics", "Calibration",
           "load_calibration", "resolve_platform"]

_ORTHO_TOL = 1e-6
_GAIN_UNITS = {"rad per m/s^2": 1.0, "deg per m/s^2": DEG}


@dataclass
class Extrinsic:
    """A static sensor-to-ground extrinsic.

    Attributes
    ----------
    rotation : ndarray (3, 3)     ground <- sensor (ground frame FLU, z = ground normal).
    translation : ndarray (3,)    sensor origin in the ground frame, m.
    meta : dict                   platform, sensor name, source, derivation notes.
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
        if not (np.all(np.isfinite(self.rotation)) and np.all(np.isfinite(self.translation))):
            raise ValueError("extrinsic rotation and translation must be finite")
        err = np.abs(self.rotation.T @ self.rotation - np.eye(3)).max()
        if err > _ORTHO_TOL or np.linalg.det(self.rotation) < 0:
            raise ValueError(f"extrinsic rotation is not a rotation (|R^T R - I| = {err:.2e}, "
                             f"det = {np.linalg.det(self.rotation):.6f})")

    def settings(self) -> dict:
        """Rotation and translation, the settings a saved state compares (:mod:`imu_ground.imu.warm_start`)."""
        return {"rotation": self.rotation, "translation": self.translation}

    @classmethod
    def coerce(cls, value) -> "Extrinsic":
        """The Extrinsic of an ``extrinsic=`` argument (:func:`resolve_platform`)."""
        return resolve_platform(value)[0]

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
        raise ImuGroundError(f"{path}:{lineno}: '{key}' needs {count} numbers, got {len(parts)}")
    try:
        values = np.array([float(v) for v in parts])
    except ValueError as e:
        raise ImuGroundError(f"{path}:{lineno}: '{key}' has a value that is not a number: {e}") from None
    if not np.all(np.isfinite(values)):
        bad = " ".join(v for v, x in zip(parts, values, strict=True) if not np.isfinite(x))
        raise ImuGroundError(f"{path}:{lineno}: '{key}' has a value that is not finite ({bad}); the file is "
                             "unusable: calibrate again or fix the line")
    return values


def load_extrinsic(name_or_path: Union[str, Path]) -> Extrinsic:
    """Read a static extrinsic from a shipped name (``"kitti_cam0"``) or a file path.

    Parameters
    ----------
    name_or_path : str or Path
        A name from :func:`available_extrinsics` or a file in the format of ``calib/README.md``.

    Returns
    -------
    Extrinsic

    Raises
    ------
    FileNotFoundError
        No such file or shipped name (the message lists the shipped names).
    ImuGroundError
        Not text, a malformed line (file and line number), no ``R``, or not a rotation.
    """
    path = _resolve(name_or_path)
    rot = None
    trans = np.zeros(3)
    meta: dict = {"source": str(path)}
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ImuGroundError(f"{path}: not a calibration file (not UTF-8 text: {e.reason} at byte {e.start}); "
                             "give the file 'imu-ground calibrate' wrote, or a shipped name") from None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if ":" not in line:
            raise ImuGroundError(f"{path}:{lineno}: expected 'key: value', got {raw.strip()!r}")
        key, value = (s.strip() for s in line.split(":", 1))
        if key == "R":
            rot = _numbers(path, lineno, key, value, 9).reshape(3, 3)
            rot_line = lineno
        elif key == "t":
            trans = _numbers(path, lineno, key, value, 3)
        else:
            meta[key] = value
    if rot is None:
        raise ImuGroundError(f"{path}: no 'R:' line (the ground <- sensor rotation, 9 numbers row-major)")
    try:
        return Extrinsic(rot, trans, meta)
    except ValueError as e:
        raise ImuGroundError(f"{path}:{rot_line}: {e}") from None


def save_extrinsic(ext: Extrinsic, path: Union[str, Path], comment: str = "") -> None:
    """Write an extrinsic in the ``calib/`` text format (17 significant digits)."""
    lines = [f"# {c}" for c in comment.splitlines()] if comment else []
    lines += [f"{k}: {v}" for k, v in ext.meta.items() if k != "source"]
    lines.append("R: " + " ".join(f"{v:.17g}" for v in ext.rotation.ravel()))
    lines.append("t: " + " ".join(f"{v:.17g}" for v in ext.translation))
    Path(path).write_text("\n".join(lines) + "\n")


def _gains_from_meta(ext: Extrinsic) -> Optional[np.ndarray]:
    """Suspension gains ``(k_pitch, k_roll)`` (rad per m/s^2) of a calibration file's metadata, or None."""
    if "suspension_gains" not in ext.meta:
        return None
    raw, where = ext.meta["suspension_gains"], f"{ext.meta.get('source', 'extrinsic')}: 'suspension_gains'"
    parts = str(raw).split()
    unit = str(ext.meta.get("suspension_gains_unit", "rad per m/s^2")).strip()
    if len(parts) != 2 or unit not in _GAIN_UNITS:
        raise ImuGroundError(f"{where} needs two numbers and a unit in {sorted(_GAIN_UNITS)}, got {raw!r} ({unit!r})")
    try:
        gains = np.array([float(p) for p in parts]) * _GAIN_UNITS[unit]
    except ValueError:
        raise ImuGroundError(f"{where} has a value that is not a number: {raw!r}") from None
    if not np.all(np.isfinite(gains)):
        raise ImuGroundError(f"{where} is not finite ({raw}): the calibration could not determine them; calibrate "
                             "again on a drive (with --lever-arm), or delete the line to use the default gains")
    return gains


@dataclass
class Calibration:
    """A platform's calibration: static extrinsic and suspension gains (:func:`~imu_ground.filters.calibration.calibrate`).

    Attributes
    ----------
    extrinsic : Extrinsic
        Ground <- sensor rotation and sensor origin (m).
    gains : ndarray (2,) or None
        ``(k_pitch, k_roll)``, rad per m/s^2 (pitch nose down + per m/s^2 forward, roll left side up + per m/s^2
        leftward); NaN where a drive had no signal, None if not estimated.
    stats : dict
        The numbers behind the result (frames used, per-source tilts in deg, ...).
    """
    extrinsic: Extrinsic
    gains: Optional[np.ndarray] = None
    stats: dict = field(default_factory=dict)

    @property
    def rotation(self) -> np.ndarray:
        """ground <- sensor rotation (3x3)."""
        return self.extrinsic.rotation

    def filter_kwargs(self) -> dict:
        """Keyword arguments of :class:`~imu_ground.filters.suspension.SuspensionAwareFilter` for this platform."""
        kw: dict[str, Any] = {"extrinsic": self.extrinsic}
        if self.gains is not None and np.all(np.isfinite(self.gains)):
            kw["gains"] = tuple(float(g) for g in self.gains)
        return kw

    def save(self, path: Union[str, Path], comment: str = "") -> None:
        """Write the calibration file (the extrinsic format with a ``suspension_gains`` line)."""
        meta = {k: v for k, v in self.extrinsic.meta.items()
                if k not in ("suspension_gains", "suspension_gains_unit")}
        if self.gains is not None:
            meta["suspension_gains"] = f"{self.gains[0]:.10g} {self.gains[1]:.10g}"
            meta["suspension_gains_unit"] = "rad per m/s^2"
        head = ("calibrated by imu_ground.filters.calibration.calibrate: R ground <- sensor, t sensor origin in the "
                "ground frame (m); suspension_gains: k_pitch k_roll")
        text = head + ("\n" + comment if comment else "")
        save_extrinsic(Extrinsic(self.extrinsic.rotation, self.extrinsic.translation, meta), path, comment=text)

    @classmethod
    def from_extrinsic(cls, ext: Extrinsic) -> "Calibration":
        """A Calibration from a loaded extrinsic whose metadata may hold ``suspension_gains``."""
        return cls(ext, _gains_from_meta(ext), {})

    def __str__(self) -> str:
        roll, pitch, yaw = np.degrees(euler_zyx(self.extrinsic.rotation))
        lines = [f"Calibration: sensor mounted with roll {roll:+.3f} deg, pitch {pitch:+.3f} deg, "
                 f"yaw {yaw:+.2f} deg relative to the ground frame (ground <- sensor = "
                 f"Rz(yaw) Ry(pitch) Rx(roll))"]
        if self.gains is not None:
            kp, kr = np.degrees(self.gains)
            lines.append(f"  suspension gains: pitch {kp:+.3f}, roll {kr:+.3f} deg per m/s^2")
        for key in ("tilt_source", "tilt_reason", "yaw_source", "cruise_s", "standstill_s", "moving_s", "gain_frames",
                    "pitch_gain_rejected", "roll_gain_rejected"):
            if key in self.stats:
                lines.append(f"  {key}: {self.stats[key]}")
        return "\n".join(lines)


def load_calibration(name_or_path: Union[str, Path]) -> Calibration:
    """Read a calibration file (or any extrinsic file; the gains are None without a ``suspension_gains`` line).

    Parameters
    ----------
    name_or_path : str or Path
        As for :func:`load_extrinsic`.
    """
    return Calibration.from_extrinsic(load_extrinsic(name_or_path))


def resolve_platform(value) -> tuple:
    """The extrinsic and suspension gains an ``extrinsic=`` argument stands for.

    Parameters
    ----------
    value : None, Extrinsic, Calibration, array_like (3, 3), str or Path
        None: identity; a 3x3 rotation: ground <- sensor; a str or Path: a shipped name or a file
        (:func:`load_extrinsic`), whose ``suspension_gains`` line, if any, gives the gains.

    Returns
    -------
    extrinsic : Extrinsic
    gains : ndarray (2,) or None
        rad per m/s^2, when the value carries them.
    """
    if value is None:
        return Extrinsic(), None
    if isinstance(value, Calibration):
        g = value.gains
        return value.extrinsic, (g if g is not None and np.all(np.isfinite(g)) else None)
    if isinstance(value, (str, Path)):
        value = load_extrinsic(value)
    if isinstance(value, Extrinsic):
        return value, _gains_from_meta(value)
    return Extrinsic(rotation=np.asarray(value, dtype=float)), None
