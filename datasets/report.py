"""The validation report of the readers' checks (their errors and warnings, from :mod:`imu_ground.errors`,
importable from here too). Nothing here imports a reader."""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from imu_ground.errors import (GapWarning, ImuValidationError, ImuValidationWarning, MalformedFileError,
                               NonFiniteWarning, SensorWarning, TimestampWarning, UnitsWarning, warn_user)
from imu_ground.units import GRAVITY

__all__ = ["STANDARD_GRAVITY", "Gap", "GapWarning", "ImuValidationError", "ImuValidationWarning", "MalformedFileError",
           "NonFiniteWarning", "SensorWarning", "TimestampWarning", "UnitsWarning", "ValidationReport", "row_names",
           "warn_user"]

#: Standard gravity, m/s^2 (the one owner is :data:`imu_ground.units.GRAVITY`).
STANDARD_GRAVITY = GRAVITY


def row_names(rows: np.ndarray, row_lines: Callable[[np.ndarray], np.ndarray] | None) -> tuple[str, list[int]]:
    """How to name input rows in a message: ``("line", 1-based file lines)`` or ``("row", 0-based rows)``."""
    rows = np.asarray(rows, dtype=np.int64)
    if row_lines is None:
        return "row", rows.tolist()
    return "line", np.asarray(row_lines(rows), dtype=np.int64).tolist()


# --------------------------------------------------------------------------- report
class Gap(NamedTuple):
    """One gap.

    Attributes
    ----------
    index, out_index : int
        Input row, and row in the cleaned output, of the sample before the gap.
    t_start, length : float
        Time of that sample, and to the next kept sample, s.
    """

    index: int  # type: ignore[assignment]  # (the public field's name hides tuple.index)
    out_index: int
    t_start: float
    length: float


_empty_int = functools.partial(np.zeros, 0, dtype=np.int64)
_empty_float = functools.partial(np.zeros, 0, dtype=float)


@dataclass
class ValidationReport:
    """What :func:`~imu_ground.datasets.validation.validate` found and did.

    Attributes
    ----------
    source, policy : str
        Where the data came from; the time-order policy asked for.
    n_in, n_out : int
        Samples before and after cleaning.
    nonfinite_index, nonfinite_columns, nonfinite_dropped : ndarray of int, dict, bool
        Input rows with NaN/inf in t, gyro or accel; column (``t``, ``wx``... ``az``) to count; dropped?
    backstep_index, backstep_size : ndarray
        Input rows where time steps back (among finite rows), and those steps, s (negative).
    out_of_order_index, duplicate_index : ndarray of int
        Input rows earlier than, and equal to, the latest time before them.
    dropped_index : ndarray of int
        Every input row not in the output.
    reordered, retimed : bool
        Whether samples were sorted (``"sort"``), or the sample index became the clock (``"retime"``).
    retime_rate : float
        Fitted sample rate of the index clock, Hz (nan when not retimed).
    retime_shift_max, retime_shift_rms : float
        Largest and RMS move of a timestamp by the retiming, s.
    retime_dropout_index : ndarray of int
        Input rows that start a new stretch after a real dropout (kept as a gap).
    retime_note : str
        Why retiming was not applied (empty when it was, or was not asked for).
    median_step, gap_threshold : float
        Median time step of the cleaned data (nan under 2 samples); steps longer than the threshold are gaps, s.
    gap_index, gap_out_index, gap_start, gap_length : ndarray
        Input and output row of the sample before each gap, its time and the gap's length, s (:attr:`gaps`).
    gyro_max_norm, gyro_sustained, gyro_limit : float
        Largest angular-rate magnitude, rad/s (nan when empty); longest time, s, above ``gyro_limit``, rad/s.
    accel_median_norm, accel_norm_at_rest : float, bool
        Median specific-force magnitude, m/s^2, and whether over samples at rest (small rate).
    issues : list of str
        One message per problem found (the texts of the warnings/errors).
    """

    source: str = ""
    policy: str = "retime"
    n_in: int = 0
    n_out: int = 0
    nonfinite_index: np.ndarray = field(default_factory=_empty_int)
    nonfinite_columns: dict[str, int] = field(default_factory=dict)
    nonfinite_dropped: bool = False
    backstep_index: np.ndarray = field(default_factory=_empty_int)
    backstep_size: np.ndarray = field(default_factory=_empty_float)
    out_of_order_index: np.ndarray = field(default_factory=_empty_int)
    duplicate_index: np.ndarray = field(default_factory=_empty_int)
    dropped_index: np.ndarray = field(default_factory=_empty_int)
    reordered: bool = False
    retimed: bool = False
    retime_rate: float = float("nan")
    retime_shift_max: float = 0.0
    retime_shift_rms: float = 0.0
    retime_dropout_index: np.ndarray = field(default_factory=_empty_int)
    retime_note: str = ""
    median_step: float = float("nan")
    gap_threshold: float = float("nan")
    gap_index: np.ndarray = field(default_factory=_empty_int)
    gap_out_index: np.ndarray = field(default_factory=_empty_int)
    gap_start: np.ndarray = field(default_factory=_empty_float)
    gap_length: np.ndarray = field(default_factory=_empty_float)
    gyro_max_norm: float = float("nan")
    gyro_sustained: float = 0.0
    gyro_limit: float = float("nan")
    accel_median_norm: float = float("nan")
    accel_norm_at_rest: bool = False
    issues: list[str] = field(default_factory=list)

    @property
    def n_dropped(self) -> int:
        """Input samples not in the output."""
        return int(self.dropped_index.size)

    @property
    def n_out_of_order(self) -> int:
        """Samples earlier than the latest time before them."""
        return int(self.out_of_order_index.size)

    @property
    def n_duplicates(self) -> int:
        """Samples repeating an earlier time."""
        return int(self.duplicate_index.size)

    @property
    def n_nonfinite(self) -> int:
        """Rows with NaN/inf in t, gyro or accel."""
        return int(self.nonfinite_index.size)

    @property
    def n_gaps(self) -> int:
        """Number of gaps."""
        return int(self.gap_start.size)

    @property
    def gaps(self) -> list[Gap]:
        """The gaps as a list of :class:`Gap` (index, out_index, t_start, length)."""
        return [Gap(int(i), int(j), float(s), float(g)) for i, j, s, g in
                zip(self.gap_index, self.gap_out_index, self.gap_start, self.gap_length, strict=True)]

    @property
    def ok(self) -> bool:
        """True when no problem was found."""
        return not self.issues

    def summary(self) -> str:
        """A few lines of text describing the findings."""
        head = (f"{self.source or '<ImuData>'}: {self.n_in} samples in, {self.n_out} out "
                f"(policy={self.policy!r}); {self.n_out_of_order} out of order, "
                f"{self.n_duplicates} duplicate times, {self.n_nonfinite} non-finite rows, "
                f"{self.n_gaps} gaps > {self.gap_threshold:.4g} s")
        if self.retimed:
            head += (f"; retimed at {self.retime_rate:.6g} Hz (max shift {self.retime_shift_max:.4g} s, "
                     f"RMS {self.retime_shift_rms:.4g} s)")
        return "\n".join([head, *self.issues]) if self.issues else head + "; no issues"

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python (JSON-friendly) version of the report."""
        out: dict[str, Any] = {}
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                out[k] = v.tolist()
            elif isinstance(v, (list, dict)):
                out[k] = type(v)(v)
            elif isinstance(v, (np.floating, np.integer, np.bool_)):
                out[k] = v.item()
            else:
                out[k] = v
        out.update(n_dropped=self.n_dropped, n_out_of_order=self.n_out_of_order,
                   n_duplicates=self.n_duplicates, n_nonfinite=self.n_nonfinite,
                   n_gaps=self.n_gaps, ok=self.ok)
        return out
