r"""Online re-estimation of a mount that moved: the static rotation ground <- sensor turned by the change.

Frames and signs: :mod:`imu_ground.filters.estimator` (body = ground frame, FLU); ``w`` is the gyro-integrated
world frame of the road's gravity/velocity filter (:mod:`imu_ground.filters.road`), gravity stored as its reaction.

A remount turns the sensor by ``R_{s<-s'}``; with the old ``R_gs`` the filter's body frame is the true one turned by
``D = R_gs R_{s<-s'} R_gs^T`` and the correct static rotation is ``D R_gs``. The gyros do not see the turn, so after
the change at frame ``k0`` ``R_k = W R^true_k D`` with the fixed world tilt ``W = R_{k0} D^T R_{k0}^T``. The gravity
reaction measured in the body frame (frame-mean specific force minus the kinematic acceleration from the measured
speed and yaw rate, less the centripetal term at the sensor's offset), turned into the world frame with ``R_k``, is
``g`` before the change and ``W g`` after. So the small rotation ``theta_k = u_ref x u_k`` from the frozen gravity
direction ``u_ref`` (the road filter's at the start of the mount monitor's window) to the measured ``u_k`` is a step,
~0 then ``w = Log(W)``, on the world frame's linear drift: level, drift and step are fitted by least squares over
the frames kept (from 5 s before the reference to :data:`WINDOW` s of usable frames after the alarm), ``k0``
searched for the least residual; the change in the body frame is ``delta = -R_{k0}^T w`` (its component about up
is not observable, left at 0).

:class:`~imu_ground.filters.suspension.SuspensionAwareFilter` applies it: ``R_gs <- Exp(delta) R_gs``, each
gravity/velocity filter's ``R_k <- R_k Exp(delta)^T`` and its gravity along the frozen direction turned by ``W`` and
the drift since, the residual filter's state kept, the mount monitor restarted. A yaw of the mount is not corrected.
"""
from __future__ import annotations

import math
from collections import deque
from typing import Optional

import numpy as np

from imu_ground.filters.mount_monitor import WINDOW as MONITOR_WINDOW
from imu_ground.imu.warm_start import as_reader

__all__ = ["WINDOW", "MountRecalibrator", "recalibrated_reason"]

#: Usable frames after the alarm the change is estimated from, s.
WINDOW = 15.0
_KEEP = MONITOR_WINDOW + WINDOW + 5.0          # s of frames kept (the monitor's window before the alarm, then WINDOW)


def recalibrated_reason(delta: np.ndarray, t: float) -> str:
    """The status note after a re-estimation (``delta``: rotation vector of the change, body frame, rad)."""
    return (f"mount re-estimated online at t = {t:.1f} s: turned {math.degrees(delta[1]):+.2f} deg in pitch, "
            f"{math.degrees(delta[0]):+.2f} deg in roll")


class MountRecalibrator:
    """The per-frame record and the estimate of the module docstring (streaming; the batch steps it too).

    Attributes
    ----------
    delta : ndarray (3,) or None
        The last change estimated (rotation vector, body frame, rad).
    note : str or None
        :func:`recalibrated_reason` of the last re-estimation.
    count : int
        Re-estimations so far.
    """

    def __init__(self, lever=(0.0, 0.0, 0.0)) -> None:
        self.lever = tuple(float(v) for v in lever)
        self.reset()

    def reset(self) -> None:
        """Forget everything."""
        self._frames: deque = deque()            # (t, gravity direction u_k (3), R_k (9)) of usable frames
        self._prev_speed = math.nan
        self._prev_R: Optional[tuple] = None
        self._after = 0.0                        # s of usable frames since the alarm
        self.delta: Optional[np.ndarray] = None
        self.note: Optional[str] = None
        self.count = 0

    def record(self, t: float, dt: float, f, speed: float, psi: float, road, usable: bool) -> None:
        """One frame.

        Parameters
        ----------
        t, dt : float
            Frame end time and duration, s.
        f : sequence of 3 float
            Frame-mean specific force, body frame (the filter's), m/s^2.
        speed, psi : float
            Measured speed at the frame's end, m/s (NaN: none), and heading change over the frame, rad.
        road : tuple or None
            The road filter's output of the frame (``(g, R, p6)``, :meth:`RoadFilter.step`), None without.
        usable : bool
            Valid frame (no gap).
        """
        prev_speed, prev_R = self._prev_speed, self._prev_R
        self._prev_speed = speed
        self._prev_R = None if road is None else road[1]
        if not (usable and road is not None and prev_R is not None and prev_speed == prev_speed):
            return
        R = road[1]
        rate = psi / dt
        c = rate * rate                                        # centripetal: the sensor is at ``lever`` (m, body)
        ax = (speed - prev_speed) / dt - c * self.lever[0]
        ay = 0.5 * (speed + prev_speed) * rate - c * self.lever[1]
        mb = (f[0] - ax, f[1] - ay, f[2])
        # world frame, the attitude at mid-frame to first order (the mean of the two ends)
        u = [0.5 * ((R[3 * i] + prev_R[3 * i]) * mb[0] + (R[3 * i + 1] + prev_R[3 * i + 1]) * mb[1]
                    + (R[3 * i + 2] + prev_R[3 * i + 2]) * mb[2]) for i in range(3)]
        fr = self._frames
        fr.append((t, u[0], u[1], u[2]) + tuple(R))
        while fr and fr[0][0] < t - _KEEP:
            fr.popleft()

    def ready(self, alarm_t: float, dt: float, usable: bool) -> bool:
        """Count the frame towards :data:`WINDOW` after an alarm at ``alarm_t``; True once enough is seen."""
        if usable and self._frames and self._frames[-1][0] > alarm_t:
            self._after += dt
        return self._after >= WINDOW

    def estimate(self, reference, t_ref: float) -> Optional[tuple]:
        """The change (module docstring) from the frames kept: ``reference`` the frozen gravity direction (world
        frame) at ``t_ref`` (s), before the change, which is searched after it.

        Returns
        -------
        (delta, w) or None
            Rotation vectors (rad) of the change in the body frame, and from the reference to
            gravity now (the step plus the drift since ``t_ref``, world frame); None if too few frames.
        """
        rows = np.array(self._frames)
        n = len(rows)
        if n < 20:
            return None
        ref = np.asarray(reference, dtype=float)
        ref = ref / np.linalg.norm(ref)
        m = rows[:, 1:4]
        theta = np.cross(ref, m) / np.linalg.norm(m, axis=1).mean()   # u_ref -> u_k, small angle, world frame
        t = rows[:, 0] - rows[-1, 0]
        best: tuple[float, int, np.ndarray | None] = (np.inf, 0, None)
        for k0 in np.flatnonzero((rows[:, 0] >= t_ref) & (np.arange(n) >= 5) & (np.arange(n) <= n - 5)).tolist():
            A = np.column_stack([np.ones(n), t, np.arange(n) >= k0])      # level, the world frame's drift, step
            coef, res, _, _ = np.linalg.lstsq(A, theta, rcond=None)
            sse = float(res.sum()) if len(res) else float(((A @ coef - theta) ** 2).sum())
            if sse < best[0]:
                best = (sse, int(k0), coef)
        _, k0, coef = best
        if coef is None:
            return None
        w = coef[2]
        R0 = rows[k0 - 1, 4:13].reshape(3, 3)                    # the attitude at the change
        delta = -R0.T @ w
        delta[2] = 0.0
        return delta, w + coef[1] * (rows[-1, 0] - t_ref)

    def accept(self, delta: np.ndarray, t: float) -> None:
        """Record a re-estimation applied at ``t`` (s); the count of frames after an alarm starts over."""
        self._after = 0.0
        self.delta, self.note, self.count = delta, recalibrated_reason(delta, t), self.count + 1

    def state_dict(self) -> dict:
        """Plain values, for a warm start."""
        return {"frames": [list(r) for r in self._frames], "prev_speed": self._prev_speed,
                "prev_R": None if self._prev_R is None else list(self._prev_R), "after": self._after,
                "delta": None if self.delta is None else self.delta.tolist(), "note": self.note, "count": self.count}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (dict or :class:`~imu_ground.imu.warm_start.StateReader`), every entry
        checked before the record changes."""
        st = as_reader(state, "MountRecalibrator")
        frames = st.rows("frames", list, 13)
        prev_speed, after = st.float("prev_speed", nan=True), st.float("after")
        prev_R, delta = st.floats("prev_R", (9,), optional=True), st.floats("delta", (3,), optional=True)
        note, count = st.text("note"), st.int("count")
        self._frames = deque(tuple(r) for r in frames.tolist())
        self._prev_speed, self._after = prev_speed, after
        self._prev_R = None if prev_R is None else tuple(prev_R.tolist())
        self.delta, self.note, self.count = delta, note, count
