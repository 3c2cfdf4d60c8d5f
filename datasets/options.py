"""The reader options a user can set, each both a ``read_imu`` argument and an ``imu-ground`` flag.

One table owns the correspondence, so that an error message can name the option
the way the user sets it: ``gyro_unit="deg/s"`` from Python, ``--gyro-unit deg/s``
from the command line. Readers raise :class:`ImuInputError`, the pipeline
:class:`OptionError` (its base, an :class:`~imu_ground.errors.ImuGroundError`), with ``option`` and ``value``
set; :meth:`OptionError.cli_message` is what the command line prints. The
readers' warnings carry the same :class:`OptionMessage`.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from imu_ground.errors import ImuGroundError

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
    """A message template that names an option, in Python or CLI spelling: the one option-message rule.

    Two placeholders: ``{hint}`` is how to set the option (``gyro_unit='deg/s'``
    / ``--gyro-unit deg/s``, with :attr:`value` when given), ``{opt}`` the
    option's bare name (``rate`` / ``--rate``). ``str()`` of the exception or
    warning carries the Python spelling; :meth:`cli_message` is what the command
    line prints.

    Attributes
    ----------
    template : str
        The text with ``{hint}`` and/or ``{opt}`` where the option goes.
    option : str or None
        The Python keyword (a key of :data:`READER_OPTIONS`, or another option such as ``rate``).
    value : optional
        The option value to suggest.
    flag : str or None
        The CLI flag when it is not the READER_OPTIONS one or ``--`` + the keyword with ``-`` for ``_``.
    """

    template: str
    option: str | None
    value: Any
    flag: str | None = None

    @property
    def name(self) -> str | None:
        """The option's Python keyword (None: no option)."""
        return self.option

    def cli_flag(self) -> str:
        """The option's ``imu-ground`` flag."""
        if self.flag:
            return self.flag
        if self.option in READER_OPTIONS:
            return READER_OPTIONS[self.option].flag
        return "--" + str(self.option).replace("_", "-")

    def _render(self, cli: bool) -> str:
        text = self.template
        if "{opt}" in text and self.option is not None:
            text = text.replace("{opt}", self.cli_flag() if cli else self.option)
        if self.option is None or "{hint}" not in text:
            return text.replace("{hint}", "the matching option")
        if cli and self.flag:
            return text.replace("{hint}", self.flag if self.value is None or isinstance(self.value, bool)
                                else f"{self.flag} {self.value}")
        return text.replace("{hint}", option_hint(self.option, self.value, cli))

    def cli_message(self) -> str:
        """The message with the option spelled as its ``imu-ground`` flag."""
        return self._render(cli=True)


class OptionError(OptionMessage, ImuGroundError):
    """A bad input or option value that an option can fix; the message names the option.

    The one error class for options, in the readers and in
    :func:`imu_ground.pipeline.estimate_log` alike.

    Parameters
    ----------
    message : str
        What is wrong, naming the file (and 1-based line where there is one). It
        may contain ``{hint}`` / ``{opt}`` (see :class:`OptionMessage`).
    option : str, optional
        The option that fixes it (Python keyword).
    value : optional
        The option value to suggest.
    flag : str, optional
        Its CLI flag, when not derived from the keyword.
    """

    def __init__(self, message: str, option: str | None = None, value: Any = None, *,
                 flag: str | None = None) -> None:
        self.template, self.option, self.value, self.flag = message, option, value, flag
        super().__init__(self._render(cli=False))


class ImuInputError(OptionError):
    """Bad input to a reader that an option can fix (an :class:`OptionError` raised by :mod:`imu_ground.datasets`)."""


class OptionText(str):
    """A message as plain text (the Python spelling) that keeps its CLI spelling: ``cli_message()``.

    What a warning becomes once collected as a line (``estimate_log``'s
    ``meta["warnings"]``): it compares and prints as the Python text, and the
    command line prints :meth:`cli_message`.
    """

    cli: str

    def __new__(cls, text: str, cli: str | None = None) -> OptionText:
        self = super().__new__(cls, text)
        self.cli = text if cli is None else cli
        return self

    def cli_message(self) -> str:
        """The text with options spelled as ``imu-ground`` flags."""
        return self.cli
