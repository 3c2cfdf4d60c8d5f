"""Sample-by-sample preintegration into frames (:class:`StreamingPreintegrator`).

One float64 buffer, one compiled :func:`~imu_ground.imu.preint_kernel.push_step` a sample: the step the batch
:func:`~imu_ground.imu.preintegration.preintegrate` runs over a whole log, so both give the same frames.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from imu_ground.imu.preint_kernel import (_O_N, _O_SIZE, _O_TEND, _O_TSTART, _O_VALID, _S_ACTIVE, _S_BIAS, _S_CD,
                                          _S_K, _S_LIM, _S_MARK, _S_N, _S_NEXT, _S_ORIGIN, _S_PREV, _S_TSTART, _S_UNC,
                                          _S_UNCERTAINTY, _S_VALID, push_step, state_buffer)
from imu_ground.imu.preint_measurement import PreintegratedImu, delta_rotation
from imu_ground.imu.preint_params import PreintegrationParams, gap_message
from imu_ground.imu.warm_start import STATE_VERSION, StateError, StateReader, pack_state, unpack_state

__all__ = ["StreamingPreintegrator"]

#: Frames one push can finish before the frames buffer grows.
_O_ROWS = 16
#: The integer entries of the saved state (buffer offsets), then the floats (``_t_start`` may be NaN).
_INTS = {"_n": _S_N, "_cd": _S_CD, "_mark": _S_MARK, "_k": _S_K}
_FLOATS = {"_t_start": _S_TSTART, "_next": _S_NEXT, "_lim": _S_LIM}
_from_state = PreintegratedImu.from_state


class StreamingPreintegrator:
    """Sample-by-sample front-end: emits a finished :class:`PreintegratedImu` per frame.

    Frames are given as in :func:`~imu_ground.imu.preintegration.preintegrate` (boundary times, a rate or a
    sample count), with the same results. A frame is emitted by the first sample at or after its end (less
    ``snap_tol``); a sample refused with ValueError leaves the state unchanged.

    Parameters
    ----------
    frame_times : iterable of float, optional
        Boundaries, s, strictly increasing; samples before the first are ignored.
    rate : float, optional
        Frame rate, Hz: boundaries ``t_origin + k / rate`` (default origin: the first sample's time, s).
    every : int, optional
        A boundary at every ``every``-th sample, starting with the first.
    params : PreintegrationParams, optional
        ``uncertainty=False``: deltas only (the fast choice for a filter).
    **options
        Fields of :class:`~imu_ground.imu.preint_params.PreintegrationParams` overriding ``params``.
    """

    def __init__(self, frame_times: Iterable[float] | None = None, *,
                 rate: float | None = None, every: int | None = None,
                 t_origin: float | None = None, params: PreintegrationParams | None = None,
                 **options: Any) -> None:
        par = self.params = PreintegrationParams.coerce(params, **options)
        if sum(x is not None for x in (frame_times, rate, every)) != 1:
            raise ValueError("give exactly one of frame_times, rate and every")
        self._times = None
        if frame_times is not None:
            self._times = np.asarray(list(frame_times), dtype=float).reshape(-1).tolist()
            if any(not (b - a > 2 * par.snap_tol) for a, b in zip(self._times, self._times[1:], strict=False)):
                raise ValueError("frame_times must be strictly increasing (by more than 2 * snap_tol)")
        if rate is not None and not rate > 0:
            raise ValueError(f"rate must be > 0, got {rate}")
        if every is not None and int(every) < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        self._rate = None if rate is None else float(rate)
        self._every = None if every is None else int(every)
        self._b = state_buffer(par, self._rate, self._every, None if t_origin is None else float(t_origin))
        self._tb = np.array(self._times or (), dtype=float)
        self._out = np.zeros((_O_ROWS, _O_SIZE))

    def push(self, t: float, gyro: Sequence[float], accel: Sequence[float]) -> tuple[PreintegratedImu, ...]:
        """Add one sample; return the frames finished by it (usually none, or one).

        Parameters
        ----------
        t : float
            Sample time, s (strictly increasing).
        gyro, accel : sequence of 3 floats
            Angular rate (rad/s) and specific force (m/s^2), body frame.

        Returns
        -------
        tuple of PreintegratedImu
            Finished frames, with ``t_start``, ``t_end``, ``valid``; ``delta_R`` is ``R_{start<-end}``.

        Raises
        ------
        ValueError
            A time not after the last sample's, a gap with ``on_gap="raise"``, a first sample
            after the first frame time, or gyro/accel not 3 numbers each.
        """
        n = self.push_counted(t, gyro, accel)
        return self.finished_frames(n) if n else ()

    def push_counted(self, t: float, gyro: Sequence[float], accel: Sequence[float]) -> int:
        """:meth:`push` answering only how many frames the sample finished (0 usually), read then with
        :meth:`finished_frames` or :meth:`finished_motion`; the same checks and errors."""
        t = float(t)
        try:
            wx, wy, wz = gyro
            ax, ay, az = accel
            done = push_step(self._b, self._tb, self._out, t, float(wx), float(wy), float(wz),
                             float(ax), float(ay), float(az))
        except (TypeError, ValueError):
            raise ValueError(f"gyro and accel must have 3 values each, got {gyro!r}, {accel!r}") from None
        if done >= 0:
            return done
        t0 = self._b[_S_PREV]
        if math.isnan(t0):
            raise ValueError(f"frame boundary {float(self._tb[0])!r} s is before the first sample at {t!r} s")
        if not t > t0:
            raise ValueError(f"IMU timestamps must be strictly increasing: got t = {t!r} s after "
                             f"{t0!r} s; drop non-increasing samples upstream (validation)")
        if t - t0 > self.params.max_gap and self.params.on_gap == "raise":
            raise ValueError(gap_message(t0, t - t0, self.params.max_gap))
        self._out = np.zeros((2 * len(self._out), _O_SIZE))    # more frames than the buffer holds
        return self.push_counted(t, gyro, accel)

    @property
    def step_buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(state, frame_times, frames)``: the buffers of :func:`push_step`, for a caller's own compiled step
        (a positive answer read with :meth:`finished_frames`, -1 by calling :meth:`push`)."""
        return self._b, self._tb, self._out

    def finished_frames(self, n: int) -> tuple[PreintegratedImu, ...]:
        """The ``n`` frames :func:`push_step` just finished (the first ``n`` rows of the frames buffer)."""
        par, unc = self.params, self._b[_S_UNCERTAINTY] != 0.0
        return tuple(_from_state(par, tuple(row[0:_S_UNC]), tuple(row[_S_UNC:_S_PREV]) if unc else None,
                                 int(row[_O_N]), row[_O_TSTART], row[_O_TEND], row[_O_VALID] != 0.0)
                     for row in self._out[:n].tolist())

    def finished_motion(self, n: int) -> list[tuple[np.ndarray, np.ndarray, float, float, float, bool]]:
        """``(delta_R, delta_v, delta_t, t_start, t_end, valid)`` of each of the ``n`` frames :func:`push_step` just
        finished (as :meth:`finished_frames` gives them: ``R_{start<-end}``, m/s in the start body frame, s), without
        building the measurements."""
        return [(delta_rotation(row[1:5]), np.array(row[5:8]), row[0], row[_O_TSTART], row[_O_TEND],
                 row[_O_VALID] != 0.0) for row in self._out[:n].tolist()]

    # settings, read-only views of params
    hold = property(lambda self: self.params.hold, doc="``'midpoint'`` or ``'left'``.")
    max_gap = property(lambda self: self.params.max_gap, doc="Longest sample step, s, that is not a gap.")
    on_gap = property(lambda self: self.params.on_gap, doc="``'raise'`` or ``'flag'``.")
    snap_tol = property(lambda self: self.params.snap_tol, doc="Boundary snapping tolerance, s.")

    @property
    def last_sample_time(self) -> float | None:
        """Time of the last sample integrated, s (None before the first)."""
        t = float(self._b[_S_PREV])
        return None if math.isnan(t) else t

    @property
    def next_boundary(self) -> float:
        """Time of the next frame end, s (inf if none or unknown: before the first sample, every-N frames)."""
        return float(self._b[_S_NEXT])

    def set_gyro_bias(self, bx: float, by: float, bz: float) -> None:
        """Remove this gyro bias (rad/s, body frame) from the next sample on, in place of ``params``' (not part of
        :meth:`state_dict`: set it again after a :meth:`load_state_dict`)."""
        self._b[_S_BIAS:_S_BIAS + 3] = float(bx), float(by), float(bz)

    def _state(self) -> tuple[tuple, tuple | None]:
        b = self._b
        return tuple(b[0:_S_UNC].tolist()), (tuple(b[_S_UNC:_S_PREV].tolist()) if b[_S_UNCERTAINTY] else None)

    @property
    def current(self) -> PreintegratedImu:
        """A snapshot of the frame being integrated (``t_end`` nan)."""
        b = self._b
        return _from_state(self.params, *self._state(), int(b[_S_N] + b[_S_MARK] - b[_S_CD]),
                           float(b[_S_TSTART]), math.nan, b[_S_VALID] != 0.0)

    def _settings(self) -> dict:
        return {"frame_times": self._times, "rate": self._rate, "every": self._every,
                "params": dataclasses.asdict(self.params)}

    def state_dict(self) -> dict:
        """The state as a plain, JSON-serialisable dict (:mod:`imu_ground.imu.warm_start`)."""
        b = self._b
        deltas, unc = self._state()
        origin = float(b[_S_ORIGIN])
        st: dict[str, Any] = {name: int(b[i]) for name, i in _INTS.items()}
        st.update({name: float(b[i]) for name, i in _FLOATS.items()})
        prev = None if self.last_sample_time is None else b[_S_PREV:_S_LIM].tolist()   # t, gyro, accel less bias
        st.update(_valid=b[_S_VALID] != 0.0, _active=b[_S_ACTIVE] != 0.0,
                  _origin=None if math.isnan(origin) else origin, prev=prev, deltas=deltas, uncertainty=unc)
        return pack_state("StreamingPreintegrator", STATE_VERSION, self._settings(), st)

    def load_state_dict(self, state: dict) -> None:
        """Resume from a :meth:`state_dict` of the same settings; else, or for a corrupt state, a
        :class:`~imu_ground.imu.warm_start.StateError` naming what is wrong, the preintegrator unchanged."""
        st = StateReader("StreamingPreintegrator",
                         unpack_state(state, "StreamingPreintegrator", STATE_VERSION, self._settings()))
        ints = {i: st.int(name) for name, i in _INTS.items()}
        floats = {_S_TSTART: st.float("_t_start", nan=True), _S_NEXT: st.float("_next", inf=True),
                  _S_LIM: st.float("_lim", inf=True)}
        valid, active, origin = st.bool("_valid"), st.bool("_active"), st.float("_origin", optional=True)
        prev = st.floats("prev", (7,), optional=True)
        deltas = st.floats("deltas", (11,))
        unc = st.floats("uncertainty", (None,), optional=True)
        if (unc is None) == bool(self._b[_S_UNCERTAINTY]) or (unc is not None and len(unc) != _S_PREV - _S_UNC):
            raise StateError("the saved state and this preintegrator differ in uncertainty")
        b = self._b
        for i, v in {**ints, **floats}.items():
            b[i] = v
        b[_S_VALID], b[_S_ACTIVE] = valid, active
        b[_S_ORIGIN] = math.nan if origin is None else origin
        b[_S_PREV:_S_LIM] = math.nan if prev is None else prev
        b[0:11] = deltas
        if unc is not None:
            b[_S_UNC:_S_PREV] = unc
