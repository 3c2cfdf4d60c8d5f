"""One container for an IMU log, whatever format it came from (every reader returns an :class:`ImuData`).

Units: ``t`` seconds (the file's epoch in ``meta["t0"]`` when it gives absolute times); ``gyro`` the body's
rate relative to inertial space, body frame, rad/s; ``accel`` the specific force (acceleration minus gravity),
body frame, m/s^2, about ``+9.81`` on the up axis at rest.
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
        Sample times, s, strictly increasing once validated.
    gyro, accel : ndarray, shape (N, 3)
        Angular rate (rad/s) and specific force (m/s^2), body frame.
    frame : str
        Name of the body frame (``"FLU"``: x forward, y left, z up; ``"device"``: a phone's axes).
    extra : pandas.DataFrame
        Other columns of the source, row for row with ``t``, in the units named by ``units`` (column -> unit).
    units : dict
    source : str
        Where the data came from (path, or ``"simulated"``).
    meta : dict
        Anything else a reader keeps (absolute start time, format, the validation report, ...).
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
