"""Mount-change detection: the measured gravity turns away from the mount's up axis faster than any drift.

With a measured speed the road's gravity/velocity filter (:mod:`imu_ground.filters.road`) keeps
gravity in its gyro-integrated world frame consistent with the accelerometer, so it turns its gravity
towards any turn of the accelerometer's view of gravity the gyro did not see: slowly for a gyro
drift, by most of a remount within seconds. The monitor compares the gravity direction now with
the one :data:`WINDOW` seconds before: an angle above :data:`THRESHOLD` raises the alarm (latched
until a reset). It first measures the gyro's own drift for :data:`GATE` seconds and stays silent if
that turns gravity by more than :data:`DRIFT_LIMIT` in a window. No comparison spans a frame without
a speed or a gap, nor starts within :data:`HOLD_OFF` seconds of the road filter's start or of such a
frame. Without a speed there is no monitor.

The monitor does not measure the change (the filter's gravity turns back over minutes): re-calibrate
(``imu-ground calibrate``) or let :mod:`imu_ground.filters.recalibration` re-estimate it online.
"""
from __future__ import annotations

import math
from math import acos, isnan, sqrt

import numpy as np

from imu_ground._jit import njit
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
# the monitor's scalars: history window [lo, hi) of the arrays, armed-at time (NaN: not armed), drift,
# alarm raised (0/1), its time, the cosine it saw, the reference direction (3)
_LO, _HI, _ARMED, _DRIFT, _ALARM, _ALARM_T, _ALARM_COS, _REF = range(8)


@njit
def _frame(s, ht, hu, t, gx, gy, gz, usable):
    """One frame on the state ``s`` and history ``ht`` (times), ``hu`` (unit gravity); NaN gravity: no road
    filter. Returns whether the alarm is raised."""
    if s[_ALARM] != 0.0:
        return True
    if not usable or isnan(gx) or isnan(gy) or isnan(gz):
        s[_LO], s[_HI], s[_ARMED] = 0.0, 0.0, np.nan            # history cleared, the drift kept
        return False
    if isnan(s[_ARMED]):                                        # (re)start the hold-off here
        s[_ARMED], s[_DRIFT] = t + HOLD_OFF, 0.0
    if t < s[_ARMED]:
        return False
    n = sqrt(gx * gx + gy * gy + gz * gz)
    ux, uy, uz = gx / n, gy / n, gz / n
    lo, hi = int(s[_LO]), int(s[_HI])
    ht[hi], hu[hi, 0], hu[hi, 1], hu[hi, 2] = t, ux, uy, uz
    hi += 1
    while hi - lo > 1 and ht[lo + 1] <= t - WINDOW:
        lo += 1
    s[_LO], s[_HI] = float(lo), float(hi)
    if ht[lo] > t - WINDOW:
        return False
    c = max(-1.0, min(1.0, ux * hu[lo, 0] + uy * hu[lo, 1] + uz * hu[lo, 2]))
    if t < s[_ARMED] + GATE:                                    # the gyro's own drift, measured first
        s[_DRIFT] = max(s[_DRIFT], acos(c))
        return False
    if c < _COS_THRESHOLD and s[_DRIFT] <= DRIFT_LIMIT:
        s[_ALARM], s[_ALARM_T], s[_ALARM_COS] = 1.0, t, c
        s[_REF], s[_REF + 1], s[_REF + 2] = hu[lo, 0], hu[lo, 1], hu[lo, 2]
        return True
    return False


@njit
def _frames(s, ht, hu, t, g, usable, out):
    """:func:`_frame` over a batch."""
    for k in range(t.shape[0]):
        out[k] = _frame(s, ht, hu, t[k], g[k, 0], g[k, 1], g[k, 2], usable[k])


class MountMonitor:
    """The monitor of the module docstring: :meth:`update` a frame, :meth:`run` a batch (one compiled body).

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
        self._s = np.zeros(_REF + 3)
        self._s[_ARMED] = math.nan
        self._ht, self._hu = np.zeros(64), np.zeros((64, 3))
        self.alarm: str | None = None
        self.alarm_t = math.nan
        self.reference: tuple | None = None
        self._engaged = False

    def _room(self, n: int) -> None:
        """Room in the history for ``n`` more entries."""
        s = self._s
        lo, hi = int(s[_LO]), int(s[_HI])
        if hi + n <= len(self._ht):
            return
        m = hi - lo
        cap = max(len(self._ht), 2 * (m + n))
        ht, hu = np.zeros(cap), np.zeros((cap, 3))
        ht[:m], hu[:m] = self._ht[lo:hi], self._hu[lo:hi]
        self._ht, self._hu, s[_LO], s[_HI] = ht, hu, 0.0, float(m)

    def _raised(self) -> str | None:
        """The alarm's reason, built once the body raised it."""
        s = self._s
        if self.alarm is None and s[_ALARM]:
            t = float(s[_ALARM_T])
            self.alarm_t, self.reference = t, tuple(s[_REF:_REF + 3].tolist())
            self.alarm = (f"mount moved: the measured gravity turned {math.acos(s[_ALARM_COS]) / DEG:.1f} deg away "
                          f"from the mount's up axis within {WINDOW:g} s, at t = {t:.1f} s")
        return self.alarm

    @property
    def active(self) -> bool:
        """Armed, past the drift check, and the gyro's drift small enough for the monitor to judge."""
        s = self._s
        lo, hi = int(s[_LO]), int(s[_HI])
        return bool(not math.isnan(s[_ARMED]) and hi > lo and self._ht[hi - 1] >= s[_ARMED] + GATE
                    and s[_DRIFT] <= DRIFT_LIMIT)

    @property
    def engaged(self) -> bool:
        """Armed or holding history: it must see every frame, with or without a road filter's gravity."""
        return self._engaged

    def _after_call(self) -> None:
        s = self._s
        self._engaged = bool(s[_HI] > s[_LO] or not math.isnan(s[_ARMED]))

    def update(self, t: float, gravity, usable: bool) -> str | None:
        """One frame: ``t`` its end (s), ``gravity`` the road filter's gravity reaction after it (world frame;
        None: no road filter), ``usable`` valid and with a speed. Returns the alarm's reason once raised, else
        None."""
        if self.alarm is not None:
            return self.alarm
        s = self._s
        if s[_HI] >= len(self._ht):
            self._room(1)
        gx, gy, gz = (math.nan, math.nan, math.nan) if gravity is None else gravity
        raised = _frame(s, self._ht, self._hu, t, gx, gy, gz, usable)
        self._after_call()
        return self._raised() if raised else None

    def run(self, t: np.ndarray, gravity: np.ndarray, usable: np.ndarray) -> np.ndarray:
        """:meth:`update` over a batch (``t`` (F,) non-decreasing, ``gravity`` (F, 3) with NaN rows for none,
        ``usable`` (F,)): per frame whether the alarm is raised, bool (F,)."""
        t = np.ascontiguousarray(t, dtype=float)
        n = len(t)
        out = np.zeros(n, dtype=bool)
        self._room(n)
        _frames(self._s, self._ht, self._hu, t, np.ascontiguousarray(gravity, dtype=float).reshape(n, 3),
                np.ascontiguousarray(usable, dtype=np.bool_).reshape(n), out)
        self._after_call()
        self._raised()
        return out

    def state_dict(self) -> dict:
        """Plain values, for a warm start."""
        s = self._s
        lo, hi = int(s[_LO]), int(s[_HI])
        return {"hist": [[t, u] for t, u in zip(self._ht[lo:hi].tolist(), self._hu[lo:hi].tolist(), strict=True)],
                "armed_at": float(s[_ARMED]), "drift": float(s[_DRIFT]), "alarm": self.alarm,
                "alarm_t": self.alarm_t, "reference": None if self.reference is None else list(self.reference)}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (a dict or a StateReader), every entry checked first."""
        st = as_reader(state, "MountMonitor")
        hist = st.rows("hist", lambda r: [r[0], *r[1]], 4)
        armed_at, drift = st.float("armed_at", nan=True), st.float("drift")
        alarm, alarm_t, reference = st.text("alarm"), st.float("alarm_t", nan=True), st.floats("reference", (3,),
                                                                                                optional=True)
        self.reset()
        self._room(len(hist))
        m = len(hist)
        self._ht[:m], self._hu[:m] = hist[:, 0], hist[:, 1:]
        s = self._s
        s[_HI], s[_ARMED], s[_DRIFT], s[_ALARM] = float(m), armed_at, drift, float(alarm is not None)
        self.alarm, self.alarm_t = alarm, alarm_t
        self.reference = None if reference is None else tuple(reference.tolist())
        self._after_call()
