r"""Closed-form smooth profiles (speed in time; curvature, grade and bank along the road): septic smooth steps
and :class:`Piecewise` sums of them, with two derivatives and two integrals in closed form (exact kinematics).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["Piecewise", "smoothstep"]


def smoothstep(u):
    """Septic smooth step S(u) on [0, 1] (C^3 at both ends), its first two derivatives, and its integrals from 0.

    Parameters
    ----------
    u : ndarray
        Normalised position in the phase, in [0, 1].

    Returns
    -------
    s, d1, d2, i1, i2 : ndarray
        ``S``, ``S'``, ``S''``, ``int_0^u S`` and ``int_0^u int_0^v S``.
    """
    u2 = u * u
    u3 = u2 * u
    w = 1.0 - u
    s = u2 * u2 * (35.0 - 84.0 * u + 70.0 * u2 - 20.0 * u3)
    d1 = 140.0 * u3 * w * w * w
    d2 = 420.0 * u2 * w * w * (1.0 - 2.0 * u)
    i1 = u * u2 * u2 * (7.0 - 14.0 * u + 10.0 * u2 - 2.5 * u3)
    i2 = u3 * u3 * (7.0 / 6.0 - 2.0 * u + 1.25 * u2 - 2.5 / 9.0 * u3)
    return s, d1, d2, i1, i2


_S2_AT_1 = 7.0 / 6.0 - 2.0 + 1.25 - 2.5 / 9.0      # = 5/36; S1(1) = 1/2


class Piecewise:
    """``y(x)``: contiguous phases, ``y = A_j + D_j S((x - x_j) / d_j)`` on phase ``j``.

    ``I1 = V_j + A_j tau + D_j d_j S1(u)`` (integral of y, ``V_0 = y1_0``) and
    ``I2 = P_j + V_j tau + A_j tau^2/2 + D_j d_j^2 S2(u)`` (integral of I1), all in
    closed form. The last phase holds forever; before ``x_0`` the first level holds.

    Parameters
    ----------
    x0, y0 : float
        Start of the first phase (s or m) and the level there.
    phases : sequence of (duration, delta)
        Each phase's length and the change of level over it.
    i1_0, i2_0 : float
        First and second integrals at ``x0``.
    snap : bool
        An integral below 1e-9 at the start of a zero-level constant phase is set to 0 (exact stops).
    """

    def __init__(self, x0: float, y0: float, phases: Sequence[tuple[float, float]],
                 i1_0: float = 0.0, i2_0: float = 0.0, snap: bool = False) -> None:
        phases = list(phases) + [(math.inf, 0.0)]
        rows = []
        x, level, v, p = float(x0), float(y0), float(i1_0), float(i2_0)
        for dur, delta in phases:
            if snap and delta == 0.0 and level == 0.0 and abs(v) < 1e-9:
                v = 0.0
            rows.append((x, dur, level, delta, v, p))
            if math.isinf(dur):
                break
            p = p + v * dur + level * dur * dur / 2.0 + delta * dur * dur * _S2_AT_1
            v = v + level * dur + delta * dur / 2.0
            level = level + delta
            x = x + dur
        self.start, self.dur, self.a, self.d, self.v, self.p = np.array(rows, dtype=float).T

    def __call__(self, x):
        """Value, first and second derivative, first and second integral at ``x``."""
        x = np.asarray(x, dtype=float)
        j = np.clip(np.searchsorted(self.start, x, side="right") - 1, 0, len(self.start) - 1)
        tau = x - self.start[j]
        dur = self.dur[j]
        finite = np.isfinite(dur)
        dsafe = np.where(finite, dur, 1.0)
        u = np.where(finite, np.clip(tau / dsafe, 0.0, 1.0), 0.0)
        s, d1, d2, i1, i2 = smoothstep(u)
        a, dd = self.a[j], self.d[j]
        y = a + dd * s
        y1 = dd * d1 / dsafe
        y2 = dd * d2 / (dsafe * dsafe)
        # before x0, tau < 0 and u = 0: the first level extends linearly in the integrals
        big1 = self.v[j] + a * tau + dd * dsafe * i1
        big2 = self.p[j] + self.v[j] * tau + a * tau * tau / 2.0 + dd * dsafe * dsafe * i2
        return y, y1, y2, big1, big2
