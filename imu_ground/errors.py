"""The one root of the errors a user can fix, :class:`ImuGroundError` (a ``ValueError``), and of the warnings.

Every error the package raises for something the user gave (a log, a file, an
option, a value) derives from :class:`ImuGroundError`; its message is one line
that names the file and the option to use. ``imu-ground`` exits with status 2
for these and for ``OSError`` (a missing or unreadable path), and reports any
other exception as a bug (status 3). A ``ValueError`` or ``TypeError`` that is
not an :class:`ImuGroundError` is a misuse of the library API or a bug.
Every warning the package defines derives from :class:`ImuGroundWarning`.

The foundation layer: this module imports nothing of the package, so every
layer raises its errors from here. The classes that name an option
(:class:`OptionError`, :class:`ImuInputError` and the readers' errors, the
warnings) carry an :class:`OptionMessage`: the Python spelling of the option in
``str()``, the ``imu-ground`` flag in ``cli_message()``.
:class:`MissingExtraError` is the error of an optional dependency that is not
installed.
"""
from __future__ import annotations

import sys
import types
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = [
    "CLI_FLAGS",
    "GapWarning",
    "ImuGroundError",
    "ImuGroundWarning",
    "ImuInputError",
    "ImuValidationError",
    "ImuValidationWarning",
    "MalformedFileError",
    "MissingExtraError",
    "MissingFilesystemError",
    "MissingPacketsError",
    "NonFiniteWarning",
    "OptionError",
    "OptionMessage",
    "PoseFileError",
    "SensorWarning",
    "StorageError",
    "TimestampWarning",
    "UnitsWarning",
    "UnknownFormatError",
    "option_hint",
    "require_extra",
    "warn_user",
]

#: Option keyword -> its ``imu-ground`` flag, for the options whose hint names the flag on the command
#: line (the reader options: :data:`imu_ground.datasets.options.READER_OPTIONS` fills it when imported;
#: any other option is spelled ``--`` + the keyword with ``-`` for ``_``, its hint the Python keyword).
CLI_FLAGS: dict[str, str] = {}


class ImuGroundError(ValueError):
    """Bad user input, option or file: the root of every error a user can fix.

    A ``ValueError``, so code that catches ``ValueError`` keeps working. The
    message is one line naming the file (and line) and what to do.
    """


class MissingExtraError(ImuGroundError, ImportError):
    """An optional dependency is not installed: the message names the extra to install.

    Both an :class:`ImuGroundError` (the user can fix it) and an ``ImportError``.

    Parameters
    ----------
    what : str
        What needs it, e.g. ``"writing .parquet files"``.
    module : str
        The missing module, e.g. ``"pyarrow"``.
    extra : str
        The package extra that installs it, e.g. ``"parquet"``.

    Attributes
    ----------
    module, extra : str
    """

    def __init__(self, what: str, module: str, extra: str) -> None:
        self.module, self.extra = module, extra
        super().__init__(f"{what} needs {module}, which is not installed: pip install 'imu-ground[{extra}]' "
                         f"(in a checkout: pip install -e \".[{extra}]\")")
        self.name = module


def require_extra(module: str, extra: str, what: str) -> ModuleType:
    """Import ``module`` of an optional extra, or raise :class:`MissingExtraError` naming the extra.

    Parameters
    ----------
    module : str
        Module to import (``"pyarrow.parquet"``, ``"rosbags.highlevel"``).
    extra : str
        The extra that installs it (``"parquet"``, ``"ros"``, ``"fleet"``, ``"plot"``).
    what : str
        What needs it, for the message (``"writing .parquet files"``).

    Returns
    -------
    module
    """
    try:
        __import__(module)              # the import statement's hook (builtins.__import__), then the module itself
    except ImportError as e:
        raise MissingExtraError(what, module.split(".")[0], extra) from e
    return sys.modules[module]


# --------------------------------------------------------------------------- errors and warnings that name an option
def option_hint(name: str, value: Any = None, cli: bool = False) -> str:
    """How to set option ``name`` (to ``value``) from Python or, with ``cli``, from the command line."""
    flag = CLI_FLAGS.get(name)
    if cli and flag is not None:
        if isinstance(value, bool) or value is None:
            return flag
        return f"{flag} {value}"
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
        The Python keyword (a reader option of :data:`CLI_FLAGS`, or another option such as ``rate``).
    value : optional
        The option value to suggest.
    flag : str or None
        The CLI flag when it is not the :data:`CLI_FLAGS` one or ``--`` + the keyword with ``-`` for ``_``.
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
        if self.option in CLI_FLAGS:
            return CLI_FLAGS[self.option]
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


# --------------------------------------------------------------------------- the readers' errors and warnings
class ImuValidationError(ImuInputError):
    """An IMU log failed a check whose policy is to raise; ``option`` names the fix, if any."""


class MalformedFileError(ImuGroundError):
    """A log file cannot be parsed: empty, truncated, wrong field count, not a number.

    Attributes
    ----------
    path : str
        The file.
    line : int or None
        1-based line number of the first bad line, when there is one.
    """

    def __init__(self, path: str | Path, message: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        where = f"{self.path}, line {line}" if line is not None else self.path
        super().__init__(f"{where}: {message}")


class ImuGroundWarning(OptionMessage, UserWarning):
    """The root of every warning the package defines (a ``UserWarning``).

    Like :class:`ImuInputError`, the text may name an option (``{hint}``, ``{opt}``);
    :meth:`cli_message` spells it as the CLI flag.
    """

    def __init__(self, message: str = "", option: str | None = None, value: Any = None) -> None:
        self.template, self.option, self.value = message, option, value
        super().__init__(self._render(cli=False))


class ImuValidationWarning(ImuGroundWarning):
    """Base class of every warning issued by the readers and
    :func:`~imu_ground.datasets.validation.validate`."""


class TimestampWarning(ImuValidationWarning):
    """Samples were retimed, dropped or reordered because of unsorted or duplicate times."""


class GapWarning(ImuValidationWarning):
    """The log has steps much longer than its usual sample period."""


class NonFiniteWarning(ImuValidationWarning):
    """Rows with NaN or inf were dropped (``nonfinite="drop"``)."""


class UnitsWarning(ImuValidationWarning):
    """Units were detected from the data and converted, or magnitudes look wrong."""


class SensorWarning(ImuValidationWarning):
    """A sensor reads what a working one does not: a dead gyro, a stuck accelerometer, or no motion at all."""


class UnknownFormatError(ImuInputError):
    """:func:`detect_format` cannot tell which reader a path needs (the message names ``format``)."""


class PoseFileError(UnknownFormatError):
    """An IMU log was asked for, but the path is a pose file (KITTI odometry or TUM)."""


class MissingPacketsError(ImuInputError, FileNotFoundError):
    """Packet files listed in ``timestamps.txt`` are missing (the message names ``allow_missing``)."""


class StorageError(ImuGroundError):
    """A URL that cannot be used: an unknown protocol, or ``memory://`` on the command line."""


class MissingFilesystemError(StorageError, ImportError):
    """The filesystem package of a URL's protocol is not installed (the message names it).

    Attributes
    ----------
    protocol, package : str
    """

    def __init__(self, url: str, protocol: str, package: str) -> None:
        self.protocol, self.package = protocol, package
        extra = " (or pip install 'imu-ground[s3]')" if package == "s3fs" else ""
        super().__init__(f"{url}: {protocol}:// needs {package}: pip install {package}{extra}")
        self.name = package


# --------------------------------------------------------------------------- issuing a warning
#: The package's folders (the readers are ``imu_ground/datasets`` once installed, ``datasets/`` beside
#: ``imu_ground/`` in a checkout): frames there are not the user's.
_PACKAGE_DIRS = tuple(str(Path(p).resolve()) for p in (
    Path(__file__).parent, Path(__file__).parent.parent / "datasets"))


def warn_user(message: str, category: type[Warning] = ImuValidationWarning, option: str | None = None,
              value: Any = None) -> None:
    """Issue a warning attributed to the first caller outside imu_ground (the user's line).

    Parameters
    ----------
    message : str
        The text, naming the file (and 1-based line where there is one); may hold
        ``{hint}`` for ``option``.
    category : Warning subclass
        The warning class.
    option, value : optional
        The option (and value) the text names (:class:`ImuGroundWarning` subclasses).
    """
    level = 1
    frame: types.FrameType | None = sys._getframe(1)
    while frame is not None and frame.f_code.co_filename.startswith(_PACKAGE_DIRS):
        frame, level = frame.f_back, level + 1
    if issubclass(category, ImuGroundWarning):
        warnings.warn(category(message, option, value), stacklevel=level + 1)
    else:
        warnings.warn(message, category, stacklevel=level + 1)
