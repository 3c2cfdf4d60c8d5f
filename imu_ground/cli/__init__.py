"""The ``imu-ground`` command: ``estimate | batch | evaluate | simulate | calibrate | preview``.

One module per command (``register`` adds its parser, ``run`` does the work and
imports the library lazily). :func:`main` is the one error handler: bad input,
options or paths never show a traceback but one line naming the file and what
to do, and exit status 2. Run ``imu-ground COMMAND --help`` for each command's options.
"""
from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Sequence

__all__ = ["COMMANDS", "build_parser", "main"]

#: Sub-command modules, in the order ``--help`` lists them.
COMMANDS = ("estimate", "batch", "evaluate", "simulate", "calibrate", "preview")


class _Parser(argparse.ArgumentParser):
    """argparse with usage errors as one line (``imu-ground CMD: error: ...; see --help``), exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command (help text for every option)."""
    import importlib

    from imu_ground.pipeline.output import package_version
    ap = _Parser(prog="imu-ground", description="Ground plane normal (pitch and roll of the body "
                                 "relative to the road) of a moving vehicle, frame by frame, from IMU logs or "
                                 "odometry.")
    ap.add_argument("--version", action="version", version=f"imu-ground {package_version()}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"imu_ground.cli.{name}").register(sub)
    return ap


def _one_line(e: BaseException) -> str:
    """The user-facing message of an exception: the CLI form when it has one, the file for OS errors."""
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
    print(f"warning: {' '.join(str(message).split())}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``imu-ground`` console script; returns the exit status.

    0 success; 1 a batch in which some logs failed; 2 bad input, option or path
    (one line on stderr: ``imu-ground COMMAND: error: ...``); 130 interrupted.
    Set ``IMU_GROUND_DEBUG=1`` to get the traceback of an unexpected error.
    """
    args = build_parser().parse_args(argv)
    old = warnings.showwarning
    warnings.showwarning = _show_warning
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print(f"imu-ground {args.command}: interrupted", file=sys.stderr)
        return 130
    except (ValueError, OSError, ImportError) as e:
        print(f"imu-ground {args.command}: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except Exception as e:
        if os.environ.get("IMU_GROUND_DEBUG"):
            raise
        print(f"imu-ground {args.command}: unexpected error: {type(e).__name__}: {_one_line(e)} (please report it; "
              f"IMU_GROUND_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 3
    finally:
        warnings.showwarning = old
