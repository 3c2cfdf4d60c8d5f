"""Lazy re-exports for package namespaces (PEP 562), so that ``import imu_ground`` stays light.

A package lists ``name -> module`` and gets ``__getattr__``/``__dir__`` that import
the module on first use of the name. Nothing else in the package depends on this.
"""
from __future__ import annotations

import importlib
from typing import Any, Callable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, names: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list]]:
    """``__getattr__`` and ``__dir__`` for ``package`` that import ``names[attr]`` on demand.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    names : mapping of str to str
        Public name to the absolute module that defines it.
    """
    def __getattr__(attr: str) -> Any:
        try:
            module = names[attr]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {attr!r}") from None
        value = getattr(importlib.import_module(module), attr)
        return value

    def __dir__() -> list:
        return sorted(set(names) | set(importlib.import_module(package).__dict__))

    return __getattr__, __dir__
