"""Live: raw IMU samples and wheel speed in, per-frame ground estimates out, causal (:class:`StreamingEstimator`).

The object a vehicle-side stack feeds from its driver callbacks; :func:`causal_track`
(``estimate_log(..., causal=True)``, ``imu-ground estimate --causal``) feeds it a recorded log.
Per sample, each piece one class:

1. **Clock** (:class:`~imu_ground.imu.live.sample_clock.SampleClock`): raw stamps to strictly
   increasing sample times (jitter retimed, back-steps and repeats by the ``retime`` or ``drop``
   policy, dropouts kept as gaps; one stamp far off the clock is a bad sample, dropped and said; three
   agreeing ones are a new clock: a dropout, or a restart when set back by more than a gap or forward
   by more than :data:`MAX_GAP_FRAMES` frames). The stamps' unit (s, ms, us, ns) is told from each
   warm-up as the readers tell it (``time_unit`` gives it); a warm-up whose period is over
   :data:`MAX_SAMPLE_PERIOD` is skipped. Each is said.
2. **Standstill and gyro bias** (:mod:`imu_ground.imu.live.causal_standstill`): a frame ends at a
   standstill when its trailing 1 s window is quiet, or when it is quiet alone and leads into such a
   window (held until that window passes, at most 0.9 s); the bias is the mean rate over the 2 s
   standstill windows seen so far (or given, or from a saved state), applied from the next sample.
3. **Preintegration** (:class:`~imu_ground.imu.preintegration.StreamingPreintegrator`): frames
   at ``rate`` Hz from the first sample, gaps flagged and integrated through.
4. **Speed over the frame** (:class:`~imu_ground.imu.live.speed_buffer.SpeedBuffer`): a frame
   waits for a speed sample at or after its end, :data:`SPEED_WAIT` s of IMU time or as long as the
   speed's measured latency needs (at most :data:`MAX_SPEED_WAIT`), then runs IMU only and says so;
   a stream that never sent a speed does not wait. A speed in km/h is told from the data
   (:class:`~imu_ground.pipeline.live_speed.SpeedUnit`), said and converted.
5. **Filter**: the method's streaming ``step`` (``on_invalid="skip"``).

After the warm-up, steps 1-3 are one compiled call a sample (:func:`_front_step`); a sample that opens
a block, a stamp far off the clock and the preintegrator's gaps go on in Python.

Data never raise: a non-finite sample, a dropped or retimed stamp, a restart, a late, repeated or
non-finite speed sample, each is said in the next frame's ``status_reason``. Misuse (a 3x3 array as
``gyro``, a string as ``t``) raises :class:`~imu_ground.errors.OptionError` naming the argument.
"""
from __future__ import annotations

import math
import numbers
from collections import deque
from typing import Any

import numpy as np

from imu_ground._jit import njit
from imu_ground.errors import OptionError
from imu_ground.imu.live.speed_buffer import SpeedBuffer
from imu_ground.filters import Extrinsic
from imu_ground.filters.estimator import GroundEstimate
from imu_ground.filters.methods import METHODS, default_method, live_methods, recalibrating_methods
from imu_ground.imu.live.causal_standstill import CausalGyroBias, StandstillBlocks, add_sample, block_index, open_row
from imu_ground.imu.egomotion import EgoFrame
from imu_ground.imu.live.preint_stream import push_step
from imu_ground.imu.preintegration import StreamingPreintegrator
from imu_ground.imu.live.sample_clock import DROP, FAR, OK, SampleClock, clock_step
from imu_ground.pipeline.live_replay import frames_track, replay
from imu_ground.pipeline.live_speed import MAX_SPEED_WAIT, NO_SPEED, SpeedLatency, SpeedUnit
from imu_ground.pipeline.live_state import MAX_RECORDS, pack, unpack
from imu_ground.so3 import quat_from_matrix
from imu_ground.units import MAX_GAP_FRAMES        # a forward step longer than this restarts the front end

__all__ = ["LIVE_METHODS", "MAX_FRAME_RATE", "MAX_GAP_FRAMES", "MAX_SAMPLE_PERIOD", "MAX_SPEED_WAIT", "SPEED_WAIT",
           "FrameEstimate",
           "StreamingEstimator", "causal_track", "estimate_row", "replay"]

#: Methods that run live (``"auto"`` is ``"suspension"``): the registry's
#: :func:`~imu_ground.filters.methods.live_methods` at import (the checks ask the registry itself).
LIVE_METHODS = live_methods()
#: Least time a frame waits for a speed sample at or after its end, s of IMU time (module docstring, step 4).
SPEED_WAIT = 0.25
#: The highest frame rate, Hz (the IMU's rate is not known before the samples come).
MAX_FRAME_RATE = 1000.0
#: A warm-up whose sample period is longer than this, s, is not an IMU's (stamps not in seconds): skipped, said.
MAX_SAMPLE_PERIOD = 1.0
_STATE_KIND = "imu_ground.StreamingEstimator"
_STATE_VERSION = 1
_UNDECIDED = "undecided"                                # a frame's speed not decided yet
# _front_step's answers beside push_step's (0: integrated, n > 0: frames finished, -1: its Python path to run)
_NOT_TAKEN, _DROPPED, _NEW_BLOCK = -4, -3, -2


@njit
def _front_step(clock: np.ndarray, blocks: np.ndarray, open_k: int, pre: np.ndarray, times: np.ndarray,
                frames: np.ndarray, origin: float, rate: float, t: float, g0: float, g1: float, g2: float,
                a0: float, a1: float, a2: float) -> int:
    """Steps 1-3 of one sample after the warm-up: ``push_step``'s answer, or :data:`_NOT_TAKEN` (non-finite or far
    off the clock: nothing changed), :data:`_DROPPED`, :data:`_NEW_BLOCK` (the clock's step done, the rest in
    Python)."""
    if not (math.isfinite(t) and math.isfinite(g0 + g1 + g2 + a0 + a1 + a2)):
        return _NOT_TAKEN
    code = clock_step(clock, t)
    if code == FAR:
        return _NOT_TAKEN
    if code == DROP:
        return _DROPPED
    tout = clock[0]
    k = block_index(tout, origin, rate)
    if k >= 0:
        if k != open_k:
            return _NEW_BLOCK
        add_sample(blocks[k % blocks.shape[0]], g0, g1, g2, a0, a1, a2)
    return push_step(pre, times, frames, tout, g0, g1, g2, a0, a1, a2)


@njit
def _block_step(ring: np.ndarray, keys: np.ndarray, k: int, pre: np.ndarray, times: np.ndarray, frames: np.ndarray,
                t: float, g0: float, g1: float, g2: float, a0: float, a1: float, a2: float) -> int:
    """Steps 2-3 of a sample :func:`_front_step` left at :data:`_NEW_BLOCK` (output time ``t``, s; in block ``k``):
    the block opened (:func:`open_row`), the sample summed there, then ``push_step``'s answer; :data:`_NEW_BLOCK`,
    nothing changed, when the blocks' ring must grow first (in Python)."""
    i = open_row(ring, keys, k)
    if i < 0:
        return _NEW_BLOCK
    add_sample(ring[i], g0, g1, g2, a0, a1, a2)
    return push_step(pre, times, frames, t, g0, g1, g2, a0, a1, a2)


class FrameEstimate(GroundEstimate):
    """A :class:`~imu_ground.filters.estimator.GroundEstimate` with its frame and what the live front end saw.

    Attributes (besides those of ``GroundEstimate``)
    ------------------------------------------------
    t : float
        Frame (end) time, s, on the sample clock.
    valid : bool
        False for a frame that spans a gap or that the filter skipped (as a track's ``valid``).
    t_start : float
        Frame start, s.
    speed : float
        Measured speed used for the frame, m/s (NaN: IMU only).
    notes : tuple of str
        What the front end says about the frame (skipped samples, retimed stamps, a restart,
        speed); appended to ``status_reason``.
    plane : ndarray (4,) or None
        With a camera: the road plane ``a b c d`` in the camera's axes (NaN when not valid).
    """
    __slots__ = ("t", "t_start", "speed", "notes", "_camera", "_plane")
    t: float
    t_start: float
    speed: float
    notes: tuple
    _camera: Any
    _plane: np.ndarray | None

    @classmethod
    def of(cls, est: GroundEstimate, t: float, t_start: float, speed: float, notes: tuple,
           camera: Any = None, frame_valid: bool = True) -> "FrameEstimate":
        """``est`` with the frame's times, speed, notes and camera; ``valid`` also False for a frame that spans
        a gap (``frame_valid``), as in a track."""
        out = cls.copy_of(est)                       # a value copy of the filter's estimate (its __slots__)
        out.valid = bool(est.valid and frame_valid)
        out.t, out.t_start, out.speed, out.notes = t, t_start, speed, notes
        out._camera, out._plane = camera, None
        return out

    @property
    def status_reason(self) -> str:
        base = super().status_reason
        return "; ".join([base, *self.notes] if base else self.notes)

    @property
    def plane(self) -> np.ndarray | None:
        if self._camera is None:
            return None
        if self._plane is None:
            from imu_ground.pipeline.planes import camera_plane
            self._plane = camera_plane(self.residual[None], [self.valid], self._camera).coefficients[0]
        return self._plane

    def __repr__(self) -> str:
        return (f"FrameEstimate(t={self.t!r}, pitch={self.pitch!r}, roll={self.roll!r}, valid={self.valid!r}, "
                f"status={self.status!r})")


def estimate_row(est: FrameEstimate) -> dict[str, Any]:
    """The output table's columns (:data:`imu_ground.pipeline.output.COLUMNS`, angles in degrees) of one estimate;
    with a camera also ``plane_a`` ... ``plane_d`` before ``valid``."""
    n = est.normal
    q = quat_from_matrix(est.residual)
    deg = math.degrees
    row: dict[str, Any] = {"t": est.t, "normal_x": float(n[0]), "normal_y": float(n[1]), "normal_z": float(n[2]),
                           "pitch_deg": deg(est.pitch), "roll_deg": deg(est.roll),
                           "qw": float(q[0]), "qx": float(q[1]), "qy": float(q[2]), "qz": float(q[3])}
    if est.plane is not None:
        row.update(zip(("plane_a", "plane_b", "plane_c", "plane_d"), (float(x) for x in est.plane), strict=True))
    row["valid"] = bool(est.valid)
    for name in ("pitch_std", "roll_std", "road_grade", "road_bank", "road_grade_std", "road_bank_std"):
        row[f"{name}_deg"] = deg(getattr(est, name))
    row["status"], row["status_reason"] = est.status, est.status_reason
    return row


# ------------------------------------------------------------------------------------------ checks
def _number(x: Any, name: str) -> float:
    if isinstance(x, float) or (isinstance(x, numbers.Real) and not isinstance(x, bool)) or (
            isinstance(x, np.ndarray) and x.shape == () and x.dtype.kind in "fiu"):
        return float(x)
    raise OptionError(f"{{opt}} must be a number (s or m/s), got {type(x).__name__} {x!r:.40}", name)


def _vec3(x: Any, name: str) -> tuple:
    if type(x) is np.ndarray:
        if x.shape != (3,) or x.dtype.kind not in "fiu":
            raise OptionError(f"{{opt}} must be 3 numbers, got an array of shape {x.shape} and dtype {x.dtype}", name)
        return tuple(x.tolist())
    try:
        a, b, c = x
        return (a if type(a) is float else _number(a, name), b if type(b) is float else _number(b, name),
                c if type(c) is float else _number(c, name))
    except (TypeError, ValueError) as e:
        if isinstance(e, OptionError):
            raise OptionError(f"{{opt}} must be 3 numbers, got {x!r:.60}", name) from None
        raise OptionError(f"{{opt}} must be 3 numbers, got {type(x).__name__} {x!r:.60}", name) from None


def _live_method(method: str) -> str:
    name = default_method(True) if method == "auto" else method
    live = live_methods()
    if name not in live:
        raise OptionError(f"{{opt}} {method!r} does not run live; choose auto or one of {', '.join(live)}",
                          "method")
    return name


def _make_filter(name: str, ext: Extrinsic, rate: float, recalibrate_online: bool):
    kw: dict[str, Any] = {"extrinsic": ext, "on_invalid": "skip"}
    spec = METHODS[name]
    if "frame_rate" in spec.options:
        kw["frame_rate"] = rate
    if recalibrate_online:
        if name not in recalibrating_methods():
            raise OptionError(f"{{opt}} needs the {' or '.join(recalibrating_methods())} method, not {name}",
                              "recalibrate_online")
        kw["recalibrate_online"] = True
    return spec.make(**kw)


# ------------------------------------------------------------------------------------------ the object
class StreamingEstimator:
    """Raw IMU samples (and wheel speed) in, per-frame ground estimates out, causal (module docstring).

    Parameters
    ----------
    method : str
        ``"auto"`` (the suspension-aware filter) or one of :data:`LIVE_METHODS`.
    extrinsic : str, Path, Extrinsic or ndarray (3, 3), optional
        Static ground <- sensor extrinsic (a shipped name such as ``kitti_imu``, a
        calibration file, ...; :func:`~imu_ground.filters.extrinsics.load_extrinsic`). Identity when None.
    rate : float
        Frame rate, Hz; frames at ``t0 + k / rate`` from the first sample.
    camera : str, Path or Camera, optional
        A camera on the platform: each estimate's ``plane`` is the road plane in its axes.
    bias_gyro : "auto" or sequence of 3 floats
        ``"auto"``: from the standstills seen so far; else this bias, rad/s.
    policy : {"retime", "drop"}
        Stamps that step back or repeat (:class:`~imu_ground.imu.live.sample_clock.SampleClock`).
    speed_wait : float
        Longest a frame waits for a speed sample at or after its end, s of IMU time.
    recalibrate_online : bool
        Re-estimate a moved mount online (suspension method).
    time_unit : {None, "s", "ms", "us", "ns"}
        The unit of the stamps ``t`` (IMU and speed). None: told from the data at each warm-up of the
        clock, as the readers do (:func:`~imu_ground.datasets.unit_checks.detect_time_unit`: the rate and
        epoch-sized values), said in the next frame; the frames are then those of the stamps in seconds.

    Notes
    -----
    ``push_imu`` returns the frames the sample completes, in time order (usually none; a frame
    waits for its speed at most ``speed_wait``). Time ``t`` is seconds on any clock, the IMU's
    and the speed's the same one. ``state_dict`` / ``load_state_dict`` save and resume
    everything (JSON-serialisable); the rest of the stream is then bit-identical.
    """
    # the settings and parts (set in __init__), declared for mypy (the methods' uses come before __init__'s)
    method: str
    rate: float
    speed_wait: float
    extrinsic: Extrinsic
    camera: Any
    recalibrate_online: bool
    policy: str
    speed_aided: bool
    _bias_arg: Any
    _clock: SampleClock
    _filter: Any                        # the method's estimator (METHODS[method].make)

    def __init__(self, method: str = "auto", extrinsic: Any = None, rate: float = 10.0, camera: Any = None, *,
                 bias_gyro: Any = "auto", policy: str = "retime", speed_wait: float = SPEED_WAIT,
                 recalibrate_online: bool = False, time_unit: str | None = None) -> None:
        self.method = _live_method(method)
        if time_unit is not None:
            from imu_ground.datasets.unit_checks import unit_scale
            self._tscale0 = unit_scale("time", time_unit)
        else:
            self._tscale0 = 1.0
        self.time_unit = time_unit
        if not (isinstance(rate, numbers.Real) and math.isfinite(rate) and rate > 0):
            raise OptionError(f"{{opt}} must be a positive frame rate in Hz, got {rate!r}", "rate")
        if rate > MAX_FRAME_RATE:
            raise OptionError(f"{{opt}} {rate:g} Hz is above the live path's highest frame rate of "
                              f"{MAX_FRAME_RATE:g} Hz", "rate")
        if not (isinstance(speed_wait, numbers.Real) and speed_wait >= 0):
            raise OptionError(f"{{opt}} must be a non-negative time in s, got {speed_wait!r}", "speed_wait")
        self.rate, self.speed_wait = float(rate), float(speed_wait)
        self.extrinsic = Extrinsic.coerce(extrinsic)
        self._ext_name = None if extrinsic is None else str(getattr(extrinsic, "name", extrinsic))
        self.camera = None
        if camera is not None:
            from imu_ground.pipeline.planes import check_camera
            self.camera = check_camera(camera, None)[0]
        self.recalibrate_online = bool(recalibrate_online)
        self._bias_arg = bias_gyro
        CausalGyroBias(bias_gyro)                        # checks it
        self.policy = policy
        self._clock = SampleClock(policy, max_jump=MAX_GAP_FRAMES / self.rate)
        self.speed_aided = bool(METHODS[self.method].speed_aided)
        self._filter = _make_filter(self.method, self.extrinsic, self.rate, self.recalibrate_online)
        self._egos: list | None = None                  # the frames stepped, kept by run
        self.reset()

    # -- state ---------------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to the start: clock, standstill window, gyro bias, speed, filter."""
        self._clock.reset()
        self._tscale = self._tscale0                    # seconds per unit of the stamps given
        self._scaled = self._tscale != 1.0
        self._bias = CausalGyroBias(self._bias_arg)
        self._filter.reset()
        self._speed = SpeedBuffer()
        self._latency = SpeedLatency(self.speed_wait)
        self._vunit = SpeedUnit(self.rate)
        self._vscale = 1.0                              # m/s per unit of the speeds given (1 / 3.6: km/h)
        self._queue: deque = deque()                   # frames: [ego, t_start, notes, speed, held, scale, index]
        self._hold: deque = deque()                    # those held at a possible start of a stop
        self._notes: list[str] = []
        self._skipped = 0
        self._slow = [0, 0.0]                           # samples of too slow warm-ups skipped, the last one's period
        self._now = -math.inf
        self._new_run()

    def _new_run(self) -> None:
        """The front end after a (re)start (no preintegrator until the clock's warm-up is over)."""
        self._pre: StreamingPreintegrator | None = None
        self._warm: list = []
        self._origin = math.nan
        self._blocks = StandstillBlocks(self.rate)
        self._bias.new_blocks()

    @property
    def bias_gyro(self) -> np.ndarray:
        """The gyro bias in use, rad/s (body frame)."""
        return np.array(self._bias.value)

    @property
    def filter(self):
        """The ground estimator (its public state: ``state_dict``, settings)."""
        return self._filter

    # -- input ---------------------------------------------------------------------------------
    def push_speed(self, t: float, speed: float) -> None:
        """A measured forward speed (wheel / CAN), m/s, at time ``t`` (s, the IMU's clock); any rate and order."""
        t = t if type(t) is float else _number(t, "t")
        speed = speed if type(speed) is float else _number(speed, "speed")
        if self._scaled:
            t *= self._tscale
        if self.speed_aided:
            self._speed.push(t, speed if self._vscale == 1.0 else speed * self._vscale)
            note = self._latency.arrived(t, self._now)
            if note is not None:
                self._notes.append(note)

    def push_imu(self, t: float, gyro, accel) -> list[FrameEstimate]:
        """One IMU sample: time ``t`` (s), angular rate ``gyro`` (rad/s) and specific force ``accel`` (m/s^2),
        body frame; returns the frames it completes (usually none), oldest first."""
        if self._scaled:                                # stamps not in seconds (told at the warm-up): to seconds
            t = (t if type(t) is float else _number(t, "t")) * self._tscale
        if type(t) is not float:
            t = _number(t, "t")
        g = _vec3(gyro, "gyro")
        a = _vec3(accel, "accel")
        pre = self._pre
        if pre is not None:                             # after the warm-up: one compiled step
            blocks = self._blocks
            b, times, frames = pre.step_buffers
            r = _front_step(self._clock.buffer, blocks.ring, blocks.open_k,
                            b, times, frames, self._origin, self.rate, t, g[0], g[1], g[2], a[0], a[1], a[2])
            if r != _NOT_TAKEN:
                if r == _DROPPED:
                    return []
                tout = self._clock.t
                if r == _NEW_BLOCK:                     # the sample opens its block (k >= 0: _front_step's test)
                    k = block_index(tout, self._origin, self.rate)
                    ring, keys = blocks.buffers
                    r = _block_step(ring, keys, k, b, times, frames, tout, g[0], g[1], g[2], a[0], a[1], a[2])
                    if r == _NEW_BLOCK:                 # (the ring grows first)
                        self._feed(tout, g, a)
                        r = 0
                    else:
                        blocks.open_k = k
                if r != 0:
                    for f in pre.finished_motion(pre.push_counted(tout, g, a) if r < 0 else r):
                        self._frame(*f)
                self._now = tout
                q = self._queue                         # (frames whose speed is decided, held at a stop's start,
                return self._decide(tout) if q and (q[-1][3] is _UNDECIDED or not q[0][4]) else []   # wait)
        if not (math.isfinite(t) and math.isfinite(g[0] + g[1] + g[2] + a[0] + a[1] + a[2])):
            self._skipped += 1
            return []
        code, tout = self._clock.push(t)
        out: list[FrameEstimate] = []
        if code != OK:
            if code == DROP:
                return []
            self._release()
            out = self._decide(math.inf)                # RESTART: the frames so far, then start again
            jump = self._clock.last_jump
            self._notes.append(f"the clock {'stepped back' if jump > 0 else 'jumped forward'} by {abs(jump):.3f} s: "
                               f"restarted at t = {tout:.3f} s")
            self._speed.clear()
            self._latency = SpeedLatency(self.speed_wait)
            self._new_run()
        if self._pre is None:
            self._warm.append((tout, g, a))
            if self._clock.warm:
                self._end_warmup()
                if self._pre is not None:
                    tout = self._clock.t                # (on seconds, when the unit was told)
        else:
            self._feed(tout, g, a)
        self._now = tout
        if self._queue:
            out += self._decide(tout)
        return out

    def flush(self) -> list[FrameEstimate]:
        """The end of the stream: the frames still waiting for a speed, decided with what has arrived (those held at
        a possible start of a stop: moving)."""
        self._release()
        return self._decide(math.inf)

    # -- the front end -------------------------------------------------------------------------
    def _end_warmup(self) -> None:
        """The warm-up is over: the stamps' unit told (module docstring, step 1), then the frames start."""
        if self.time_unit is None:
            from imu_ground.datasets.unit_checks import TIME_UNITS, detect_time_unit
            from imu_ground.errors import ImuGroundError
            try:
                unit, note = detect_time_unit(np.array([w[0] / self._tscale for w in self._warm]), "IMU stream", "t")
            except ImuGroundError:
                unit = None
            if unit is not None and TIME_UNITS[unit] != self._tscale:
                self._rescale(TIME_UNITS[unit], "IMU stamps in seconds again (told from the data)" if note is None else
                              note.split(" (pass")[0].replace("IMU stream: time column 't' read", "IMU stamps read")
                              + ": converted to seconds (pass time_unit to say so)")
        if self._clock.dt > MAX_SAMPLE_PERIOD:
            self._slow = [self._slow[0] + len(self._warm), self._clock.dt]
            self._clock.reset()
            self._warm = []
            return
        warm, self._warm = self._warm, []
        self._origin = warm[0][0]
        self._pre = StreamingPreintegrator(rate=self.rate, t_origin=self._origin, max_gap=self._clock.max_gap,
                                           on_gap="flag", uncertainty=False)
        self._pre.set_gyro_bias(*self._bias.value)     # the preintegrator removes the causal bias
        for w in warm:
            self._feed(*w)

    def _rescale(self, scale: float, note: str) -> None:
        """The stamps are in another unit (``scale`` s each): the warm-up and the speed samples again on seconds."""
        factor = scale / self._tscale
        self._tscale, self._scaled = scale, scale != 1.0
        clock = self._clock
        clock.reset(keep_counts=True)
        warm, self._warm = self._warm, []
        for tw, g, a in warm:
            self._warm.append((clock.push(tw * factor)[1], g, a))
        self._speed.rescale(factor)
        self._latency = SpeedLatency(self.speed_wait)  # (latencies measured in the other unit)
        self._notes.append(note)

    def _kmh(self, notes: list) -> float:
        """The speed is in km/h: converted from now on, the filter run again since its first speed; the factor."""
        unit, k = self._vunit, 1.0 / 3.6
        self._vscale = k
        sp = self._speed
        sp.v = [x * k for x in sp.v]
        again = unit.rerun(self._filter, k)
        notes.append(f"speed read as km/h from the data: it changes {unit.slope:.2f} times as fast as the "
                     f"accelerometer says over {unit.n} s of driving; converted to m/s"
                     + (f" (the filter run again over the {again} frames since its first speed)" if again >= 0
                        else " from here on"))
        return k

    def _feed(self, t: float, g: tuple, a: tuple) -> None:
        k = block_index(t, self._origin, self.rate)
        if k >= 0:
            self._blocks.add(k, g, a)
        assert self._pre is not None                    # after the warm-up
        pre = self._pre
        for f in pre.finished_motion(pre.push_counted(t, g, a)):
            self._frame(*f)

    def _frame(self, dR: np.ndarray, dv: np.ndarray, dt: float, t_start: float, t_end: float, valid: bool) -> None:
        """A frame finished (:meth:`StreamingPreintegrator.finished_motion`): its standstill tests, the gyro bias, then
        it waits in the queue for its speed (or is held at a possible start of a stop)."""
        j = round((t_end - self._origin) * self.rate) - 1
        blocks = self._blocks
        still, for_bias, quiet = blocks.frame_windows(j, self._bias.auto)
        quiet = quiet and not still
        if for_bias:
            self._bias.absorb(j, blocks.Wb, blocks.block)
            assert self._pre is not None                # a frame came from it
            self._pre.set_gyro_bias(*self._bias.value)  # from the next sample on
        blocks.done(j)
        entry = [EgoFrame(dR, dv, dt, still, valid, t_end), t_start,
                 self._take_notes(), _UNDECIDED, quiet, 1.0, j]
        hold = self._hold
        if still:                                       # a stop: the quiet frames before it were at rest too
            for e in hold:
                e[0], e[4] = e[0]._replace(stationary=True), False
            hold.clear()
        elif not quiet:
            self._release()
        else:                                           # perhaps the start of a stop: held (at most W - 1 frames)
            hold.append(entry)
        while hold and hold[0][6] <= j - (blocks.W - 1):
            hold.popleft()[4] = False                   # no stop within its window: moving
        self._queue.append(entry)

    def _release(self) -> None:
        """The frames held at a possible start of a stop go on as moving."""
        for e in self._hold:
            e[4] = False
        self._hold.clear()

    def _take_notes(self) -> list[str]:
        notes, self._notes = self._notes, []
        c = self._clock
        if self._skipped:
            notes.append(f"{self._skipped} non-finite IMU sample(s) skipped")
            self._skipped = 0
        if self._slow[0]:
            notes.append(f"IMU stamps step by {self._slow[1]:.3g} s, more than {MAX_SAMPLE_PERIOD:g} s: stamps not in "
                         f"seconds (ns, us, ms)? IMU samples skipped: {self._slow[0]}")
            self._slow = [0, 0.0]
        return notes + c.take_notes()

    def _decide(self, now: float) -> list[FrameEstimate]:
        """The frames' speeds as they come (or their wait ends); the filter over them up to one held at a stop."""
        q, sp = self._queue, self._speed
        for e in q:
            if e[3] is not _UNDECIDED:
                continue
            if not (self.speed_aided and sp.received):
                e[3] = None
                continue
            ego, ts, notes = e[0], e[1], e[2]
            te = ego.t
            kept = sp.t                                 # (sp.covers(te), inlined: this runs every sample a frame waits)
            wait = self._latency.wait
            if not ((kept and kept[-1] >= te) or now >= te + wait):
                break
            v = sp.mean(ts, te)
            notes += sp.take_notes()
            if math.isnan(v):
                notes.append(NO_SPEED if wait == self.speed_wait else self._latency.timed_out())
            sp.done(te)
            e[3], e[5] = v, self._vscale
        out = []
        while q and q[0][3] is not _UNDECIDED and not q[0][4]:
            ego, ts, notes, v, _, scale, _ = q.popleft()
            if v is not None:
                if scale != self._vscale:              # (decided before the speed was told to be km/h)
                    v = v * (self._vscale / scale)
                unit = self._vunit
                if unit.open and unit.frame(float(ego.delta_v[0]), v, self._filter, ego):
                    v = self._kmh(notes) * v           # the speed's unit told now: km/h
            est = self._filter.step(ego) if v is None and not self.speed_aided else self._filter.step(ego, speed=v)
            if self._egos is not None:
                self._egos.append(ego)
            out.append(FrameEstimate.of(est, ego.t, ts, math.nan if v is None else v, tuple(notes), self.camera,
                                        ego.valid))
        return out

    # -- warm start ----------------------------------------------------------------------------
    def _settings(self) -> dict:
        bias = self._bias_arg if isinstance(self._bias_arg, str) else [float(x) for x in
                                                                       np.asarray(self._bias_arg).ravel()]
        return {"method": self.method, "rate": self.rate, "extrinsic": self.extrinsic.rotation.ravel().tolist(),
                "bias_gyro": bias, "policy": self.policy, "speed_wait": self.speed_wait,
                "recalibrate_online": self.recalibrate_online, "time_unit": self.time_unit}

    def state_dict(self) -> dict[str, Any]:
        """Everything (clock, preintegrator, standstill window, gyro bias, speed, waiting frames, filter) as a
        JSON-serialisable dict (:mod:`~imu_ground.pipeline.live_state`); :meth:`load_state_dict` resumes."""
        queue = [[ego.delta_R.ravel().tolist(), ego.delta_v.tolist(), ego.delta_t, ego.stationary, ego.valid,
                  ego.t, ts, list(notes), v, held, scale, j] for ego, ts, notes, v, held, scale, j in self._queue]
        return {"kind": _STATE_KIND, "version": _STATE_VERSION, "settings": self._settings(),
                "clock": self._clock.state_dict(), "warm": [[t, *g, *a] for t, g, a in self._warm],
                "origin": None if math.isnan(self._origin) else self._origin,
                "preintegrator": None if self._pre is None else pack(self._pre.state_dict()),
                "max_gap": None if self._pre is None else self._pre.max_gap,
                "blocks": pack(self._blocks.state_dict()), "bias": self._bias.state_dict(),
                "speed": pack(self._speed.state_dict()), "queue": queue, "notes": list(self._notes),
                "skipped": self._skipped, "slow_warmups": list(self._slow), "now": None if self._now == -math.inf else self._now,
                "time_scale": self._tscale, "speed_latency": self._latency.state_dict(),
                "speed_unit": [self._vscale, self._vunit.state_dict()],
                "filter": pack(self._filter.state_dict())}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Resume from :meth:`state_dict`; a refused state leaves the estimator as it was.

        Raises
        ------
        OptionError
            Another kind, version or settings (naming ``state``).
        StateError
            A corrupt or out-of-range entry (:class:`~imu_ground.imu.warm_start.StateError`, naming it).
        """
        if not isinstance(state, dict) or state.get("kind") != _STATE_KIND:
            kind = state.get("kind") if isinstance(state, dict) else type(state).__name__
            raise OptionError(f"{{opt}} is not a StreamingEstimator state (kind {kind!r:.60})", "state")
        if state.get("version") != _STATE_VERSION:
            raise OptionError(f"{{opt}} has version {state.get('version')!r:.40}, this estimator reads "
                              f"{_STATE_VERSION}", "state")
        mine = self._settings()
        theirs = state.get("settings", {})
        theirs = theirs if isinstance(theirs, dict) else {}
        differ = sorted(k for k in mine if theirs.get(k) != mine[k])
        if differ:
            raise OptionError(f"{{opt}} was saved with other settings ({', '.join(differ)}): "
                              f"{', '.join(f'{k}={theirs.get(k)!r:.60}' for k in differ)}", "state")
        self.__dict__.update(self._read_state(state))  # every entry checked: raises before anything changes

    def _read_state(self, state: dict) -> dict[str, Any]:
        """The attributes ``state`` sets, every entry checked and built into new objects (the estimator unchanged);
        a corrupt entry raises :class:`~imu_ground.imu.warm_start.StateError` naming it. Entries older states lack
        (``time_scale``, ``speed_latency``, ``speed_unit``, ``slow_warmups``, a queue record's last four) take
        their defaults."""
        from imu_ground.datasets.unit_checks import TIME_UNITS
        from imu_ground.imu.live.sample_clock import WARMUP
        from imu_ground.imu.warm_start import StateError, StateReader
        r = StateReader("StreamingEstimator", state)

        def records(name: str, limit: int) -> list:
            value = r.state.get(name)
            if not isinstance(value, list):
                raise r.error(name, f"is {type(value).__name__}, expected a list")
            if len(value) > limit:
                raise r.error(name, f"holds {len(value)} records, more than {limit}")
            return value

        def packed(name: str) -> StateReader:
            return StateReader("StreamingEstimator", unpack(r.state.get(name), name), f"{name}.")

        def loaded(name: str, obj: Any, value: Any, layout: str = "") -> Any:
            try:
                obj.load_state_dict(value)
            except StateError as e:
                raise StateError(f"this StreamingEstimator state is corrupt in its entry {name}: {e}") from None
            except (KeyError, TypeError, ValueError, IndexError, AttributeError) as e:
                raise r.error(name, f"is not {layout} ({e})" if layout else
                              f"is damaged ({type(e).__name__}: {str(e)[:80]})") from None
            return obj

        # the clock, the stamps' unit, the warm-up
        clock = SampleClock(self.policy, max_jump=MAX_GAP_FRAMES / self.rate)
        clock.load_checked(r.part("clock"), MAX_SAMPLE_PERIOD)
        scale = r.float("time_scale") if r.has("time_scale") else 1.0
        if scale not in TIME_UNITS.values() or (self.time_unit is not None and scale != self._tscale0):
            raise r.error("time_scale", f"is {scale!r}, expected one of {sorted(set(TIME_UNITS.values()))}"
                                        f"{'' if self.time_unit is None else ' (that of time_unit)'}")
        warm = r.rows("warm", lambda x: [float(v) for v in x] if len(x) == 7 else [], 7)
        if len(warm) > WARMUP:
            raise r.error("warm", f"holds {len(warm)} samples, more than the warm-up's {WARMUP}")
        # the preintegrator (once the frames have started), the standstill blocks, the gyro bias
        origin = r.float("origin", optional=True)
        pre = None
        if r.has("preintegrator"):
            if math.isnan(clock.dt):
                raise r.error("clock.dt", "is NaN (a warm-up) where the frames have started (a preintegrator is saved)")
            if origin is None:
                raise r.error("origin", "is null where the frames have started (a preintegrator is saved)")
            max_gap, most = r.float("max_gap"), clock.gap_factor * MAX_SAMPLE_PERIOD
            if not 0 < max_gap <= most:
                raise r.error("max_gap", f"is {max_gap!r}, expected a positive time of at most {most:g} s")
            pre = StreamingPreintegrator(rate=self.rate, t_origin=origin, max_gap=max_gap, on_gap="flag",
                                         uncertainty=False)
            loaded("preintegrator", pre, unpack(state["preintegrator"], "preintegrator"))
            last = clock.t if pre.last_sample_time is None else pre.last_sample_time
            if not (abs(clock.t - last) <= max_gap and abs(pre.next_boundary - clock.t) <= 2.0 / self.rate + max_gap):
                raise r.error("clock.t", f"is {clock.t!r}, off the preintegrator's last sample ({last!r}) and next "
                                         f"frame end ({pre.next_boundary!r})")
        blocks = StandstillBlocks(self.rate)
        blocks.load_checked(packed("blocks"), MAX_RECORDS)
        bias = CausalGyroBias(self._bias_arg)
        bias.load_checked(r.part("bias"))
        if pre is not None:
            pre.set_gyro_bias(*bias.value)                  # (not in the preintegrator's state: the causal bias)
        # the speed: its samples, latency and unit
        speed = SpeedBuffer()
        speed.load_checked(packed("speed"), MAX_RECORDS)
        latency = SpeedLatency(self.speed_wait)
        if r.has("speed_latency"):
            loaded("speed_latency", latency, r.state["speed_latency"], "[wait, said, latencies, periods, last stamp]")
        vunit, vscale = SpeedUnit(self.rate), 1.0
        if r.has("speed_unit"):
            try:
                vscale, rec = r.state["speed_unit"]
            except (TypeError, ValueError) as e:
                raise r.error("speed_unit", f"is not [scale, check] ({e})") from None
            if vscale not in (1.0, 1.0 / 3.6):
                raise r.error("speed_unit", f"is not [scale, check] (scale {vscale!r})")
            loaded("speed_unit", vunit, rec, "[scale, check]")
        # the frames waiting: [ego, t_start, notes, speed, held, scale, index] (older states: the first five)
        queue: deque[list] = deque()
        for i, q in enumerate(records("queue", MAX_RECORDS)):
            name = f"queue[{i}]"
            if not (isinstance(q, list) and len(q) in (8, 12) and isinstance(q[3], bool) and isinstance(q[4], bool)
                    and isinstance(q[7], list) and all(isinstance(x, str) for x in q[7])):
                raise r.error(name, "is a record of another layout")
            v, held, vs, j = q[8:] if len(q) == 12 else (_UNDECIDED, False, 1.0, -1)
            v = _UNDECIDED if v == _UNDECIDED else v        # (the marker itself: compared by identity)
            if not ((v is None or v is _UNDECIDED or type(v) is float) and type(held) is bool
                    and vs in (1.0, 1 / 3.6) and type(j) is int):
                raise r.error(name, "is a record of another layout (its speed, hold, scale or index)")
            qr = StateReader("StreamingEstimator", {"delta_R": q[0], "delta_v": q[1], "times": [q[2], q[5], q[6]]},
                             f"{name}.")
            dt, t_end, t_start = qr.floats("times", (3,)).tolist()
            ego = EgoFrame(qr.floats("delta_R", (9,)).reshape(3, 3), qr.floats("delta_v", (3,)), dt, q[3], q[4], t_end)
            queue.append([ego, t_start, list(q[7]), v, held, vs, j])
        # notes and counts
        notes = records("notes", 1000)
        if not all(isinstance(x, str) and len(x) <= 1000 for x in notes):
            raise r.error("notes", "holds something other than short texts")
        slow = r.floats("slow_warmups", (2,)) if r.has("slow_warmups") else np.zeros(2)
        if slow[0] < 0 or slow[0] != int(slow[0]) or slow[1] < 0:
            raise r.error("slow_warmups", f"holds {slow.tolist()!r}, expected a count and a period")
        now = r.float("now", optional=True)
        flt = loaded("filter", _make_filter(self.method, self.extrinsic, self.rate, self.recalibrate_online),
                     unpack(r.state.get("filter"), "filter"))
        return {"_clock": clock, "_tscale": scale, "_scaled": scale != 1.0,
                "_warm": [(float(w[0]), tuple(w[1:4].tolist()), tuple(w[4:7].tolist())) for w in warm],
                "_origin": math.nan if origin is None else origin, "_pre": pre, "_blocks": blocks, "_bias": bias,
                "_speed": speed, "_latency": latency, "_vunit": vunit, "_vscale": vscale,
                "_queue": queue, "_hold": deque(e for e in queue if e[4]), "_notes": list(notes),
                "_skipped": r.int("skipped"), "_slow": [int(slow[0]), float(slow[1])],
                "_now": -math.inf if now is None else now, "_filter": flt}

    # -- a whole log at once ---------------------------------------------------------------------
    def run(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
            speed: tuple[np.ndarray, np.ndarray] | None = None):
        """This estimator, from :meth:`reset`, fed a whole log sample by sample: :func:`causal_track`'s answer."""
        self.reset()
        self._egos = []
        try:
            frames = replay(self, t, gyro, accel, speed)
            return frames_track(frames, self, self._egos)
        finally:
            self._egos = None


# ------------------------------------------------------------------------------------ offline counterpart
def causal_track(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, *, method: str = "auto", extrinsic: Any = None,
                 rate: float = 10.0, speed: tuple[np.ndarray, np.ndarray] | None = None, bias_gyro: Any = "auto",
                 policy: str = "retime", speed_wait: float = SPEED_WAIT, recalibrate_online: bool = False):
    """What a :class:`StreamingEstimator` gives for a whole log fed sample by sample (IMU sample ``i`` after the
    speed samples up to its stamp, the rest before :meth:`StreamingEstimator.flush`).

    Parameters
    ----------
    t, gyro, accel : ndarray (N,), (N, 3), (N, 3)
        Stamps (s), angular rate (rad/s), specific force (m/s^2), body frame, in arrival order.
    speed : (ndarray (M,), ndarray (M,)), optional
        Speed samples (s on the same clock, increasing; m/s).
    method, extrinsic, rate, bias_gyro, policy, speed_wait, recalibrate_online :
        As :class:`StreamingEstimator`.

    Returns
    -------
    track : GroundTrack
        Per frame, ``status_reason`` with the front end's notes.
    egomotion : EgoMotion
        The frames as the filter stepped them (stationary flags of the trailing window; ``bias_gyro`` the last bias).
    """
    est = StreamingEstimator(method, extrinsic, rate, bias_gyro=bias_gyro, policy=policy, speed_wait=speed_wait,
                             recalibrate_online=recalibrate_online)
    return est.run(t, gyro, accel, speed)
