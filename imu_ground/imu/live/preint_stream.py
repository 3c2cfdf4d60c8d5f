"""Sample-by-sample preintegration into frames: the streaming front-end.

:class:`StreamingPreintegrator` cuts the stream into the same frames as the batch
:func:`~imu_ground.imu.preint_batch.preintegrate` (same knots, held values,
boundary splitting and gap rule, see :mod:`imu_ground.imu.preintegration`) and
integrates each interval with the same scalar kernel as
:class:`~imu_ground.imu.preint_measurement.PreintegratedImu`
(:func:`~imu_ground.imu.preint_kernel.integrate`).

``push`` is one compiled call per sample (:func:`push_step`, through :mod:`imu_ground._jit`):
the state and the bookkeeping live in one float64 buffer (layout ``_S_*``); the compiled
step integrates inside frames and splits the sample interval at rate or frame_times
boundaries (writing the finished frames' states to a second buffer); the first sample,
gaps, every-N boundaries and errors go through :meth:`StreamingPreintegrator._push_slow`
on the attributes, which reads and writes the same buffer around its work.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from imu_ground._jit import njit
from imu_ground.imu.preint_frames import first_rate_boundary
from imu_ground.imu.preint_kernel import DELTAS_IDENTITY, UNCERTAINTY_ZERO, integrate
from imu_ground.imu.preint_measurement import PreintegratedImu
from imu_ground.imu.preint_params import PreintegrationParams, gap_message
from imu_ground.imu.warm_start import STATE_VERSION, StateError, StateReader, pack_state, unpack_state

__all__ = ["StreamingPreintegrator"]

_INF = math.inf

# The state buffer (offsets in floats): deltas (11) and uncertainty (90), then the bookkeeping
_S_UNC, _S_PREV, _S_LIM, _S_MAXGAP, _S_CD, _S_BIAS, _S_NOISE, _S_MIDPOINT, _S_UNCERTAINTY = (
    11, 101, 108, 109, 110, 111, 117, 119, 120)
_S_K, _S_NEXT, _S_ACTIVE, _S_N, _S_MARK, _S_TSTART, _S_VALID = 121, 122, 123, 124, 125, 126, 127
_S_TOL, _S_MODE, _S_RATE, _S_ORIGIN, _S_SIZE = 128, 129, 130, 131, 132
# (_S_PREV: t, gyro (3), accel (3) of the last sample, bias removed; _S_MODE: boundaries every-N 0, rate 1,
# frame_times 2; _S_N: intervals integrated by the boundary path in this frame; _S_MARK: _S_CD at its start)
# A finished frame's row of the frames buffer: deltas, uncertainty, then these
_O_N, _O_TSTART, _O_TEND, _O_VALID, _O_SIZE = 101, 102, 103, 104, 105
#: Frames one compiled push can finish (more: the Python path).
_O_ROWS = 16
_from_state = PreintegratedImu.from_state


@njit
def _integrate(b: np.ndarray, dt: float, x: float, y: float, z: float, fx: float, fy: float, fz: float) -> None:
    """:func:`~imu_ground.imu.preint_kernel.integrate` on the state buffer (its one call site here)."""
    u = b[_S_UNC:_S_PREV] if b[_S_UNCERTAINTY] != 0.0 else b[_S_UNC:_S_UNC]
    integrate(b[0:_S_UNC], u, dt, x, y, z, fx, fy, fz, b[_S_NOISE], b[_S_NOISE + 1])


@njit
def _integrate_piece(b: np.ndarray, dt: float, ka: np.ndarray, kb: np.ndarray) -> None:
    """One piece of length ``dt`` (s) between knots with bias-free values ``ka`` and ``kb`` (6: rad/s, m/s^2):
    held at their mean (midpoint) or at ``ka`` (left)."""
    if b[_S_MIDPOINT] != 0.0:
        hh = 0.5 * dt
        _integrate(b, dt, (ka[0] + kb[0]) * hh, (ka[1] + kb[1]) * hh, (ka[2] + kb[2]) * hh,
                   (ka[3] + kb[3]) * hh, (ka[4] + kb[4]) * hh, (ka[5] + kb[5]) * hh)
    else:
        _integrate(b, dt, ka[0] * dt, ka[1] * dt, ka[2] * dt, ka[3] * dt, ka[4] * dt, ka[5] * dt)


@njit
def _boundary_after(b: np.ndarray, times: np.ndarray, k: float) -> float:
    """Time of boundary ``k`` (rate or frame_times mode), s; inf past the last frame time."""
    if b[_S_MODE] == 2.0:
        return times[int(k)] if k < times.size else math.inf
    return b[_S_ORIGIN] + k / b[_S_RATE]


@njit
def _cross_boundary(b: np.ndarray, times: np.ndarray, out: np.ndarray, nout: int, tb: float) -> int:
    """A boundary at ``tb`` (rate or frame_times): the running frame's state into row ``nout`` of ``out``,
    the next frame started; returns the rows written so far."""
    if b[_S_ACTIVE] != 0.0:
        out[nout, 0:_S_PREV] = b[0:_S_PREV]
        out[nout, _O_N] = b[_S_N] + b[_S_MARK] - b[_S_CD]
        out[nout, _O_TSTART] = b[_S_TSTART]
        out[nout, _O_TEND] = tb
        out[nout, _O_VALID] = b[_S_VALID]
        nout += 1
    k = b[_S_K] + 1.0
    nxt = _boundary_after(b, times, k)
    b[_S_K] = k
    b[_S_NEXT] = nxt
    b[_S_ACTIVE] = 1.0 if nxt != math.inf else 0.0
    b[_S_LIM] = nxt - b[_S_TOL] if nxt != math.inf else -math.inf
    b[0:_S_PREV] = 0.0
    b[1] = 1.0                                  # identity quaternion
    b[_S_N] = 0.0
    b[_S_MARK] = b[_S_CD]
    b[_S_TSTART] = tb
    b[_S_VALID] = 1.0
    return nout


@njit
def push_step(b: np.ndarray, times: np.ndarray, out: np.ndarray, t: float, wx: float, wy: float, wz: float,
              ax: float, ay: float, az: float) -> int:
    """:meth:`StreamingPreintegrator.push` on the state buffer ``b``, where it takes the sample.

    Returns 0 when the sample was integrated inside a frame (no boundary, no gap, not an every-N
    sample), the number of frames it finished (their states in the rows of ``out``) when it crossed
    rate or frame_times boundaries without a gap (split there, midpoint values interpolated, as
    :meth:`StreamingPreintegrator._push_slow`), and -1, the buffer untouched, for everything else
    (first sample, gaps, every-N boundaries, errors: the Python path's).
    """
    t0 = b[_S_PREV]
    h = t - t0
    if t < b[_S_LIM]:                           # inside a frame (_S_LIM is -inf before the first sample)
        cd = b[_S_CD] - 1.0
        if not (0.0 < h <= b[_S_MAXGAP] and cd != 0.0):
            return -1
        b[_S_CD] = cd
        wx, wy, wz = wx - b[_S_BIAS], wy - b[_S_BIAS + 1], wz - b[_S_BIAS + 2]
        ax, ay, az = ax - b[_S_BIAS + 3], ay - b[_S_BIAS + 4], az - b[_S_BIAS + 5]
        gx, gy, gz, fx, fy, fz = b[_S_PREV + 1], b[_S_PREV + 2], b[_S_PREV + 3], b[_S_PREV + 4], b[_S_PREV + 5], \
            b[_S_PREV + 6]
        b[_S_PREV], b[_S_PREV + 1], b[_S_PREV + 2], b[_S_PREV + 3] = t, wx, wy, wz
        b[_S_PREV + 4], b[_S_PREV + 5], b[_S_PREV + 6] = ax, ay, az
        if b[_S_MIDPOINT] != 0.0:               # mean of the two samples, the 1/2 folded into dt
            hh = 0.5 * h
            _integrate(b, h, (gx + wx) * hh, (gy + wy) * hh, (gz + wz) * hh, (fx + ax) * hh, (fy + ay) * hh,
                       (fz + az) * hh)
        else:                                   # the left sample's value
            _integrate(b, h, gx * h, gy * h, gz * h, fx * h, fy * h, fz * h)
        return 0
    if not (b[_S_MODE] != 0.0 and b[_S_ACTIVE] != 0.0 and 0.0 < h <= b[_S_MAXGAP]):
        return -1
    # boundaries inside (t0, t - tol], no gap: count them first (more than out holds: the Python path's)
    tol = b[_S_TOL]
    nxt, k, rows = b[_S_NEXT], b[_S_K], 0
    while nxt < t - tol:
        rows += 1
        k += 1.0
        nxt = _boundary_after(b, times, k)
    if abs(nxt - t) <= tol:
        rows += 1
    if rows > out.shape[0]:
        return -1
    k1 = np.empty(6)
    k1[0], k1[1], k1[2] = wx - b[_S_BIAS], wy - b[_S_BIAS + 1], wz - b[_S_BIAS + 2]
    k1[3], k1[4], k1[5] = ax - b[_S_BIAS + 3], ay - b[_S_BIAS + 4], az - b[_S_BIAS + 5]
    pv = b[_S_PREV + 1:_S_PREV + 7].copy()
    k0 = pv.copy()
    kb = np.empty(6)
    b[_S_PREV] = t
    b[_S_PREV + 1:_S_PREV + 7] = k1
    tk, nout = t0, 0
    while b[_S_NEXT] < t - tol:
        tb = b[_S_NEXT]
        if b[_S_MIDPOINT] != 0.0:
            wgt = (tb - t0) / h
            for i in range(6):
                kb[i] = pv[i] + (k1[i] - pv[i]) * wgt
        else:
            kb[:] = k0
        if b[_S_ACTIVE] != 0.0:
            _integrate_piece(b, tb - tk, k0, kb)
            b[_S_N] += 1.0
        nout = _cross_boundary(b, times, out, nout, tb)
        tk = tb
        k0[:] = kb
    if b[_S_ACTIVE] != 0.0:
        _integrate_piece(b, t - tk, k0, k1)
        b[_S_N] += 1.0
    if abs(b[_S_NEXT] - t) <= tol:
        nout = _cross_boundary(b, times, out, nout, b[_S_NEXT])
    return nout


class StreamingPreintegrator:
    """Sample-by-sample front-end: emits a finished :class:`PreintegratedImu` per frame.

    Frames are given by explicit boundary times, a frame rate, or a sample
    count, exactly as in :func:`~imu_ground.imu.preint_batch.preintegrate`, and
    the results are the same.

    Parameters
    ----------
    frame_times : iterable of float, optional
        Boundaries, s, strictly increasing; samples before the first are ignored.
    rate : float, optional
        Frame rate, Hz: boundaries ``t_origin + k / rate``, unbounded.
    every : int, optional
        A boundary at every ``every``-th sample, starting with the first.
    t_origin : float, optional
        First boundary for ``rate`` (default: the first sample's time), s.
    params : PreintegrationParams, optional
        Biases, noise densities, hold, gap rule, snapping, ``uncertainty``
        (False: deltas only, the fast choice for a filter that needs just
        ``delta_R``/``delta_v``).
    **options
        Fields of :class:`~imu_ground.imu.preint_params.PreintegrationParams`
        overriding ``params``.

    Notes
    -----
    A frame is emitted by the first sample at or after its end boundary (less
    ``snap_tol``), since the interval that straddles the boundary is needed.
    For speed pass Python floats (tuples or lists); numpy rows are converted
    with ``tolist()``. Each emitted frame has ``t_start``, ``t_end`` and
    ``valid`` set; its ``delta_R`` is ``R_{start<-end}`` (body frame at
    ``t_end`` -> body frame at ``t_start``). A sample rejected with ValueError
    (non-increasing time, gap with ``on_gap="raise"``) leaves the state unchanged.
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
        self._origin = None if t_origin is None else float(t_origin)
        self._bias = par.bias
        self._noise = par.noise
        self._max_gap = par.max_gap
        self._tol = par.snap_tol
        self._midpoint = par.hold == "midpoint"
        self._u0 = UNCERTAINTY_ZERO if par.uncertainty else None
        self._n = 0                         # intervals integrated by the slow path in this frame
        self._t_start, self._valid = math.nan, True
        self._prev: tuple | None = None     # (t, wx, wy, wz, ax, ay, az) of the last sample, bias removed
        self._cd = 1 << 52                  # samples until the next every-N boundary (exact as a float too)
        self._mark = self._cd               # _cd at the frame's start: the fast path's intervals are _mark - _cd
        self._k = 0                         # index of the next boundary
        self._next = _INF                   # time of the next boundary
        self._lim = -_INF                   # fast path while t < _lim (= _next - snap_tol, inside a frame)
        self._active = False                # inside a frame
        self._kernel_init()                 # kernel state: (deltas, uncertainty)

    # -- the state buffer -------------------------------------------------------
    def _kernel_init(self) -> None:
        b = self._b = np.zeros(_S_SIZE)
        b[0:11] = DELTAS_IDENTITY
        b[_S_MAXGAP], b[_S_TOL] = self._max_gap, self._tol
        b[_S_BIAS:_S_BIAS + 6] = self._bias
        b[_S_NOISE:_S_NOISE + 2] = self._noise
        b[_S_MIDPOINT] = 1.0 if self._midpoint else 0.0
        b[_S_UNCERTAINTY] = 0.0 if self._u0 is None else 1.0
        b[_S_MODE] = 0.0 if self._every is not None else (1.0 if self._rate is not None else 2.0)
        b[_S_RATE] = self._rate or 0.0
        self._tb = np.array(self._times or (), dtype=float)
        self._out = np.zeros((_O_ROWS, _O_SIZE))
        self._save()

    def _kernel_reset(self) -> None:
        self._b[0:_S_PREV] = 0.0
        self._b[1] = 1.0                    # identity quaternion

    def _kernel_state(self) -> tuple[tuple, tuple | None]:
        b = self._b
        return tuple(b[0:_S_UNC].tolist()), (None if self._u0 is None else tuple(b[_S_UNC:_S_PREV].tolist()))

    def _kernel_load(self, deltas: tuple, unc) -> None:
        self._b[0:11] = deltas
        if unc is not None:
            self._b[_S_UNC:_S_UNC + len(unc)] = unc
        self._save()

    def _integrate(self, dt: float, x: float, y: float, z: float, fx: float, fy: float, fz: float) -> None:
        _integrate(self._b, dt, x, y, z, fx, fy, fz)

    def _load(self) -> None:
        """Buffer -> attributes: what the compiled push changes."""
        b = self._b
        if self._prev is not None:
            self._prev = tuple(b[_S_PREV:_S_LIM].tolist())
        self._lim, cd = float(b[_S_LIM]), b[_S_CD]
        k, self._next, active, n, mark, self._t_start, valid = b[_S_K:_S_TOL].tolist()
        self._cd, self._k, self._n, self._mark = int(cd), int(k), int(n), int(mark)
        self._active, self._valid = active != 0.0, valid != 0.0

    def _save(self) -> None:
        """Attributes -> buffer: what the Python slow path changes and the compiled push reads."""
        b = self._b
        if self._prev is not None:
            b[_S_PREV:_S_LIM] = self._prev
        b[_S_LIM], b[_S_CD] = self._lim, float(self._cd)
        b[_S_K:_S_TOL] = (self._k, self._next, self._active, self._n, self._mark, self._t_start, self._valid)
        b[_S_ORIGIN] = math.nan if self._origin is None else self._origin

    def push(self, t: float, gyro: Sequence[float], accel: Sequence[float]) -> tuple[PreintegratedImu, ...]:
        """Add one sample; return the frames finished by it (usually none, or one).

        Parameters
        ----------
        t : float
            Sample time, s (strictly increasing).
        gyro : sequence of 3 floats
            Angular rate, rad/s, body frame.
        accel : sequence of 3 floats
            Specific force, m/s^2, body frame.

        Returns
        -------
        tuple of PreintegratedImu
            Finished frames (usually an empty tuple), each with ``t_start``,
            ``t_end``, ``valid``; ``delta_R`` of each is ``R_{start<-end}``.
        """
        try:
            wx, wy, wz = gyro
            ax, ay, az = accel
            done = push_step(self._b, self._tb, self._out, float(t), float(wx), float(wy), float(wz),
                         float(ax), float(ay), float(az))
        except (TypeError, ValueError):         # not three numbers each: the Python path says so
            done = -1
        if done == 0:
            return ()
        if done > 0:                            # boundaries crossed: the finished frames' states
            return self.finished_frames(done)
        if isinstance(gyro, np.ndarray):
            gyro = gyro.tolist()
        if isinstance(accel, np.ndarray):
            accel = accel.tolist()
        self._load()
        out = self._push_slow(float(t), gyro, accel)
        self._save()
        return out

    @property
    def step_buffers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(state, frame_times, frames)``: the float64 buffers :func:`push_step` runs on (for a caller that
        runs it inside its own compiled step); a positive answer of it is read with :meth:`finished_frames`."""
        return self._b, self._tb, self._out

    def finished_frames(self, n: int) -> tuple[PreintegratedImu, ...]:
        """The ``n`` frames :func:`push_step` just finished (the first ``n`` rows of the frames buffer)."""
        par, unc = self.params, self._u0 is not None
        frames = []
        for row in self._out[:n].tolist():
            frames.append(_from_state(par, tuple(row[0:_S_UNC]), tuple(row[_S_UNC:_S_PREV]) if unc else None,
                                      int(row[_O_N]), row[_O_TSTART], row[_O_TEND], row[_O_VALID] != 0.0))
        return tuple(frames)

    # settings, read-only views of params
    hold = property(lambda self: self.params.hold, doc="``'midpoint'`` or ``'left'``.")
    max_gap = property(lambda self: self.params.max_gap, doc="Longest sample step, s, that is not a gap.")
    on_gap = property(lambda self: self.params.on_gap, doc="``'raise'`` or ``'flag'``.")
    snap_tol = property(lambda self: self.params.snap_tol, doc="Boundary snapping tolerance, s.")

    def set_gyro_bias(self, bx: float, by: float, bz: float) -> None:
        """Remove this gyro bias (rad/s, body frame) from the samples from the next one on, in place of
        ``params.bias``'s (a live estimate that changes as the stream goes; the accelerometer's stays). Not part
        of :meth:`state_dict`: the caller that sets it sets it again after a :meth:`load_state_dict`."""
        self._bias = (float(bx), float(by), float(bz), *self._bias[3:])
        self._b[_S_BIAS:_S_BIAS + 3] = self._bias[:3]       # (the compiled push reads its copy in the buffer)

    @property
    def current(self) -> PreintegratedImu:
        """A snapshot of the frame being integrated (``t_end`` nan)."""
        self._load()
        return PreintegratedImu.from_state(self.params, *self._kernel_state(), self._n + self._mark - self._cd,
                                           self._t_start, math.nan, self._valid)

    # -- warm start ---------------------------------------------------------
    # The state is the frame being integrated (deltas and, with ``uncertainty``, their covariance and
    # Jacobians, as the kernel holds them) and the bookkeeping of the sample stream (last sample, next
    # boundary, counts); the settings are the frame boundaries and the PreintegrationParams. A stream stopped
    # after any sample and resumed from its state emits the frames of the uninterrupted stream.
    _INTS = ("_n", "_cd", "_mark", "_k")
    _FLOATS = ("_t_start", "_next", "_lim")

    def _settings(self) -> dict:
        return {"frame_times": self._times, "rate": self._rate, "every": self._every,
                "params": dataclasses.asdict(self.params)}

    def state_dict(self) -> dict:
        """The state as a plain, JSON-serialisable dict (:mod:`imu_ground.imu.warm_start`); resume with
        :meth:`load_state_dict` on a preintegrator built with the same settings."""
        self._load()                                # (the buffer -> the attributes)
        deltas, unc = self._kernel_state()
        st = {name: getattr(self, name) for name in self._INTS + self._FLOATS}
        st.update(_valid=self._valid, _active=self._active, _origin=self._origin, prev=self._prev, deltas=deltas,
                  uncertainty=unc)
        return pack_state("StreamingPreintegrator", STATE_VERSION, self._settings(), st)

    def load_state_dict(self, state: dict) -> None:
        """Resume from a :meth:`state_dict`; another kind, layout or settings, or a corrupt state (entries
        not finite or of another shape), raises :class:`~imu_ground.imu.warm_start.StateError` (a ValueError)
        naming what is wrong, and the preintegrator is unchanged."""
        st = StateReader("StreamingPreintegrator",
                         unpack_state(state, "StreamingPreintegrator", STATE_VERSION, self._settings()))
        ints = {name: st.int(name) for name in self._INTS}
        floats = {"_t_start": st.float("_t_start", nan=True), "_next": st.float("_next", inf=True),
                  "_lim": st.float("_lim", inf=True)}
        valid, active, origin = st.bool("_valid"), st.bool("_active"), st.float("_origin", optional=True)
        prev = st.floats("prev", (7,), optional=True)
        deltas = st.floats("deltas", (11,))
        unc = st.floats("uncertainty", (None,), optional=True)
        if (unc is None) != (self._u0 is None) or (unc is not None and self._u0 is not None and len(unc) != len(self._u0)):
            raise StateError("the saved state and this preintegrator differ in uncertainty")
        for name, v in {**ints, **floats}.items():
            setattr(self, name, v)
        self._valid, self._active, self._origin = valid, active, origin
        self._prev = None if prev is None else tuple(prev.tolist())
        self._kernel_load(tuple(deltas.tolist()), None if unc is None else tuple(unc.tolist()))

    # -- boundaries ---------------------------------------------------------
    def _boundary(self, k: int) -> float:
        if self._times is not None:
            return self._times[k] if k < len(self._times) else _INF
        if self._rate is not None:
            assert self._origin is not None         # set with the first sample at the latest
            return self._origin + k / self._rate
        return _INF     # every-N boundaries are counted in samples

    def _cross(self, tb: float, out: list) -> None:
        """A boundary at tb: emit the running frame, start the next if there is one."""
        if self._active:
            out.append(PreintegratedImu.from_state(self.params, *self._kernel_state(), self._n + self._mark - self._cd,
                                                   self._t_start, tb, self._valid))
        self._k += 1
        self._next = self._boundary(self._k)
        self._active = self._every is not None or self._next != _INF
        self._lim = self._next - self._tol if self._active else -_INF
        self._kernel_reset()
        self._n, self._mark = 0, self._cd
        self._t_start, self._valid = tb, True

    def _piece(self, dt: float, ka: tuple, kb: tuple, gap: bool) -> None:
        """Integrate a piece of length dt between knots with (bias-free) values ka and kb."""
        if gap:
            self._valid = False
        if self._midpoint:
            hh = 0.5 * dt
            self._integrate(dt, (ka[0] + kb[0]) * hh, (ka[1] + kb[1]) * hh, (ka[2] + kb[2]) * hh,
                            (ka[3] + kb[3]) * hh, (ka[4] + kb[4]) * hh, (ka[5] + kb[5]) * hh)
        else:
            self._integrate(dt, ka[0] * dt, ka[1] * dt, ka[2] * dt, ka[3] * dt, ka[4] * dt, ka[5] * dt)
        self._n += 1

    def _start(self, t: float, out: list) -> None:
        """The first sample: place the first boundary."""
        tol = self._tol
        if self._every is not None:
            self._cross(t, out)
            self._cd = self._mark = self._every
            return
        if self._rate is not None:
            if self._origin is None:
                self._origin = t
            self._k = first_rate_boundary(t, self._rate, self._origin, tol)   # as make_frame_times
        self._next = self._boundary(self._k)
        self._lim = -_INF
        if self._next < t - tol:
            raise ValueError(f"frame boundary {self._next!r} s is before the first sample at {t!r} s")
        if abs(self._next - t) <= tol:
            self._cross(self._next, out)

    def _push_slow(self, t: float, gyro: Sequence[float], accel: Sequence[float]) -> tuple:
        try:
            wx, wy, wz = gyro
            ax, ay, az = accel
        except ValueError:
            raise ValueError(f"gyro and accel must have 3 values each, got {gyro!r}, {accel!r}") from None
        bgx, bgy, bgz, bax, bay, baz = self._bias
        sample = (t, float(wx) - bgx, float(wy) - bgy, float(wz) - bgz,
                  float(ax) - bax, float(ay) - bay, float(az) - baz)
        out: list[PreintegratedImu] = []
        prev = self._prev
        tol = self._tol
        if prev is None:
            self._start(t, out)
            self._prev = sample
            return tuple(out)
        t0 = prev[0]
        h = t - t0
        if not h > 0.0:
            raise ValueError(f"IMU timestamps must be strictly increasing: got t = {t!r} s after "
                             f"{t0!r} s; drop non-increasing samples upstream (validation)")
        gap = h > self._max_gap
        if gap and self.params.on_gap == "raise" and (self._active or self._next < t - tol):
            raise ValueError(gap_message(t0, h, self._max_gap))
        self._prev = sample
        # boundaries strictly inside (t0, t - tol): split the interval there
        tk, k0, k1 = t0, prev[1:], sample[1:]
        while self._next < t - tol:
            tb = self._next
            if self._midpoint:
                wgt = (tb - t0) / h
                _, g0, g1, g2, f0, f1, f2 = prev
                kb = (g0 + (sample[1] - g0) * wgt, g1 + (sample[2] - g1) * wgt, g2 + (sample[3] - g2) * wgt,
                      f0 + (sample[4] - f0) * wgt, f1 + (sample[5] - f1) * wgt, f2 + (sample[6] - f2) * wgt)
            else:
                kb = k0
            if self._active:
                self._piece(tb - tk, k0, kb, gap)
            self._cross(tb, out)
            tk, k0 = tb, kb
        if self._active:
            self._piece(t - tk, k0, k1, gap)
        if self._every is not None:
            self._cd -= 1
            self._mark -= 1                 # not a fast-path interval
            if self._cd == 0:
                self._cross(t, out)
                self._cd = self._mark = self._every
        elif abs(self._next - t) <= tol:
            self._cross(self._next, out)
        return tuple(out)
