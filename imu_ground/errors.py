"""The one root of the errors a user can fix: :class:`ImuGroundError` (a ``ValueError``).

Every error the package raises for something the user gave (a log, a file, an
option, a value) derives from :class:`ImuGroundError`; its message is one line
that names the file and the option to use. ``imu-ground`` exits with status 2
for these and for ``OSError`` (a missing or unreadable path), and reports any
other exception as a bug (status 3). A ``ValueError`` or ``TypeError`` that is
not an :class:`ImuGroundError` is a misuse of the library API or a bug.

The classes that name an option (``OptionError``, ``ImuInputError`` and the
readers' errors) live in :mod:`imu_ground.datasets.options` and derive from
this root; :class:`MissingExtraError` is the error of an optional dependency
that is not installed.
"""
from __future__ import annotations

import sys
from types import ModuleType

__all__ = ["ImuGroundError", "MissingExtraError", "require_extra"]


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
