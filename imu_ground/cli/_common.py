"""What the ``imu-ground`` commands share: option types, reader flags, progress, messages (nothing heavy imported:
``imu-ground --help`` and argument errors stay fast)."""
from __future__ import annotations

import math
import sys
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import argparse

from imu_ground.datasets import FORMATS
from imu_ground.datasets.options import READER_OPTIONS
from imu_ground.pipeline.estimate import POSE_FORMATS

__all__ = ["INPUT_FLAGS", "LazyHelp", "add_progress_flag", "add_reader_flags", "estimate_said", "first_given",
           "input_paths", "no_warnings", "nonnegative_int", "positive_float", "progress_enabled", "reader_options",
           "say", "warn_line", "warnings_as_lines", "write_said"]


class LazyHelp(str):
    """Help text computed only when ``--help`` prints it (lists that need a library import)."""
    _fn: Callable[[], str]

    def __new__(cls, fn: Callable[[], str]) -> LazyHelp:
        obj = super().__new__(cls, "(listed by --help)")
        obj._fn = fn
        return obj

    def __mod__(self, params: Any) -> str:
        return self._fn().replace("%", "%%") % params

    def __str__(self) -> str:
        return self._fn()

    def strip(self, chars: Any = None) -> str:
        return self._fn().strip(chars)


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def nonnegative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return v


def _format_help(poses: bool) -> str:
    names = sorted(FORMATS)
    if poses:
        names += sorted(POSE_FORMATS)
    return f"input format, detected when omitted: {', '.join(names)}"


def add_reader_flags(parser: argparse.ArgumentParser, poses: bool = False) -> None:
    """One flag per entry of :data:`imu_ground.datasets.options.READER_OPTIONS` (the table owns them)."""
    group = parser.add_argument_group("reading the log")
    for opt in READER_OPTIONS.values():
        dest = opt.name
        if opt.name == "format":
            group.add_argument(opt.flag, dest=dest, metavar="NAME", help=LazyHelp(lambda: _format_help(poses)))
        elif opt.default is False:
            group.add_argument(opt.flag, dest=dest, action="store_true", default=None, help=opt.help)
        else:
            group.add_argument(opt.flag, dest=dest, choices=opt.choices, default=None, help=opt.help)


def add_logs_command(sub, name: str, *, help: str, description: str, logs_metavar: str, logs_help: str,
                     output_metavar: str, output_help: str) -> argparse.ArgumentParser:
    """A sub-command that takes one or more logs and a required ``-o/--output``."""
    p = sub.add_parser(name, help=help, description=description)
    p.add_argument("logs", nargs="+", metavar=logs_metavar, help=logs_help)
    p.add_argument("-o", "--output", required=True, metavar=output_metavar, help=output_help)
    return p


def reader_options(args: argparse.Namespace) -> dict:
    """The reader flags the user set, as ``read_imu`` keywords (``format`` included)."""
    return {name: getattr(args, name) for name in READER_OPTIONS if getattr(args, name, None) is not None}


#: The flags of a command that name an input file (besides its positional logs): what no output may replace.
INPUT_FLAGS = {"speed": "--speed", "extrinsic": "--extrinsic", "times": "--times", "camera": "--camera",
               "replay": "--replay", "images": "--images", "lidar_extrinsic": "--lidar-extrinsic",
               "lidar_planes": "--lidar-planes", "real": "--real"}


def input_paths(args: argparse.Namespace, logs: str = "log") -> list[tuple[str, Any]]:
    """``(flag, path)`` of every input the user named: the positional ``logs`` (``LOG``) and the
    :data:`INPUT_FLAGS` set (a camera's ``DIR:2`` as its folder); for
    :func:`~imu_ground.pipeline.output.check_run_paths`."""
    given = getattr(args, logs, None)
    out = [("LOG", p) for p in ([given] if isinstance(given, str) else given or [])]
    for name, flag in INPUT_FLAGS.items():
        value = getattr(args, name, None)
        if isinstance(value, str) and name == "camera" and ":" in value:
            value = value.rsplit(":", 1)[0]
        if isinstance(value, str):
            out.append((flag, value))
    return out


def add_progress_flag(parser: argparse.ArgumentParser) -> None:
    """``--no-progress`` (bars are shown only when stderr is a terminal anyway)."""
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress bars (they are shown only when stderr is a terminal)")


def progress_enabled(args: argparse.Namespace) -> bool:
    """Progress bars only when asked for and stderr is a terminal."""
    return not getattr(args, "no_progress", False) and sys.stderr.isatty()


def say(text: str) -> None:
    """One line of a command's result on stdout."""
    print(text, flush=True)


def warn_line(message: Warning | str, file: Any = None) -> None:
    """A warning as one line on stderr, ``file: warning: message`` (no Python source line; options as CLI flags)."""
    text = " ".join((message.cli_message() if hasattr(message, "cli_message") else str(message)).split())
    prefix = f"{file}: " if file is not None else ""
    if prefix and text.startswith(prefix):
        text = text[len(prefix):]
    print(f"{prefix}warning: {text}", file=sys.stderr, flush=True)


@contextmanager
def warnings_as_lines(file: Any = None) -> Iterator[None]:
    """Collect the warnings raised inside the block and print each once, one line each, at its end."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for message in {str(w.message): w.message for w in caught}.values():
        warn_line(message, file)


def write_said(path: str | Path, text: str | Callable[[Path], Any]) -> None:
    """``text`` (or what ``text(tmp)`` writes) written to ``path`` whole (or not at all), then said."""
    from imu_ground.pipeline.output import atomic_path
    with atomic_path(path) as tmp:
        if callable(text):
            text(tmp)
        else:
            tmp.write_text(text, encoding="utf-8")
    say(f"wrote {path}")


@contextmanager
def no_warnings() -> Iterator[None]:
    """The warnings raised inside the block are dropped (the caller says them its own way)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def estimate_said(log: Any, **kwargs: Any) -> Any:
    """:func:`~imu_ground.pipeline.estimate_log` of ``log``, its warnings said one line each."""
    from imu_ground.pipeline.estimate import estimate_log
    with no_warnings():
        res = estimate_log(log, **kwargs)
    for w in res.meta["warnings"]:
        warn_line(w, log)
    return res


def first_given(*flags: tuple[str, Any]) -> str | None:
    """The first of ``(flag, value)`` whose value is set (for "FLAG goes with ..." messages)."""
    return next((flag for flag, value in flags if value), None)
