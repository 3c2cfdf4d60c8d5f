"""The ``imu-ground`` command: ``estimate | stream | batch | evaluate | simulate | calibrate | preview``.

One module per command (``register`` adds its parser, ``run`` does the work; heavy dependencies load only when a
command needs them). :func:`main` is the one error handler (its exit statuses). ``imu-ground COMMAND --help`` lists
each command's options.
"""
from __future__ import annotations

import argparse
import importlib
import os
import re
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

# Nothing of the library is imported at module level: a Ctrl-C during those imports could only end in a traceback.

__all__ = ["COMMANDS", "Terminated", "build_parser", "main"]

#: Sub-command modules, in the order ``--help`` lists them.
COMMANDS = ("estimate", "stream", "batch", "evaluate", "simulate", "calibrate", "preview")


#: An argument that is a negative number, scientific notation included (``-1e5``, ``-.5``, ``-2.5E-3``):
#: a value, never an option (argparse's own pattern misses the exponent form).
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


class _Parser(argparse.ArgumentParser):
    """argparse with usage errors as one line, exit status 2, and ``-1e5`` read as a value."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n")

    def refuse_urls(self, args: argparse.Namespace) -> None:
        """Refuse a URL the command cannot use (``memory://``, a protocol whose package is missing) before any work."""
        from imu_ground.errors import StorageError
        from imu_ground.datasets.storage import cli_refusal
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                action.choices[args.command].refuse_urls(args)
            if action.dest in _NOT_PATHS:
                continue
            value = getattr(args, action.dest, None)
            flag = action.option_strings[0] if action.option_strings else str(action.metavar or action.dest.upper())
            for v in value if isinstance(value, list) else [value]:
                reason = cli_refusal(v, flag) if isinstance(v, str) else None
                if reason:
                    raise StorageError(reason)


#: Options whose values are addresses, not files (``tcp://`` of a Dask scheduler), and the sub-command's name.
_NOT_PATHS = ("scheduler", "command")


class _VersionAction(argparse.Action):
    """``--version``: the version and whether the loops run compiled, on one line (argparse's own would wrap it)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from imu_ground import _jit
        from imu_ground.pipeline.output import package_version
        if _jit.JIT_ENABLED:
            mode = "loops compiled by numba"
        elif os.environ.get(_jit.DISABLE_JIT_ENV, "") not in ("", "0"):
            mode = f"loops interpreted: {_jit.DISABLE_JIT_ENV} is set"
        else:
            mode = "loops interpreted: numba is not installed"
        print(f"imu-ground {package_version()}, {mode}")
        parser.exit()


def build_parser() -> _Parser:
    """The argument parser of every command (help text for every option)."""
    ap = _Parser(prog="imu-ground", description="Ground plane normal (pitch and roll of the body "
                                 "relative to the road) of a moving vehicle, frame by frame, from IMU logs or "
                                 "odometry.")
    ap.add_argument("--version", action=_VersionAction,
                    help="show the version and whether the loops run compiled by numba or interpreted, and exit")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"imu_ground.cli.{name}").register(sub)
    return ap


def _one_line(e: BaseException) -> str:
    """An exception's one-line message: its CLI form when it has one, the file for OS errors."""
    if hasattr(e, "cli_message"):
        text = e.cli_message()
    elif isinstance(e, OSError) and e.filename is not None and str(e.filename) not in str(e.strerror or ""):
        what = {FileNotFoundError: "no such file or folder", IsADirectoryError: "is a folder, a file is needed",
                NotADirectoryError: "a part of this path is a file, not a folder",
                PermissionError: "permission denied"}.get(type(e), e.strerror or str(e))
        text = f"{e.filename}: {what}"
    else:
        text = str(e) or type(e).__name__
    return " ".join(text.split())


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    text = message.cli_message() if hasattr(message, "cli_message") else str(message)
    print(f"warning: {' '.join(text.split())}", file=sys.stderr)


class Terminated(KeyboardInterrupt):
    """SIGTERM received: raised in the main thread so that every ``finally`` (temporary files) runs."""


def _on_sigterm(signum, frame) -> None:
    raise Terminated()


@contextmanager
def _sigterm_as_exception() -> Iterator[None]:
    """Turn SIGTERM into :class:`Terminated` for the block (main thread only; the old handler comes back)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def _quiet_stdout() -> None:
    """After a broken pipe on stdout (``| head -1``): stdout to the null device (Python flushes it at exit)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``imu-ground`` console script; returns the exit status.

    0 success; 1 a batch in which some logs failed; 2 bad input, option or path
    (one line on stderr: ``imu-ground COMMAND: error: ...``); 3 an unexpected error
    (a bug: one line, ``IMU_GROUND_DEBUG=1`` shows the traceback); 130 interrupted
    (Ctrl-C); 143 terminated (SIGTERM); 141 the reader of stdout went away (``| head``),
    quietly. Interrupted or terminated, no temporary or partial file is left.
    """
    try:
        parser = build_parser()
        args = parser.parse_args(argv)                  # imports every command's module: Ctrl-C may come here
        from imu_ground.errors import ImuGroundError    # the root of the errors a user can fix (exit 2)
    except KeyboardInterrupt:
        print("imu-ground: interrupted", file=sys.stderr)
        return 130
    old = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        with _sigterm_as_exception():
            parser.refuse_urls(args)
            return args.func(args)
    except Terminated:
        print(f"imu-ground {args.command}: terminated", file=sys.stderr)
        return 143
    except KeyboardInterrupt:
        print(f"imu-ground {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        _quiet_stdout()
        return 141
    except (ImuGroundError, OSError) as e:
        print(f"imu-ground {args.command}: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except Exception as e:
        if os.environ.get("IMU_GROUND_DEBUG", "").strip() not in ("", "0"):
            traceback.print_exc(file=sys.stderr)
        print(f"imu-ground {args.command}: bug: unexpected {type(e).__name__}: {_one_line(e)} (please report it; "
              f"IMU_GROUND_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 3
    finally:
        warnings.showwarning = old
