"""The reader options a user can set, each both a ``read_imu`` argument and an ``imu-ground`` flag.

One table, so that a message names the option as the user sets it (``gyro_unit="deg/s"`` from Python,
``--gyro-unit deg/s`` from the command line); it fills :data:`~imu_ground.errors.CLI_FLAGS`, which
:class:`~imu_ground.errors.OptionError` and :class:`~imu_ground.errors.OptionMessage` (importable from here
too) use.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from imu_ground.errors import CLI_FLAGS, ImuInputError, OptionError, OptionMessage, option_hint

__all__ = ["READER_OPTIONS", "ImuInputError", "OptionError", "OptionMessage", "OptionText", "ReaderOption", "option_hint"]


@dataclass(frozen=True)
class ReaderOption:
    """One reader option: its Python name, its CLI flag, the values it takes and what it does."""
    name: str
    flag: str
    help: str
    choices: Sequence[str] | None = None
    default: Any = None


#: Python keyword -> option. The CLI adds one flag per entry (``imu-ground estimate``,
#: ``calibrate``, ``batch``) and passes it to :func:`imu_ground.datasets.read_imu`.
READER_OPTIONS: dict[str, ReaderOption] = {o.name: o for o in (
    ReaderOption("format", "--format", "log format (detected when omitted)"),
    ReaderOption("policy", "--policy", "out-of-order or duplicate timestamps: retime (default: sample index as "
                 "the clock where the rate is steady, else drop), drop, sort, or strict (fail)",
                 ("retime", "drop", "sort", "strict"), "retime"),
    ReaderOption("nonfinite", "--nonfinite", "rows with NaN/inf values: raise (default) or drop",
                 ("raise", "drop"), "raise"),
    ReaderOption("time_unit", "--time-unit", "unit of the time column of a CSV table (detected when omitted)",
                 ("s", "ms", "us", "ns"), None),
    ReaderOption("gyro_unit", "--gyro-unit", "unit of the gyro columns (detected when omitted)",
                 ("rad/s", "deg/s"), None),
    ReaderOption("accel_unit", "--accel-unit", "unit of the accelerometer columns (detected when omitted)",
                 ("m/s^2", "g"), None),
    ReaderOption("columns", "--columns", "CSV table: which column holds what, e.g. t=timestamp,wx=gyro_x,wy=gyro_y,"
                 "wz=gyro_z,ax=acc_x,ay=acc_y,az=acc_z (only those not named t, wx, wy, wz, ax, ay, az; names "
                 "are matched regardless of case)"),
    ReaderOption("times", "--times", "KITTI odometry pose file: the sequence's times.txt (one time a line, s), "
                 "the camera's own clock (without it frames are timed by --rate)"),
    ReaderOption("topic", "--topic", "ROS bag / MCAP: the topic to read when the log has several of the kind "
                 "(IMU, pose or speed)"),
    ReaderOption("scene", "--scene", "nuScenes CAN bus folder with several scenes: the scene to read "
                 "(e.g. scene-0103)"),
    ReaderOption("allow_missing", "--allow-missing", "KITTI OXTS: skip missing packet files instead of failing",
                 None, False),
)}


#: The CLI flags of the reader options, for the hints of every :class:`OptionMessage`.
CLI_FLAGS.update({o.name: o.flag for o in READER_OPTIONS.values()})


class OptionText(str):
    """A message as plain text (the Python spelling) that keeps its CLI spelling: ``cli_message()``.

    A warning collected as a line (``estimate_log``'s ``meta["warnings"]``).
    """

    cli: str

    def __new__(cls, text: str, cli: str | None = None) -> OptionText:
        self = super().__new__(cls, text)
        self.cli = text if cli is None else cli
        return self

    def cli_message(self) -> str:
        """The text with options spelled as ``imu-ground`` flags."""
        return self.cli
