"""Build hook for the compiled kernels (everything else is declared in pyproject.toml).

Every ``_*_native.c`` file under ``imu_ground/`` is one C extension module of
the same dotted name (``imu_ground/filters/_residual_native.c`` ->
``imu_ground.filters._residual_native``): the scalar per-frame kernels of the
streaming filters and of the preintegration, written against the plain CPython
API (no numpy headers), each with a pure-Python twin that is the reference its
tests compare it with. The extensions are optional: without a C compiler the
package installs and runs on the pure-Python kernels (slower, same results);
see :mod:`imu_ground._native` (``IMU_GROUND_PURE_PYTHON=1`` forces them).

The kernels share the static inline helpers of ``imu_ground/_native_util.h``
(rotations, argument reading, module creation).

Compiled without fused multiply-add contraction (``-ffp-contract=off``) so the
C and the Python kernels round alike on every platform.
"""
from pathlib import Path

from setuptools import Extension, setup

HERE = Path(__file__).resolve().parent
#: The helpers every kernel includes (``#include "_native_util.h"``), relative to this file: in each
#: extension's ``depends`` (a change rebuilds every kernel, and setuptools puts it in the sdist).
SHARED_HEADER = Path("imu_ground") / "_native_util.h"
#: Folders whose ``_*_native.c`` files are built -> the package they are installed as (pyproject's package-dir).
NATIVE_FOLDERS = {"imu_ground": "imu_ground"}


def native_extensions() -> list:
    """One optional Extension per ``_*_native.c`` file under :data:`NATIVE_FOLDERS`."""
    exts = []
    for folder, package in NATIVE_FOLDERS.items():
        for src in sorted((HERE / folder).rglob("_*_native.c")):
            rel = src.relative_to(HERE)
            name = ".".join([package, *src.relative_to(HERE / folder).with_suffix("").parts])
            exts.append(Extension(name, [rel.as_posix()],
                                  include_dirs=[SHARED_HEADER.parent.as_posix()],
                                  depends=[SHARED_HEADER.as_posix()],
                                  extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"]
                                  if not _msvc() else ["/O2", "/fp:precise"],
                                  optional=True))
    return exts


def _msvc() -> bool:
    import sysconfig
    return sysconfig.get_platform().startswith("win")


setup(ext_modules=native_extensions())
