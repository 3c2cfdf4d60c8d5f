"""One container for an IMU log, whatever format it came from.

Every reader in :mod:`imu_ground.datasets` returns an :class:`ImuData`; the
preintegration, the simulator and the command-line tool consume it.

Frames and units
----------------
- ``t``: sample times in seconds (float64). Readers convert from the file's unit
  (ns, us, ms) and keep the epoch of the file in ``meta["t0"]`` when the file
  gives absolute times; ``t`` itself may start anywhere.
- ``gyro``: angular rate of the body frame relative to inertial space, expressed
  in the body frame, rad/s.
- ``accel``: specific force (acceleration minus gravity, what an accelerometer
  measures) in the body frame, m/s^2; about ``+9.81`` on the up axis at rest.
- ``frame``: the body frame's name and axes, e.g. ``"FLU"`` (x forward, y left,
  z up: KITTI OXTS, nuScenes) or ``"device"`` (a phone's own axes).
- ``extra``: every other column of the source (reference attitude, velocity,
  GPS, ...), one row per sample, in the source's units (named in ``units``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:       # pandas is imported where it is used, not with the package
    import pandas as pd

__all__ = ["ImuData"]


def _empty_frame() -> pd.DataFrame:
    """The default ``extra``: an empty DataFrame (pandas imported on first use)."""
    import pandas as pd
    return pd.DataFrame()


@dataclass
class ImuData:
    """An IMU log: times, angular rate and specific force, plus extra columns.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times, seconds, strictly increasing once validated.
    gyro : ndarray, shape (N, 3)
        Angular rate in the body frame, rad/s.
    accel : ndarray, shape (N, 3)
        Specific force in the body frame, m/s^2.
    frame : str
        Name of the body frame (``"FLU"``: x forward, y left, z up).
    extra : pandas.DataFrame
        Other columns of the source, aligned row for row with ``t``.
    units : dict
        Units of the ``extra`` columns (column name to unit string).
    source : str
        Where the data came from (path, or ``"simulated"``).
    meta : dict
        Anything else a reader wants to keep (absolute start time, format, the
        validation report, ...).
    """

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    frame: str = "FLU"
    extra: pd.DataFrame = field(default_factory=_empty_frame)
    units: dict[str, str] = field(default_factory=dict)
    source: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.t = np.ascontiguousarray(self.t, dtype=float)
        self.gyro = np.ascontiguousarray(self.gyro, dtype=float)
        self.accel = np.ascontiguousarray(self.accel, dtype=float)
        n = self.t.shape[0]
        if self.t.ndim != 1:
            raise ValueError(f"ImuData.t must be 1-D, got shape {self.t.shape}")
        for name, arr in (("gyro", self.gyro), ("accel", self.accel)):
            if arr.shape != (n, 3):
                raise ValueError(f"ImuData.{name} must have shape ({n}, 3), got {arr.shape}")
        if len(self.extra) not in (0, n):
            raise ValueError(f"ImuData.extra has {len(self.extra)} rows, expected {n}")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time from first to last sample, seconds (0 for fewer than 2 samples)."""
        return float(self.t[-1] - self.t[0]) if len(self) > 1 else 0.0

    @property
    def rate(self) -> float:
        """Median sample rate, Hz (nan for fewer than 2 samples)."""
        if len(self) < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.t)))

    def select(self, mask_or_index: np.ndarray) -> ImuData:
        """A new ImuData with only the given rows (boolean mask or integer index)."""
        idx = np.asarray(mask_or_index)
        extra = self.extra.iloc[idx].reset_index(drop=True) if len(self.extra) else self.extra
        return ImuData(self.t[idx], self.gyro[idx], self.accel[idx], self.frame, extra,
                       dict(self.units), self.source, dict(self.meta))

    def to_dataframe(self) -> pd.DataFrame:
        """All columns as one DataFrame: t, wx, wy, wz (rad/s), ax, ay, az (m/s^2), extras."""
        import pandas as pd
        df = pd.DataFrame({"t": self.t,
                           "wx": self.gyro[:, 0], "wy": self.gyro[:, 1], "wz": self.gyro[:, 2],
                           "ax": self.accel[:, 0], "ay": self.accel[:, 1], "az": self.accel[:, 2]})
        if len(self.extra):
            df = pd.concat([df, self.extra.reset_index(drop=True)], axis=1)
        return df
