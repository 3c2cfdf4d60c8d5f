"""The one root of the errors a user can fix, :class:`ImuGroundError` (a ``ValueError``), and of the warnings.

Every error raised for something the user gave (a log, a file, an option, a value) derives from
:class:`ImuGroundError`; its message is one line naming the file and the option to use. ``imu-ground`` exits with
status 2 for these and for ``OSError``, and reports any other exception as a bug (status 3). Every warning the
package defines derives from :class:`ImuGroundWarning`. The classes that name an option carry an
:class:`OptionMessage`: the Python spelling of the option in ``str()``, the ``imu-ground`` flag in
``cli_message()``. The foundation layer: it imports nothing of the package.
"""
from __future__ import annotations

import sys
import types
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = [
    "CLI_FLAGS", "GapWarning", "ImuGroundError", "ImuGroundWarning", "ImuInputError", "ImuValidationError",
    "ImuValidationWarning", "MalformedFileError", "MissingExtraError", "MissingFilesystemError",
    "MissingPacketsError", "NonFiniteWarning", "OptionError", "OptionMessage", "PoseFileError", "SensorWarning",
    "StorageError", "TimestampWarning", "UnitsWarning", "UnknownFormatError", "option_hint", "require_extra",
    "warn_user",
]

#: Option keyword -> its ``imu-ground`` flag (the reader options: :data:`imu_ground.datasets.options.READER_OPTIONS`
#: fills it when imported; any other option is ``--`` + the keyword with ``-`` for ``_``).
CLI_FLAGS: dict[str, str] = {}


class ImuGroundError(ValueError):
    """Bad user input, option or file: the root of every error a user can fix (one line naming the file)."""


class MissingExtraError(ImuGroundError, ImportError):
    """An optional dependency is not installed (also an ``ImportError``): the message names the extra to install.

    Parameters
    ----------
    what : str
        What needs it, e.g. ``"writing .parquet files"``.
    module, extra : str
        The missing module (``"pyarrow"``) and the package extra that installs it (``"parquet"``); both attributes.
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
        Module to import (``"pyarrow.parquet"``).
    extra, what : str
        The extra that installs it (``"parquet"``) and what needs it, for the message.

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
    """A message that names an option, in Python or CLI spelling: the one option-message rule.

    ``{hint}`` in the text is how to set the option (``gyro_unit='deg/s'`` / ``--gyro-unit deg/s``, with ``value``
    when given), ``{opt}`` its bare name (``rate`` / ``--rate``).

    Parameters
    ----------
    message : str
        What is wrong, naming the file (and 1-based line where there is one), with ``{hint}``/``{opt}``.
    option : str, optional
        The option that fixes it (Python keyword).
    value : optional
        The option value to suggest.
    flag : str, optional
        Its CLI flag, when not the :data:`CLI_FLAGS` one or ``--`` + the keyword with ``-`` for ``_``.

    Attributes
    ----------
    template, option, value, flag
        The parameters.
    """

    template: str
    option: str | None
    value: Any
    flag: str | None = None

    def __init__(self, message: str = "", option: str | None = None, value: Any = None, *,
                 flag: str | None = None) -> None:
        self.template, self.option, self.value, self.flag = message, option, value, flag
        super().__init__(self._render(cli=False))  # type: ignore[call-arg]  # the exception or warning base

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
    """A bad input or option value that an option can fix, in the readers and the pipeline alike.

    Parameters as :class:`OptionMessage`.
    """


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
    """The root of every warning the package defines (a ``UserWarning``); parameters as :class:`OptionMessage`."""


class ImuValidationWarning(ImuGroundWarning):
    """Base class of every warning issued by the readers and :func:`~imu_ground.datasets.validation.validate`."""


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
#: The package's folders (the readers: ``datasets/`` beside ``imu_ground/`` in a checkout): not the user's frames.
_PACKAGE_DIRS = tuple(str(Path(p).resolve()) for p in (
    Path(__file__).parent, Path(__file__).parent.parent / "datasets"))


def warn_user(message: str, category: type[Warning] = ImuValidationWarning, option: str | None = None,
              value: Any = None) -> None:
    """Issue a warning attributed to the first caller outside imu_ground (the user's line).

    Parameters
    ----------
    message : str
        The text, naming the file (and 1-based line); may hold ``{hint}`` for ``option``.
    category : Warning subclass
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
