r"""How sure an estimate is: the calibrated 1-sigma of pitch and roll, and a per-frame status with its reason.

1-sigma
-------
The residual filter's covariance of the road attitude is ``diag(a, a, c)`` (rad^2,
:mod:`imu_ground.filters.residual`); it knows the unmodelled body motion but not the errors of the
suspension model nor of the gravity estimate. The variance of the body-relative-to-road pitch and roll is

.. math::

    \sigma^2 = c_a^2\,a + (g_x u_x)^2 + (g_y u_y)^2 + (h\,\omega)^2 + f^2 + \sigma_b^2 + (r\,\rho)^2 + (m\,d)^2

with ``u`` the suspension model's load (m/s^2, body frame), ``omega`` the yaw rate (rad/s,
:func:`~imu_ground.so3.heading_change` over the frame duration) and ``h`` its weight, ``f`` a floor,
``sigma_b^2`` the gravity estimate's horizontal variance carried through the load into the modelled tilt
(:func:`tilt_weights`). The drive terms (:class:`DriveStatistics`, causal, IMU-only): ``rho`` the RMS body
rate about the angle's axis over the moving frames so far (a rough road), ``d`` the mean load along that axis
off a centre ``c`` (m/s^2; an accelerometer bias, which cannot be told from a road crown, so it only widens the
1-sigma), weighted by ``r`` and ``m``. The constants are fitted by ``benchmarks/studies/calibrate_std.py``.

Status
------
One of :data:`STATUSES` per frame, the first that applies in this order:

- ``invalid``: a bad frame the estimator skipped (``on_invalid="skip"``); the values are the previous frame's;
- ``gap``: the frame was integrated through a timestamp gap (``valid`` False);
- ``degraded``: a monitor flags it, the reason says which (the mount monitor,
  :mod:`imu_ground.filters.mount_monitor`, from the alarm on until re-estimated);
- ``standstill``: the frame ends at a standstill (the road and the body are held);
- ``converging``: from the start (and a reset) until ``max(pitch_std, roll_std)`` without the drive terms has
  once been at or below :data:`CONVERGED_STD` (:data:`FILTER_CONVERGED_STD` for the filter without
  suspension model) after :data:`CONVERGED_MOVING_SECONDS` of moving frames (latched);
- ``ok``; its reason is empty or a note (:func:`ok_note`): :data:`SLOW_REASON` below :data:`SLOW_SPEED`
  (road and body tilt no longer well separated), and, where the road is not estimated, why.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from imu_ground._jit import jitable, njit
from imu_ground.imu.warm_start import as_reader
from imu_ground.units import DEG

__all__ = ["STATUSES", "CONVERGING", "OK", "STANDSTILL", "GAP", "DEGRADED", "INVALID", "CONVERGED_STD", "FILTER_CONVERGED_STD",
           "CONVERGED_MOVING_SECONDS",
           "AngleStd", "DriveStatistics", "DRIVE_PRIOR_SECONDS", "SigmaModel", "frame_std", "frame_reason", "SUSPENSION_STD", "FILTER_STD",
           "SLOW_SPEED", "SLOW_REASON", "ok_note", "tilt_weights", "status_reason", "frame_status_code", "gap_run_durations",
           "track_statuses", "track_reasons", "status_names"]

#: The statuses, indexed by their code.
STATUSES = ("converging", "ok", "standstill", "gap", "degraded", "invalid")
CONVERGING, OK, STANDSTILL, GAP, DEGRADED, INVALID = range(6)
#: A frame whose larger 1-sigma (pitch or roll) is at or below this (rad, 0.15 deg) ends ``converging``
#: (:class:`~imu_ground.filters.suspension.SuspensionAwareFilter`).
CONVERGED_STD = 0.15 * DEG
#: The same for :class:`~imu_ground.filters.ground.GroundNormalFilter` (rad, 0.8 deg: the end of its initial
#: covariance's transient).
FILTER_CONVERGED_STD = 0.8 * DEG
#: Seconds of moving frames (:class:`DriveStatistics`) the suspension filter's latch waits for besides its
#: 1-sigma threshold (chosen by ``benchmarks/studies/convergence_time.py``).
CONVERGED_MOVING_SECONDS = 10.0
#: Below this speed (m/s; the evaluation's moving-frame threshold) an ``ok`` frame carries :data:`SLOW_REASON`.
SLOW_SPEED = 3.0
#: The note of an ``ok`` frame slower than :data:`SLOW_SPEED`.
SLOW_REASON = "too slow to separate road from body (below 3 m/s)"


@dataclass(frozen=True)
class AngleStd:
    """Constants of the 1-sigma model of the module docstring, one set per angle.

    Attributes
    ----------
    cov_scale, load_x, load_y, floor, turn, rough, drive_load, load_center : float
        ``c_a``; ``g_x, g_y`` (rad per m/s^2 of load); ``f`` (rad); ``h`` (rad per rad/s of yaw rate); ``r``
        (rad per rad/s of RMS body rate); ``m`` (rad per m/s^2 of mean load off ``c``); ``c`` (m/s^2).
    """
    cov_scale: float
    load_x: float
    load_y: float
    floor: float
    turn: float = 0.0
    rough: float = 0.0
    drive_load: float = 0.0
    load_center: float = 0.0

    def variance(self, a, load_x=0.0, load_y=0.0, tilt_var=0.0, yaw_rate=0.0, rate_ms=0.0, load_offset=0.0):
        """``sigma^2`` (rad^2) of the module docstring; floats or arrays alike.

        Parameters
        ----------
        a : float or ndarray
            The filter's horizontal variance of the road attitude, rad^2.
        load_x, load_y, tilt_var, yaw_rate : float or ndarray
            ``u_x, u_y`` (m/s^2, body frame), ``sigma_b^2`` (rad^2), ``omega`` (rad/s, either sign).
        rate_ms, load_offset : float or ndarray
            ``rho^2`` ((rad/s)^2) and ``d`` (m/s^2) of :meth:`DriveStatistics.terms`.
        """
        gx, gy, h, m = self.load_x * load_x, self.load_y * load_y, self.turn * yaw_rate, self.drive_load * load_offset
        return (self.cov_scale * self.cov_scale * a + gx * gx + gy * gy + h * h + self.floor * self.floor + tilt_var
                + self.rough * self.rough * rate_ms + m * m)


#: Pitch and roll 1-sigma constants of :class:`~imu_ground.filters.suspension.SuspensionAwareFilter`.
SUSPENSION_STD = (AngleStd(0.0416, 0.0221 * DEG, 0.0259 * DEG, 0.0129 * DEG, 0.00785 * DEG, 0.0763, 0.362 * DEG,
                           0.0018),
                  AngleStd(0.395, 0.0262 * DEG, 0.0563 * DEG, 0.0396 * DEG, 0 * DEG, 0.0754, 0.488 * DEG, 0.177))
#: Pitch and roll 1-sigma constants of :class:`~imu_ground.filters.ground.GroundNormalFilter` (no load; its
#: covariance is a tuning, so the 1-sigma is a constant: never ``converging``).
FILTER_STD = (AngleStd(0.0, 0.0, 0.0, 0.226 * DEG), AngleStd(0.0, 0.0, 0.0, 0.327 * DEG))


def tilt_weights(k_pitch: Any, k_roll: Any, load_share: float, cross_gain: float) -> tuple:
    """Factors of the gravity estimate's horizontal variance ((m/s^2)^2) in the modelled pitch's and roll's
    (rad^2): ``h (k_pitch^2 + k_cross^2)`` and ``h k_roll^2``, ``h = (1 - s)^2 / 2``; floats or arrays alike."""
    h = 0.5 * (1.0 - load_share) ** 2
    return h * (k_pitch * k_pitch + cross_gain * cross_gain), h * k_roll * k_roll


def ok_note(slow: bool, road_note: Optional[str]) -> Optional[str]:
    """The note of an ``ok`` frame: :data:`SLOW_REASON` when ``slow``, then ``road_note`` (None: no note)."""
    if slow:
        return SLOW_REASON if road_note is None else f"{SLOW_REASON}; {road_note}"
    return road_note


def status_reason(code: int, gap_seconds: float = math.nan, std: float = math.nan,
                  detail: Optional[str] = None, converged_std: float = CONVERGED_STD,
                  moving_seconds: float = 0.0) -> str:
    """The short text of a status (empty for ``ok``).

    Parameters
    ----------
    code : int
        Index into :data:`STATUSES`.
    gap_seconds : float
        Duration of the gap, s (``gap``; a frame's own, the output table the run's: :func:`gap_run_durations`).
    std, converged_std, moving_seconds : float
        For ``converging``: the larger 1-sigma (rad), the threshold (rad), the moving time the latch waits for (s).
    detail : str, optional
        The reason of ``degraded``, the problem of ``invalid`` or the note of ``ok``.
    """
    if code == OK:
        return detail or ""
    if code == CONVERGING:
        if moving_seconds > 0:
            return (f"converging: 1-sigma {std / DEG:.2f} deg; ok once at or below {converged_std / DEG:.2f} deg "
                    f"after {moving_seconds:.0f} s of driving above {SLOW_SPEED:.0f} m/s since the start or a reset")
        return (f"converging: 1-sigma {std / DEG:.2f} deg, not yet below {converged_std / DEG:.2f} deg "
                f"since the start or a reset")
    if code == STANDSTILL:
        return "standstill: road and body attitude held"
    if code == GAP:
        return f"{gap_seconds:.1f} s gap in the log, integrated through"
    if code == INVALID:
        return "bad ego-motion frame skipped" + (f": {detail}" if detail else "")
    return detail or "degraded"


def status_names(codes: np.ndarray) -> np.ndarray:
    """The :data:`STATUSES` names of an array of codes (object array of str)."""
    return np.asarray(STATUSES, dtype=object)[np.asarray(codes, dtype=np.intp)]


def frame_status_code(converged: Any, stationary: Any, valid: Any, degraded: Any = False) -> Any:
    """The status code of one processed frame, or of a batch's (0/1 int arrays): the latch ``converged``, then
    ``standstill``, ``degraded`` and ``gap``, each overriding the ones before."""
    code = CONVERGING + (OK - CONVERGING) * converged
    code = code + (STANDSTILL - code) * stationary
    code = code + (DEGRADED - code) * degraded
    return code + (GAP - code) * (1 - valid)


def track_statuses(var_max: np.ndarray, stationary: np.ndarray, valid: np.ndarray, good: np.ndarray,
                   converged: bool = False, degraded: Optional[np.ndarray] = None,
                   converged_std: float = CONVERGED_STD) -> tuple[np.ndarray, bool]:
    """The status codes of a batch: :func:`frame_status_code` with the latch accumulated, ``invalid`` where skipped.

    Parameters
    ----------
    var_max : ndarray (F,)
        ``max(pitch_std, roll_std)^2`` per frame, rad^2.
    stationary, valid, good : ndarray of bool (F,)
        The ego-motion's flags; ``good`` False for a skipped bad frame.
    converged : bool
        The latch before the first frame.
    degraded : ndarray of bool (F,), optional
        Frames a monitor flags.
    converged_std : float
        The threshold, rad.

    Returns
    -------
    codes : ndarray of uint8 (F,)
    converged : bool
        The latch after the last frame.
    """
    good = np.asarray(good, dtype=bool)
    n = len(good)
    below = good & (np.asarray(var_max, dtype=float) <= converged_std * converged_std)
    conv = np.logical_or.accumulate(below) | converged if n else below
    deg = 0 if degraded is None else np.asarray(degraded, dtype=np.intp)
    codes = frame_status_code(conv.astype(np.intp), np.asarray(stationary, dtype=np.intp),
                              np.asarray(valid, dtype=np.intp), deg).astype(np.uint8)
    codes[~good] = INVALID
    return codes, bool(conv[-1]) if n else bool(converged)


def gap_run_durations(gap: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """``dt`` (s) with each run of consecutive ``gap`` frames replaced by the run's summed duration."""
    gap, dt = np.asarray(gap, dtype=bool), np.asarray(dt, dtype=float)
    if not gap.any():
        return dt
    start = gap & ~np.concatenate([[False], gap[:-1]])
    run = np.cumsum(start) - 1
    total = np.bincount(run[gap], weights=dt[gap])
    out = dt.copy()
    out[gap] = total[run[gap]]
    return out


def track_reasons(codes: np.ndarray, std_max: np.ndarray, dt: np.ndarray,
                  details: Optional[np.ndarray] = None, converged_std: float = CONVERGED_STD,
                  moving_seconds: float = 0.0) -> np.ndarray:
    """:func:`status_reason` of every frame of a batch (object array of str).

    Parameters
    ----------
    codes, std_max, dt : ndarray (F,)
        Status codes, ``max(pitch_std, roll_std)`` (rad), frame durations (s).
    details : ndarray of object (F,), optional
        ``detail`` of :func:`status_reason` per frame.
    converged_std, moving_seconds : float
        As in :func:`status_reason`.
    """
    codes = np.asarray(codes)
    out = np.full(len(codes), "", dtype=object)
    detail = np.full(len(codes), None, dtype=object) if details is None else np.asarray(details, dtype=object)
    for code in (OK, STANDSTILL, DEGRADED, INVALID):
        k = np.flatnonzero(codes == code)
        if k.size:
            d = detail[k].tolist()
            texts = {v: status_reason(code, detail=v) for v in set(d)}
            out[k] = [texts[v] for v in d]
    for i in np.flatnonzero((codes == CONVERGING) | (codes == GAP)).tolist():
        out[i] = status_reason(int(codes[i]), float(dt[i]), float(std_max[i]), detail[i], converged_std,
                               moving_seconds)
    return out

#: Prior weight of the drive statistics, s of moving frames at zero body rate and at the load centre
#: (:class:`DriveStatistics`): the drive terms grow in as the drive shows its road and its accelerometer.
DRIVE_PRIOR_SECONDS = 30.0


def _rows(Rgs) -> Optional[tuple]:
    """The first two rows of ``Rgs`` as 6 floats (None: the identity)."""
    return None if Rgs is None else tuple(np.asarray(Rgs, dtype=float)[:2].ravel().tolist())


@jitable
def _drive_frame(s, m, dt, speed, stationary, valid, ux, uy, r):
    """One frame of :class:`DriveStatistics` on its state ``s``: ``m`` (9, row-major), ``r`` :func:`_rows`."""
    if not valid or stationary or not abs(speed) >= SLOW_SPEED:
        return
    vx, vy = 0.5 * (m[7] - m[5]), 0.5 * (m[2] - m[6])
    if r is not None:
        vz = 0.5 * (m[3] - m[1])
        vx, vy = r[0] * vx + r[1] * vy + r[2] * vz, r[3] * vx + r[4] * vy + r[5] * vz
    wx, wy = vx / dt, vy / dt
    s[0] += dt
    s[1] += dt * ux
    s[2] += dt * uy
    s[3] += dt * wx * wx
    s[4] += dt * wy * wy


@njit
def _drive_frames(s, d, dt, speed, stationary, valid, load, r, out):
    for k in range(dt.shape[0]):
        _drive_frame(s, d[k], dt[k], speed[k], stationary[k], valid[k], load[k, 0], load[k, 1], r)
        for i in range(5):
            out[k, i] = s[i]


class DriveStatistics:
    r"""The drive terms of the 1-sigma (module docstring): duration-weighted sums over the moving frames (valid,
    not at a standstill, speed at or above :data:`SLOW_SPEED`). One body: :meth:`update` a frame, :meth:`run` a
    batch. The body rates are ``vee((D - D^T) / 2) / dt`` of the sensor increment ``D``, turned into the ground
    frame (x roll, y pitch, rad/s).

    Attributes
    ----------
    state : list of 5 float
        ``[t, S_ux, S_uy, S_wx2, S_wy2]``: moving seconds, and the sums over the moving frames of ``dt u_x``,
        ``dt u_y`` (m), ``dt w_x^2``, ``dt w_y^2`` (rad^2/s).
    """

    def __init__(self) -> None:
        self._rgs: Any = None
        self._rows = _rows(None)
        self.reset()

    def reset(self) -> None:
        """No moving frame yet."""
        self.state = [0.0, 0.0, 0.0, 0.0, 0.0]

    def update(self, d: np.ndarray, dt: float, speed: float, stationary: bool, valid: bool, ux: float, uy: float,
               Rgs: Optional[np.ndarray] = None) -> None:
        """One frame: ``d`` the sensor increment (3x3), ``dt`` s, ``speed`` m/s, ``ux, uy`` the load (m/s^2),
        ``Rgs`` ground <- sensor (None: the identity)."""
        if Rgs is not self._rgs:
            self._rgs, self._rows = Rgs, _rows(Rgs)
        _drive_frame(self.state, np.asarray(d, dtype=float).ravel().tolist(), dt, speed, stationary, valid, ux, uy,
                     self._rows)

    def run(self, delta_R: np.ndarray, dt: np.ndarray, speed: np.ndarray, stationary: np.ndarray,
            valid: np.ndarray, load: np.ndarray, Rgs: Optional[np.ndarray] = None) -> np.ndarray:
        """:meth:`update` over N frames (``delta_R`` (N, 3, 3), ``load`` (N, 2), the others (N,)): the state
        after each, (N, 5); :attr:`state` advanced to the last."""
        c = np.ascontiguousarray
        n = len(dt)
        out, s = np.empty((n, 5)), np.array(self.state, dtype=float)
        _drive_frames(s, c(delta_R, dtype=float).reshape(n, 9), c(dt, dtype=float), c(speed, dtype=float),
                      c(stationary, dtype=np.bool_), c(valid, dtype=np.bool_), c(load, dtype=float), _rows(Rgs), out)
        self.state = s.tolist()
        return out

    @staticmethod
    def terms(state, pitch: AngleStd, roll: AngleStd) -> tuple:
        """``(rho_p^2, d_x, rho_r^2, d_y)`` of :meth:`AngleStd.variance` from a state (5, or (..., 5)), each
        with :data:`DRIVE_PRIOR_SECONDS` of prior at zero rate and the load centre."""
        t, sx, sy, rx2, ry2 = (state[..., k] for k in range(5)) if isinstance(state, np.ndarray) else state
        T = t + DRIVE_PRIOR_SECONDS
        return ry2 / T, (sx - pitch.load_center * t) / T, rx2 / T, (sy - roll.load_center * t) / T


def frame_std(info: tuple, angle: int) -> float:
    """The 1-sigma (rad) of pitch (``angle`` 0) or roll (1) of a frame's :meth:`SigmaModel.frame` inputs."""
    drive = DriveStatistics.terms(info[11], info[0], info[1])[2 * angle:2 * angle + 2]
    return math.sqrt(info[angle].variance(info[2], info[3], info[4], info[5 + angle], info[10], *drive))


def frame_reason(info: tuple, status_code: int, std: float) -> str:
    """The status reason of a frame's :meth:`SigmaModel.frame` inputs with its status and larger 1-sigma (rad)."""
    return status_reason(status_code, info[7], std, info[8], info[9], info[12])


class SigmaModel:
    """The 1-sigma model of one estimator (module docstring) and its convergence latch (its state).

    Parameters
    ----------
    constants : (AngleStd, AngleStd)
        Pitch and roll constants (:data:`SUSPENSION_STD` or :data:`FILTER_STD`).
    converged_std : float
        The latch's threshold, rad.
    load_share, cross_gain : float
        The suspension model's ``s`` and ``k_cross`` (batch only).
    min_moving_seconds : float
        Moving time the latch also waits for, s (0: none).

    Attributes
    ----------
    converged : bool
        The latch (module docstring, ``converging``).
    drive : DriveStatistics
        The drive so far (advanced by the estimator before each :meth:`frame`).
    """

    def __init__(self, constants=SUSPENSION_STD, converged_std: float = CONVERGED_STD, load_share: float = 1.0,
                 cross_gain: float = 0.0, min_moving_seconds: float = 0.0) -> None:
        self.constants, self.converged_std = constants, float(converged_std)
        self.min_moving_seconds = float(min_moving_seconds)
        self.load_share, self.cross_gain = float(load_share), float(cross_gain)
        self._var = self.converged_std * self.converged_std
        self.drive = DriveStatistics()
        self.reset()

    def reset(self) -> None:
        """Not converged, no drive seen."""
        self.converged = False
        self.drive.reset()

    def frame(self, a: float, ux: float = 0.0, uy: float = 0.0, gravity_var: float = 0.0,
              weights: tuple = (0.0, 0.0), dt: float = math.nan, note: Optional[str] = None,
              yaw_rate: float = 0.0) -> tuple:
        """One frame (plain floats): advances the latch and returns the frame's 1-sigma inputs.

        Parameters
        ----------
        a, ux, uy, gravity_var : float
            Level variance (rad^2), load (m/s^2), gravity's horizontal variance ((m/s^2)^2).
        weights : (float, float)
            :func:`tilt_weights` of the gains used at this frame.
        dt, yaw_rate : float
            Frame duration (s), ``|omega|`` (rad/s).
        note : str or None
            The note of an ``ok`` frame (or the monitor's alarm).

        Returns
        -------
        tuple
            Read by :func:`frame_std` and :func:`frame_reason` only.
        """
        pm, rm = self.constants
        info = (pm, rm, a, ux, uy, gravity_var * weights[0], gravity_var * weights[1], dt, note, self.converged_std,
                yaw_rate, tuple(self.drive.state), self.min_moving_seconds)
        if not self.converged and self.drive.state[0] >= self.min_moving_seconds:
            self.converged = max(pm.variance(a, ux, uy, info[5], yaw_rate),
                                 rm.variance(a, ux, uy, info[6], yaw_rate)) <= self._var
        return info

    def track(self, a: np.ndarray, load: Optional[np.ndarray] = None, gains: Optional[np.ndarray] = None,
              gravity_cov: Optional[np.ndarray] = None, yaw_rate: Optional[np.ndarray] = None,
              drive: Optional[np.ndarray] = None) -> np.ndarray:
        """The variances (G, 2) of pitch and roll of a batch, rad^2 (:meth:`frame`'s inputs as arrays).

        Parameters
        ----------
        a : ndarray (G,)
            Level variance, rad^2.
        load, gains : ndarray (G, 2), optional
            Load (m/s^2) and gains used (rad per m/s^2); None: no load.
        gravity_cov : ndarray (G, 6, 6), optional
            The gravity/velocity filter's covariance.
        yaw_rate : ndarray (G,), optional
            rad/s.
        drive : ndarray (G, 5), optional
            :meth:`DriveStatistics.run`'s states; None: :attr:`drive`'s now, for all.
        """
        pm, rm = self.constants
        rp, dx, rr, dy = DriveStatistics.terms(self.drive.state if drive is None else drive, pm, rm)
        if load is None:
            return np.stack([pm.variance(a, rate_ms=rp, load_offset=dx), rm.variance(a, rate_ms=rr, load_offset=dy)],
                            axis=1)
        assert gains is not None and gravity_cov is not None and yaw_rate is not None     # given with a load
        gv = gravity_cov[:, 3, 3] + gravity_cov[:, 4, 4]
        wp, wr = tilt_weights(gains[:, 0], gains[:, 1], self.load_share, self.cross_gain)
        w = np.abs(yaw_rate)
        return np.stack([pm.variance(a, load[:, 0], load[:, 1], gv * wp, w, rp, dx),
                         rm.variance(a, load[:, 0], load[:, 1], gv * wr, w, rr, dy)], axis=1)

    def latch_variance(self, a: np.ndarray, load: Optional[np.ndarray] = None, gains: Optional[np.ndarray] = None,
                       gravity_cov: Optional[np.ndarray] = None, yaw_rate: Optional[np.ndarray] = None,
                       moving: Optional[np.ndarray] = None) -> np.ndarray:
        """The variance the latch compares (G,), rad^2: the larger of :meth:`track`'s without the drive terms,
        inf where ``moving`` (s, (G,)) is below ``min_moving_seconds``."""
        var = self.track(a, load, gains, gravity_cov, yaw_rate, np.zeros((len(a), 5))).max(axis=1)
        if moving is not None and self.min_moving_seconds > 0:
            var[np.asarray(moving, dtype=float) < self.min_moving_seconds] = np.inf
        return var

    def statuses(self, var_max: np.ndarray, stationary: np.ndarray, valid: np.ndarray, good: np.ndarray,
                 degraded: Optional[np.ndarray] = None) -> np.ndarray:
        """:func:`track_statuses` of a batch with this latch (advanced)."""
        codes, self.converged = track_statuses(var_max, stationary, valid, good, self.converged, degraded,
                                               self.converged_std)
        return codes

    def state_dict(self) -> dict:
        """``{"converged": ..., "drive": [5 floats]}``, for a warm start."""
        return {"converged": self.converged, "drive": list(self.drive.state)}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (a dict or a StateReader; without ``drive``: none seen)."""
        st = as_reader(state, "SigmaModel")
        converged = st.bool("converged")
        drive = st.floats("drive", (5,)) if st.has("drive") else None
        self.converged = converged
        self.drive.state = [0.0] * 5 if drive is None else [float(v) for v in drive]
