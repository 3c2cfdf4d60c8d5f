"""The preintegrated measurement between two times (:class:`PreintegratedImu`, GTSAM's
``PreintegratedImuMeasurements``), its composition and error forms. Frames: :mod:`imu_ground.imu.preintegration`.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from imu_ground import so3
from imu_ground.imu.preint_kernel import (DELTAS_IDENTITY, UNCERTAINTY_ZERO, integrate_interval,
                                          quaternion_from_rotation, rotation_from_quaternion)
from imu_ground.imu.preint_params import ParamsView, PreintegrationParams

__all__ = ["JACOBIAN_BLOCKS", "PreintegratedImu", "bias_corrected", "compose_left", "delta_rotation", "left_to_right",
           "right_form", "right_to_left"]

_I9 = np.eye(9)
#: The 3x3 blocks (row, column) of the 9x6 bias Jacobian (rows rotation, velocity, position; columns bg, ba).
JACOBIAN_BLOCKS = {"d_R_d_bg": (0, 0), "d_v_d_bg": (3, 0), "d_p_d_bg": (6, 0),
                   "d_v_d_ba": (3, 3), "d_p_d_ba": (6, 3)}


def delta_rotation(q: Sequence[float]) -> np.ndarray:
    """``R_{start<-end}`` (3, 3) of the deltas' quaternion ``q`` ``(w, x, y, z)`` (normalised first): a measurement's
    :attr:`PreintegratedImu.delta_R`."""
    return np.array(rotation_from_quaternion(q)).reshape(3, 3)


def _gather_indices() -> tuple[np.ndarray, np.ndarray]:
    """Positions in ``(*uncertainty, 0.0)`` of the left-form q-form J (9x6) and S (9x9) entries."""
    J = np.full((9, 6), 90)
    for k, (r, c) in enumerate(JACOBIAN_BLOCKS.values()):
        J[r:r + 3, c:c + 3] = np.arange(9 * k, 9 * k + 9).reshape(3, 3)
    S = np.full((9, 9), 90)
    sym = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
    blocks = {(0, 0): (45, True), (0, 3): (51, False), (0, 6): (60, False),
              (3, 3): (69, True), (3, 6): (75, False), (6, 6): (84, True)}
    for (r, c), (o, is_sym) in blocks.items():
        idx = o + (sym if is_sym else np.arange(9).reshape(3, 3))
        S[r:r + 3, c:c + 3] = idx
        S[c:c + 3, r:r + 3] = idx.T
    return J, S


_J_IDX, _S_IDX = _gather_indices()


def _left_p_form(T: Any, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's uncertainty (..., 90) as the bias Jacobian (..., 9, 6) and covariance (..., 9, 9), left error,
    p form (``p = q + T v``: position rows and columns plus ``T`` times the velocity's)."""
    a = np.concatenate([u, np.zeros(np.shape(u)[:-1] + (1,))], axis=-1)
    J, S = a[..., _J_IDX], a[..., _S_IDX]
    T = np.asarray(T, dtype=float)[..., None, None]
    J[..., 6:9, :] += T * J[..., 3:6, :]
    S[..., 6:9, :] += T * S[..., 3:6, :]
    S[..., :, 6:9] += T * S[..., :, 3:6]
    return J, S


def right_form(T: Any, R: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forster's right-error, p-form bias Jacobian (..., 9, 6) and covariance (..., 9, 9) of kernel states:
    integrated times ``T`` (...) s, ``delta_R`` (..., 3, 3) (``R_{start<-end}``), uncertainty ``u`` (..., 90)."""
    return left_to_right(R, *_left_p_form(T, u))


def left_to_right(R: np.ndarray, J: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bias Jacobian ``J`` (..., 9, 6) and covariance ``S`` (..., 9, 9) from the left rotation error (start
    frame) to Forster's right error, ``D = diag(R^T, I, I)`` with ``R = delta_R`` (..., 3, 3); S symmetrised."""
    Rt = np.swapaxes(R, -1, -2)
    J = J.copy()
    J[..., 0:3, :] = Rt @ J[..., 0:3, :]
    S = S.copy()
    S[..., 0:3, :] = Rt @ S[..., 0:3, :]
    S[..., :, 0:3] = S[..., :, 0:3] @ R
    return J, 0.5 * (S + np.swapaxes(S, -1, -2))


def right_to_left(R: np.ndarray, J: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`left_to_right`."""
    return left_to_right(np.swapaxes(R, -1, -2), J, S)


def compose_left(a: tuple, b: tuple) -> tuple:
    """Compose two consecutive measurements ``a`` then ``b``, each ``(T, R, v, p, J, S)`` of shapes (...),
    (..., 3, 3), (..., 3), (..., 3), (..., 9, 6), (..., 9, 9) (left error, p form; ``J``, ``S`` may be None):
    exact for the deltas and the linear error propagation."""
    Ta, Ra, va, pa, Ja, Sa = a
    Tb, Rb, vb, pb, Jb, Sb = b
    R = Ra @ Rb
    Rvb = np.einsum("...ij,...j->...i", Ra, vb)
    Rpb = np.einsum("...ij,...j->...i", Ra, pb)
    v = va + Rvb
    p = pa + va * Tb[..., None] + Rpb
    T = Ta + Tb
    if Ja is None:
        return T, R, v, p, None, None
    shape = Ta.shape
    Fa = np.broadcast_to(_I9, shape + (9, 9)).copy()
    Fa[..., 3:6, 0:3] = -so3.hat(Rvb)
    Fa[..., 6:9, 0:3] = -so3.hat(Rpb)
    Fa[..., 6:9, 3:6] = Tb[..., None, None] * np.eye(3)
    Fb = np.zeros(shape + (9, 9))
    for k in range(3):
        Fb[..., 3 * k:3 * k + 3, 3 * k:3 * k + 3] = Ra
    J = Fa @ Ja + Fb @ Jb
    S = Fa @ Sa @ np.swapaxes(Fa, -1, -2) + Fb @ Sb @ np.swapaxes(Fb, -1, -2)
    return T, R, v, p, J, 0.5 * (S + np.swapaxes(S, -1, -2))


def bias_corrected(R: np.ndarray, v: np.ndarray, p: np.ndarray, J: np.ndarray, dbg: np.ndarray,
                   dba: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First-order bias update (Forster, Sec. VI-C) of deltas ``R`` (..., 3, 3), ``v``, ``p`` (..., 3) with their
    right-form bias Jacobian ``J`` (..., 9, 6) for bias changes ``dbg``, ``dba`` (..., 3; rad/s, m/s^2):
    ``R Exp(J_R dbg)``, ``v + J_v [dbg, dba]``, ``p + J_p [dbg, dba]``."""
    e = np.einsum("...ij,...j->...i", J, np.concatenate([dbg, dba], axis=-1))
    return R @ so3.exp(e[..., 0:3]), v + e[..., 3:6], p + e[..., 6:9]


def _jacobian_block(row: int, col: int, doc: str) -> property:
    """A read-only property: the 3x3 block at (row, col) of the right-form bias Jacobian."""
    return property(lambda self: self._right()[0][row:row + 3, col:col + 3].copy(), doc=doc)


class PreintegratedImu(ParamsView):
    """Preintegrated IMU measurements between two times (value type): :meth:`integrate` each interval, read the
    deltas, covariance and bias Jacobians, :meth:`reset` to start again.

    Parameters
    ----------
    params : PreintegrationParams, optional
        ``uncertainty=False``: deltas only (the covariance and Jacobian properties raise ValueError).
    **options
        Fields of :class:`PreintegrationParams` overriding ``params``.

    Attributes
    ----------
    params : PreintegrationParams
    t_start, t_end : float
        Times of the interval, s (``nan`` unless set by a frame of a preintegrator or of ``FrameDeltas``).
    valid : bool
        False when the interval spans a timestamp gap longer than ``max_gap``.
    n_intervals : int
        Integration intervals since the last reset.
    """

    __slots__ = ("_right_cache", "_s", "_u", "n_intervals", "params", "t_end", "t_start", "valid")
    _right_cache: tuple | None              # (the uncertainty it is of, J, S) of :meth:`_right`

    def __init__(self, params: PreintegrationParams | None = None, **options: Any) -> None:
        self.params = PreintegrationParams.coerce(params, **options)
        self.reset()

    @classmethod
    def from_state(cls, params: PreintegrationParams, s: tuple, u: tuple | None, n: int,
                   t_start: float, t_end: float, valid: bool) -> PreintegratedImu:
        """A measurement from the kernel's deltas ``s`` (11) and uncertainty ``u`` (90 or None) tuples
        (:mod:`imu_ground.imu.preint_kernel`), ``n`` intervals from ``t_start`` to ``t_end`` (s)."""
        out = cls.__new__(cls)
        out.params = params
        out._s, out._u, out.n_intervals = s, u, n
        out._right_cache = None
        out.t_start, out.t_end, out.valid = t_start, t_end, valid
        return out

    def reset(self, bias_gyro: Sequence[float] | None = None,
              bias_accel: Sequence[float] | None = None) -> None:
        """Start over (identity deltas, zero covariance and Jacobians), with new linearisation biases (rad/s,
        m/s^2, body frame) unless None."""
        self.params = PreintegrationParams.coerce(self.params, bias_gyro=bias_gyro, bias_accel=bias_accel)
        self._s = DELTAS_IDENTITY
        self._u = UNCERTAINTY_ZERO if self.params.uncertainty else None
        self._right_cache = None
        self.n_intervals = 0
        self.t_start = self.t_end = math.nan
        self.valid = True

    def copy(self) -> PreintegratedImu:
        """An independent copy (the states are immutable tuples, shared)."""
        return PreintegratedImu.from_state(self.params, self._s, self._u, self.n_intervals,
                                            self.t_start, self.t_end, self.valid)

    def integrate(self, dt: float, gyro: Sequence[float], accel: Sequence[float]) -> None:
        """Add one interval with constant measurements.

        Parameters
        ----------
        dt : float
            Interval length, s (> 0).
        gyro, accel : sequence of 3 floats
            Angular rate (rad/s) and specific force (m/s^2) held over it, body frame, bias not removed.
        """
        if not dt > 0.0:
            raise ValueError(f"dt must be > 0, got {dt!r}")
        dt = float(dt)
        bgx, bgy, bgz, bax, bay, baz = self.params.bias
        wx, wy, wz = (float(g) for g in gyro)
        ax, ay, az = (float(a) for a in accel)
        self._s, self._u = integrate_interval(self._s, self._u, dt, (wx - bgx) * dt, (wy - bgy) * dt,
                                              (wz - bgz) * dt, (ax - bax) * dt, (ay - bay) * dt,
                                              (az - baz) * dt, self.params.noise)
        self.n_intervals += 1

    @property
    def uncertainty(self) -> bool:
        """Whether the covariance and the bias Jacobians are propagated."""
        return self._u is not None

    @property
    def delta_t(self) -> float:
        """Integrated time, s (sum of the interval lengths)."""
        return self._s[0]

    @property
    def delta_R(self) -> np.ndarray:
        """``R_{start<-end}``, shape (3, 3): body frame at the end -> body frame at the start."""
        return delta_rotation(self._s[1:5])

    @property
    def delta_v(self) -> np.ndarray:
        """Velocity increment without gravity, m/s, body frame at the start, shape (3,)."""
        return np.array(self._s[5:8])

    @property
    def delta_p(self) -> np.ndarray:
        """Position increment without gravity, m, body frame at the start, shape (3,)."""
        return np.array(self._s[8:11])

    def _left_arrays(self) -> tuple:
        """(T, R, v, p, J, S): left-error, p-form arrays of the state."""
        if self._u is None:
            raise ValueError("this preintegration was made with uncertainty=False: it has no covariance "
                             "or bias Jacobians (use uncertainty=True)")
        s = self._s
        return (np.float64(s[0]), self.delta_R, self.delta_v, self.delta_p, *_left_p_form(s[0], np.array(self._u)))

    def _right(self) -> tuple[np.ndarray, np.ndarray]:
        """(J, S) in Forster's right form (:func:`right_form`), computed once per state (the tuples are immutable)."""
        cache = self._right_cache
        if cache is None or cache[0] is not self._u:
            if self._u is None:
                self._left_arrays()         # raises the uncertainty=False error
            cache = self._right_cache = (self._u, *right_form(self._s[0], self.delta_R, np.array(self._u)))
        return cache[1], cache[2]

    @property
    def bias_jacobian(self) -> np.ndarray:
        """All bias Jacobians (9, 6): rows [rotation (right, end body frame), velocity, position], columns [bg, ba]."""
        return self._right()[0].copy()

    @property
    def covariance(self) -> np.ndarray:
        """Noise covariance (9, 9): [rotation (right error, end body frame, rad), velocity (m/s), position (m)]."""
        return self._right()[1].copy()

    d_R_d_bg = _jacobian_block(0, 0, "(3, 3), rad per rad/s: ``delta_R(bg + d) ~= delta_R Exp(d_R_d_bg @ d)`` "
                                      "(right, end body frame).")
    d_v_d_bg = _jacobian_block(3, 0, "d delta_v / d bg, (3, 3), m/s per rad/s (start body frame).")
    d_p_d_bg = _jacobian_block(6, 0, "d delta_p / d bg, (3, 3), m per rad/s (start body frame).")
    d_v_d_ba = _jacobian_block(3, 3, "d delta_v / d ba, (3, 3), s (start body frame).")
    d_p_d_ba = _jacobian_block(6, 3, "d delta_p / d ba, (3, 3), s^2 (start body frame).")

    def corrected(self, bias_gyro: Sequence[float], bias_accel: Sequence[float]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First-order bias update of the deltas without re-integration (Forster, Sec. VI-C).

        Parameters
        ----------
        bias_gyro, bias_accel : array_like, shape (3,)
            New bias estimates, rad/s and m/s^2, body frame.

        Returns
        -------
        delta_R, delta_v, delta_p : ndarray (3, 3), (3,), (3,)
            ``delta_R Exp(d_R_d_bg @ dbg)`` (``R_{start<-end}``), ``delta_v + d_v_d_bg @ dbg + d_v_d_ba @ dba``
            (m/s) and likewise ``delta_p`` (m), start body frame.
        """
        return bias_corrected(self.delta_R, self.delta_v, self.delta_p, self.bias_jacobian,
                              np.asarray(bias_gyro, dtype=float) - self.bias_gyro,
                              np.asarray(bias_accel, dtype=float) - self.bias_accel)

    def predict(self, R_world_start: np.ndarray, v_world: Sequence[float], p_world: Sequence[float]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Navigation state at the end from the state at the start (Forster, Sec. VI-A).

        Parameters
        ----------
        R_world_start : array_like (3, 3)
            ``R_{world<-body}`` at the start (world: z up, gravity ``[0, 0, -params.gravity]``).
        v_world, p_world : array_like (3,)
            Velocity (m/s) and position (m) at the start, world frame.

        Returns
        -------
        R_world_end, v_world_end, p_world_end
            ``R_i delta_R``, ``v_i + g T + R_i delta_v``, ``p_i + v_i T + g T^2 / 2 + R_i delta_p``.
        """
        Ri = np.asarray(R_world_start, dtype=float).reshape(3, 3)
        vi = np.asarray(v_world, dtype=float).reshape(3)
        pi = np.asarray(p_world, dtype=float).reshape(3)
        T = self.delta_t
        g = np.array([0.0, 0.0, -self.params.gravity])
        return (Ri @ self.delta_R, vi + g * T + Ri @ self.delta_v,
                pi + vi * T + 0.5 * g * T * T + Ri @ self.delta_p)

    def combine(self, other: PreintegratedImu) -> PreintegratedImu:
        """This interval followed by ``other`` (equal biases and noise densities): ``delta_R`` is
        ``self.delta_R @ other.delta_R``; covariance and bias Jacobians propagated exactly (:func:`compose_left`)."""
        if not self.params.same_model(other.params):
            raise ValueError("combine needs equal biases and noise densities")
        T, R, v, p, J, S = compose_left(self._left_arrays(), other._left_arrays())
        return PreintegratedImu.from_arrays(
            self.params, T, R, v, p, J, S, t_start=self.t_start, t_end=other.t_end,
            valid=bool(self.valid and other.valid), n_intervals=self.n_intervals + other.n_intervals)

    @classmethod
    def from_arrays(cls, params: PreintegrationParams, T: float, R: np.ndarray, v: np.ndarray,
                    p: np.ndarray, J: np.ndarray, S: np.ndarray, *, t_start: float = math.nan,
                    t_end: float = math.nan, valid: bool = True, n_intervals: int = 0) -> PreintegratedImu:
        """A measurement from left-error, p-form arrays (as :func:`compose_left` returns them)."""
        T = float(T)
        J = np.array(J, dtype=float)
        S = np.array(S, dtype=float)
        J[6:9] -= T * J[3:6]
        S[6:9] -= T * S[3:6]
        S[:, 6:9] -= T * S[:, 3:6]
        u = np.empty(91)
        u[_J_IDX] = J
        u[_S_IDX] = S
        q = quaternion_from_rotation(tuple(np.asarray(R, dtype=float).reshape(9).tolist()))
        s = (T, *q, *np.asarray(v, dtype=float).tolist(), *np.asarray(p, dtype=float).tolist())
        return cls.from_state(params, s, tuple(u[:90].tolist()), int(n_intervals), float(t_start),
                               float(t_end), bool(valid))

    def __repr__(self) -> str:
        phi = so3.log(self.delta_R)
        return (f"PreintegratedImu(delta_t={self.delta_t:.6g} s, n_intervals={self.n_intervals}, "
                f"rotvec={np.array2string(phi, precision=5)}, delta_v={np.array2string(self.delta_v, precision=5)}, "
                f"delta_p={np.array2string(self.delta_p, precision=5)}, valid={self.valid})")
