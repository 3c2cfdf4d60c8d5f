"""Fresh-process benchmarks measure the package as installed: its bytecode compiled.

``pip install`` of a wheel compiles every module to ``__pycache__``; an editable
install (or ``PYTHONDONTWRITEBYTECODE=1``, set on some machines) can leave the
modules to be compiled from source at every start, which adds about 0.2 s to
each fresh ``imu-ground`` process and is not what a user's installation pays.
The scripts that time fresh processes call :func:`compile_package` first.
"""
from __future__ import annotations

import compileall
import importlib.util

__all__ = ["compile_package"]

PACKAGES = ("imu_ground", "imu_ground.datasets", "imu_ground.calib")


def compile_package() -> None:
    """Write the bytecode of every module of the package (and its installed sub-package folders)."""
    for name in PACKAGES:
        spec = importlib.util.find_spec(name)
        for folder in (spec.submodule_search_locations or []) if spec else []:
            compileall.compile_dir(folder, quiet=1)
