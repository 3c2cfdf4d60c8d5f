"""A causal sample clock: raw IMU stamps in, strictly increasing sample times out, one sample at a time.

The readers retime a jittered log on the sample index with one fit over the whole
file (:mod:`imu_ground.datasets.retime`); a live stream cannot wait for the end.
:class:`SampleClock` makes the same choices from the stamps seen so far:

- **Warm-up**: the first :data:`WARMUP` samples with increasing stamps pass as they
  are (non-increasing ones are dropped); the median of their steps is the first
  sample period ``dt`` (s).
- **Index clock**: afterwards each sample is one period after the last output,
  ``t_out = t_prev + dt + alpha c`` with the stamp's offset ``e = t - (t_prev + dt)``
  clipped to ``c = clip(e, -dt / 2, dt / 2)``; the period follows ``dt += beta c``
  (a second-order phase-locked loop: ``alpha`` pulls the clock onto the stamps,
  ``beta`` follows the true rate). Stamps that step back or repeat (``policy
  "retime"``) are thereby retimed on the sample index; with ``policy "drop"`` a stamp
  not later than every earlier one is dropped instead (the readers' ``drop``).
- **Dropouts**: a stamp more than half a period ahead of the clock is jitter while
  it comes back within ``hold`` seconds (the OXTS extract jumps ahead by up to
  0.55 s and steps back by 50 ms every 6 samples); when it stays ahead for ``hold``
  seconds the clock jumps forward by the least offset seen (a dropout, a gap the
  preintegrator flags and integrates through). An offset of more than ``hold`` is
  a dropout at once.
- **Restart**: a stamp more than ``max_gap`` before the one pushed last (a clock set
  back, a log started again), or more than ``max_jump`` after it (a clock set forward:
  integrating through such a gap would make a gap frame for every frame period of it),
  restarts the clock (warm-up again); :meth:`push` says so and the caller starts its
  front end afresh.

Times are seconds; nothing here allocates per sample beyond Python floats.
"""
from __future__ import annotations

import math
from array import array
from typing import Any

__all__ = ["DROP", "OK", "RESTART", "WARMUP", "SampleClock"]

#: Samples of the warm-up: their median step is the first sample period.
WARMUP = 10
#: What :meth:`SampleClock.push` says about a sample.
OK, DROP, RESTART = 0, 1, 2
_POLICIES = ("retime", "drop")


class SampleClock:
    """Causal retiming of raw stamps on the sample index (module docstring).

    Parameters
    ----------
    policy : {"retime", "drop"}
        Stamps that step back or repeat: retimed on the index clock, or dropped.
    hold : float
        How long a stamp may run ahead of the clock before it counts as a dropout, s.
    gap_factor : float
        ``max_gap = gap_factor * dt``: the longest sample step that is not a gap, and
        how far back a stamp may be before the clock restarts.
    alpha, beta : float
        Phase and period gains of the loop (per sample).
    max_jump : float
        Longest step forward of the stamps (from the one pushed last) that is a dropout, s;
        a longer one restarts the clock (default: none does).

    Attributes
    ----------
    dt : float
        Current sample period, s (NaN during the warm-up).
    t : float
        Last output time, s (NaN before the first sample).
    retimed, dropped, dropouts, restarts : int
        Samples moved by more than half a period, samples dropped, dropouts inserted,
        restarts, since construction or :meth:`reset`.
    """

    def __init__(self, policy: str = "retime", hold: float = 1.0, gap_factor: float = 10.0,
                 alpha: float = 0.02, beta: float = 1e-4, max_jump: float = math.inf) -> None:
        if policy not in _POLICIES:
            raise ValueError(f"policy must be one of {', '.join(_POLICIES)} for a stream (sort and strict need the "
                             f"whole log), got {policy!r}")
        self.policy, self.hold, self.gap_factor = policy, float(hold), float(gap_factor)
        self.max_jump = float(max_jump)
        self.alpha, self.beta = float(alpha), float(beta)
        self.reset()

    def reset(self) -> None:
        """Back to the warm-up."""
        self.t = math.nan
        self.dt = math.nan
        self._raw_max = -math.inf
        self._raw_prev = math.nan            # the last stamp pushed
        self._steps: list[float] = []
        self._pending = math.nan            # output time when the stamps went ahead (NaN: they are not)
        self._pmin = math.inf               # the least offset since then, s
        self.retimed = self.dropped = self.dropouts = self.restarts = 0
        self.last_jump = 0.0                # the last restart's step back, s (negative: a step forward)

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
        out, dt = self.t, self.dt
        prev, self._raw_prev = self._raw_prev, t
        if t < prev - self.gap_factor * dt or t > prev + self.max_jump:     # the clock was set back or forward
            counts = (self.retimed, self.dropped, self.dropouts, self.restarts + 1)
            self.reset()
            self.retimed, self.dropped, self.dropouts, self.restarts = counts
            self.last_jump = prev - t
            self._warmup(t)
            return RESTART, t
        if t > self._raw_max:
            self._raw_max = t
        elif self.policy == "drop":
            self.dropped += 1
            return DROP, math.nan
        e = t - (out + dt)
        if e > 0.5 * dt:
            if e > self.hold:                               # far ahead: a dropout at once
                self._pending = math.nan
                self.dropouts += 1
                self.t = t
                return OK, t
            if math.isnan(self._pending):
                self._pending, self._pmin = out, e
            elif e < self._pmin:
                self._pmin = e
            if out + dt - self._pending >= self.hold:       # ahead for hold seconds: a dropout
                out = out + dt + self._pmin
                self._pending = math.nan
                self.dropouts += 1
            else:
                out = out + dt
                self.retimed += 1
            self.t = out
            return OK, out
        self._pending = math.nan
        if e < -0.5 * dt:
            e = -0.5 * dt
            self.retimed += 1
        out = out + dt + self.alpha * e
        self.dt = dt + self.beta * e
        self.t = out
        return OK, out

    def _warmup(self, t: float) -> tuple[int, float]:
        self._raw_prev = t
        if not t > self._raw_max:
            self.dropped += 1
            return DROP, math.nan
        if self._raw_max > -math.inf:
            self._steps.append(t - self._raw_max)
        self._raw_max = self.t = t
        if len(self._steps) >= WARMUP - 1:
            s = sorted(self._steps)
            m = len(s) // 2
            self.dt = s[m] if len(s) % 2 else 0.5 * (s[m - 1] + s[m])
            self._steps = []
        return OK, t

    # -- the compiled twin's buffer --------------------------------------------
    def to_buffer(self, b) -> None:
        """Write the state and settings into ``b[0:14]`` (a float64 buffer, the layout ``F_*`` of
        ``imu/_front_native.c``), where the compiled ``push`` runs on them; :meth:`from_buffer` reads them back."""
        b[0:14] = array("d", (self.t, self.dt, self._raw_max, self._raw_prev, self._pending, self._pmin, self.hold,
                              self.gap_factor, self.alpha, self.beta, 1.0 if self.policy == "drop" else 0.0,
                              self.retimed, self.dropped, self.dropouts))

    def from_buffer(self, b) -> None:
        """The state the compiled ``push`` left in ``b`` (:meth:`to_buffer`)."""
        (self.t, self.dt, self._raw_max, self._raw_prev, self._pending, self._pmin) = b[0:6]
        self.retimed, self.dropped, self.dropouts = int(b[11]), int(b[12]), int(b[13])

    # -- warm start ---------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """The state as plain floats and ints (JSON: non-finite floats as None)."""
        return {"t": _f(self.t), "dt": _f(self.dt), "raw_max": _f(self._raw_max), "raw_prev": _f(self._raw_prev),
                "steps": list(self._steps),
                "pending": _f(self._pending), "pmin": _f(self._pmin),
                "counts": [self.retimed, self.dropped, self.dropouts, self.restarts], "last_jump": self.last_jump}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Resume from :meth:`state_dict`."""
        self.t, self.dt = _g(state["t"]), _g(state["dt"])
        self._raw_max, self._raw_prev = _g(state["raw_max"]), _g(state["raw_prev"])
        self._steps = [float(x) for x in state["steps"]]
        self._pending, self._pmin = _g(state["pending"]), _g(state["pmin"])
        self.retimed, self.dropped, self.dropouts, self.restarts = (int(x) for x in state["counts"])
        self.last_jump = float(state["last_jump"])


def _f(x: float) -> float | str | None:
    """A float for JSON: None for NaN and infinities (:func:`_g` reads it back)."""
    return x if math.isfinite(x) else (None if math.isnan(x) else ("inf" if x > 0 else "-inf"))


def _g(x: Any) -> float:
    """The float :func:`_f` wrote (None: NaN; "inf", "-inf": infinities)."""
    return math.nan if x is None else float(x)
