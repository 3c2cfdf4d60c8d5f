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

Covariances are updated in Joseph form (for ``H = I`` in the equivalent
information form ``P <- K Rn``, positive definite by construction) and kept
exactly symmetric (the upper triangle is computed, the lower mirrored); the
state's quaternion is renormalised every :data:`imu_ground.units.RENORM_EVERY`
corrections, so both stay valid over millions of steps. Frames and signs: the
glossary of :mod:`imu_ground.so3`.

Implementation: one predict/update touches a handful of 3x3 matrices, where
numpy's per-call overhead dominates, so the kernels are scalar Python on
row-major 9-tuples (:func:`imu_ground.so3.mul_flat` and friends) and the state
is held as a unit quaternion. The filterpy attributes (``x``, ``P``, ``K``,
``x_prior``, ...) are properties that build their array on access; ``x``,
``P``, ``Q``, ``R`` may be assigned or changed in place as in filterpy.
"""
from __future__ import annotations

import math
from typing import Optional, Union

import numpy as np

from imu_ground import so3
from imu_ground.so3 import (exp_flat, flat_from_quat, hat_flat, log_flat, mul_flat, mul_nt_flat, mul_tn_flat,
                            quat_exp, quat_from_flat, quat_mul, quat_normalise, transpose_flat)
from imu_ground.units import RENORM_EVERY

__all__ = ["InvariantEKF"]

ArrayLike = Union[np.ndarray, list, tuple]
_I3 = np.eye(3)
_I9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
_ZERO9 = (0.0,) * 9
_LOG2PI = math.log(2.0 * math.pi)


def _flat_rotation(u) -> Optional[tuple]:
    """Row-major 9 floats of a 3x3 matrix or a rotation vector (rad); None stays None."""
    if u is None:
        return None
    u = np.asarray(u, dtype=float)
    if u.shape == (3, 3):
        return u.ravel().tolist()
    if u.shape == (3,):
        return exp_flat(*u.tolist())
    raise ValueError(f"rotation increment must be a 3x3 matrix or a rotation vector of shape (3,), got {u.shape}")


def _check_cov(name: str, m: Optional[ArrayLike]) -> Optional[np.ndarray]:
    m = np.asarray(m, dtype=float)
    if m.ndim == 0:
        return float(m) * _I3
    if m.shape != (3, 3):
        raise ValueError(f"{name} must be a scalar or a 3x3 matrix, got shape {m.shape}")
    return m


def _congruence(a, p, q=_ZERO9) -> tuple:
    """``A P A^T + Q`` for symmetric ``P`` and ``Q`` (upper triangle computed, lower mirrored), 9-tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    m0, m1, m2, m3, m4, m5, m6, m7, m8 = mul_flat(a, p)
    c00 = m0 * a0 + m1 * a1 + m2 * a2 + q[0]
    c01 = m0 * a3 + m1 * a4 + m2 * a5 + q[1]
    c02 = m0 * a6 + m1 * a7 + m2 * a8 + q[2]
    c11 = m3 * a3 + m4 * a4 + m5 * a5 + q[4]
    c12 = m3 * a6 + m4 * a7 + m5 * a8 + q[5]
    c22 = m6 * a6 + m7 * a7 + m8 * a8 + q[8]
    return c00, c01, c02, c01, c11, c12, c02, c12, c22


def _sym_upper(m) -> tuple:
    """The symmetric matrix of the upper triangle of ``m`` (row-major 9-tuple)."""
    return m[0], m[1], m[2], m[1], m[4], m[5], m[2], m[5], m[8]


def _inv_flat(m):
    """Inverse (row-major 9-tuple) and determinant of a 3x3 matrix by cofactors."""
    a, b, c, d, e, f, g, h, i = m
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    if det == 0.0 or not math.isfinite(det):
        raise np.linalg.LinAlgError(f"innovation covariance is singular (det = {det})")
    r = 1.0 / det
    return (A * r, (c * h - b * i) * r, (b * f - c * e) * r,
            B * r, (a * i - c * g) * r, (c * d - a * f) * r,
            C * r, (b * g - a * h) * r, (a * e - b * d) * r), det


def _update_rotation_left(q, P, z, r):
    """Left-error update with a rotation measurement, unrolled (H = I; the state a unit quaternion).

    Unrolls ``y = Log(x^T z)`` (as ``2 atan2(|v|, w) v / |v|`` of the quaternion
    ``conj(q) q_z``, accurate up to pi), ``S = P + R``, ``S^-1`` by symmetric
    cofactors, ``K = P S^-1``, ``q <- q Exp(K y)`` and ``P <- K R`` (upper
    triangle, mirrored); matrices are row-major 9-tuples. Returns ``q, P, y, K,
    S, SI, det S``.
    """
    qw, qx, qy, qz = q
    zw, zx, zy, zz = quat_from_flat(z)
    aw, ax, ay, az = (qw * zw + qx * zx + qy * zy + qz * zz, qw * zx - qx * zw - qy * zz + qz * zy,
                      qw * zy + qx * zz - qy * zw - qz * zx, qw * zz - qx * zy + qy * zx - qz * zw)
    if aw < 0.0:
        aw, ax, ay, az = -aw, -ax, -ay, -az
    vn = math.sqrt(ax * ax + ay * ay + az * az)
    f = 2.0 * math.atan2(vn, aw) / vn if vn > 0.0 else 2.0
    y0, y1, y2 = ax * f, ay * f, az * f
    p0, p1, p2, _, p4, p5, _, _, p8 = P
    r0, r1, r2, _, r4, r5, _, _, r8 = r
    s0, s1, s2, s4, s5, s8 = p0 + r0, p1 + r1, p2 + r2, p4 + r4, p5 + r5, p8 + r8
    i00, i01, i02 = s4 * s8 - s5 * s5, s2 * s5 - s1 * s8, s1 * s5 - s2 * s4
    det = s0 * i00 + s1 * i01 + s2 * i02
    if det == 0.0 or not math.isfinite(det):
        raise np.linalg.LinAlgError(f"innovation covariance is singular (det = {det})")
    d = 1.0 / det
    i00, i01, i02 = i00 * d, i01 * d, i02 * d
    i11, i12, i22 = (s0 * s8 - s2 * s2) * d, (s1 * s2 - s0 * s5) * d, (s0 * s4 - s1 * s1) * d
    SI = (i00, i01, i02, i01, i11, i12, i02, i12, i22)
    K = k0, k1, k2, k3, k4, k5, k6, k7, k8 = mul_flat(P, SI)
    if r1 == 0.0 and r2 == 0.0 and r5 == 0.0:   # diagonal R (the same numbers, without the zero terms)
        n01, n02, n12 = k1 * r4, k2 * r8, k5 * r8
        Pn = (k0 * r0, n01, n02, n01, k4 * r4, n12, n02, n12, k8 * r8)
    else:
        n01 = k0 * r1 + k1 * r4 + k2 * r5
        n02 = k0 * r2 + k1 * r5 + k2 * r8
        n12 = k3 * r2 + k4 * r5 + k5 * r8
        Pn = (k0 * r0 + k1 * r1 + k2 * r2, n01, n02, n01, k3 * r1 + k4 * r4 + k5 * r5, n12,
              n02, n12, k6 * r2 + k7 * r5 + k8 * r8)
    return (quat_mul(q, quat_exp(k0 * y0 + k1 * y1 + k2 * y2, k3 * y0 + k4 * y1 + k5 * y2, k6 * y0 + k7 * y1 + k8 * y2)),
            Pn, (y0, y1, y2), K, (s0, s1, s2, s1, s4, s5, s2, s5, s8), SI, det)


def _matrix(t) -> np.ndarray:
    return np.array(t).reshape(3, 3)


def _state_property(name: str, doc: str) -> property:
    """A 3x3 attribute held as a 9-tuple in ``_<name>``; the array the getter builds (and caches in
    ``_<name>_a``), once handed out, is what the next step reads (so ``f.P *= 2`` is seen)."""
    slot, cache = "_" + name, "_" + name + "_a"

    def get(self):
        a = self.__dict__[cache]
        if a is None:
            a = self.__dict__[cache] = _matrix(self.__dict__[slot])
        return a

    def set_(self, value):
        a = np.asarray(value, dtype=float)
        if a.shape != (3, 3):
            raise ValueError(f"{name} must be a 3x3 matrix, got shape {a.shape}")
        self.__dict__[cache] = a
        self.__dict__[slot] = a.ravel().tolist()

    return property(get, set_, doc=doc)


def _output_property(name: str, doc: str, shape=(3, 3), rotation: bool = False) -> property:
    """A result attribute (``K``, ``S``, ``x_prior``, ...) held as a tuple (a quaternion for a
    ``rotation``), built as an array on access."""
    slot = "_" + name

    def get(self):
        t = self.__dict__[slot]
        return None if t is None else np.array(flat_from_quat(t) if rotation else t).reshape(shape)

    def set_(self, value):
        t = None if value is None else np.asarray(value, dtype=float).ravel().tolist()
        self.__dict__[slot] = quat_from_flat(t) if rotation and t is not None else t

    return property(get, set_, doc=doc)


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
        self._left = error == "left"
        x = _I3 if x is None else np.asarray(x, dtype=float)
        if x.shape != (3, 3):
            raise ValueError(f"x must be a 3x3 rotation matrix, got shape {x.shape}")
        self._x = self._x_t = tuple(x.ravel().tolist())     # matrix (None: stale), as handed out
        self._q, self._x_a = quat_from_flat(self._x), None          # the state: a unit quaternion
        self._P, self._P_a = _check_cov("P", 1.0 if P is None else P).ravel().tolist(), None
        self._Q, self._Q_a = _check_cov("Q", 1e-2 if Q is None else Q).ravel().tolist(), None
        self._R, self._R_a = _check_cov("R", 1.0 if R is None else R).ravel().tolist(), None
        b = np.array([0.0, 0.0, 1.0]) if b is None else np.asarray(b, dtype=float)
        if b.shape != (3,) or not np.isclose(np.linalg.norm(b), 1.0):
            raise ValueError("b must be a unit vector of shape (3,)")
        self.b = b
        self._bt = tuple(b.tolist())
        self._Hb = tuple(-v for v in hat_flat(*self._bt))     # H = -[b]x of the left direction update
        self._z, self._z_shape = None, None
        self._y = (0.0, 0.0, 0.0)
        self._K = self._S = self._SI = (0.0,) * 9
        self._detS = None                   # no update yet
        self._x_prior = self._x_post = self._q
        self._P_prior = self._P_post = self._P
        self._updates = 0

    def _xmat(self) -> tuple:
        """The state as a row-major 9-tuple (built from the quaternion when stale)."""
        if self._x is None:
            self._x = flat_from_quat(self._q)
        return self._x

    def _pull_x(self) -> None:
        """Take in an ``x`` array handed out and changed in place since."""
        xl = tuple(self._x_a.ravel().tolist())
        if xl != self._x_t:
            self._x, self._q = xl, quat_from_flat(xl)
        self._x_a = None

    @property
    def x(self) -> np.ndarray:
        """Current rotation, world <- body (3x3)."""
        if self._x_a is None:
            self._x_t = self._xmat()
            self._x_a = _matrix(self._x_t)
        return self._x_a

    @x.setter
    def x(self, value) -> None:
        a = np.asarray(value, dtype=float)
        if a.shape != (3, 3):
            raise ValueError(f"x must be a 3x3 matrix, got shape {a.shape}")
        self._x = self._x_t = tuple(a.ravel().tolist())
        self._q, self._x_a = quat_from_flat(self._x), a

    P = _state_property("P", "Current error covariance, tangent space (rad^2, 3x3).")
    Q = _state_property("Q", "Process noise per predict (rad^2, 3x3; symmetric, its upper triangle is used).")
    R = _state_property("R", "Measurement noise (3x3; symmetric, its upper triangle is used).")
    x_prior = _output_property("x_prior", "Rotation after the last predict.", rotation=True)
    P_prior = _output_property("P_prior", "Covariance after the last predict.")
    x_post = _output_property("x_post", "Rotation after the last update.", rotation=True)
    P_post = _output_property("P_post", "Covariance after the last update.")
    y = _output_property("y", "Last innovation (3,): tangent (rotation) or body-frame residual (direction).", (3,))
    K = _output_property("K", "Last Kalman gain (3x3).")
    S = _output_property("S", "Last innovation covariance (3x3).")
    SI = _output_property("SI", "Inverse of the last innovation covariance (3x3).")

    @property
    def z(self) -> Optional[np.ndarray]:
        """Last measurement, (3, 3) rotation or (3,) direction; None after a skipped update."""
        return None if self._z is None else np.array(self._z).reshape(self._z_shape)

    @z.setter
    def z(self, value) -> None:
        if value is None:
            self._z, self._z_shape = None, None
        else:
            value = np.asarray(value, dtype=float)
            self._z, self._z_shape = value.ravel().tolist(), value.shape

    # -- filterpy-style derived quantities ---------------------------------
    def _ysiy(self) -> float:
        y0, y1, y2 = self._y
        s = self._SI
        return (y0 * (s[0] * y0 + s[1] * y1 + s[2] * y2) + y1 * (s[3] * y0 + s[4] * y1 + s[5] * y2)
                + y2 * (s[6] * y0 + s[7] * y1 + s[8] * y2))

    @property
    def log_likelihood(self) -> float:
        """Log-likelihood of the last innovation under N(0, S) (computed on access)."""
        if self._detS is None:
            return math.log(1e-300)                       # filterpy's value before any update
        return -0.5 * (self._ysiy() + math.log(self._detS) + 3 * _LOG2PI)

    @property
    def likelihood(self) -> float:
        """``exp(log_likelihood)``, floored at the smallest positive float as in filterpy."""
        return max(math.exp(self.log_likelihood), np.finfo(float).tiny)

    @property
    def mahalanobis(self) -> float:
        """Mahalanobis distance of the last innovation, ``sqrt(y^T S^-1 y)``."""
        return math.sqrt(max(self._ysiy(), 0.0))

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
        if self._x_a is not None:
            self._pull_x()
        Pa = self._P_a
        P = self._P if Pa is None else Pa.ravel().tolist()
        q, x = self._q, None
        if Q is None:
            Qa = self._Q_a
            qn = self._Q if Qa is None else Qa.ravel().tolist()
        else:
            qn = _check_cov("Q", Q).ravel().tolist()
        if u is None:
            U = None
        elif type(u) is np.ndarray and u.shape == (3, 3):
            U = u.ravel().tolist()
        else:
            U = _flat_rotation(u)
        if U is not None:
            q = quat_mul(q, quat_from_flat(U))
            if self._left:              # P <- U^T P U + Q
                self._P = self._P_prior = _congruence(transpose_flat(U), P, qn)
                self._q = self._x_prior = q
                self._x = self._P_a = None
                return
        else:
            x = self._x
        if not self._left:              # P <- P + A Q A^T, A = x U
            x = flat_from_quat(q) if x is None else x
            qn = _congruence(x, qn)
        p0, p1, p2, _, p4, p5, _, _, p8 = P
        q0, q1, q2, _, q4, q5, _, _, q8 = qn
        a, b, c = p1 + q1, p2 + q2, p5 + q5
        self._P = self._P_prior = (p0 + q0, a, b, a, p4 + q4, c, b, c, p8 + q8)
        self._q = self._x_prior = q
        self._x, self._P_a = x, None

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
        if self._x_a is not None:
            self._pull_x()
        Pa = self._P_a
        P = self._P if Pa is None else Pa.ravel().tolist()
        if z is None:
            self._z = self._z_shape = None
            self._x_post = self._q
            self._P = self._P_post = P
            self._P_a = None
            self._y = (0.0, 0.0, 0.0)
            return
        if R is None:
            Ra = self._R_a
            r = self._R if Ra is None else Ra.ravel().tolist()
        else:
            r = _check_cov("R", R).ravel().tolist()
        if type(z) is not np.ndarray:
            z = np.asarray(z, dtype=float)
        shape = z.shape
        zl = z.ravel().tolist()
        if shape == (3, 3) and self._left:       # the usual case, stored here (as _finish_update)
            q, Pn, y, K, S, SI, detS = _update_rotation_left(self._q, P, zl, r)
            self._updates += 1
            if self._updates % RENORM_EVERY == 0:
                q = quat_normalise(q)
            self._q = self._x_post = q
            self._P = self._P_post = Pn
            self._x = self._P_a = None
            self._z, self._z_shape, self._y, self._K, self._S, self._SI, self._detS = zl, shape, y, K, S, SI, detS
            return
        x = self._xmat()
        if shape == (3, 3):
            # H = I: K = P S^-1, P <- (I - K) P = K Rn (information form, PD by construction)
            if self._left:
                y = log_flat(mul_tn_flat(x, zl))
                Rn = r
            else:
                y = log_flat(mul_nt_flat(zl, x))
                Rn = _congruence(x, r)
            p0, p1, p2, _, p4, p5, _, _, p8 = P
            r0, r1, r2, _, r4, r5, _, _, r8 = Rn
            a, b, c = p1 + r1, p2 + r2, p5 + r5
            S = (p0 + r0, a, b, a, p4 + r4, c, b, c, p8 + r8)
            SI, detS = _inv_flat(S)
            K = mul_flat(P, SI)
            Pn = _sym_upper(mul_flat(K, Rn))
        elif shape == (3,):
            z0, z1, z2 = zl
            if self._left:
                x0, x1, x2, x3, x4, x5, x6, x7, x8 = x
                b0, b1, b2 = self._bt
                y = (x0 * z0 + x3 * z1 + x6 * z2 - b0, x1 * z0 + x4 * z1 + x7 * z2 - b1,
                     x2 * z0 + x5 * z1 + x8 * z2 - b2)
                H = self._Hb
                Rn = _congruence((x0, x3, x6, x1, x4, x7, x2, x5, x8), r)
            else:
                b0, b1, b2 = self._bt
                xb = (x[0] * b0 + x[1] * b1 + x[2] * b2, x[3] * b0 + x[4] * b1 + x[5] * b2,
                      x[6] * b0 + x[7] * b1 + x[8] * b2)
                y = (z0 - xb[0], z1 - xb[1], z2 - xb[2])
                H = tuple(-v for v in hat_flat(*xb))
                Rn = r
            PHT = mul_nt_flat(P, H)
            S = tuple(m + n for m, n in zip(_sym_upper(mul_flat(H, PHT)), _sym_upper(Rn)))
            SI, detS = _inv_flat(S)
            K = mul_flat(PHT, SI)
            KH = mul_flat(K, H)
            IKH = tuple(i - kh for i, kh in zip(_I9, KH))           # Joseph form
            Pn = tuple(m + n for m, n in zip(_congruence(IKH, P), _congruence(K, Rn)))
        else:
            raise ValueError(f"z must be a 3x3 rotation or a unit vector of shape (3,), got {shape}")
        y0, y1, y2 = y
        k0, k1, k2, k3, k4, k5, k6, k7, k8 = K
        e = quat_exp(k0 * y0 + k1 * y1 + k2 * y2, k3 * y0 + k4 * y1 + k5 * y2, k6 * y0 + k7 * y1 + k8 * y2)
        self._finish_update(quat_mul(self._q, e) if self._left else quat_mul(e, self._q), Pn, zl, shape,
                            y, K, S, SI, detS)

    def _finish_update(self, q, Pn, zl, shape, y, K, S, SI, detS) -> None:
        """Renormalise every RENORM_EVERY corrections and store the results of an update."""
        self._updates += 1
        if self._updates % RENORM_EVERY == 0:
            q = quat_normalise(q)
        self._q = self._x_post = q
        self._x = None
        self._P = self._P_post = Pn
        self._P_a = None
        self._z, self._z_shape = zl, shape
        self._y, self._K, self._S, self._SI, self._detS = y, K, S, SI, detS

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
        Xsm, Psm = Xs.copy(), Ps.copy()
        Cs, Ppr = np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
        if n:
            Ppr[0] = Ps[0]
        for k in range(n - 2, -1, -1):
            U = _I3 if us is None else _matrix(_flat_rotation(us[k + 1]))
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
                Xsm[k] = so3.renormalise(Xs[k] @ so3.exp_one(C @ d))
            else:
                d = so3.log_one(Xsm[k + 1] @ Xpred.T)
                Xsm[k] = so3.renormalise(so3.exp_one(C @ d) @ Xs[k])
            P = Ps[k] + C @ (Psm[k + 1] - Pp) @ C.T
            Psm[k] = 0.5 * (P + P.T)
            Cs[k] = C
            Ppr[k + 1] = Pp
        return Xsm, Psm, Cs, Ppr
