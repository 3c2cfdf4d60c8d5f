"""The one place that chooses between the compiled kernels and their pure-Python twins.

The per-frame scalar kernels of the streaming path exist twice: in C
(``imu_ground/**/_*_native.c``, built by ``setup.py`` when a C compiler is
available) and in pure Python, the reference each C kernel is tested against.
This module imports each compiled twin once, at import, and exposes it (or None
when it is not built or switched off); the modules that own a kernel take it
from here and fall back to their Python twin when it is None:

=======================  =========================================  =========================================
name                     compiled module                            Python twin
=======================  =========================================  =========================================
:data:`EKF`              ``imu_ground.filters._ekf_native``         :mod:`imu_ground.filters.invariant_ekf_kernel`
=======================  =========================================  =========================================

Equality rule between twins (the one the tests check, all with
:func:`assert_twins_equal`): every output of a C kernel equals its Python twin's
to :data:`TWIN_RTOL` (``1e-12``) relative to ``max(1, |value|)``, with NaN and
infinities in the same places and integers and flags exactly equal. Most paths
agree bit for bit (the C is the Python formula term for term, compiled without
FMA contraction), but vectorised numpy steps of a Python batch path may round differently in the
last bit, so the rule promised is the tolerance.

Environment
-----------
``IMU_GROUND_PURE_PYTHON=1`` (before the first import)
    Use the pure-Python kernels everywhere, e.g. to compare the two.
``IMU_GROUND_REQUIRE_NATIVE=1``
    A compiled kernel that is not built is an error of the test suite (CI sets
    it: ``.ci/run``) instead of a skip.

A foundation module: it imports nothing of the package (numpy only, for :func:`assert_twins_equal`).
"""
from __future__ import annotations

import importlib
import os
from types import ModuleType
from typing import Any, Dict, Optional

import numpy as np

__all__ = ["load_native", "native_kernels", "kernels_in_use", "PURE_PYTHON_ENV", "REQUIRE_NATIVE_ENV",
           "EKF", "STREAMING_KERNELS",
           "TWIN_RTOL", "assert_twins_equal"]

PURE_PYTHON_ENV = "IMU_GROUND_PURE_PYTHON"
REQUIRE_NATIVE_ENV = "IMU_GROUND_REQUIRE_NATIVE"

_LOADED: Dict[str, bool] = {}


def _switched_on(variable: str) -> bool:
    """The environment variable is set to a non-empty value other than ``0``."""
    return os.environ.get(variable, "") not in ("", "0")


def load_native(name: str) -> Optional[ModuleType]:
    """The compiled kernel module ``name`` (dotted), or None when it is not built or is switched off.

    Parameters
    ----------
    name : str
        Dotted module name, e.g. ``"imu_ground.filters._ekf_native"``.

    Returns
    -------
    module or None
        None when ``IMU_GROUND_PURE_PYTHON`` is set to a non-empty value other
        than ``0``, or when the extension was not built (no C compiler at install).
    """
    module = None
    if not _switched_on(PURE_PYTHON_ENV):
        try:
            module = importlib.import_module(name)
        except ImportError:
            module = None
    _LOADED[name] = module is not None
    return module


#: The compiled twins of the streaming path (module or None), each imported once, here.
EKF = load_native("imu_ground.filters._ekf_native")
#: Their dotted names, in the order above.
STREAMING_KERNELS = tuple(_LOADED)


def native_kernels() -> Dict[str, bool]:
    """Compiled kernel module name -> whether it is in use (every streaming kernel, from the first import on)."""
    return dict(_LOADED)


def kernels_in_use() -> str:
    """One line for ``imu-ground --version``: the compiled kernels or pure Python, and why.

    Returns
    -------
    str
        ``"compiled kernels"`` when every streaming kernel is built; otherwise
        ``"pure Python kernels: ..."`` naming the cause (the switch, or which
        kernels are not built).
    """
    if _switched_on(PURE_PYTHON_ENV):
        return f"pure Python kernels: {PURE_PYTHON_ENV} is set"
    missing = [name.rsplit(".", 1)[1] for name in STREAMING_KERNELS if not _LOADED[name]]
    if not missing:
        return "compiled kernels"
    if len(missing) == len(STREAMING_KERNELS):
        return "pure Python kernels: the compiled ones are not built (no C compiler at install?)"
    return f"compiled kernels, but pure Python for {', '.join(missing)}: not built"


#: The twin rule's tolerance: relative to ``max(1, |value|)``.
TWIN_RTOL = 1e-12


def assert_twins_equal(compiled: Any, python: Any, what: str = "") -> None:
    """Check the twin rule: a C kernel's output against its Python twin's (the one check the tests use).

    Parameters
    ----------
    compiled, python : array_like, scalar, or None
        The same output of the two twins (any shape; tuples of floats, buffers and
        arrays alike). None only matches None.
    what : str
        Named in the failure message.

    Raises
    ------
    AssertionError
        Shapes differ; a number differs by more than :data:`TWIN_RTOL` times
        ``max(1, |python|)``; NaN or infinities in different places; an integer
        or boolean output differs at all.
    """
    if compiled is None or python is None:
        if compiled is not python:
            raise AssertionError(f"{what}: {compiled!r} (compiled) against {python!r} (Python)")
        return
    a, b = np.asarray(compiled), np.asarray(python)
    if a.shape != b.shape:
        raise AssertionError(f"{what}: shape {a.shape} (compiled) against {b.shape} (Python)")
    if a.dtype.kind not in "fc" and b.dtype.kind not in "fc":
        if not np.array_equal(a, b):
            raise AssertionError(f"{what}: {np.count_nonzero(a != b)} of {a.size} values differ")
        return
    a, b = a.astype(float), b.astype(float)
    same = (a == b) | (np.isnan(a) & np.isnan(b))
    finite = np.isfinite(a) & np.isfinite(b)
    af, bf = np.where(finite, a, 0.0), np.where(finite, b, 0.0)
    err = np.where(same, 0.0, np.abs(af - bf) / np.maximum(1.0, np.abs(bf)))
    if not np.all(same | finite) or err.max(initial=0.0) > TWIN_RTOL:
        k = np.unravel_index(np.argmax(np.where(same, -1.0, np.where(finite, err, np.inf))), a.shape)
        raise AssertionError(f"{what}: compiled {a[k]!r} against Python {b[k]!r} at {tuple(int(i) for i in k)} "
                             f"(rule: equal to {TWIN_RTOL:g} relative to max(1, |value|), NaN in the same places)")
