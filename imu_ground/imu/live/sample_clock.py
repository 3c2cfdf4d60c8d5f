"""A causal sample clock: raw IMU stamps (s) in, strictly increasing sample times out, one sample at a time.

The causal form of the readers' retiming on the sample index (:mod:`imu_ground.datasets.retime`):

- **Warm-up**: the first :data:`WARMUP` increasing stamps pass as they are (others dropped); the median of
  their steps is the first sample period ``dt``.
- **Index clock**: then ``t_out = t_prev + dt + alpha c`` and ``dt += beta c`` with the stamp's offset
  ``e = t - (t_prev + dt)`` clipped to ``c = clip(e, -dt / 2, dt / 2)`` (a second-order phase-locked loop):
  stamps that step back or repeat are retimed (``"retime"``), or dropped unless later than all (``"drop"``).
- **Dropouts**: a stamp more than half a period ahead is jitter while it comes back within ``hold`` s; ahead
  for ``hold`` s (or by more than ``hold``), the clock jumps forward by the least offset seen.
- **Stamps far off** (more than ``max_gap`` back, or ``hold`` ahead): a bad sample (:data:`DROP`), unless the
  :data:`CONFIRM`-th of consecutive ones that agree (each within ``max_gap`` of the one before): then the clock
  changed: ahead by at most ``max_jump``, a dropout; else a **restart** (warm-up again, said by
  :meth:`~SampleClock.push`). In the warm-up, :data:`CONFIRM` agreeing stamps before its latest one, or
  :data:`WARMUP_FAR_STEPS` times the median step ahead, start it again.
"""
from __future__ import annotations

import math
import statistics
from typing import Any

import numpy as np

from imu_ground._jit import njit

__all__ = ["CONFIRM", "DROP", "FAR", "OK", "RESTART", "WARMUP", "SampleClock", "clock_step"]

#: Samples of the warm-up: their median step is the first sample period.
WARMUP = 10
#: A warm-up stamp more than this many median steps ahead of the latest (once :data:`WARMUP_FAR_AFTER` steps are
#: known) is far off.
WARMUP_FAR_STEPS = 1000.0
WARMUP_FAR_AFTER = 3
#: Consecutive far-off stamps, agreeing with each other, that make a real change of the clock (fewer: bad stamps).
CONFIRM = 3
#: What :meth:`SampleClock.push` says about a sample.
OK, DROP, RESTART = 0, 1, 2
_POLICIES = ("retime", "drop")
_COUNTS = ("retimed", "dropped", "dropouts", "restarts", "bad", "bad_offset", "confirming")
#: :func:`clock_step`'s answer for a stamp far off the clock (nothing changed: :meth:`SampleClock.push` decides).
FAR = -1
# The clock's state and settings in one float64 buffer (SampleClock._c), where the compiled step runs on them
(_C_T, _C_DT, _C_RAW_MAX, _C_RAW_PREV, _C_PENDING, _C_PMIN, _C_RETIMED, _C_DROPPED, _C_DROPOUTS, _C_SUS_N, _C_HOLD,
 _C_GAP_FACTOR, _C_ALPHA, _C_BETA, _C_DROP_POLICY, _C_SIZE) = range(16)


@njit
def clock_step(c: np.ndarray, t: float) -> int:
    """One raw stamp ``t`` (finite, s) after the warm-up, on the clock buffer ``c``: :data:`OK` (the output
    time in ``c[0]``), :data:`DROP`, or :data:`FAR` (nothing changed: :meth:`SampleClock.push` decides)."""
    out, dt = c[_C_T], c[_C_DT]
    hold = c[_C_HOLD]
    e = t - (out + dt)
    if t < c[_C_RAW_PREV] - c[_C_GAP_FACTOR] * dt or e > hold:
        return FAR
    c[_C_SUS_N] = 0.0
    c[_C_RAW_PREV] = t
    if t > c[_C_RAW_MAX]:
        c[_C_RAW_MAX] = t
    elif c[_C_DROP_POLICY] != 0.0:
        c[_C_DROPPED] += 1.0
        return DROP
    if e > 0.5 * dt:
        if math.isnan(c[_C_PENDING]):
            c[_C_PENDING], c[_C_PMIN] = out, e
        elif e < c[_C_PMIN]:
            c[_C_PMIN] = e
        if out + dt - c[_C_PENDING] >= hold:                # ahead for hold seconds: a dropout
            out = out + dt + c[_C_PMIN]
            c[_C_PENDING] = math.nan
            c[_C_DROPOUTS] += 1.0
        else:
            out = out + dt
            c[_C_RETIMED] += 1.0
        c[_C_T] = out
        return OK
    c[_C_PENDING] = math.nan
    if e < -0.5 * dt:
        e = -0.5 * dt
        c[_C_RETIMED] += 1.0
    c[_C_T] = out + dt + c[_C_ALPHA] * e
    c[_C_DT] = dt + c[_C_BETA] * e
    return OK


def _slot(i: int, kind: type = float) -> Any:
    """An attribute kept in the clock buffer at ``i`` (read back as ``kind``)."""
    def get(self: SampleClock) -> Any:
        return kind(self._c[i])

    def put(self: SampleClock, v: Any) -> None:
        self._c[i] = v
    return property(get, put)


class SampleClock:
    """Causal retiming of raw stamps on the sample index (module docstring).

    Parameters
    ----------
    policy : {"retime", "drop"}
        Stamps that step back or repeat: retimed on the index clock, or dropped.
    hold : float
        How long a stamp may run ahead of the clock before it counts as a dropout, s.
    gap_factor : float
        ``max_gap = gap_factor * dt``: the longest step that is not a gap, and how far back a stamp may be.
    alpha, beta : float
        Phase and period gains of the loop (per sample).
    max_jump : float
        Longest step forward of the stamps that is a dropout, s; a longer one restarts the clock.

    Attributes
    ----------
    dt, t : float
        Current sample period (NaN during the warm-up) and last output time (NaN before the first sample), s.
    retimed, dropped, dropouts, restarts : int
        Samples moved by more than half a period, dropped, dropouts inserted, restarts (since :meth:`reset`).
    bad, bad_offset : int, float
        Samples dropped for a stamp far off the clock, and the last one's offset, s (positive: ahead).
    confirming : int
        Samples dropped while a change of the clock was confirmed.
    """

    t = _slot(_C_T)
    dt = _slot(_C_DT)
    _raw_max = _slot(_C_RAW_MAX)
    _raw_prev = _slot(_C_RAW_PREV)          # the last stamp pushed
    _pending = _slot(_C_PENDING)            # output time when the stamps went ahead (NaN: they are not)
    _pmin = _slot(_C_PMIN)                  # the least offset since then, s
    retimed = _slot(_C_RETIMED, int)
    dropped = _slot(_C_DROPPED, int)
    dropouts = _slot(_C_DROPOUTS, int)
    _sus_n = _slot(_C_SUS_N, int)           # far-off stamps in a row that agree so far
    hold = _slot(_C_HOLD)
    gap_factor = _slot(_C_GAP_FACTOR)
    alpha = _slot(_C_ALPHA)
    beta = _slot(_C_BETA)

    def __init__(self, policy: str = "retime", hold: float = 1.0, gap_factor: float = 10.0,
                 alpha: float = 0.02, beta: float = 1e-4, max_jump: float = math.inf) -> None:
        self._c = np.zeros(_C_SIZE)
        if policy not in _POLICIES:
            raise ValueError(f"policy must be one of {', '.join(_POLICIES)} for a stream (sort and strict need the "
                             f"whole log), got {policy!r}")
        self.policy, self.hold, self.gap_factor = policy, float(hold), float(gap_factor)
        self._c[_C_DROP_POLICY] = 1.0 if policy == "drop" else 0.0
        self.max_jump = float(max_jump)
        self.alpha, self.beta = float(alpha), float(beta)
        self.reset()

    def reset(self, keep_counts: bool = False) -> None:
        """Back to the warm-up (``keep_counts``: the counts of what was done so far are kept)."""
        counts = [getattr(self, k) for k in _COUNTS] if keep_counts else None
        self.t = math.nan
        self.dt = math.nan
        self._raw_max = -math.inf
        self._raw_prev = math.nan
        self._steps: list[float] = []       # the warm-up's steps
        self._pending = math.nan
        self._pmin = math.inf
        self.retimed = self.dropped = self.dropouts = self.restarts = self.bad = 0
        self.bad_offset = 0.0
        self.confirming = 0
        self.last_jump = 0.0                # the last restart's step back, s (negative: a step forward)
        self._sus_t = math.nan              # the last of the far-off stamps in a row (NaN: none)
        self._sus_n = 0
        if counts is not None:
            for k, v in zip(_COUNTS, counts, strict=True):
                setattr(self, k, v)

    @property
    def buffer(self) -> np.ndarray:
        """The state and settings :func:`clock_step` runs on, for a caller's own compiled step."""
        return self._c

    @property
    def max_gap(self) -> float:
        """Longest sample step that is not a gap, s (NaN during the warm-up)."""
        return self.gap_factor * self.dt

    @property
    def warm(self) -> bool:
        """The period is known (the warm-up is over)."""
        return not math.isnan(self.dt)

    def push(self, t: float) -> tuple[int, float]:
        """One raw stamp (finite, s) -> ``(OK, t_out)``, ``(DROP, nan)`` or ``(RESTART, t_out)``."""
        if not self.warm:
            return self._warmup(t)
        code = clock_step(self._c, t)
        if code == FAR:
            return self._far_off(t, self._raw_prev, t - (self.t + self.dt))
        return (OK, self.t) if code == OK else (DROP, math.nan)

    def _suspect(self, t: float, agrees: bool) -> bool:
        """One more far-off stamp (``agrees``: with the one before it); True at the :data:`CONFIRM`-th."""
        self._sus_n = self._sus_n + 1 if (self._sus_n > 0 and agrees) else 1
        self._sus_t = t
        return self._sus_n >= CONFIRM

    def _restart(self, t: float, jump: float) -> tuple[int, float]:
        """A new clock from ``t`` (``jump``: the step back, s), warmed up again; the counts kept."""
        self.reset(keep_counts=True)
        self.restarts += 1
        self.last_jump = jump
        self._warmup(t)
        return RESTART, t

    def _far_off(self, t: float, prev: float, e: float) -> tuple[int, float]:
        """A stamp far off the clock: dropped as bad, unless it is the :data:`CONFIRM`-th of agreeing ones."""
        if not self._suspect(t, abs(t - self._sus_t) <= self.gap_factor * self.dt):
            self.bad += 1
            self.bad_offset = e if e > 0 else t - prev
            return DROP, math.nan
        self._sus_n = 0
        self.bad = max(self.bad - (CONFIRM - 1), 0)         # the first of them: not bad stamps, a change of clock
        self.confirming += CONFIRM - 1
        if t < prev or t > prev + self.max_jump:            # the clock was set back or forward: start again
            return self._restart(t, prev - t)
        self._pending = math.nan                            # far ahead for CONFIRM samples: a dropout
        self.dropouts += 1
        self._raw_prev = t
        self._raw_max = max(self._raw_max, t)
        self.t = t
        return OK, t

    def _warmup(self, t: float) -> tuple[int, float]:
        self._raw_prev = t
        if not t > self._raw_max:
            # before the warm-up's latest stamp: dropped; CONFIRM increasing ones in a row start it again
            if self._suspect(t, t > self._sus_t):
                return self._restart(t, self._raw_max - t)
            self.dropped += 1
            return DROP, math.nan
        far = WARMUP_FAR_STEPS * sorted(self._steps)[len(self._steps) // 2] if len(self._steps) >= WARMUP_FAR_AFTER \
            else math.inf
        if t - self._raw_max > far:
            # far ahead of the warm-up's steps: a bad stamp, unless the CONFIRM-th of agreeing ones: a new clock
            if self._suspect(t, 0 < t - self._sus_t <= far):
                return self._restart(t, self._raw_max - t)
            self.bad += 1
            self.bad_offset = t - self._raw_max
            return DROP, math.nan
        self._sus_n = 0
        if self._raw_max > -math.inf:
            self._steps.append(t - self._raw_max)
        self._raw_max = self.t = t
        if len(self._steps) >= WARMUP - 1:
            self.dt = statistics.median(self._steps)
            self._steps = []
        return OK, t

    # -- warm start ---------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """The state as plain floats and ints (JSON: non-finite floats as None)."""
        return {"t": _f(self.t), "dt": _f(self.dt), "raw_max": _f(self._raw_max), "raw_prev": _f(self._raw_prev),
                "steps": list(self._steps),
                "pending": _f(self._pending), "pmin": _f(self._pmin),
                "counts": [self.retimed, self.dropped, self.dropouts, self.restarts], "last_jump": self.last_jump,
                "bad": [self.bad, self.bad_offset, self.confirming], "suspect": [_f(self._sus_t), self._sus_n]}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Resume from :meth:`state_dict` (checked as :meth:`load_checked`, any period)."""
        from imu_ground.imu.warm_start import StateReader
        self.load_checked(StateReader("SampleClock", state), math.inf)

    def take_notes(self) -> list[str]:
        """What the clock did since the last call, one phrase each (for ``status_reason``); the counts start again."""
        if not (self.bad or self.confirming or self.dropped or self.retimed):
            return []                                       # (the usual case: nothing to say, the counts at 0)
        notes = []
        if self.bad:
            off = self.bad_offset
            notes.append(f"{self.bad} IMU sample(s) dropped: stamp far off the clock (the last {abs(off):.6g} s "
                         f"{'ahead' if off > 0 else 'behind'}), a bad stamp, not a new clock")
            self.bad = 0
        for count, text in (("confirming", "IMU sample(s) dropped while the change of the clock was confirmed"),
                            ("dropped", f"IMU sample(s) dropped (time not after the last; policy {self.policy})"),
                            ("retimed", "stamp(s) retimed on the sample clock")):
            if getattr(self, count):
                notes.append(f"{getattr(self, count)} {text}")
                setattr(self, count, 0)
        return notes

    def load_checked(self, c: Any, max_period: float) -> None:
        """Resume from a :meth:`state_dict` read through ``c`` (a :class:`~imu_ground.imu.warm_start.StateReader`),
        every entry checked (``dt`` NaN or 1e-6 to ``max_period`` s); a corrupt one raises a ``StateError``."""
        from imu_ground.imu.warm_start import StateReader

        def stamp(name: str, nan: bool = True, inf: bool = False) -> float:
            v = c.state.get(name) if isinstance(c.state, dict) else None
            if v in ("inf", "-inf") and inf:
                return math.inf if v == "inf" else -math.inf
            return math.nan if v is None and nan and name in c.state else c.float(name)

        t, dt = stamp("t"), stamp("dt")
        if not (math.isnan(dt) or 1e-6 <= dt <= max_period):
            raise c.error("dt", f"is {dt!r}, expected NaN (a warm-up) or a sample period of 1e-6 to {max_period:g} s")
        raw_max, raw_prev = stamp("raw_max", inf=True), stamp("raw_prev")
        steps = c.floats("steps", (None,))
        if len(steps) >= WARMUP or (steps <= 0).any():
            raise c.error("steps", f"holds {len(steps)} steps (expected fewer than {WARMUP}, each positive)")
        pending, pmin = stamp("pending"), stamp("pmin", inf=True)
        counts = c.state.get("counts")
        if not (isinstance(counts, list) and len(counts) == 4):
            raise c.error("counts", f"is {counts!r:.60}, expected 4 counts")
        cr = StateReader(c.kind, {str(i): x for i, x in enumerate(counts)}, f"{c.prefix}counts.")
        counts = [cr.int(str(i)) for i in range(4)]
        last_jump = c.float("last_jump")
        bad = c.floats("bad", (3,)) if c.has("bad") else np.zeros(3)
        if bad[0] < 0 or bad[2] < 0 or bad[0] != int(bad[0]) or bad[2] != int(bad[2]):
            raise c.error("bad", f"holds {bad.tolist()!r}, expected counts (integers >= 0) and an offset")
        sus = c.state.get("suspect") if c.has("suspect") else [None, 0]
        if not (isinstance(sus, list) and len(sus) == 2 and type(sus[1]) is int and 0 <= sus[1] < CONFIRM
                and (sus[0] is None or (isinstance(sus[0], float) and math.isfinite(sus[0])))):
            raise c.error("suspect", f"is {sus!r:.60}, expected [a stamp or null, a count below {CONFIRM}]")
        self.t, self.dt, self._raw_max, self._raw_prev, self._steps = t, dt, raw_max, raw_prev, steps.tolist()
        self._pending, self._pmin, self.last_jump = pending, pmin, last_jump
        self.retimed, self.dropped, self.dropouts, self.restarts = counts
        self.bad, self.bad_offset, self.confirming = int(bad[0]), float(bad[1]), int(bad[2])
        self._sus_t, self._sus_n = (math.nan if sus[0] is None else sus[0]), sus[1]


def _f(x: float) -> float | str | None:
    """A float for JSON: None for NaN, "inf" and "-inf" for infinities (:meth:`SampleClock.load_checked` reads it)."""
    return x if math.isfinite(x) else (None if math.isnan(x) else ("inf" if x > 0 else "-inf"))
