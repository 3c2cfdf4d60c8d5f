r"""Invariant extended Kalman filter on SO(3), with filterpy's interface.

The model
---------
The state is a rotation ``X`` (3x3, world <- body: ``X @ v_body`` is the
vector in world axes). It evolves by a body-frame increment ``U`` (optional,
known) and process noise ``w ~ N(0, Q)`` in the body tangent space::

    X_k = X_{k-1} @ U_k @ Exp(w_k)

Two kinds of measurement are supported by :meth:`InvariantEKF.update`:

* a full rotation, ``Z = X @ Exp(v)``, ``v ~ N(0, R)`` (body tangent space);
* a unit direction, the world-frame image of a known body axis ``b``:
  ``z = X @ b + v``, ``v ~ N(0, R)`` (world frame, 3x3). With ``b = e_z`` this
  observes only the up axis (tilt), which is all a ground normal needs.

The error and why it is "invariant"
-----------------------------------
``error="left"`` (default) uses the left-invariant error, written as a
body-frame perturbation ``X = Xhat @ Exp(xi)`` (``Exp(xi) = Xhat^-1 X`` is
unchanged when both are left-multiplied by the same rotation). Then

* predict: ``Xhat <- Xhat U``, ``xi <- U^T xi + w``, so ``F = U^T`` and
  ``P <- U^T P U + Q``;
* full rotation: ``y = Log(Xhat^T Z) ~= xi + v``, ``H = I``;
* direction: ``y = Xhat^T z - b ~= Exp(xi) b - b ~= -[b]x xi + Xhat^T v``, so
  ``H = -[b]x`` does not depend on the estimate (the invariant-EKF property
  of Barrau & Bonnabel 2017 for left-invariant observations), and the noise
  covariance seen in the body frame is ``Xhat^T R Xhat``;
* correction: ``Xhat <- Xhat Exp(K y)``.

``error="right"`` uses the right-invariant error, a world-frame perturbation
``X = Exp(xi) @ Xhat``: predict ``P <- P + A Q A^T`` with ``A = Xhat U`` (the
adjoint of SO(3) is the rotation itself), full rotation ``y = Log(Z Xhat^T)``
with ``H = I`` and noise ``A R A^T``, direction ``y = z - Xhat b`` with
``H = -[Xhat b]x`` (now state dependent), correction ``Xhat <- Exp(K y) Xhat``.
For body-axis observations the left error is the natural one; the right error
is there for world-frame measurements and for comparison.

Covariances are updated in Joseph form and symmetrised; the state is
re-orthonormalised after every correction, so both stay valid over millions
of steps.
"""
from __future__ import annotations

import math
from typing import Optional, Union

import numpy as np

from imu_ground import so3

__all__ = ["InvariantEKF"]

ArrayLike = Union[np.ndarray, list, tuple]
_I3 = np.eye(3)
_LOG2PI = math.log(2.0 * math.pi)
_RENORM_EVERY = 32   # updates between re-orthonormalisations (drift is ~1e-16 a step)


def _as_rotation(u: Optional[ArrayLike]) -> Optional[np.ndarray]:
    """3x3 rotation from a 3x3 matrix or a rotation vector (rad); None stays None."""
    if u is None:
        return None
    u = np.asarray(u, dtype=float)
    if u.shape == (3, 3):
        return u
    if u.shape == (3,):
        return so3.exp_one(u)
    raise ValueError(f"rotation increment must be a 3x3 matrix or a rotation vector of shape (3,), got {u.shape}")


def _inv3(m: np.ndarray):
    """Inverse and determinant of a 3x3 matrix by cofactors (scalar, fast)."""
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    if det == 0.0 or not math.isfinite(det):
        raise np.linalg.LinAlgError(f"innovation covariance is singular (det = {det})")
    r = 1.0 / det
    inv = np.array([[A * r, (c * h - b * i) * r, (b * f - c * e) * r],
                    [B * r, (a * i - c * g) * r, (c * d - a * f) * r],
                    [C * r, (b * g - a * h) * r, (a * e - b * d) * r]])
    return inv, det


def _renormalise(x: np.ndarray) -> np.ndarray:
    """One Newton step towards the nearest rotation: X (3 I - X^T X) / 2."""
    return x @ (1.5 * _I3 - 0.5 * (x.T @ x))


def _check_cov(name: str, m: Optional[ArrayLike]) -> Optional[np.ndarray]:
    if m is None:
        return None
    m = np.asarray(m, dtype=float)
    if m.ndim == 0:
        return float(m) * _I3
    if m.shape != (3, 3):
        raise ValueError(f"{name} must be a scalar or a 3x3 matrix, got shape {m.shape}")
    return m


class InvariantEKF:
    """Invariant EKF on SO(3) with filterpy's attribute names.

    Parameters
    ----------
    x : ndarray (3, 3), optional
        Initial rotation, world <- body. Default identity.
    P : float or ndarray (3, 3), optional
        Initial error covariance in the tangent space (rad^2). Default ``I``.
    Q : float or ndarray (3, 3), optional
        Process noise per predict, body tangent space (rad^2). Default
        ``1e-2 I`` (Zhang et al. 2022).
    R : float or ndarray (3, 3), optional
        Measurement noise (rad^2 for rotations, squared unit-vector components
        for directions). Default ``I`` (Zhang et al. 2022).
    error : {"left", "right"}
        Which invariant error the covariance describes (see the module notes).
    b : array_like (3,), optional
        Body axis observed by direction measurements. Default ``[0, 0, 1]``
        (the up axis).

    Attributes
    ----------
    x, P : the current estimate and its covariance.
    x_prior, P_prior : after the last :meth:`predict`.
    x_post, P_post : after the last :meth:`update`.
    z, y, K, S, SI : last measurement, innovation (tangent / body-frame
        residual), gain, innovation covariance and its inverse.
    log_likelihood, likelihood, mahalanobis : of the last innovation.

    Examples
    --------
    >>> import numpy as np
    >>> from imu_ground.filters.invariant_ekf import InvariantEKF
    >>> f = InvariantEKF()
    >>> f.predict()
    >>> f.update(np.array([0.0, 0.0, 1.0]))   # the body up axis is seen straight up
    """

    def __init__(self, x: Optional[ArrayLike] = None, P: Union[float, ArrayLike, None] = None,
                 Q: Union[float, ArrayLike, None] = None, R: Union[float, ArrayLike, None] = None,
                 error: str = "left", b: Optional[ArrayLike] = None) -> None:
        if error not in ("left", "right"):
            raise ValueError(f"error must be 'left' or 'right', got {error!r}")
        self.error = error
        self.x = _I3.copy() if x is None else np.array(x, dtype=float)
        if self.x.shape != (3, 3):
            raise ValueError(f"x must be a 3x3 rotation matrix, got shape {self.x.shape}")
        self.P = _check_cov("P", 1.0 if P is None else P).copy()
        self.Q = _check_cov("Q", 1e-2 if Q is None else Q).copy()
        self.R = _check_cov("R", 1.0 if R is None else R).copy()
        b = np.array([0.0, 0.0, 1.0]) if b is None else np.asarray(b, dtype=float)
        if b.shape != (3,) or not np.isclose(np.linalg.norm(b), 1.0):
            raise ValueError("b must be a unit vector of shape (3,)")
        self.b = b
        self._hb = so3.hat(b)
        self.z: Optional[np.ndarray] = None
        self.y = np.zeros(3)
        self.K = np.zeros((3, 3))
        self.S = np.zeros((3, 3))
        self.SI = np.zeros((3, 3))
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()
        self.x_post = self.x.copy()
        self.P_post = self.P.copy()
        self._updates = 0
        self._log_likelihood = math.log(1e-300)
        self._mahalanobis: Optional[float] = None

    # -- filterpy-style derived quantities ---------------------------------
    @property
    def log_likelihood(self) -> float:
        """Log-likelihood of the last innovation under N(0, S) (computed on first access)."""
        if self._log_likelihood is None:
            self._log_likelihood = float(-0.5 * (self.y @ self.SI @ self.y + math.log(self._detS) + 3 * _LOG2PI))
        return self._log_likelihood

    @property
    def likelihood(self) -> float:
        """``exp(log_likelihood)``, floored at the smallest positive float as in filterpy."""
        return max(math.exp(self.log_likelihood), np.finfo(float).tiny)

    @property
    def mahalanobis(self) -> float:
        """Mahalanobis distance of the last innovation, ``sqrt(y^T S^-1 y)``."""
        if self._mahalanobis is None:
            self._mahalanobis = float(math.sqrt(max(float(self.y @ self.SI @ self.y), 0.0)))
        return self._mahalanobis

    # -- the filter ----------------------------------------------------------
    def predict(self, u: Optional[ArrayLike] = None, Q: Union[float, ArrayLike, None] = None) -> None:
        """Propagate with the body-frame increment ``u`` and process noise.

        Parameters
        ----------
        u : ndarray (3, 3) or (3,), optional
            Body-frame rotation increment (body_{k-1} <- body_k), as a matrix
            or a rotation vector in rad: ``x <- x @ u``. None: random walk.
        Q : float or ndarray (3, 3), optional
            Process noise for this step (body tangent space); default ``self.Q``.
        """
        Q = self.Q if Q is None else _check_cov("Q", Q)
        U = _as_rotation(u)
        if U is not None:
            self.x = self.x @ U
        if self.error == "left":
            P = self.P if U is None else U.T @ self.P @ U
            self.P = P + Q
        else:
            A = self.x
            P = self.P + A @ Q @ A.T
            self.P = 0.5 * (P + P.T)
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()

    def update(self, z: Optional[ArrayLike], R: Union[float, ArrayLike, None] = None) -> None:
        """Correct with a rotation or a direction measurement.

        Parameters
        ----------
        z : ndarray (3, 3) or (3,) or None
            A rotation (world <- body, ``Z = X Exp(v)``) or a unit vector in
            world axes (``z = X b + v``). None skips the update (like filterpy).
        R : float or ndarray (3, 3), optional
            Measurement noise for this update; default ``self.R``.
        """
        if z is None:
            self.z = None
            self.x_post = self.x.copy()
            self.P_post = self.P.copy()
            self.y = np.zeros(3)
            return
        R = self.R if R is None else _check_cov("R", R)
        z = np.asarray(z, dtype=float)
        x = self.x
        if z.shape == (3, 3):
            if self.error == "left":
                y = so3.log_one(x.T @ z)
                Rn = R
            else:
                y = so3.log_one(z @ x.T)
                Rn = x @ R @ x.T
            H = None
        elif z.shape == (3,):
            if self.error == "left":
                y = x.T @ z - self.b
                H = -self._hb
                Rn = x.T @ R @ x
            else:
                xb = x @ self.b
                y = z - xb
                H = -so3.hat(xb)
                Rn = R
        else:
            raise ValueError(f"z must be a 3x3 rotation or a unit vector of shape (3,), got {z.shape}")

        P = self.P
        if H is None:                       # H = I
            PHT = P
            S = P + Rn
        else:
            PHT = P @ H.T
            S = H @ PHT + Rn
        SI, detS = _inv3(S)
        K = PHT @ SI
        dx = K @ y
        if self.error == "left":
            x = x @ so3.exp_one(dx)
        else:
            x = so3.exp_one(dx) @ x
        self._updates += 1
        if self._updates % _RENORM_EVERY == 0:
            x = _renormalise(x)
        self.x = x
        if H is None:
            # H = I: (I - K) P = P (P + Rn)^-1 Rn = K Rn, the information form
            # (P^-1 + Rn^-1)^-1, positive definite by construction.
            P = K @ Rn
        else:
            IKH = _I3 - K @ H       # Joseph form
            P = IKH @ P @ IKH.T + K @ Rn @ K.T
        self.P = 0.5 * (P + P.T)

        self.z = z.copy()
        self.y, self.K, self.S, self.SI = y, K, S, SI
        self._detS = detS
        self._log_likelihood = None
        self._mahalanobis = None
        self.x_post = self.x.copy()
        self.P_post = self.P.copy()

    # -- batch -----------------------------------------------------------------
    def batch_filter(self, zs, us=None, Rs=None, Qs=None, saver=None):
        """Run predict/update over a sequence of measurements.

        Parameters
        ----------
        zs : sequence or ndarray, (N, 3, 3) rotations or (N, 3) directions
            Measurements; an entry of None skips that update.
        us : sequence or ndarray, (N, 3, 3) or (N, 3), optional
            Body-frame increments used in the predict before each update.
        Rs, Qs : sequence of (3, 3), optional
            Per-step noise; default the filter's ``R`` and ``Q``.
        saver : filterpy.common.Saver, optional
            Called with ``saver.save()`` after every step.

        Returns
        -------
        Xs, Ps : ndarray (N, 3, 3)
            Posterior rotations (world <- body) and covariances.
        Xs_prior, Ps_prior : ndarray (N, 3, 3)
            Predicted rotations and covariances (what :meth:`rts_smoother` needs).
        """
        n = len(zs)
        Xs = np.empty((n, 3, 3))
        Ps = np.empty((n, 3, 3))
        Xp = np.empty((n, 3, 3))
        Pp = np.empty((n, 3, 3))
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
            Posterior rotations (world <- body) and covariances from
            :meth:`batch_filter`.
        us : ndarray (N, 3, 3) or (N, 3), optional
            The same increments as given to :meth:`batch_filter` (``us[k]``
            propagates from step k-1 to k).
        Qs : sequence of (3, 3), optional
            Per-step process noise; default ``self.Q``.

        Returns
        -------
        Xs_smooth, Ps_smooth : ndarray (N, 3, 3)
            Smoothed rotations and covariances.
        Cs : ndarray (N, 3, 3)
            Smoother gains.
        Ps_prior : ndarray (N, 3, 3)
            Predicted covariances recomputed from ``Ps``.

        Notes
        -----
        With the left error, ``X_{k+1}^- = X_k U_{k+1}``, ``F = U_{k+1}^T`` and
        ``C_k = P_k F^T (P_{k+1}^-)^-1``; the smoothed state is
        ``X_k Exp(C_k Log((X_{k+1}^-)^-1 Xs_{k+1}))`` and
        ``Ps_k = P_k + C_k (Ps_{k+1} - P_{k+1}^-) C_k^T``. With the right error
        ``F = I``, the process noise enters as ``A Q A^T`` with ``A = X_k U_{k+1}``
        and the correction multiplies on the left.
        """
        Xs = np.asarray(Xs, dtype=float)
        Ps = np.asarray(Ps, dtype=float)
        n = len(Xs)
        Xsm = Xs.copy()
        Psm = Ps.copy()
        Cs = np.zeros((n, 3, 3))
        Ppr = np.zeros((n, 3, 3))
        if n:
            Ppr[0] = Ps[0]
        for k in range(n - 2, -1, -1):
            U = _I3 if us is None else _as_rotation(us[k + 1])
            Q = self.Q if Qs is None else _check_cov("Q", Qs[k + 1])
            Xpred = Xs[k] @ U
            if self.error == "left":
                F = U.T
                Pp = F @ Ps[k] @ F.T + Q
            else:
                F = _I3
                Pp = Ps[k] + Xpred @ Q @ Xpred.T
            Pp = 0.5 * (Pp + Pp.T)
            C = Ps[k] @ F.T @ np.linalg.inv(Pp)
            if self.error == "left":
                d = so3.log_one(Xpred.T @ Xsm[k + 1])
                Xsm[k] = _renormalise(Xs[k] @ so3.exp_one(C @ d))
            else:
                d = so3.log_one(Xsm[k + 1] @ Xpred.T)
                Xsm[k] = _renormalise(so3.exp_one(C @ d) @ Xs[k])
            P = Ps[k] + C @ (Psm[k + 1] - Pp) @ C.T
            Psm[k] = 0.5 * (P + P.T)
            Cs[k] = C
            Ppr[k + 1] = Pp
        return Xsm, Psm, Cs, Ppr
