"""Warm start of :class:`~imu_ground.imu.preint_stream.StreamingPreintegrator`: its state as a plain dict.

The format and its checks are :mod:`imu_ground.imu.warm_start`'s. The state is the
frame being integrated (deltas and, with ``uncertainty``, their covariance and
Jacobians, as the kernel holds them) and the bookkeeping of the sample stream
(last sample, next boundary, counts); the settings are the frame boundaries
(``frame_times``, ``rate`` or ``every``) and the :class:`PreintegrationParams`.
A state saved with the compiled kernel loads into the pure-Python one and back
(the same layout). A stream stopped after any sample and resumed from its state
emits the frames of the uninterrupted stream.
"""
from __future__ import annotations

import dataclasses

from imu_ground.imu.warm_start import pack_state, unpack_state

__all__ = ["STATE_VERSION", "preintegrator_state", "load_preintegrator_state"]

#: Layout of the saved state (raised when it changes).
STATE_VERSION = 1
_ATTRS = ("_n", "_t_start", "_valid", "_cd", "_mark", "_k", "_next", "_lim", "_active", "_origin")


def _settings(p) -> dict:
    return {"frame_times": p._times, "rate": p._rate, "every": p._every, "params": dataclasses.asdict(p.params)}


def preintegrator_state(p) -> dict:
    """``StreamingPreintegrator.state_dict()``."""
    p._load()                                   # (compiled kernel: its buffer -> the attributes)
    deltas, unc = p._kernel_state()
    st = {name: getattr(p, name) for name in _ATTRS}
    st.update(prev=p._prev, deltas=deltas, uncertainty=unc)
    return pack_state("StreamingPreintegrator", STATE_VERSION, _settings(p), st)


def load_preintegrator_state(p, saved) -> None:
    """``StreamingPreintegrator.load_state_dict(saved)``."""
    st = unpack_state(saved, "StreamingPreintegrator", STATE_VERSION, _settings(p))
    ints = {"_n", "_cd", "_mark", "_k"}
    for name in _ATTRS:
        v = st[name]
        setattr(p, name, None if v is None else int(v) if name in ints else
                bool(v) if name in ("_valid", "_active") else float(v))
    p._prev = None if st["prev"] is None else tuple(float(v) for v in st["prev"])
    deltas = tuple(float(v) for v in st["deltas"])
    unc = None if st["uncertainty"] is None else tuple(float(v) for v in st["uncertainty"])
    if (unc is None) != (p._u0 is None):
        raise ValueError("the saved state and this preintegrator differ in uncertainty")
    if hasattr(p, "_b"):                        # compiled kernel: one buffer
        b = p._b
        b[0:11] = type(b)("d", deltas)
        if unc is not None:
            b[11:11 + len(unc)] = type(b)("d", unc)
        p._save()
    else:
        p._st = (deltas, unc)
