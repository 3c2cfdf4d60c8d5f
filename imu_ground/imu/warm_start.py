"""Warm start: a streaming object's state as a plain dict, and back.

Every streaming object has ``state_dict()`` and ``load_state_dict(state)``. A state is a dict of plain Python
values, so ``json.dumps`` / ``json.loads`` round-trip it exactly (NaN and infinities as ``NaN`` / ``Infinity``)::

    {"kind": "SuspensionAwareFilter", "state_version": 1, "package_version": "...",
     "settings": {...}, "state": {...}}

``kind``, ``state_version`` and ``settings`` (the options that determine the numbers) must equal the loading
object's; else :class:`StateError` (a ``ValueError``) says which, nested settings as ``gravity.q_v``, with both
values. Every entry of ``state`` is checked as it is read (:class:`StateReader`): its shape, finite numbers
(NaN only where the layout has "none yet") of at most :data:`MAX_MAGNITUDE`. A run resumed from its state
gives the frames of the uninterrupted run.
"""
from __future__ import annotations

import builtins
import math
from typing import Any, Mapping

import numpy as np

from imu_ground._version import __version__
from imu_ground.errors import ImuGroundError

__all__ = ["MAX_MAGNITUDE", "STATE_VERSION", "StateError", "StateReader", "as_reader", "buffer_like", "pack_state",
           "plain", "unpack_state"]

#: Layout of the saved states of the streaming filters and the preintegrator (raised when one changes).
STATE_VERSION = 1
#: The largest magnitude a number of a saved state may have (beyond it, a covariance overflows at its first square).
MAX_MAGNITUDE = 1e100


class StateError(ImuGroundError):
    """A saved state that this object cannot load (another kind, layout or settings)."""


def plain(value: Any) -> Any:
    """``value`` as plain JSON-serialisable Python values (arrays and tuples to lists, numpy scalars to floats)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)) or type(value).__name__ == "array":
        return [plain(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"cannot put a {type(value).__name__} into a saved state")


def buffer_like(old, values):
    """``values`` in the container type of ``old`` (``array('d')``, numpy array or list of float)."""
    if type(old).__name__ == "array" and not isinstance(old, np.ndarray):
        return type(old)("d", values)
    if isinstance(old, np.ndarray):
        return np.array(values, dtype=float)
    return [float(v) for v in values]


def pack_state(kind: str, state_version: int, settings: Mapping[str, Any], state: Mapping[str, Any]) -> dict:
    """The saved-state dict of the module docstring: the saving object's class name ``kind``, the layout
    ``state_version``, its ``settings`` and dynamic ``state``."""
    return {"kind": kind, "state_version": int(state_version), "package_version": __version__,
            "settings": plain(dict(settings)), "state": plain(dict(state))}


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def unpack_state(saved: Any, kind: str, state_version: int, settings: Mapping[str, Any]) -> dict:
    """The dynamic state of a saved-state dict ``saved`` (``state_dict()``'s, possibly through JSON), after checking
    it belongs to this object (``kind``, ``state_version``, ``settings``: the loading object's).

    Raises
    ------
    StateError
        Not a saved state, another kind, a ``state_version`` that is not the layout's integer, another
        layout, or other settings (each named, nested ones as ``gravity.q_v``, with both values).
    """
    if not isinstance(saved, Mapping) or not {"kind", "state_version", "settings", "state"} <= set(saved):
        raise StateError(f"not a saved state of {kind} (expected the dict of state_dict(), with kind, "
                         f"state_version, settings and state)")
    if saved["kind"] != kind:
        raise StateError(f"this state was saved by {saved['kind']}, not {kind}: load it into a {saved['kind']}")
    version = saved["state_version"]
    if type(version) is not int:                    # (bool is an int subclass: refused too)
        raise StateError(f"this {kind} state's state_version is {type(version).__name__} {version!r}, not the "
                         f"layout number (an integer, {state_version} for imu-ground {__version__}): the file was "
                         f"edited or written by another tool; save the state again with state_dict()")
    if version != state_version:
        raise StateError(f"this {kind} state has layout {saved['state_version']} (saved by imu-ground "
                         f"{saved.get('package_version', '?')}); imu-ground {__version__} reads layout "
                         f"{state_version} only: start this filter afresh")
    mine, theirs = plain(dict(settings)), plain(saved["settings"])
    if not isinstance(theirs, dict) or not isinstance(saved["state"], Mapping):
        raise StateError(f"not a saved state of {kind}: its settings and state must be dicts")
    if not _same(theirs, mine):
        diff = "; ".join(f"{name}: saved {a}, this {kind} {b}" for name, a, b in _differences(theirs, mine))
        raise StateError(f"this {kind} state was saved with other settings ({diff}): "
                         f"construct the {kind} with the saved settings to resume")
    return dict(saved["state"])


def _short(value: Any) -> str:
    text = "missing" if value is _MISSING else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


_MISSING = object()


def _differences(saved: dict, mine: dict, prefix: str = "") -> list:
    """``(dotted name, saved value, this object's value)`` of every setting that differs, nested dicts opened."""
    out = []
    for k in sorted(set(saved) | set(mine)):
        a, b = saved.get(k, _MISSING), mine.get(k, _MISSING)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _differences(a, b, f"{prefix}{k}.")
        elif a is _MISSING or b is _MISSING or not _same(a, b):
            out.append((f"{prefix}{k}", _short(a), _short(b)))
    return out


class StateReader:
    """The entries of a saved state's ``state``, each checked as it is read: every method raises
    :class:`StateError` naming the entry (``monitor.hist`` in a nested part) when it is missing, of another shape
    or type, not finite (NaN only with ``nan``, infinities with ``inf``) or larger than :data:`MAX_MAGNITUDE`.

    Parameters
    ----------
    kind : str
        The loading object's class name (said in the message).
    state : mapping
        What :func:`unpack_state` returns, or a nested part of it.
    prefix : str
        The dotted name of that part (``""`` at the top).
    """

    def __init__(self, kind: str, state: Mapping[str, Any], prefix: str = "") -> None:
        self.kind, self.state, self.prefix = kind, state, prefix

    def error(self, name: str, problem: str) -> StateError:
        """The :class:`StateError` saying that entry ``name`` ``problem`` (for checks of its own a loader adds)."""
        return StateError(f"this {self.kind} state is corrupt: its entry {self.prefix}{name!s} {problem}; "
                          f"save the state again with state_dict() or start afresh")

    def _get(self, name: str) -> Any:
        if not isinstance(self.state, Mapping) or name not in self.state:
            raise self.error(name, "is missing")
        return self.state[name]

    def has(self, name: str) -> bool:
        """Whether the entry is there and not None."""
        return isinstance(self.state, Mapping) and self.state.get(name) is not None

    def floats(self, name: str, shape: tuple, nan: bool | slice = False, optional: bool = False,
               inf: bool = False) -> Any:
        """A float array of ``shape`` (``None``: any length on that axis); None if ``optional`` and null.
        ``nan``: NaN allowed (everywhere, or in a slice of a 1-d entry); ``inf``: infinities allowed."""
        v = self._get(name)
        if v is None and optional:
            return None
        try:
            a = np.array(v, dtype=float)
        except (TypeError, ValueError):
            raise self.error(name, f"is not numbers of shape {_shape_text(shape)} (got {_short(v)})") from None
        if isinstance(v, (bool, str)) or a.dtype != float or a.ndim != len(shape) or any(
                want is not None and got != want for got, want in zip(a.shape, shape, strict=True)):
            raise self.error(name, f"has shape {a.shape}, expected {_shape_text(shape)}")
        nan_ok = np.zeros(a.shape, dtype=bool)
        nan_ok[nan if isinstance(nan, slice) else ...] = bool(nan)
        bad = (np.isnan(a) & ~nan_ok) | (np.isinf(a) & (not inf))
        big = np.abs(np.where(np.isfinite(a), a, 0.0)) > MAX_MAGNITUDE
        if bad.any() or big.any():
            i = np.argwhere(bad | big)[0]
            where = "" if not a.ndim else f" at index {tuple(int(j) for j in i) if len(i) > 1 else int(i[0])}"
            value = float(a[tuple(i)])
            raise self.error(name, f"holds {value!r}{where} (expected finite numbers of at most "
                                   f"{MAX_MAGNITUDE:g} in size{', or NaN' if nan is True else ''}"
                                   f"{', or infinite' if inf else ''})")
        return a

    def float(self, name: str, nan: bool = False, optional: bool = False, inf: bool = False) -> Any:
        """One float (a Python float); None if ``optional`` and null."""
        a = self.floats(name, (), nan=nan, optional=optional, inf=inf)
        return None if a is None else float(a)

    def int(self, name: str, minimum: builtins.int = 0) -> builtins.int:
        """One integer at least ``minimum``."""
        v = self._get(name)
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < minimum or abs(int(v)) > MAX_MAGNITUDE:
            raise self.error(name, f"is {_short(v)}, expected an integer >= {minimum}")
        return int(v)

    def bool(self, name: str) -> builtins.bool:
        """One bool."""
        v = self._get(name)
        if not isinstance(v, (bool, np.bool_)):
            raise self.error(name, f"is {_short(v)}, expected true or false")
        return bool(v)

    def text(self, name: str) -> Any:
        """A str or None."""
        v = self._get(name)
        if v is not None and not isinstance(v, str):
            raise self.error(name, f"is {_short(v)}, expected a text or null")
        return v

    def rows(self, name: str, flatten, width: builtins.int, nan: builtins.bool = False) -> np.ndarray:
        """A list of records, each made a row of ``width`` floats by ``flatten``, checked as :meth:`floats`."""
        v = self._get(name)
        if not isinstance(v, list):
            raise self.error(name, f"is {_short(v)}, expected a list")
        try:
            flat = [flatten(r) for r in v]
        except (TypeError, IndexError, KeyError):
            raise self.error(name, f"holds records of another layout (got {_short(v)})") from None
        if not flat:
            return np.zeros((0, width))
        return StateReader(self.kind, {name: flat}, self.prefix).floats(name, (None, width), nan=nan).reshape(-1, width)

    def part(self, name: str, optional: builtins.bool = False) -> Any:
        """The reader of a nested dict entry; None if ``optional`` and null."""
        v = self._get(name)
        if v is None and optional:
            return None
        if not isinstance(v, Mapping):
            raise self.error(name, f"is {_short(v)}, expected a dict")
        return StateReader(self.kind, v, f"{self.prefix}{name}.")


def as_reader(state: Any, kind: str) -> StateReader:
    """``state`` as a :class:`StateReader` (a plain dict is read as ``kind``'s; a reader is kept)."""
    return state if isinstance(state, StateReader) else StateReader(kind, state)


def _shape_text(shape: tuple) -> str:
    return "(" + ", ".join("any" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
