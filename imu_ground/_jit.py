"""The one place that decides how the package's per-sample and per-frame loops run: compiled or interpreted.

Each loop that must run at machine speed (a whole log's preintegration, the
residual filter over a drive, ...) is written once, in plain Python on floats
and numpy arrays, and decorated with :func:`njit`. With numba installed (a
dependency: it compiles that same source with LLVM at first use and caches the
machine code beside the module, so nothing needs a C compiler at install) the
decorated function runs compiled; with ``NUMBA_DISABLE_JIT=1`` in the
environment (numba's own switch, read at import) or without numba it is the
plain Python function, the same body interpreted. The test suite runs a subset
both ways so the two modes stay equal.

A foundation module: it imports nothing of the package.
"""
from __future__ import annotations

import os
from types import ModuleType
from typing import Any, Callable, Optional, TypeVar, cast

__all__ = ["njit", "jitable", "JIT_ENABLED", "DISABLE_JIT_ENV"]

#: numba's own environment switch: set to 1 before the first import, every :func:`njit` body runs interpreted.
DISABLE_JIT_ENV = "NUMBA_DISABLE_JIT"

F = TypeVar("F", bound=Callable[..., Any])

_numba: Optional[ModuleType]
try:                                            # pragma: no cover - which branch runs depends on the install
    import numba as _numba
except ImportError:                             # pragma: no cover
    _numba = None

#: True when :func:`njit` bodies run compiled (numba importable and not switched off).
JIT_ENABLED: bool = _numba is not None and os.environ.get(DISABLE_JIT_ENV, "") in ("", "0")


def njit(function: F) -> F:
    """Compile ``function`` with numba (``nopython``, cached on disk), or return it unchanged.

    The body must keep to what numba's nopython mode compiles: floats, ints,
    bools, tuples and numpy arrays, no Python objects. Floating point is not
    reassociated (no ``fastmath``), so the compiled and interpreted bodies round
    alike up to the last bit of library functions such as ``sin``.

    Parameters
    ----------
    function : callable
        The one body of the loop.

    Returns
    -------
    callable
        numba's dispatcher (same call signature), or ``function`` itself when
        :data:`JIT_ENABLED` is False.
    """
    if not JIT_ENABLED or _numba is None:
        return function
    return cast(F, _numba.njit(cache=True, nogil=True)(function))


def jitable(function: F) -> F:
    """Make ``function`` callable from :func:`njit` bodies, compiled into them, and leave it plain Python otherwise.

    For small helpers shared by compiled bodies and by plain Python callers (e.g. the
    scalar rotation kernels of :mod:`imu_ground.so3`): a Python caller gets the function
    itself (no dispatch), a compiled body inlines its compiled form (numba's
    ``register_jitable``). The same rules for the body as :func:`njit`.

    Parameters
    ----------
    function : callable
        The one body of the helper.

    Returns
    -------
    callable
        ``function`` itself.
    """
    if not JIT_ENABLED:
        return function
    from numba.extending import register_jitable
    registered: F = register_jitable(function)
    return registered
