"""Speed over a frame from the speed samples received so far (:class:`SpeedBuffer`).

A frame's mean speed as :func:`~imu_ground.datasets.speed.frame_speed` defines it (holes included), once a sample
at or after its end has arrived. Samples with a non-finite or repeated time, or after their frames, are ignored
and counted (:attr:`SpeedBuffer.rejected`).
"""
from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np

__all__ = ["SpeedBuffer"]

#: Slack of the span test, s (as ``frame_speed``'s).
_EDGE = 1e-9


class SpeedBuffer:
    """Speed samples (s, m/s) in time order, pruned as frames are done.

    Attributes
    ----------
    t, v : list of float
        The samples kept.
    received : bool
        A finite sample has arrived since construction or :meth:`clear`.
    rejected : dict
        ``{"nonfinite": n, "late": n, "repeated": n}`` since the last :meth:`take_notes`.
    """

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self.t: list[float] = []
        self.v: list[float] = []
        self.received = False
        self.done_until = -math.inf         # frames up to this time are decided
        self.rejected = {"nonfinite": 0, "late": 0, "repeated": 0}

    def push(self, t: float, v: float) -> None:
        """One sample: time ``t`` (s, the IMU's clock) and forward speed ``v`` (m/s; NaN or infinite: a hole)."""
        ts = self.t
        if ts and t - t == 0.0 and v - v == 0.0 and t > ts[-1] and t >= self.done_until:
            ts.append(t)                        # the usual case: finite, after the others
            self.v.append(v)
            return
        if not math.isfinite(v):
            v = math.nan                        # a hole
        if not math.isfinite(t):
            self.rejected["nonfinite"] += 1
            return
        self.received = True
        if t < self.done_until:
            self.rejected["late"] += 1          # before the end of a frame already decided
            return
        i = bisect.bisect_left(ts, t)
        if i < len(ts) and ts[i] == t:
            self.rejected["repeated"] += 1
            return
        ts.insert(i, t)
        self.v.insert(i, v)

    def covers(self, t_end: float) -> bool:
        """A sample at or after ``t_end`` (s) has arrived."""
        return bool(self.t) and self.t[-1] >= t_end

    def mean(self, t_start: float, t_end: float) -> float:
        """Mean speed over ``(t_start, t_end]``, m/s; NaN unless a finite sample at or before ``t_start`` (within
        1e-9 s) and one at or after ``t_end`` have arrived and no hole reaches the frame."""
        ts, vs = self.t, self.v
        total = sum(vs)
        if total != total:                      # a hole (NaN) among them (or an overflow: checked the same)
            for i, v in enumerate(vs):
                if v == v:
                    continue
                lo = next((ts[j] for j in range(i - 1, -1, -1) if vs[j] == vs[j]), -math.inf)
                hi = next((ts[j] for j in range(i + 1, len(ts)) if vs[j] == vs[j]), math.inf)
                if lo < t_end and hi > t_start:
                    return math.nan
            keep = [i for i, v in enumerate(vs) if v == v]
            ts, vs = [ts[i] for i in keep], [vs[i] for i in keep]
        if not ts or ts[0] > t_start + _EDGE or ts[-1] < t_end:
            return math.nan
        if len(ts) == 1:
            return vs[0]
        a = ts[0] if ts[0] > t_start else t_start     # max(t_start, ts[0]), min(t_end, ts[-1])
        b = ts[-1] if ts[-1] < t_end else t_end
        i = max(bisect.bisect_right(ts, a) - 1, 0)
        total = 0.0
        t0, v0 = ts[i], vs[i]
        for t1, v1 in zip(ts[i + 1:], vs[i + 1:], strict=True):   # the intervals (t0, t1] from the one holding a
            if not t0 < b:
                break
            lo = t0 if t0 > a else a                   # max(a, t0), min(b, t1)
            hi = t1 if t1 < b else b
            if hi > lo:
                slope = (v1 - v0) / (t1 - t0)
                total += (hi - lo) * (v0 + 0.5 * slope * ((lo - t0) + (hi - t0)))
            t0, v0 = t1, v1
        return total / (t_end - t_start)

    def done(self, t: float) -> None:
        """Frames up to ``t`` (s) are decided: keep only the last sample at or before it and the later ones."""
        self.done_until = t
        ts = self.t
        k = bisect.bisect_right(ts, t) - 1
        if k > 0:
            del ts[:k]
            del self.v[:k]

    def rescale(self, factor: float) -> None:
        """The times were in another unit: each multiplied by ``factor`` (to seconds)."""
        self.t = [x * factor for x in self.t]
        if math.isfinite(self.done_until):
            self.done_until *= factor

    def take_notes(self) -> list[str]:
        """What was rejected since the last call, one phrase each (and the counts start again)."""
        r = self.rejected
        if not (r["nonfinite"] or r["late"] or r["repeated"]):
            return []                           # (the usual case: nothing rejected, the counts at 0)
        notes = [f"{n} {what} speed sample(s) {how}" for what, how, n in
                 (("non-finite-time", "ignored", r["nonfinite"]),
                  ("late (after their frames)", "ignored", r["late"]),
                  ("repeated-time", "ignored", r["repeated"])) if n]
        self.rejected = {"nonfinite": 0, "late": 0, "repeated": 0}
        return notes

    def state_dict(self) -> dict[str, Any]:
        return {"t": list(self.t), "v": list(self.v), "received": self.received,
                "done_until": None if self.done_until == -math.inf else self.done_until,
                "rejected": dict(self.rejected)}

    def load_checked(self, r: Any, limit: float) -> None:
        """Resume from a :meth:`state_dict` read through ``r`` (a :class:`~imu_ground.imu.warm_start.StateReader`),
        checked (at most ``limit`` samples, increasing times); else a ``StateError`` naming the entry."""
        times = r.state.get("t") if isinstance(r.state, dict) else None
        if not isinstance(times, list) or len(times) > limit:
            raise r.error("t", f"is not a list of at most {limit} times")
        ts = r.floats("t", (len(times),))
        vs = r.floats("v", (len(ts),), nan=True)
        if (np.diff(ts) <= 0).any():
            raise r.error("t", "is not increasing")
        received, done = r.bool("received"), r.float("done_until", optional=True)
        rej = r.part("rejected")
        self.rejected = {k: rej.int(k) for k in ("nonfinite", "late", "repeated")}
        self.t, self.v, self.received = ts.tolist(), vs.tolist(), received
        self.done_until = -math.inf if done is None else done

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Resume from :meth:`state_dict` (checked as :meth:`load_checked`)."""
        from imu_ground.imu.warm_start import StateReader
        self.load_checked(StateReader("SpeedBuffer", state), math.inf)
