"""Loading the optional compiled kernels (foundation layer: imports nothing of the package).

The per-frame scalar kernels of the streaming filters and of the preintegration
exist twice: in C (``imu_ground/**/_*_native.c``, built by ``setup.py`` when a C
compiler is available) and in pure Python, the reference each C kernel is
tested against (equal to 1e-12 or better). A module that owns a kernel asks
:func:`load_native` for its compiled twin and falls back to the Python one when
it is missing.

Set the environment variable ``IMU_GROUND_PURE_PYTHON=1`` (before the first
import) to use the pure-Python kernels everywhere, e.g. to compare the two.
"""
from __future__ import annotations

import importlib
import os
from types import ModuleType
from typing import Dict, Optional

__all__ = ["load_native", "native_kernels", "PURE_PYTHON_ENV"]

PURE_PYTHON_ENV = "IMU_GROUND_PURE_PYTHON"

_LOADED: Dict[str, bool] = {}


def load_native(name: str) -> Optional[ModuleType]:
    """The compiled kernel module ``name`` (dotted), or None when it is not built or is switched off.

    Parameters
    ----------
    name : str
        Dotted module name, e.g. ``"imu_ground.filters._residual_native"``.

    Returns
    -------
    module or None
        None when ``IMU_GROUND_PURE_PYTHON`` is set to a non-empty value other
        than ``0``, or when the extension was not built (no C compiler at install).
    """
    module = None
    if os.environ.get(PURE_PYTHON_ENV, "") in ("", "0"):
        try:
            module = importlib.import_module(name)
        except ImportError:
            module = None
    _LOADED[name] = module is not None
    return module


def native_kernels() -> Dict[str, bool]:
    """Which compiled kernels the modules imported so far asked for, and whether each is in use."""
    return dict(_LOADED)
