"""The reader options a user can set, each both a ``read_imu`` argument and an ``imu-ground`` flag.

One table owns the correspondence, so that an error message can name the option
the way the user sets it: ``gyro_unit="deg/s"`` from Python, ``--gyro-unit deg/s``
from the command line. Readers raise :class:`ImuInputError` (a ``ValueError``)
with ``option`` and ``value`` set; :meth:`ImuInputError.cli_message` is what the
command line prints.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["READER_OPTIONS", "ImuInputError", "OptionMessage", "ReaderOption", "option_hint"]


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
    ReaderOption("topic", "--topic", "ROS bag / MCAP: the topic to read when the log has several of the kind "
                 "(IMU, pose or speed)"),
    ReaderOption("scene", "--scene", "nuScenes CAN bus folder with several scenes: the scene to read "
                 "(e.g. scene-0103)"),
    ReaderOption("allow_missing", "--allow-missing", "KITTI OXTS: skip missing packet files instead of failing",
                 None, False),
)}


def option_hint(name: str, value: Any = None, cli: bool = False) -> str:
    """How to set option ``name`` (to ``value``) from Python or, with ``cli``, from the command line."""
    opt = READER_OPTIONS.get(name)
    if cli and opt is not None:
        if isinstance(value, bool) or value is None:
            return opt.flag
        return f"{opt.flag} {value}"
    if value is None:
        return f"{name}=..."
    return f"{name}={value!r}"


class OptionMessage:
    """A message template whose ``{hint}`` names a reader option, in Python or CLI spelling.

    Attributes
    ----------
    template : str
        The text with ``{hint}`` where the option goes.
    option : str or None
        Key of :data:`READER_OPTIONS`.
    value : optional
        The option value to suggest.
    """

    template: str
    option: str | None
    value: Any

    def _render(self, cli: bool) -> str:
        if self.option is None or "{hint}" not in self.template:
            return self.template.replace("{hint}", "the matching option")
        return self.template.replace("{hint}", option_hint(self.option, self.value, cli))

    def cli_message(self) -> str:
        """The message with the option spelled as its ``imu-ground`` flag."""
        return self._render(cli=True)


class ImuInputError(OptionMessage, ValueError):
    """Bad input to a reader that an option can fix; the message names the option.

    Parameters
    ----------
    message : str
        What is wrong, naming the file (and 1-based line where there is one). It
        may contain ``{hint}``, replaced by the option's Python form in ``str(e)``
        and by its CLI flag in :meth:`cli_message`.
    option : str, optional
        Key of :data:`READER_OPTIONS` that fixes it.
    value : optional
        The option value to suggest.
    """

    def __init__(self, message: str, option: str | None = None, value: Any = None) -> None:
        self.template, self.option, self.value = message, option, value
        super().__init__(self._render(cli=False))
