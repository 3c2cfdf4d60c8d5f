r"""Mount-change detection: the measured gravity turns away from the mount's up axis faster than any drift.

A sensor that is bumped or remounted makes the static extrinsic wrong. With a
measured speed the road's gravity/velocity filter (:mod:`imu_ground.filters.road`)
keeps gravity in its gyro-integrated world frame consistent with the
accelerometer: the speed and the vehicle constraints pin the velocity, so the
filter turns its gravity towards whatever turn of the accelerometer's view of
gravity the gyro did not see. A drift of the gyro-integrated frame (gyro bias) turns
it slowly; a remount by 1 deg turns it by 0.7-0.9 deg within 15 s (then back over
minutes, see below). The monitor compares the gravity direction now with the one
:data:`WINDOW` seconds before: an angle above :data:`THRESHOLD` raises the alarm
(latched until a reset). It first measures the gyro's own drift for :data:`GATE`
seconds and stays silent if that turns gravity by more than :data:`DRIFT_LIMIT` in a
window (a raw consumer MEMS gyro: its bias, up to ~1 deg/s, turns the frame by
degrees). No comparison spans a frame without a speed or a gap, nor starts within
:data:`HOLD_OFF` seconds of the road filter's start or of such a frame (the filter
re-converges after them). Without a speed there is no road filter and no monitor
(the accelerometer's gravity cannot then be told from the vehicle's own acceleration
along the road).

The monitor does not measure the change: the filter's gravity turns by most of the
change within seconds and then turns back over minutes (the velocity constraints
take up the rest), so neither its gravity nor its body-frame velocity keeps a
record of the mount's new pitch accurate to 0.1 deg. Re-calibrate with
``imu-ground calibrate`` when the status says the mount moved, or let
:mod:`imu_ground.filters.recalibration` re-estimate it online (``recalibrate_online``).

Measured on synthetic drives (true speed) and on the shared KITTI drives with
``--speed auto`` in ``benchmarks/RESULTS.md`` (``benchmarks/studies/confidence.py``).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Optional

import numpy as np

from imu_ground.imu.warm_start import as_reader
from imu_ground.units import DEG

__all__ = ["MountMonitor", "WINDOW", "THRESHOLD", "HOLD_OFF", "GATE", "DRIFT_LIMIT"]

#: Time between the two gravity directions compared, s.
WINDOW = 15.0
#: Angle between them that raises the alarm, rad (0.6 deg).
THRESHOLD = 0.6 * DEG
#: No comparison starts within this long after the road filter's start, a gap or a frame without speed, s.
HOLD_OFF = 60.0
#: For this long after the hold-off the monitor measures the largest turn in :data:`WINDOW` s (the gyro's
#: drift) instead of judging, s ...
GATE = 60.0
#: ... and stays silent until the next hold-off if it is above this, rad (0.35 deg).
DRIFT_LIMIT = 0.35 * DEG
_COS_THRESHOLD = math.cos(THRESHOLD)


def _unit(g) -> tuple:
    n = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
    return g[0] / n, g[1] / n, g[2] / n


class MountMonitor:
    """The monitor of the module docstring: one :meth:`update` a frame, or :meth:`run` over a batch (vectorised).

    Attributes
    ----------
    alarm : str or None
        The reason once raised.
    alarm_t : float
        Time of the alarm, s (NaN before).
    reference : tuple of 3 float or None
        The unit gravity (world frame of the road filter) the alarm's comparison started from.
    """

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget everything."""
        self._hist: deque = deque()            # (t, unit gravity) of the last WINDOW s, once armed
        self._armed_at = math.nan              # comparisons may start at frames after this time
        self._drift = 0.0                      # largest turn in WINDOW s during the first GATE s once armed
        self.alarm: Optional[str] = None
        self.alarm_t = math.nan
        self.reference: Optional[tuple] = None

    @property
    def active(self) -> bool:
        """Armed, past the drift check, and the gyro's drift small enough for the monitor to judge."""
        return (self._armed_at == self._armed_at and bool(self._hist)
                and self._hist[-1][0] >= self._armed_at + GATE and self._drift <= DRIFT_LIMIT)

    def update(self, t: float, gravity, usable: bool) -> Optional[str]:
        """One frame.

        Parameters
        ----------
        t : float
            Frame end time, s.
        gravity : sequence of 3 float or None
            The road filter's gravity reaction (world frame) after the frame; None without a road filter.
        usable : bool
            The frame is valid (no gap) and has a speed.

        Returns
        -------
        str or None
            The alarm's reason once raised (latched), else None.
        """
        if self.alarm is not None:
            return self.alarm
        if gravity is None or not usable:
            self._hist.clear()
            self._armed_at = math.nan
            return None
        if self._armed_at != self._armed_at:          # NaN: (re)start the hold-off here
            self._armed_at, self._drift = t + HOLD_OFF, 0.0
        if t < self._armed_at:
            return None
        u = _unit(gravity)
        h = self._hist
        h.append((t, u))
        while len(h) > 1 and h[1][0] <= t - WINDOW:
            h.popleft()
        t0, r = h[0]
        if t0 > t - WINDOW:
            return None
        c = max(-1.0, min(1.0, u[0] * r[0] + u[1] * r[1] + u[2] * r[2]))
        if t < self._armed_at + GATE:                 # the gyro's own drift, measured first
            self._drift = max(self._drift, math.acos(c))
            return None
        if c < _COS_THRESHOLD and self._drift <= DRIFT_LIMIT:
            self.alarm, self.alarm_t, self.reference = (
                f"mount moved: the measured gravity turned {math.acos(c) / DEG:.1f} deg away from the mount's "
                f"up axis within {WINDOW:g} s, at t = {t:.1f} s", t, r)
        return self.alarm

    @property
    def engaged(self) -> bool:
        """Armed or holding history: it must see every frame, with or without a road filter's gravity."""
        return bool(self._hist) or self._armed_at == self._armed_at

    def state_dict(self) -> dict:
        """Plain values, for a warm start."""
        return {"hist": [[t, list(u)] for t, u in self._hist], "armed_at": self._armed_at, "drift": self._drift,
                "alarm": self.alarm, "alarm_t": self.alarm_t,
                "reference": None if self.reference is None else list(self.reference)}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (a dict or a :class:`~imu_ground.imu.warm_start.StateReader`); every
        entry checked (finite, shapes) before the monitor changes."""
        st = as_reader(state, "MountMonitor")
        hist = st.rows("hist", lambda r: [r[0], *r[1]], 4)
        armed_at, drift = st.float("armed_at", nan=True), st.float("drift")
        alarm, alarm_t, reference = st.text("alarm"), st.float("alarm_t", nan=True), st.floats("reference", (3,),
                                                                                                optional=True)
        self._hist = deque((float(r[0]), tuple(r[1:].tolist())) for r in hist)
        self._armed_at, self._drift = armed_at, drift
        self.alarm, self.alarm_t = alarm, alarm_t
        self.reference = None if reference is None else tuple(reference.tolist())

    def run(self, t: np.ndarray, gravity: np.ndarray, usable: np.ndarray) -> np.ndarray:
        """:meth:`update` over a batch (frames in order), vectorised; per frame whether the alarm is raised.

        The twin of calling ``update`` frame by frame (same flags, same state after the batch, the
        same floating-point operations on every compared value): the frames that use the road filter
        form runs between breaks (a frame without gravity or not usable); in a run armed at ``A`` (its
        first time plus :data:`HOLD_OFF`, or the monitor's own arming when the batch continues its run)
        the frames from ``A`` on enter the history, and each is compared with the last history entry at
        least :data:`WINDOW` s older (the one ``update``'s deque holds first). The drift of a run is the
        largest angle of its first :data:`GATE` s, ``acos`` of the smallest cosine (``acos`` decreases).

        Parameters
        ----------
        t : ndarray (F,)
            Frame times, s, non-decreasing.
        gravity : ndarray (F, 3)
            The road filter's gravity per frame (rows of NaN: no road filter at that frame).
        usable : ndarray of bool (F,)

        Returns
        -------
        ndarray of bool (F,)
        """
        t = np.asarray(t, dtype=float)
        n = len(t)
        out = np.zeros(n, dtype=bool)
        if self.alarm is not None:
            out[:] = True
            return out
        if n == 0:
            return out
        g = np.asarray(gravity, dtype=float).reshape(n, 3)
        on = np.isfinite(g).all(axis=1) & np.asarray(usable, dtype=bool)
        # runs of frames in use: run r starts at frame first[r]
        edges = np.flatnonzero(np.diff(np.concatenate([[False], on, [False]]).astype(np.int8)))
        first = edges[0::2]
        carried = bool(first.size) and first[0] == 0 and self._armed_at == self._armed_at
        armed = t[first] + HOLD_OFF
        if carried:
            armed[0] = self._armed_at
        run_of = np.cumsum(np.concatenate([[0], np.diff(on.astype(np.int8)) == 1]))[on]   # run of each used frame
        run_of -= run_of[0] if run_of.size else 0
        used = np.flatnonzero(on)
        hist = used[t[used] >= armed[run_of]]                # frames appended to the history, in order
        hrun = np.searchsorted(first, hist, side="right") - 1
        # the history as arrays: the carried entries (if this batch continues the monitor's run), then the frames
        old = self._hist if carried else ()
        m0 = len(old)
        ht = np.concatenate([[e[0] for e in old], t[hist]]) if m0 else t[hist]
        gx, gy, gz = g[hist, 0], g[hist, 1], g[hist, 2]
        norm = np.sqrt(gx * gx + gy * gy + gz * gz)          # as _unit
        hu = np.stack([gx / norm, gy / norm, gz / norm], axis=1)
        if m0:
            hu = np.concatenate([np.array([e[1] for e in old], dtype=float).reshape(m0, 3), hu])
        hr = np.concatenate([np.zeros(m0, dtype=np.intp), hrun])
        start = np.searchsorted(hr, np.arange(len(first)), side="left")    # first history entry of each run
        k = np.arange(m0, len(ht))                                          # entries of this batch
        ref = np.searchsorted(ht, ht[k] - WINDOW, side="right") - 1         # last entry at least WINDOW s older
        has_ref = ref >= start[hr[k]]
        ref = np.where(has_ref, ref, start[hr[k]])
        u, r = hu[k], hu[ref]
        c = np.clip(u[:, 0] * r[:, 0] + u[:, 1] * r[:, 1] + u[:, 2] * r[:, 2], -1.0, 1.0)
        gate_end = armed[hr[k]] + GATE
        gating = has_ref & (ht[k] < gate_end)
        # the drift of each run: the largest angle of its gate (acos of the smallest cosine), from 0 or the carried one
        low = np.full(len(first), np.inf)
        np.minimum.at(low, hr[k][gating], c[gating])
        drift = np.zeros(len(first))
        if carried:
            drift[0] = self._drift
        for j in np.flatnonzero(low < np.inf).tolist():          # (one a run, not a frame)
            drift[j] = max(drift[j], math.acos(float(low[j])))
        judge = has_ref & ~gating & (c < _COS_THRESHOLD) & (drift[hr[k]] <= DRIFT_LIMIT)
        hit = np.flatnonzero(judge)
        if hit.size:
            a = int(hit[0])
            frame, j, end = int(hist[a]), int(hr[m0 + a]), m0 + a
            out[frame:] = True
            ca = float(c[a])
            self.alarm, self.alarm_t, self.reference = (
                f"mount moved: the measured gravity turned {math.acos(ca) / DEG:.1f} deg away from the mount's "
                f"up axis within {WINDOW:g} s, at t = {float(t[frame]):.1f} s", float(t[frame]),
                tuple(hu[ref[a]].tolist()))
        else:
            frame = n - 1
            j = len(first) - 1 if on[-1] else -1
            end = len(ht) - 1
        self._set_batch_state(t, ht, hu, hr, start, j, end, armed, drift, frame, on)
        return out

    def _set_batch_state(self, t, ht, hu, hr, start, j: int, end: int, armed, drift, frame: int, on) -> None:
        """The state after ``frame`` of :meth:`run` (``j``: that frame's run, -1 for a break)."""
        if j < 0:                                   # the last frame was a break: history cleared, drift kept
            self._hist.clear()
            self._armed_at = math.nan
            runs = np.flatnonzero(np.diff(np.concatenate([[False], on[:frame + 1]]).astype(np.int8)) == 1)
            if runs.size:                           # the drift of the last run before it (else unchanged)
                self._drift = float(drift[len(runs) - 1])
            return
        self._armed_at = float(armed[j])
        self._drift = float(drift[j])
        lo = int(start[j])
        if end < lo or hr[end] != j or ht[end] > t[frame]:           # nothing of this run entered the history yet
            self._hist = deque()
            return
        keep = int(np.searchsorted(ht[:end + 1], ht[end] - WINDOW, side="right")) - 1
        lo = max(lo, keep)
        self._hist = deque((float(ht[i]), tuple(hu[i].tolist())) for i in range(lo, end + 1))
