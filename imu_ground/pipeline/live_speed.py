"""The live estimator's speed: how long frames wait for a late one (:class:`SpeedLatency`), and whether it is in
m/s or km/h (:class:`SpeedUnit`)."""
from __future__ import annotations

import math
from collections import deque
from typing import Any

from imu_ground.datasets.speed import UNIT_WINDOW_S, speed_unit

__all__ = ["MAX_SPEED_WAIT", "NO_SPEED", "SpeedLatency", "SpeedUnit"]

#: Longest a frame waits for a late speed, s of IMU time (or ``speed_wait`` when that is longer).
MAX_SPEED_WAIT = 1.0
#: Speed samples whose latency and period set the wait (the last ones).
_LATENCY_SAMPLES = 20
#: Allowance over the measured latency and period, s (the sample that finds the speed arrived comes after it).
_WAIT_MARGIN = 0.02
#: The note of a frame that runs IMU only for want of a speed.
NO_SPEED = "no speed over this frame: IMU only"


class SpeedLatency:
    """How long frames wait for their speed: the largest latency (IMU time of arrival less stamp, s) of the last
    :data:`_LATENCY_SAMPLES` speed samples plus their median period and :data:`_WAIT_MARGIN`, at least ``least``
    (``speed_wait``) and at most :data:`MAX_SPEED_WAIT` (or ``least`` when longer)."""

    def __init__(self, least: float) -> None:
        self.least, self.most = least, max(least, MAX_SPEED_WAIT)
        self.wait = self.said = least
        self.lags: deque = deque(maxlen=_LATENCY_SAMPLES)
        self.steps: deque = deque(maxlen=_LATENCY_SAMPLES)
        self.last = math.nan                            # the last speed stamp
        self.lag, self.count = -1.0, 0                  # the largest latency when the wait was worked out; since

    def arrived(self, t: float, now: float) -> str | None:
        """A speed sample stamped ``t`` arrived at IMU time ``now`` (s); a note when the wait changed (worked out again
        every tenth sample, or at a latency over the largest kept)."""
        if not (t - t == 0.0 and now > -math.inf):
            return None
        step, self.last = t - self.last, t
        lag = now - t
        self.count += 1
        if not (lag > self.lag or self.count >= 10):    # (the usual call: nothing more)
            return None
        lag = lag if lag > 0.0 else 0.0
        if step > 0:
            self.steps.append(step)
        self.lags.append(lag)
        if not self.steps:
            return None
        self.count = 0
        self.lag = lag_max = max(self.lags)
        steps = sorted(self.steps)
        need = lag_max + steps[len(steps) // 2] + _WAIT_MARGIN
        wait = self.least if need <= self.least else (need if need < self.most else self.most)
        self.wait = wait
        if abs(wait - self.said) <= 0.02:               # (said again when it changes by more)
            return None
        self.said = wait
        return (f"speed samples arrive up to {lag_max:.2f} s after their stamps: frames wait up to "
                f"{wait:.2f} s for them" + (" (the most they wait)" if wait == self.most else ""))

    def timed_out(self) -> str:
        return (f"{NO_SPEED} (waited {self.wait:.2f} s; speed samples arrive up to "
                f"{max(self.lags, default=0.0):.2f} s after their stamps)")

    def state_dict(self) -> list:
        return [self.wait, self.said, list(self.lags), list(self.steps), None if math.isnan(self.last) else self.last,
                self.lag, self.count]

    def load_state_dict(self, state: Any) -> None:
        wait, said, lags, steps, last, lag, count = state
        if not (type(lag) is float and math.isfinite(lag) and type(count) is int and 0 <= count < 10):
            raise ValueError("not a speed latency record")
        self.lag, self.count = lag, count
        vals = [wait, said, *lags, *steps] + ([] if last is None else [last])
        if not (all(type(x) is float and math.isfinite(x) for x in vals) and self.least <= wait <= self.most
                and len(lags) <= _LATENCY_SAMPLES and len(steps) <= _LATENCY_SAMPLES
                and min(lags + steps, default=0.0) >= 0.0):
            raise ValueError("not a speed latency record")
        self.wait, self.said = wait, said
        self.lags.extend(lags)
        self.steps.extend(steps)
        self.last = math.nan if last is None else last


class SpeedUnit:
    """m/s or km/h, told from the data as :func:`~imu_ground.datasets.speed.check_speed` tells a speed file's unit.

    :func:`~imu_ground.datasets.speed.speed_unit` over windows of whole frames (the frames' ``delta_v`` x
    against the change of their speeds), summed frame by frame: km/h ends the check with True, m/s (or
    :data:`_UNIT_MAX_WINDOWS` windows) ends it. While it is open the filter's state at the first
    frame with a speed and the frames since are kept (:meth:`rerun`).
    """

    def __init__(self, rate: float) -> None:
        self.W = max(1, int(round(UNIT_WINDOW_S * rate)))
        self.open, self.started = True, False
        self.k, self.dv, self.v0 = 0, 0.0, math.nan     # frames in the window, its sum of dv, the speed before it
        self.n, self.s = 0, [0.0] * 5                   # windows; sums x, y, xx, yy, xy
        self.slope = math.nan
        self.snapshot: dict | None = None               # the filter's state at the first speed, the frames since
        self.frames: list = []

    def frame(self, dvx: float, v: float, flt: Any, ego: Any) -> bool:
        """One frame (its forward delta-v, m/s, and speed); True when the speed is told to be km/h now."""
        if not self.started:                            # (from the first frame with a speed)
            if v != v:
                return False
            self.started = True
            self.snapshot = {} if flt is None else flt.state_dict()
        if self.snapshot is not None:
            self.frames.append((ego, v))
        self.dv += dvx
        self.k += 1
        if self.k < self.W:
            return False
        x, v0, self.v0, self.k, self.dv = self.dv, self.v0, v, 0, 0.0
        if not (abs(v0) > 1.0 and abs(v) > 1.0):
            return False
        y, s = v - v0, self.s
        self.n += 1
        s[0] += x
        s[1] += y
        s[2] += x * x
        s[3] += y * y
        s[4] += x * y
        unit, k = speed_unit(self.n, s)
        if unit is not None:
            self.slope = k
        if unit == "km/h":
            self.open = False
            return True
        if unit == "m/s" or self.n >= _UNIT_MAX_WINDOWS:
            self._close()
        return False

    def _close(self) -> None:
        self.open, self.snapshot, self.frames = False, None, []

    def rerun(self, flt: Any, k: float) -> int:
        """The filter back at the first speed, then run over the frames since with their speeds times ``k``; how
        many (-1: none kept, a resumed state)."""
        snapshot, frames = self.snapshot, self.frames[:-1]      # (the last: the frame being decided)
        self._close()
        if snapshot is None:
            return -1
        flt.load_state_dict(snapshot)
        for ego, v in frames:
            flt.step(ego, speed=v * k)
        return len(frames)

    def state_dict(self) -> list:
        return [self.open, self.started, self.k, self.dv, None if math.isnan(self.v0) else self.v0, self.n,
                list(self.s)]

    def load_state_dict(self, state: Any) -> None:
        open_, started, k, dv, v0, n, s = state
        vals = [dv, *s] + ([] if v0 is None else [v0])
        if not (type(open_) is bool and type(started) is bool and type(k) is int and 0 <= k < self.W and type(n) is int and 0 <= n
                and len(s) == 5 and all(type(x) is float and math.isfinite(x) for x in vals)):
            raise ValueError("not a speed unit record")
        self.open, self.started, self.k, self.dv, self.n, self.s = open_, started, k, dv, n, s
        self.v0 = math.nan if v0 is None else v0


#: Windows after which the live speed-unit check gives up (the speed is then taken as m/s).
_UNIT_MAX_WINDOWS = 300
