"""Warm start: a streaming object's state as a plain dict, and back.

Every streaming estimator (and :class:`~imu_ground.imu.preint_stream.StreamingPreintegrator`)
has ``state_dict()`` and ``load_state_dict(state)``. A state is a dict of plain
Python values (floats, ints, bools, strings, None and lists of them), so
``json.dumps`` writes it and ``json.loads`` gives it back unchanged (floats
round-trip exactly; NaN and infinities are written as JSON's ``NaN`` / ``Infinity``):

    {"kind": "SuspensionAwareFilter", "state_version": 1, "package_version": "...",
     "settings": {...}, "state": {...}}

``kind`` and ``state_version`` must match the loading object's (a state from
another estimator, or from a layout this version cannot read, is refused with
:class:`StateError`, a ``ValueError`` that says which); ``settings`` are the
options that determine the numbers, and must equal the loading object's too
(resuming with other settings would not continue the same run). A run stopped
after frame k and resumed from its state gives the frames of the uninterrupted
run (the tests check 1e-12; the kernels' buffers are restored bit for bit).
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from imu_ground._version import __version__
from imu_ground.errors import ImuGroundError

__all__ = ["StateError", "pack_state", "unpack_state", "plain"]


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


def _version() -> str:
    return __version__


def pack_state(kind: str, state_version: int, settings: Mapping[str, Any], state: Mapping[str, Any]) -> dict:
    """The saved-state dict of the module docstring.

    Parameters
    ----------
    kind : str
        The class name of the saving object.
    state_version : int
        The layout of ``state`` (raised when it changes).
    settings : mapping
        The options that determine the numbers.
    state : mapping
        The dynamic state.
    """
    return {"kind": kind, "state_version": int(state_version), "package_version": _version(),
            "settings": plain(dict(settings)), "state": plain(dict(state))}


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def unpack_state(saved: Any, kind: str, state_version: int, settings: Mapping[str, Any]) -> dict:
    """The dynamic state of a saved-state dict, after checking it belongs to this object.

    Parameters
    ----------
    saved : dict
        What ``state_dict()`` returned (possibly through JSON).
    kind, state_version, settings
        The loading object's (as for :func:`pack_state`).

    Raises
    ------
    StateError
        Not a saved state, another kind, another layout, or other settings.
    """
    if not isinstance(saved, Mapping) or not {"kind", "state_version", "settings", "state"} <= set(saved):
        raise StateError(f"not a saved state of {kind} (expected the dict of state_dict(), with kind, "
                         f"state_version, settings and state)")
    if saved["kind"] != kind:
        raise StateError(f"this state was saved by {saved['kind']}, not {kind}: load it into a {saved['kind']}")
    if saved["state_version"] != state_version:
        raise StateError(f"this {kind} state has layout {saved['state_version']} (saved by imu-ground "
                         f"{saved.get('package_version', '?')}); imu-ground {_version()} reads layout "
                         f"{state_version} only: start this filter afresh")
    mine = plain(dict(settings))
    if not _same(plain(saved["settings"]), mine):
        diff = sorted(k for k in set(mine) | set(saved["settings"])
                      if not _same(mine.get(k), plain(saved["settings"]).get(k)))
        raise StateError(f"this {kind} state was saved with other settings ({', '.join(diff)}): "
                         f"construct the {kind} with the saved settings to resume")
    return dict(saved["state"])
