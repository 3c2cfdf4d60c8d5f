r"""Invariant extended Kalman filter on SO(3), with filterpy's interface.

The state is a rotation ``X`` (world <- body). It evolves by a known body-frame increment ``U`` and process noise
``w ~ N(0, Q)`` in the body tangent space, ``X_k = X_{k-1} U_k Exp(w_k)``, and is observed (:meth:`InvariantEKF.update`)
as a rotation ``Z = X Exp(v)``, ``v ~ N(0, R)`` (body tangent space), or as the world image of a known unit body axis
``b``, ``z = X b + v``, ``v ~ N(0, R)`` (world frame; ``b = e_z`` observes the tilt alone).

``error="left"`` (default): the left-invariant error ``X = Xhat Exp(xi)`` (unchanged when both are left-multiplied
by one rotation). Predict ``Xhat <- Xhat U``, ``P <- U^T P U + Q``; rotation ``y = Log(Xhat^T Z)``, ``H = I``;
direction ``y = Xhat^T z - b ~= -[b]x xi + Xhat^T v``, so ``H = -[b]x`` does not depend on the estimate (Barrau &
Bonnabel 2017) and the noise in the body frame is ``Xhat^T R Xhat``; correction ``Xhat <- Xhat Exp(K y)``.

``error="right"``: ``X = Exp(xi) Xhat``; predict ``P <- P + A Q A^T``, ``A = Xhat U``; rotation ``y = Log(Z Xhat^T)``,
``H = I``, noise ``A R A^T``; direction ``y = z - Xhat b``, ``H = -[Xhat b]x``; correction ``Xhat <- Exp(K y) Xhat``.

Covariances are updated in Joseph form (for ``H = I`` in the information form ``P <- K Rn``) and kept symmetric;
the quaternion is renormalised every :data:`imu_ground.units.RENORM_EVERY` corrections. The predict and updates
are :mod:`imu_ground.filters.invariant_ekf_kernel` on the state held in one float64 array; the filterpy attributes
are properties, and ``x``, ``P``, ``Q``, ``R`` may be assigned or changed in place as in filterpy.
"""
from __future__ import annotations

import math
from typing import Union

import numpy as np

from imu_ground import so3
from imu_ground.filters import invariant_ekf_kernel as _kernel
from imu_ground.filters.invariant_ekf_kernel import (
    B_B, B_DET, B_K, B_NUP, B_P, B_PPO, B_PPR, B_Q, B_QN, B_RN, B_S, B_SI, B_X, B_XPO, B_XPR, B_XV, B_Y, B_Z, B_ZN,
    check_cov, fill_x, flat_rotation, new_state
)
from imu_ground.so3 import flat_from_quat, quat_from_flat
from imu_ground.units import RENORM_EVERY

__all__ = ["InvariantEKF"]

ArrayLike = Union[np.ndarray, list, tuple]
_I3 = np.eye(3)
_LOG2PI = math.log(2.0 * math.pi)


def _matrix(t) -> np.ndarray:
    return np.array(t).reshape(3, 3)


def _state_property(name: str, start: int, doc: str) -> property:
    """A 3x3 input (``P``, ``Q``, ``R``) in the state at ``start``; the array handed out or assigned (cached in
    ``_<name>_a``) is what the next step reads, so ``f.P *= 2`` is seen."""
    cache = "_" + name + "_a"

    def get(self):
        a = self.__dict__[cache]
        if a is None:
            a = self.__dict__[cache] = _matrix(self._s[start:start + 9])
            self._held = True
        return a

    def set_(self, value):
        a = np.asarray(value, dtype=float)
        if a.shape != (3, 3):
            raise ValueError(f"{name} must be a 3x3 matrix, got shape {a.shape}")
        self.__dict__[cache] = a if a.flags.c_contiguous else np.ascontiguousarray(a)
        self._s[start:start + 9] = a.ravel()
        self._held = True

    return property(get, set_, doc=doc)


def _output_property(name: str, start: int, doc: str, shape=(3, 3), rotation: bool = False) -> property:
    """A result (``K``, ``S``, ``x_prior``, ...) in the state at ``start`` (a quaternion for a ``rotation``), a
    fresh array on access."""
    size = 4 if rotation else int(np.prod(shape))

    def get(self):
        t = self._s[start:start + size].tolist()
        return np.array(flat_from_quat(t) if rotation else t).reshape(shape)

    def set_(self, value):
        t = np.asarray(value, dtype=float).reshape(shape).ravel().tolist()
        self._s[start:start + size] = quat_from_flat(t) if rotation else t

    return property(get, set_, doc=doc)


class InvariantEKF:
    """Invariant EKF on SO(3) with filterpy's attribute names.

    Parameters
    ----------
    x : ndarray (3, 3), optional
        Initial rotation, world <- body. Default identity.
    P, Q : float or ndarray (3, 3), optional
        Initial covariance (tangent space) and process noise per predict (body tangent space), rad^2. Defaults
        ``I`` and ``1e-2 I`` (Zhang et al. 2022).
    R : float or ndarray (3, 3), optional
        Measurement noise (rad^2 for rotations, squared unit-vector components for directions). Default ``I``.
    error : {"left", "right"}
        Which invariant error the covariance describes (module docstring).
    b : array_like (3,), optional
        Unit body axis observed by direction measurements. Default ``[0, 0, 1]`` (up).

    Attributes
    ----------
    x, P : the current estimate and its covariance.
    x_prior, P_prior, x_post, P_post : after the last :meth:`predict` and :meth:`update`.
    z, y, K, S, SI : last measurement, innovation, gain, innovation covariance and its inverse.
    log_likelihood, likelihood, mahalanobis : of the last innovation.
    """

    def __init__(self, x: ArrayLike | None = None, P: float | ArrayLike | None = None,
                 Q: float | ArrayLike | None = None, R: float | ArrayLike | None = None,
                 error: str = "left", b: ArrayLike | None = None) -> None:
        if error not in ("left", "right"):
            raise ValueError(f"error must be 'left' or 'right', got {error!r}")
        self.error = error
        self._left = error == "left"
        x = _I3 if x is None else np.asarray(x, dtype=float)
        if x.shape != (3, 3):
            raise ValueError(f"x must be a 3x3 rotation matrix, got shape {x.shape}")
        P, Q, R = (check_cov(n, d if v is None else v) for n, v, d in (("P", P, 1.0), ("Q", Q, 1e-2), ("R", R, 1.0)))
        b = np.array([0.0, 0.0, 1.0]) if b is None else np.asarray(b, dtype=float)
        if b.shape != (3,) or not np.isclose(np.linalg.norm(b), 1.0):
            raise ValueError("b must be a unit vector of shape (3,)")
        self.b = b
        # the whole state, one flat buffer (layout: invariant_ekf_kernel); what the kernels read and write
        self._s = new_state(quat_from_flat(tuple(x.ravel().tolist())), P.ravel().tolist(), Q.ravel().tolist(),
                            R.ravel().tolist(), b.tolist(), self._left, RENORM_EVERY)
        self._put_x(x)                  # x as given (the quaternion is its Shepperd conversion)
        self._x_t = b""                          # bytes of x as last handed out or assigned
        self._x_a: np.ndarray | None = None      # arrays handed out (see _state_property)
        self._P_a = self._Q_a = self._R_a = None
        self._held = False                       # any of them not None

    def _put_x(self, a: np.ndarray) -> None:
        """Set ``x`` (3x3) in the state: the matrix as given and its quaternion."""
        xl = a.ravel().tolist()
        self._s[B_X:B_X + 9] = xl
        self._s[B_XV] = 1.0
        self._s[B_Q:B_Q + 4] = quat_from_flat(xl)

    def _take_held(self) -> None:
        """Take in the ``x`` and ``P`` arrays handed out or assigned since the last step (maybe changed in place)."""
        s, xa, Pa = self._s, self._x_a, self._P_a
        if xa is not None:
            if xa.tobytes() != self._x_t:       # changed in place since handed out
                self._put_x(xa)
            self._x_a = None
        if Pa is not None:
            s[B_P:B_P + 9] = Pa.ravel()
            self._P_a = None
        self._held = self._Q_a is not None or self._R_a is not None

    def kernel_state(self) -> list:
        """The whole state buffer (the arrays handed out taken in first) as plain floats, for a warm start."""
        self._take_held()
        return self._s.tolist()

    def read_kernel_state(self, reader, name: str) -> list:
        """Entry ``name`` of a saved state (a :class:`~imu_ground.imu.warm_start.StateReader`) checked as a buffer
        of this layout (finite, NaN only in the last step's records)."""
        return reader.floats(name, (len(self._s),), nan=slice(B_XPR, B_B)).tolist()

    def load_kernel_state(self, values: list) -> None:
        """Back to a :meth:`kernel_state` (arrays handed out before are forgotten)."""
        self._s = np.array(values, dtype=float)
        self._x_a = self._P_a = self._Q_a = self._R_a = None
        self._x_t, self._held = b"", False

    @property
    def x(self) -> np.ndarray:
        """Current rotation, world <- body (3x3)."""
        a = self._x_a
        if a is None:
            fill_x(self._s)
            a = self._x_a = _matrix(self._s[B_X:B_X + 9])
            self._x_t = a.tobytes()
            self._held = True
        return a

    @x.setter
    def x(self, value) -> None:
        a = np.asarray(value, dtype=float)
        if a.shape != (3, 3):
            raise ValueError(f"x must be a 3x3 matrix, got shape {a.shape}")
        self._put_x(a)
        self._x_a, self._x_t = a, a.tobytes()
        self._held = True

    P = _state_property("P", B_P, "Current error covariance, tangent space (rad^2, 3x3).")
    Q = _state_property("Q", B_QN, "Process noise per predict (rad^2, 3x3; symmetric, its upper triangle is used).")
    R = _state_property("R", B_RN, "Measurement noise (3x3; symmetric, its upper triangle is used).")
    x_prior = _output_property("x_prior", B_XPR, "Rotation after the last predict.", rotation=True)
    P_prior = _output_property("P_prior", B_PPR, "Covariance after the last predict.")
    x_post = _output_property("x_post", B_XPO, "Rotation after the last update.", rotation=True)
    P_post = _output_property("P_post", B_PPO, "Covariance after the last update.")
    y = _output_property("y", B_Y, "Last innovation (3,): tangent (rotation) or body-frame residual (direction).",
                         (3,))
    K = _output_property("K", B_K, "Last Kalman gain (3x3).")
    S = _output_property("S", B_S, "Last innovation covariance (3x3).")
    SI = _output_property("SI", B_SI, "Inverse of the last innovation covariance (3x3).")

    @property
    def z(self) -> np.ndarray | None:
        """Last measurement, (3, 3) rotation or (3,) direction; None after a skipped update."""
        n = int(self._s[B_ZN])
        return None if n == 0 else self._s[B_Z:B_Z + n].copy().reshape((3, 3) if n == 9 else (3,))

    @z.setter
    def z(self, value) -> None:
        if value is None:
            self._s[B_ZN] = 0.0
            return
        t = np.asarray(value, dtype=float).ravel().tolist()
        if len(t) not in (3, 9):
            raise ValueError(f"z must be a 3x3 rotation or a unit vector of shape (3,), got {len(t)} values")
        self._s[B_Z:B_Z + len(t)] = t
        self._s[B_ZN] = float(len(t))

    @property
    def _updates(self) -> int:
        """Number of updates so far (the renormalisation counter)."""
        return int(self._s[B_NUP])

    # -- filterpy-style derived quantities ---------------------------------
    def _ysiy(self) -> float:
        y = self._s[B_Y:B_Y + 3]
        return float(y @ self._s[B_SI:B_SI + 9].reshape(3, 3) @ y)

    @property
    def log_likelihood(self) -> float:
        """Log-likelihood of the last innovation under N(0, S) (computed on access)."""
        det = float(self._s[B_DET])
        if math.isnan(det):
            return math.log(1e-300)                       # filterpy's value before any update
        return -0.5 * (self._ysiy() + math.log(det) + 3 * _LOG2PI)

    @property
    def likelihood(self) -> float:
        """``exp(log_likelihood)``, floored at the smallest positive float as in filterpy."""
        return max(math.exp(self.log_likelihood), np.finfo(float).tiny)

    @property
    def mahalanobis(self) -> float:
        """Mahalanobis distance of the last innovation, ``sqrt(y^T S^-1 y)``."""
        return math.sqrt(max(self._ysiy(), 0.0))

    # -- the filter ----------------------------------------------------------
    def predict(self, u: ArrayLike | None = None, Q: float | ArrayLike | None = None) -> None:
        """Propagate with the body-frame increment ``u`` and process noise.

        Parameters
        ----------
        u : ndarray (3, 3) or (3,), optional
            Body-frame increment body_{k-1} <- body_k (matrix or rotation vector, rad): ``x <- x u``. None: random walk.
        Q : float or ndarray (3, 3), optional
            Process noise of this step (body tangent space, rad^2); default ``self.Q``.
        """
        if self._held:
            self._take_held()
        Q = self._Q_a if Q is None else check_cov("Q", Q)
        _kernel.predict(self._s, u, Q)

    def update(self, z: ArrayLike | None, R: float | ArrayLike | None = None) -> None:
        """Correct with a rotation or a direction measurement.

        Parameters
        ----------
        z : ndarray (3, 3) or (3,) or None
            A rotation (world <- body, ``Z = X Exp(v)``) or a unit vector in world axes (``z = X b + v``). None
            skips the update (like filterpy).
        R : float or ndarray (3, 3), optional
            Measurement noise of this update; default ``self.R``.
        """
        if self._held:
            self._take_held()
        R = self._R_a if R is None else check_cov("R", R)
        _kernel.update(self._s, z, R)

    # -- batch -----------------------------------------------------------------
    def batch_filter(self, zs, us=None, Rs=None, Qs=None, saver=None):
        """Run predict/update over a sequence of measurements.

        Parameters
        ----------
        zs : sequence or ndarray, (N, 3, 3) rotations or (N, 3) directions
            Measurements; an entry of None skips that update.
        us : sequence or ndarray, (N, 3, 3) or (N, 3), optional
            Body-frame increments of the predict before each update.
        Rs, Qs : sequence of (3, 3), optional
            Per-step noise; default the filter's ``R`` and ``Q``.
        saver : filterpy.common.Saver, optional
            ``saver.save()`` after every step.

        Returns
        -------
        Xs, Ps, Xs_prior, Ps_prior : ndarray (N, 3, 3)
            Posterior rotations (world <- body) and covariances, then the predicted ones.
        """
        n = len(zs)
        Xs, Ps, Xp, Pp = (np.empty((n, 3, 3)) for _ in range(4))
        for k in range(n):
            self.predict(None if us is None else us[k], None if Qs is None else Qs[k])
            Xp[k], Pp[k] = self.x, self.P
            self.update(zs[k], None if Rs is None else Rs[k])
            Xs[k], Ps[k] = self.x, self.P
            if saver is not None:
                saver.save()
        return Xs, Ps, Xp, Pp

    def rts_smoother(self, Xs, Ps, us=None, Qs=None):
        """Rauch-Tung-Striebel smoother on the group (offline, zero lag).

        Parameters
        ----------
        Xs, Ps : ndarray (N, 3, 3)
            Posterior rotations (world <- body) and covariances from :meth:`batch_filter`.
        us : ndarray (N, 3, 3) or (N, 3), optional
            The increments given to :meth:`batch_filter` (``us[k]`` propagates from step k-1 to k).
        Qs : sequence of (3, 3), optional
            Per-step process noise; default ``self.Q``.

        Returns
        -------
        Xs_smooth, Ps_smooth, Cs, Ps_prior : ndarray (N, 3, 3)
            Smoothed rotations and covariances, smoother gains, predicted covariances recomputed from ``Ps``.

        Notes
        -----
        Left error: ``X_{k+1}^- = X_k U_{k+1}``, ``F = U_{k+1}^T``, ``C_k = P_k F^T (P_{k+1}^-)^-1``, smoothed
        ``X_k Exp(C_k Log((X_{k+1}^-)^-1 Xs_{k+1}))`` and ``Ps_k = P_k + C_k (Ps_{k+1} - P_{k+1}^-) C_k^T``. Right
        error: ``F = I``, the noise enters as ``A Q A^T`` (``A = X_k U_{k+1}``), the correction on the left.
        """
        Xs = np.asarray(Xs, dtype=float)
        Ps = np.asarray(Ps, dtype=float)
        n = len(Xs)
        Xsm, Psm = Xs.copy(), Ps.copy()
        Cs, Ppr = np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
        if n:
            Ppr[0] = Ps[0]
        left = self.error == "left"
        for k in range(n - 2, -1, -1):
            U = _I3 if us is None else _matrix(flat_rotation(us[k + 1]))
            Q = self.Q if Qs is None else check_cov("Q", Qs[k + 1])
            Xpred = Xs[k] @ U
            F = U.T if left else _I3
            Pp = F @ Ps[k] @ F.T + Q if left else Ps[k] + Xpred @ Q @ Xpred.T
            Pp = 0.5 * (Pp + Pp.T)
            C = Ps[k] @ F.T @ np.linalg.inv(Pp)
            e = so3.exp_one(C @ so3.log_one(Xpred.T @ Xsm[k + 1] if left else Xsm[k + 1] @ Xpred.T))
            Xsm[k] = so3.renormalise(Xs[k] @ e if left else e @ Xs[k])
            P = Ps[k] + C @ (Psm[k + 1] - Pp) @ C.T
            Psm[k] = 0.5 * (P + P.T)
            Cs[k] = C
            Ppr[k + 1] = Pp
        return Xsm, Psm, Cs, Ppr
