"""A live estimator's saved state packed: long lists of floats as base64 of their compressed float64 bytes, and back.

:func:`pack` writes a list of equally shaped items of floats (at least 8 in all) as
``{"float64_zlib_base64": text, "n": items, "item": shape}``; :func:`unpack` reads it back with
bounds (inflated up to the size it says, never more).
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["MAX_PACKED_FLOATS", "MAX_RECORDS", "pack", "unpack"]

#: The most records a list of a saved state (waiting frames, speed samples, blocks, notes) may hold.
MAX_RECORDS = 100_000

_PACKED = "float64_zlib_base64"
_PACK_MIN = 8


def _shape(x: Any) -> Any:
    """0 for a float, the list of its items' shapes for a list of such; None for anything else."""
    if type(x) is float:
        return 0
    if type(x) is list and x:
        items = [_shape(y) for y in x]
        return None if any(i is None for i in items) else items
    return None


def _leaves(x: Any, out: list) -> None:
    if type(x) is float:
        out.append(x)
    else:
        for y in x:
            _leaves(y, out)


def pack(x: Any) -> Any:
    """``x`` with each list of equally shaped items of floats (at least 8 in all) packed (module docstring)."""
    if type(x) is dict:
        return {k: pack(v) for k, v in x.items()}
    if type(x) is list:
        shape = _shape(x)
        if shape is not None and all(s == shape[0] for s in shape):
            flat: list = []
            _leaves(x, flat)
            if len(flat) >= _PACK_MIN:
                import base64
                import zlib
                raw = zlib.compress(np.array(flat, dtype=float).tobytes(), 9)
                return {_PACKED: base64.b64encode(raw).decode("ascii"), "n": len(x), "item": shape[0]}
        return [pack(v) for v in x]
    return x


#: The most floats a packed list of a saved state may hold (bounds what a corrupt one inflates to: 8 MB).
MAX_PACKED_FLOATS = 1_000_000


def _size(shape: Any) -> int:
    return 1 if shape == 0 else sum(_size(s) for s in shape)


def _build(shape: Any, it) -> Any:
    return next(it) if shape == 0 else [_build(s, it) for s in shape]


def unpack(x: Any, name: str = "state") -> Any:
    """:func:`pack` undone; a packed list that is garbled, truncated, of another size than it says or larger than
    :data:`MAX_PACKED_FLOATS` raises :class:`~imu_ground.imu.warm_start.StateError` naming entry ``name``."""
    if type(x) is dict:
        if _PACKED in x:
            return _unpacked(x, name)
        return {k: unpack(v, f"{name}.{k}") for k, v in x.items()}
    if type(x) is list:
        return [unpack(v, name) for v in x]
    return x


def _valid_shape(shape: Any, depth: int = 0) -> bool:
    if shape == 0 and type(shape) is int:
        return True
    return type(shape) is list and 0 < len(shape) <= MAX_PACKED_FLOATS and depth < 4 and \
        all(_valid_shape(s, depth + 1) for s in shape)


def _unpacked(x: dict, name: str) -> list:
    import base64
    import binascii
    import zlib

    from imu_ground.imu.warm_start import StateError

    def bad(problem: str) -> StateError:
        return StateError(f"this StreamingEstimator state is corrupt: its entry {name} {problem}; save the state "
                          f"again with state_dict() or start afresh")
    text, n, item = x.get(_PACKED), x.get("n"), x.get("item")
    if type(text) is not str or type(n) is not int or not 0 < n <= MAX_PACKED_FLOATS or not _valid_shape(item):
        raise bad("is not a packed list (its text, count or item shape is missing or of another type)")
    want = n * _size(item)
    if want > MAX_PACKED_FLOATS:
        raise bad(f"says it holds {want} numbers, more than a saved state's {MAX_PACKED_FLOATS}")
    if len(text) > 12 * want + 1024:                 # (the base64 of zlib of 8 bytes a float is less than this)
        raise bad(f"is {len(text)} characters long for {want} numbers")
    try:
        raw = base64.b64decode(text, validate=True)
        d = zlib.decompressobj()
        data = d.decompress(raw, 8 * want + 1)
        complete = d.eof and not d.unconsumed_tail
    except (binascii.Error, zlib.error, ValueError) as e:
        raise bad(f"is garbled ({type(e).__name__}: {e})") from None
    if not complete or len(data) != 8 * want:
        raise bad(f"holds {len(data) // 8}{'' if complete else ' or more'} numbers where it says {want} "
                  f"(truncated or garbled)")
    it = iter(np.frombuffer(data, dtype=float).tolist())
    return [_build(item, it) for _ in range(n)]
