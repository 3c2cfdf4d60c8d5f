r"""Online re-estimation of a mount that moved: the static rotation ground <- sensor turned by the change.

Frames and signs as in :mod:`imu_ground.filters.estimator` (body = ground frame, FLU); ``w`` is
the gyro-integrated world frame of the road's gravity/velocity filter
(:mod:`imu_ground.filters.road`), gravity stored as its reaction (up).

Model
-----
A remount turns the sensor by ``R_{s<-s'}``; with the old static rotation ``R_gs`` the
filter's body frame is then the true one turned by ``D = R_gs R_{s<-s'} R_gs^T``
(``x_true = D x_est``), and the correct static rotation is ``D R_gs``. The gyros do not see
the turn, so the gyro-integrated attitude continues smoothly: after the change at frame
``k0``, ``R_k = W R^true_k D`` with the fixed world tilt ``W = R_{k0} D^T R_{k0}^T``. The
gravity reaction measured in the filter's body frame is the frame-mean specific force minus
the kinematic acceleration (``a_x = dv/dt`` from the measured speed, ``a_y = v psi / dt``,
``a_z = 0``, less the centripetal ``(psi / dt)^2`` times the sensor's horizontal offset, the
extrinsic's translation; the neglected terms are along the body's up axis, a tilted gravity's
direction moves with them by their size times the tilt, and they average out over seconds: the
mean vertical velocity is zero); turned into
the world frame with ``R_k`` it is ``g`` before the change and ``W g`` after it, whatever the
road's grade and however the vehicle turned. So, per usable frame (valid, with a measured
speed now and at the frame before), the small rotation ``theta_k = u_ref x u_k`` from the
frozen gravity direction ``u_ref`` (the road filter's, at the start of the mount monitor's
window, before the change) to the measured one ``u_k`` (world frame) is a step
function of time: ~0, then ``w = Log(W)``, on top of the slow turn of the gyro-integrated
world frame (the gyro's bias: a linear drift over the fit). Level, drift and step are fitted by
least squares over the frames kept (from 5 s before the monitor's reference, :data:`WINDOW` s of
usable frames after the alarm), the step's time ``k0`` searched from the reference on (the
least residual); ``w`` is the step (a constant bias of the measurement is in the level and
cancels), and the change in the body frame is ``delta = -R_{k0}^T w`` (rotation vector; its
component about up is not observable from gravity and is left at 0). The attitude at ``k0``
matters: the vehicle may have turned since the change, and the change is a rotation of the
body axes it had then.

Applying it: ``R_gs <- Exp(delta) R_gs`` in every part of the filter that turns sensor
increments into the body frame, each gravity/velocity filter's attitude ``R_k <- R_k
Exp(delta)^T`` (the body axes change, the world does not), its gravity set to the frozen
direction turned by ``W`` and the drift since (its own magnitude kept), the residual filter's
state (road <- body: the suspension model and the road's adaptation keep it near the truth
through the change) kept, and the mount monitor restarted (its hold-off and drift check run
again). A yaw of the mount is not corrected.

Measured on synthetic drives in ``benchmarks/RESULTS.md`` (``benchmarks/studies/confidence.py``).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Optional

import numpy as np

from imu_ground import so3
from imu_ground.filters.estimator import SuspensionTrack
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.frame_checks import checked_frames
from imu_ground.filters.mount_monitor import WINDOW as MONITOR_WINDOW

__all__ = ["WINDOW", "MountRecalibrator", "apply_mount_change", "recalibrated_reason", "run_by_steps",
           "step_recalibration"]

#: Usable frames after the alarm the change is estimated from, s (15: on the synthetic navigation-grade drives the
#: normal is then within 0.07 deg of the truth; 10 s: 0.1 deg; benchmarks/RESULTS.md has the 15 s figures).
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
        speed : float
            Measured speed at the frame's end, m/s (NaN: none).
        psi : float
            Heading change over the frame, rad.
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
        """The change from the frames kept: ``reference`` is the frozen gravity direction (world frame) at
        ``t_ref`` (s), before the change, which is searched after it.

        The rotation from the reference to each frame's measured gravity is fitted as a level, a
        linear drift (the gyro-integrated world frame turns with the gyro's bias: on the synthetic
        navigation-grade drives up to 0.02 deg/s, 0.2 deg over the fit) and the step.

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
        best = (np.inf, 0, None)
        for k0 in np.flatnonzero((rows[:, 0] >= t_ref) & (np.arange(n) >= 5) & (np.arange(n) <= n - 5)):
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

    @staticmethod
    def restore_mount(f, Rgs: np.ndarray) -> None:
        """Set the static rotation ``Rgs`` (ground <- sensor) on the Python side of filter ``f`` (a warm start:
        the kernels' buffers hold it)."""
        _set_mount_attributes(f, Rgs)

    def state(self) -> dict:
        """Plain values, for a warm start."""
        return {"frames": [list(r) for r in self._frames], "prev_speed": self._prev_speed,
                "prev_R": None if self._prev_R is None else list(self._prev_R), "after": self._after,
                "delta": None if self.delta is None else self.delta.tolist(), "note": self.note, "count": self.count}

    def load(self, st: dict) -> None:
        """Back to a :meth:`state`."""
        self._frames = deque(tuple(float(v) for v in r) for r in st["frames"])
        self._prev_speed, self._after = float(st["prev_speed"]), float(st["after"])
        self._prev_R = None if st["prev_R"] is None else tuple(float(v) for v in st["prev_R"])
        self.delta = None if st["delta"] is None else np.array(st["delta"], dtype=float)
        self.note, self.count = st["note"], int(st["count"])


def _set_gravity_filter(gf, Rgs: np.ndarray, D: np.ndarray, direction: np.ndarray) -> None:
    """A gravity/velocity filter after the change: its extrinsic, attitude ``R D^T`` and gravity direction."""
    from imu_ground.filters.gravity_kernel import I_EXTR
    if gf._w.sync is not None:
        gf._pull()
    s = gf._s
    R = np.array(s[27:36], dtype=float).reshape(3, 3) @ D.T
    g = np.array(s[3:6], dtype=float)
    s[3:6] = (np.linalg.norm(g) * direction).tolist()
    s[27:36] = R.ravel().tolist()
    s[I_EXTR] = 1.0
    s[I_EXTR + 1:I_EXTR + 10] = Rgs.ravel().tolist()


def apply_mount_change(f, delta: np.ndarray, w: np.ndarray, reference) -> None:
    """Turn the static rotation of a :class:`~imu_ground.filters.suspension.SuspensionAwareFilter` by ``delta``.

    Parameters
    ----------
    f : SuspensionAwareFilter
    delta : ndarray (3,)
        Rotation vector of the change, body frame, rad (``R_gs <- Exp(delta) R_gs``).
    w : ndarray (3,)
        Rotation vector of the world tilt, the road filter's world frame, rad.
    reference : sequence of 3 float
        The frozen gravity direction before the change (road filter's world frame).
    """
    D = so3.exp(np.asarray(delta, dtype=float))
    Rgs = D @ (np.eye(3) if f._Rgs is None else f._Rgs)
    road = f.road_filter.gravity_filter
    Rr = np.array(road._s[27:36] if road._w.sync is None else road.cumulative, dtype=float).reshape(3, 3)
    Rm = f.gravity_filter.cumulative.copy()
    up = so3.exp(np.asarray(w, dtype=float)) @ (np.asarray(reference, dtype=float) / np.linalg.norm(reference))
    _set_gravity_filter(road, Rgs, D, up)
    _set_gravity_filter(f.gravity_filter, Rgs, D, Rm @ Rr.T @ up)    # (its world: Rm Rr^T <- the road filter's)
    buf = f._kernel.buf
    buf[28] = 1.0                                                   # residual kernel: has_Rgs, then R_gs
    buf[30:39] = _array_like(buf, Rgs.ravel().tolist())
    _set_mount_attributes(f, Rgs)


def _set_mount_attributes(f, Rgs: np.ndarray) -> None:
    """The static rotation where the filter's Python objects keep it (its kernels' buffers aside)."""
    f._Rgs = f.model._Rgs = Rgs
    for gf in (f.gravity_filter, f.road_filter.gravity_filter):
        if gf is not None:
            gf._Rgs, gf._identity_extrinsic, gf._rgs9 = Rgs, False, Rgs.ravel().tolist()
    f.road_filter._kw["extrinsic"] = Extrinsic(Rgs, f.extrinsic.translation, dict(f.extrinsic.meta))


def _array_like(buf, values: list):
    """``values`` ready to be assigned into a slice of ``buf`` (array('d'), ndarray or list)."""
    from array import array
    return array("d", values) if isinstance(buf, array) else values


def step_recalibration(f, dt: float, force, speed: float, psi: float, road, valid: bool, alarm):
    """One frame of the online re-estimation of a :class:`~imu_ground.filters.suspension.SuspensionAwareFilter`.

    Records the frame; once :data:`WINDOW` s of usable frames followed the mount monitor's alarm,
    estimates the change, applies it (:func:`apply_mount_change`) and restarts the monitor.

    Parameters
    ----------
    f : SuspensionAwareFilter
        With ``recalibrate_online``; its clock ``_time`` is the frame's end.
    dt, force, speed, psi, road, valid
        As :meth:`MountRecalibrator.record` takes them.
    alarm : str or None
        The monitor's alarm of the frame.

    Returns
    -------
    str or None
        The alarm still standing after the frame (None once re-estimated).
    """
    r = f.recalibrator
    usable = valid and road is not None
    r.record(f._time, dt, force, speed, psi, road, valid)
    if alarm is None:
        return None
    mm = f.mount_monitor
    if not r.ready(mm.alarm_t, dt, usable):
        return alarm
    est = r.estimate(mm.reference, mm.alarm_t - MONITOR_WINDOW)
    if est is None:
        return alarm
    delta, w = est
    apply_mount_change(f, delta, w, mm.reference)
    mm.reset()
    r._after = 0.0
    r.delta, r.note, r.count = delta, recalibrated_reason(delta, f._time), r.count + 1
    return None


def run_by_steps(f, em, speed: Optional[np.ndarray]) -> SuspensionTrack:
    """``SuspensionAwareFilter.run`` frame by frame through ``step`` (what online re-estimation needs: the
    static rotation may change within the batch); the same track fields as the vectorised run."""
    n = len(em)
    checked_frames(em.delta_R, em.delta_v, em.delta_t, em.t, f.on_invalid)   # (raises before any frame)
    f.model.design(float(em.rate))
    if speed is not None:
        speed = np.asarray(speed, dtype=float)
        if speed.shape != (n,):
            raise ValueError(f"speed must have one value per frame ({n}), got shape {speed.shape}")
    E, P, cum, Rgs = (np.zeros((n, 3, 3)) for _ in range(4))
    load, gains, grav = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 3))
    sp, valid = np.zeros(n), np.zeros(n, dtype=bool)
    extra = {k: np.full(n, np.nan) for k in ("pitch_std", "roll_std", "road_grade", "road_bank",
                                               "road_grade_std", "road_bank_std")}
    status, reasons = np.zeros(n, dtype=np.uint8), np.full(n, "", dtype=object)
    d, dv, dts = (np.asarray(a, dtype=float) for a in (em.delta_R, em.delta_v, em.delta_t))
    st, ok = np.asarray(em.stationary, dtype=bool), np.asarray(em.valid, dtype=bool)
    eye = np.eye(3)
    for k in range(n):
        gains[k] = f.gains
        est = f.step(d[k], dv[k], float(dts[k]), bool(st[k]), bool(ok[k]),
                     speed=None if speed is None else float(speed[k]))
        E[k], P[k], cum[k] = f.residual, f.P, f.cumulative
        Rgs[k] = eye if f._Rgs is None else f._Rgs
        load[k], sp[k], grav[k] = f.last_load, f.speed, f.gravity_filter.x[3:]
        valid[k] = est.valid and ok[k]
        status[k], reasons[k] = est.status_code, est.status_reason
        for key, v in extra.items():
            v[k] = getattr(est, key)
    return SuspensionTrack.from_residuals(
        E, cum @ np.swapaxes(E, 1, 2), P, cum, Rgs, f.extrinsic.translation, em.t, valid, load=load, speed=sp,
        gains=gains, suspension=f.model.tilt(gains, load), gravity=grav, status=status, status_reason=reasons,
        **extra)
