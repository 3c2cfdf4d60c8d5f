"""Lazy re-exports for package namespaces (PEP 562), so that ``import imu_ground`` stays light."""
from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(package: str, modules: Mapping[str, str]) -> tuple[Callable[[str], Any], Callable[[], list], list]:
    """``__getattr__``, ``__dir__`` and ``__all__`` for ``package``, importing each name's module on demand.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    modules : mapping of str to str
        Module (absolute, or relative to ``package`` when it starts with ``.``) to the space-separated public names
        it defines; a name listed twice keeps its first module.

    Returns
    -------
    __getattr__, __dir__, __all__
    """
    names: dict[str, str] = {}
    for module, listed in modules.items():
        target = package + module if module.startswith(".") else module
        for name in listed.split():
            names.setdefault(name, target)

    def __getattr__(attr: str) -> Any:
        try:
            module = names[attr]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {attr!r}") from None
        return getattr(importlib.import_module(module), attr)

    def __dir__() -> list:
        return sorted(set(names) | set(importlib.import_module(package).__dict__))

    return __getattr__, __dir__, list(names)
