r"""The road's own attitude: grade and bank relative to gravity, from the body's attitude to gravity and to the road.

Frames and signs as in :mod:`imu_ground.filters.estimator`. With ``u_b`` the up
direction (reaction to gravity, unit) in the body frame and ``E`` (road <- body)
the estimator's residual, the up direction in the road frame is ``u_r = E u_b``
(exactly: level <- road = (level <- body)(body <- road)); its pitch and roll
(:func:`~imu_ground.filters.estimator.pitch_roll_from_normal`) are the road's
attitude relative to gravity, and

- ``road_grade = -pitch(u_r)`` (+ uphill in the direction of travel: the road's nose is up),
- ``road_bank = roll(u_r)`` (+ left side up);

to first order the body's attitude to gravity minus its attitude to the road.

``u_b`` comes from a gravity/velocity filter of its own (the estimator's options with a gravity random
walk ``q_g`` of :data:`ROAD_Q_G`, to follow the gyro-integrated world frame's drift). It needs a measured
speed (else a slow grade cannot be told from a slow acceleration): the road is estimated from the first
frame with a finite speed on, and is NaN before and wherever the frame's speed is NaN.

1-sigma: ``sigma_grade^2 = sigma_pitch^2 + c^2 P_x / |g|^2 + f^2`` and the same for the bank with ``P_y``,
``P`` the gravity filter's covariance of gravity in the body frame, ``(c, f)`` :data:`ROAD_STD`.
"""
from __future__ import annotations

import math
from typing import Optional

import numpy as np

from imu_ground._jit import jitable, njit
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.frame_checks import frames_of
from imu_ground.filters.gravity_velocity import GravityTrack, GravityVelocityFilter
from imu_ground.imu.warm_start import as_reader
from imu_ground.so3 import quat_from_matrix
from imu_ground.units import DEG

__all__ = ["ROAD_Q_G", "ROAD_STD", "NO_SPEED_REASON", "NO_ROAD_REASON", "RoadFilter", "road_gravity_options", "road_angles",
           "road_angles_one", "road_one", "road_std"]

#: Gravity random walk of the road's gravity/velocity filter, m/s^2/sqrt(s).
ROAD_Q_G = 0.01
#: ``(c, f)`` of the road's 1-sigma (module docstring): scale of the gravity term, floor (rad).
ROAD_STD = (1.0, 0.05 * DEG)
#: Status reason of a frame whose road is not estimated.
NO_SPEED_REASON = "road grade and bank not estimated: no measured speed (give --speed)"
#: Status reason of every frame of a method that cannot estimate the road (no accelerometer).
NO_ROAD_REASON = "road grade and bank not estimated: this method has no gravity (use the suspension method and --speed)"
_UPPER = np.triu_indices(3)
_NO_COV = (0.0,) * 6


def road_gravity_options(options: Optional[dict] = None) -> dict:
    """The estimator's gravity/velocity options with the road's gravity random walk."""
    kw = dict(options or {})
    kw["q_g"] = ROAD_Q_G
    return kw


@jitable
def _quad(p, a0, a1, a2):
    """``a^T P a``, ``p`` = P's (xx, xy, xz, yy, yz, zz)."""
    return (a0 * (p[0] * a0 + p[1] * a1 + p[2] * a2) + a1 * (p[1] * a0 + p[3] * a1 + p[4] * a2)
            + a2 * (p[2] * a0 + p[4] * a1 + p[5] * a2))


@jitable
def _ratio(a, b):
    """``a / b`` as numpy divides (inf or NaN where ``b`` is 0)."""
    if b != 0.0:
        return a / b
    return math.nan if a == 0.0 or a != a else math.copysign(math.inf, a)


@jitable
def road_one(q, g, R, p6) -> tuple[float, float, float, float]:
    """Grade, bank (rad) and the gravity filter's share of their variances (rad^2) of one frame: the one body
    of the road, driven over a batch by :func:`road_angles`, :func:`road_std` and :meth:`RoadFilter.run`.

    Parameters
    ----------
    q : sequence of 4 float
        ``E`` (road <- body) as a unit quaternion (w, x, y, z).
    g : sequence of 3 float
        Gravity reaction, world frame, m/s^2.
    R : sequence of 9 float
        World <- body, row-major.
    p6 : sequence of 6 float
        The gravity covariance's unique entries ``(xx, xy, xz, yy, yz, zz)``, world frame, (m/s^2)^2.

    Returns
    -------
    grade, bank, var_grade, var_bank : float
        + uphill, + left side up; ``c^2 P_b / |g|^2 + f^2`` (module docstring).
    """
    ux = R[0] * g[0] + R[3] * g[1] + R[6] * g[2]              # R^T g: up, body frame
    uy = R[1] * g[0] + R[4] * g[1] + R[7] * g[2]
    uz = R[2] * g[0] + R[5] * g[1] + R[8] * g[2]
    w, x, y, z = q[0], q[1], q[2], q[3]                      # E u: up in the road frame
    n0 = (1 - 2 * (y * y + z * z)) * ux + 2 * (x * y - w * z) * uy + 2 * (x * z + w * y) * uz
    n1 = 2 * (x * y + w * z) * ux + (1 - 2 * (x * x + z * z)) * uy + 2 * (y * z - w * x) * uz
    n2 = 2 * (x * z - w * y) * ux + 2 * (y * z + w * x) * uy + (1 - 2 * (x * x + y * y)) * uz
    c, f = ROAD_STD
    g2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2]
    return (math.atan2(n0, math.hypot(n1, n2)), math.atan2(n1, n2),
            _ratio(c * c * _quad(p6, R[0], R[3], R[6]), g2) + f * f, _ratio(c * c * _quad(p6, R[1], R[4], R[7]), g2) + f * f)


@njit
def _road_frames(q, g, R, p6, out):
    for k in range(q.shape[0]):
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = road_one(q[k], g[k], R[k], p6[k])


def _road_track(q, gravity, cumulative, cov=None) -> np.ndarray:
    """:func:`road_one` of every frame, (F, 4) (``cov`` (F, 3, 3) or None: zero)."""
    n = len(q)
    out = np.empty((n, 4))
    p6 = np.zeros((n, 6)) if cov is None else np.asarray(cov, dtype=float)[:, _UPPER[0], _UPPER[1]]
    c = np.ascontiguousarray
    _road_frames(c(q, dtype=float), c(gravity, dtype=float), c(cumulative, dtype=float).reshape(n, 9), c(p6), out)
    return out


def road_angles(E: np.ndarray, gravity: np.ndarray, cumulative: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Road grade and bank (rad) per frame (:func:`road_one` of each).

    Parameters
    ----------
    E : ndarray (F, 3, 3)
        Residual road <- body.
    gravity, cumulative : ndarray (F, 3), (F, 3, 3)
        The gravity filter's reaction to gravity (its world frame, m/s^2) and attitude world <- body.

    Returns
    -------
    grade, bank : ndarray (F,)
        + uphill; + left side up.
    """
    out = _road_track(quat_from_matrix(np.asarray(E, dtype=float)), gravity, cumulative)
    return out[:, 0], out[:, 1]


def road_angles_one(q, g, R) -> tuple[float, float]:
    """:func:`road_angles` of one frame from plain floats (``q``, ``g``, ``R`` as in :func:`road_one`)."""
    return road_one(q, g, R, _NO_COV)[:2]


def road_std(pitch_std, roll_std, gravity_cov: np.ndarray, gravity: np.ndarray,
             cumulative: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """1-sigma of road grade and bank (rad), module docstring (:func:`road_one` of each frame).

    Parameters
    ----------
    pitch_std, roll_std : ndarray (F,)
        The estimator's 1-sigma, rad.
    gravity_cov, gravity, cumulative : ndarray (F, 3, 3), (F, 3), (F, 3, 3)
        Covariance ((m/s^2)^2) and value (m/s^2) of the gravity reaction, world frame; world <- body.
    """
    out = _road_track(np.tile([1.0, 0.0, 0.0, 0.0], (len(gravity), 1)), gravity, cumulative, gravity_cov)
    return np.sqrt(np.square(pitch_std) + out[:, 2]), np.sqrt(np.square(roll_std) + out[:, 3])


class RoadFilter:
    """The road's gravity/velocity filter (module docstring), started at the first frame with a finite speed.

    Parameters
    ----------
    extrinsic, lever_arm, gravity
        The estimator's extrinsic, lever arm and gravity/velocity options (``q_g``: :data:`ROAD_Q_G`).

    Attributes
    ----------
    gravity_filter : GravityVelocityFilter or None
        None until the first frame with a speed.
    """

    def __init__(self, extrinsic, lever_arm=None, gravity: Optional[dict] = None) -> None:
        self._kw = dict(road_gravity_options(gravity), extrinsic=extrinsic, lever_arm=lever_arm)
        self.gravity_filter: Optional[GravityVelocityFilter] = None

    def reset(self) -> None:
        """Back to no road filter."""
        self.gravity_filter = None

    def state_dict(self) -> dict:
        """``{"road": ...}``: the gravity/velocity filter's buffer once started, else None."""
        return {"road": None if self.gravity_filter is None else self.gravity_filter.kernel_state()}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (a dict or a StateReader; the buffer checked first)."""
        st = as_reader(state, "RoadFilter")
        gf = GravityVelocityFilter(**self._kw)
        values = gf.read_kernel_state(st, "road", optional=True)
        self.gravity_filter = None if values is None else gf
        if values is not None:
            gf.load_kernel_state(values)

    def set_mount(self, Rgs: np.ndarray, turn: Optional[np.ndarray] = None,
                  direction: Optional[np.ndarray] = None) -> None:
        """A new static rotation ground <- sensor, for the running filter and one started later
        (:meth:`GravityVelocityFilter.set_mount`)."""
        self._kw["extrinsic"] = Extrinsic(Rgs, self._kw["extrinsic"].translation, dict(self._kw["extrinsic"].meta))
        if self.gravity_filter is not None:
            self.gravity_filter.set_mount(Rgs, turn, direction)

    def start(self) -> GravityVelocityFilter:
        """The gravity/velocity filter, created if there is none yet."""
        if self.gravity_filter is None:
            self.gravity_filter = GravityVelocityFilter(**self._kw)
        return self.gravity_filter

    def step(self, d, dv, dt: float, stationary: bool, valid: bool, speed: float) -> Optional[tuple]:
        """One frame (as :meth:`GravityVelocityFilter.step_sensor` takes it): ``(g, R, p6)`` of :func:`road_one`
        after it, or None when it has no speed (the filter still advances once started)."""
        if self.gravity_filter is None:
            if math.isnan(speed):
                return None
        gf = self.start()
        gf.step_sensor(d, dv, dt, stationary, valid, speed)
        return None if math.isnan(speed) else gf.gravity_snapshot()

    def gravity_pass(self, egomotion, speed: np.ndarray) -> Optional[tuple[np.ndarray, GravityTrack]]:
        """The first half of :meth:`run`: the filter over checked frames (sensor frame; ``speed`` (F,) m/s, NaN:
        none), started at the first with a speed. Touches only this object (it may run in another thread).

        Returns
        -------
        (keep, track) or None
            The frames from the filter's start on (bool (F,)) and its GravityTrack over them; None: no start.
        """
        n = len(speed)
        if self.gravity_filter is None:
            fin = np.isfinite(speed)
            if not fin.any():
                return None
            i0 = int(np.argmax(fin))
        else:
            i0 = 0
        keep = np.arange(n) >= i0
        em = egomotion if i0 == 0 else frames_of(egomotion, keep)
        return keep, self.start().run(em, speed=speed[keep])

    def run(self, egomotion, speed: np.ndarray, q: np.ndarray, pitch_std: np.ndarray, roll_std: np.ndarray,
            gravity_pass=None):
        """The road of a batch of frames (already checked), continuing as :meth:`step` would.

        Parameters
        ----------
        egomotion, speed
            As in :meth:`gravity_pass`.
        q : ndarray (F, 4)
            The estimator's residuals road <- body, unit quaternions (w, x, y, z).
        pitch_std, roll_std : ndarray (F,)
            The estimator's 1-sigma, rad.
        gravity_pass : callable, optional
            Returns :meth:`gravity_pass` of these frames, already run (e.g. a Future's ``result``).

        Returns
        -------
        road : ndarray (F, 4)
            Grade, bank and their 1-sigma (rad); NaN without a speed or before the start.
        gravity : ndarray (F, 3)
            The filter's gravity reaction (its world frame, m/s^2); NaN before the start.
        """
        n = len(speed)
        out, grav = np.full((n, 4), np.nan), np.full((n, 3), np.nan)
        done = self.gravity_pass(egomotion, speed) if gravity_pass is None else gravity_pass()
        if done is None:
            return out, grav
        keep, gt = done
        road = _road_track(q[keep], gt.gravity, gt.cumulative, gt.P[:, 3:, 3:])
        road[:, 2] = np.sqrt(np.square(pitch_std[keep]) + road[:, 2])
        road[:, 3] = np.sqrt(np.square(roll_std[keep]) + road[:, 3])
        out[keep] = road
        out[~np.isfinite(speed)] = np.nan
        grav[keep] = gt.gravity
        return out, grav
