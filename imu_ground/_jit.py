"""The one place that decides how the package's per-sample and per-frame loops run: compiled or interpreted.

Each loop that must run at machine speed is written once, in plain Python on floats and numpy arrays, and decorated
with :func:`njit`: with numba installed (a dependency; it compiles that source at first use and caches the machine
code beside the module, no C compiler at install) it runs compiled; with ``NUMBA_DISABLE_JIT=1`` (numba's own
switch, read at import) or without numba it is the same body interpreted (the test suite runs a subset both ways). A
foundation module: it imports nothing of the package.
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

    The body keeps to numba's nopython mode (floats, ints, bools, tuples, numpy arrays). No ``fastmath``: compiled
    and interpreted bodies round alike up to the last bit of ``sin`` and the like.

    Parameters
    ----------
    function : callable
        The one body of the loop.

    Returns
    -------
    callable
        numba's dispatcher (same signature), or ``function`` itself when :data:`JIT_ENABLED` is False.
    """
    if not JIT_ENABLED or _numba is None:
        return function
    return cast(F, _numba.njit(cache=True, nogil=True)(function))


def jitable(function: F) -> F:
    """Make ``function`` callable from :func:`njit` bodies (compiled into them, numba's ``register_jitable``).

    For small helpers shared by compiled bodies and plain Python callers (e.g. the scalar rotation kernels of
    :mod:`imu_ground.so3`); the same rules for the body as :func:`njit`.

    Parameters
    ----------
    function : callable
        The one body of the helper.

    Returns
    -------
    callable
        ``function`` itself (a Python caller gets no dispatch).
    """
    if not JIT_ENABLED:
        return function
    from numba.extending import register_jitable
    registered: F = register_jitable(function)
    return registered
