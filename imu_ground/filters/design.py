"""Discrete-time filter design for the estimators: band-pass, second-order response, a streaming IIR runner.

Every design takes the frame rate (Hz) or interval (s) it is for. scipy is imported inside the functions that
need it, so the streaming path does not load it.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from imu_ground._jit import njit
from imu_ground.imu.warm_start import as_reader

__all__ = ["butter_bandpass", "foh_filter", "IIRFilter", "lfilter_df2t"]


def butter_bandpass(band: Sequence[float], rate: float, order: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Butterworth band-pass ``(b, a)`` for a signal sampled at ``rate``.

    Parameters
    ----------
    band, rate : (float, float), float
        Pass band, strictly inside (0, rate / 2), and the sampling (frame) rate, Hz.
    order : int
        Order of the low-pass prototype (the band-pass has twice as many poles).

    Returns
    -------
    b, a : ndarray
        Numerator and denominator, as for :func:`scipy.signal.lfilter`.

    Raises
    ------
    ValueError
        A band outside (0, rate / 2).
    """
    from scipy.signal import butter
    nyq = 0.5 * float(rate)
    lo, hi = float(band[0]), float(band[1])
    if not 0.0 < lo < hi < nyq:
        raise ValueError(f"band {(lo, hi)} Hz must lie inside (0, {nyq:g}) Hz at a frame rate of {rate:g} Hz")
    return butter(order, [lo / nyq, hi / nyq], "bandpass")


def foh_filter(freq: float, damping: float, dt: float):
    """Exact discretisation of ``x'' + 2 zeta w x' + w^2 x = w^2 u`` for a first-order-hold input.

    The input is linear between samples ``dt`` apart; ``(x, x')`` is propagated by the matrix exponential of
    the system augmented with the input and its slope (no discretisation error).

    Parameters
    ----------
    freq, damping, dt : float
        Undamped natural frequency (Hz, ``w = 2 pi freq``), damping ratio ``zeta``, sample interval (s).

    Returns
    -------
    num_x, num_xdot, den : ndarray (3,)
        Transfer functions from ``u`` to ``x`` (unit static gain) and to ``x'``, for :func:`scipy.signal.lfilter`.
    """
    from scipy.linalg import expm
    w = 2.0 * math.pi * float(freq)
    # augmented state (x, x', u, u'): u' constant over the sample interval
    big = np.zeros((4, 4))
    big[0, 1] = 1.0
    big[1, 0], big[1, 1], big[1, 2] = -w * w, -2.0 * float(damping) * w, w * w
    big[2, 3] = 1.0
    e = expm(big * float(dt))
    phi = e[:2, :2]
    gu, gs = e[:2, 2], e[:2, 3]
    # x_{k+1} = phi x_k + gu u_k + gs (u_{k+1} - u_k) / dt  =  phi x_k + c0 u_k + c1 u_{k+1}
    c1 = gs / dt
    c0 = gu - c1
    adj = np.array([[-phi[1, 1], phi[0, 1]], [phi[1, 0], -phi[0, 0]]])     # adj(z I - phi) = z I + adj
    num = np.column_stack([c1, c0 + adj @ c1, adj @ c0])
    den = np.array([1.0, -np.trace(phi), np.linalg.det(phi)])
    return num[0], num[1], den


@njit
def lfilter_df2t(b: np.ndarray, a: np.ndarray, z: np.ndarray, u: np.ndarray, y: np.ndarray) -> None:
    """Direct form II transposed, :func:`scipy.signal.lfilter`'s recursion, of ``u`` into ``y`` (compiled; callable
    from other compiled bodies).

    Parameters
    ----------
    b, a : ndarray (M + 1,)
        Numerator and denominator, normalised (``a[0] == 1``).
    z : ndarray (M, C)
        The filter's memory, advanced in place.
    u, y : ndarray (N, C)
        Input samples, and the output written, one column per channel.
    """
    m = z.shape[0]
    for k in range(u.shape[0]):
        for c in range(u.shape[1]):
            x = u[k, c]
            out = b[0] * x + z[0, c]
            for i in range(m - 1):
                z[i, c] = b[i + 1] * x + z[i + 1, c] - a[i + 1] * out
            z[m - 1, c] = b[m] * x - a[m] * out
            y[k, c] = out


class IIRFilter:
    """A causal IIR filter over a few channels: :meth:`step` a sample, :meth:`run` a batch that continues it (one
    compiled body).

    Parameters
    ----------
    b, a : array_like
        Numerator and denominator.
    channels : int
        Independent channels filtered alike.
    steady : bool
        Start in equilibrium with the first input (instead of from zero).
    """

    def __init__(self, b, a, channels: int, steady: bool = False) -> None:
        a = np.asarray(a, dtype=float)
        self.b = np.asarray(b, dtype=float) / a[0]
        self.a = a / a[0]
        self.z = np.zeros((len(self.a) - 1, channels))
        self.steady = bool(steady)
        self.started = False

    def step(self, u) -> np.ndarray:
        """Filter one sample (one value per channel)."""
        return self.run(np.asarray(u, dtype=float).reshape(1, -1))[0]

    def run(self, u: np.ndarray) -> np.ndarray:
        """Filter samples (N, channels), continuing from the current state."""
        u = np.ascontiguousarray(u, dtype=float)
        if len(u) and not self.started:
            if self.steady:
                from scipy.signal import lfilter_zi
                self.z = lfilter_zi(self.b, self.a)[:, None] * u[0][None, :]
            self.started = True
        y = np.empty_like(u)
        lfilter_df2t(self.b, self.a, self.z, u, y)
        return y

    def state_dict(self) -> dict:
        """The filter's memory as plain values (``z``, ``started``), for a warm start."""
        return {"z": self.z.tolist(), "started": self.started}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (a dict or a :class:`~imu_ground.imu.warm_start.StateReader`), checked
        (``z`` of this filter's shape, finite) before any is set."""
        state = as_reader(state, "IIRFilter")
        z = state.floats("z", self.z.shape)
        self.z, self.started = np.ascontiguousarray(z, dtype=float), state.bool("started")
