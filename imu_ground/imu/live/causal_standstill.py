"""Causal standstill detection and gyro bias: from the samples seen so far, one frame at a time.

The whole-log detector (:mod:`imu_ground.imu.standstill`) looks at windows that start at each sample and
so sees up to a window ahead; a live estimator cannot. Here the samples are summed in blocks, one per
output frame (block ``k`` holds the samples in ``(t0 + k / rate, t0 + (k + 1) / rate]``,
:func:`block_index`), and frame ``k`` ends at a standstill when the trailing window of the
``W = round(window * rate)`` blocks ``k - W + 1 .. k`` passes the whole-log detector's still test
(:func:`~imu_ground.imu.standstill.window_test`, the same body) with every block holding samples (a gap
is no standstill). Gravity's magnitude is fixed (:data:`~imu_ground.units.GRAVITY` by default): a causal
detector cannot take the log's own median at rest.

The gyro bias (:class:`CausalGyroBias`) is the mean rate over every block of the standstills seen so far
(each block once) in windows of ``bias_window`` (2 s, as the whole-log bias), or a given bias.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from imu_ground._jit import jitable, njit
from imu_ground.imu.standstill import (ACCEL_NORM_TOL, ACCEL_STD_MAX, GYRO_NORM_MAX, GYRO_STD_MAX, WINDOW,
                                       window_test)
from imu_ground.units import GRAVITY

__all__ = ["MAX_GYRO_BIAS", "CausalGyroBias", "StandstillBlocks", "StandstillTests", "block_index", "open_row"]

#: Rounding allowance of :func:`block_index`, frames.
_EDGE = 1e-6
_FREE = np.iinfo(np.int64).min            # a free row of the blocks' ring
#: Floats of a block: the sample count, 6 sums (gyro rad/s, then specific force m/s^2), their 6 sums of squares.
BLOCK_SIZE = 13
#: The largest gyro bias a saved state may hold, rad/s.
MAX_GYRO_BIAS = 1.0


@njit
def add_sample(b: np.ndarray, g0: float, g1: float, g2: float, a0: float, a1: float, a2: float) -> None:
    """Sum one sample (gyro rad/s, specific force m/s^2) into the block ``b`` (:data:`BLOCK_SIZE` floats)."""
    b[0] += 1.0
    b[1] += g0
    b[2] += g1
    b[3] += g2
    b[4] += a0
    b[5] += a1
    b[6] += a2
    b[7] += g0 * g0
    b[8] += g1 * g1
    b[9] += g2 * g2
    b[10] += a0 * a0
    b[11] += a1 * a1
    b[12] += a2 * a2


@njit
def open_row(ring: np.ndarray, keys: np.ndarray, k: int) -> int:
    """Block ``k``'s row of the ``ring`` (its sums zeroed and its key set unless it holds block ``k`` already); -1,
    nothing changed, when that row holds another block (the ring must grow: :meth:`StandstillBlocks.open_block`)."""
    i = k % ring.shape[0]
    key = keys[i]
    if key != k:
        if key != _FREE:
            return -1
        ring[i, :] = 0.0
        keys[i] = k
    return i


@jitable
def block_index(t: float, t0: float, rate: float) -> int:
    """The block (frame) of a sample at ``t`` (s): ``ceil((t - t0) rate - 1e-6) - 1``; -1 for the first sample
    (callable from compiled bodies too)."""
    return math.ceil((t - t0) * rate - _EDGE) - 1


class StandstillTests:
    """The thresholds of a standstill window (defaults as :func:`imu_ground.imu.standstill.detect_standstill`).

    Parameters
    ----------
    window : float
        Trailing window, s.
    gyro_std_max, gyro_norm_max : float
        rad/s.
    accel_std_max, accel_norm_tol, gravity : float
        m/s^2 (``gravity``: the specific force's magnitude at rest).
    """

    def __init__(self, window: float = 1.0, gyro_std_max: float = GYRO_STD_MAX, gyro_norm_max: float = GYRO_NORM_MAX,
                 accel_std_max: float = ACCEL_STD_MAX, accel_norm_tol: float = ACCEL_NORM_TOL,
                 gravity: float = GRAVITY) -> None:
        self.window, self.gyro_std_max, self.gyro_norm_max = float(window), float(gyro_std_max), float(gyro_norm_max)
        self.accel_std_max, self.accel_norm_tol = float(accel_std_max), float(accel_norm_tol)
        self.gravity = float(gravity)

    def blocks(self, rate: float) -> int:
        """Blocks in the window at ``rate`` frames a second."""
        return max(1, int(round(self.window * rate)))

    def array(self) -> np.ndarray:
        """The thresholds in the order :func:`_windows` reads them."""
        return np.array([self.gyro_std_max, self.gyro_norm_max, self.accel_std_max, self.accel_norm_tol,
                         self.gravity])


@njit
def _windows(ring: np.ndarray, keys: np.ndarray, k: int, W: int, Wb: int, Wq: int, thresholds: np.ndarray,
             work: np.ndarray) -> int:
    """:meth:`StandstillBlocks.windows` on the ring (bit 0: ``W`` passes, bit 1: ``Wb``, bit 2: ``Wq``; 0: not asked;
    ``work`` (5, 6) scratch), the three summed in one pass."""
    R = ring.shape[0]
    s, q, zero, m, sd = work[0], work[1], work[2], work[3], work[4]
    s[:] = 0.0
    q[:] = 0.0
    n = 0.0
    res = 0
    for i in range(max(W, Wb, Wq)):
        j = k - i
        slot = j % R
        if j < 0 or keys[slot] != j or ring[slot, 0] == 0.0:
            break
        n += ring[slot, 0]
        for c in range(6):
            s[c] += ring[slot, 1 + c]
            q[c] += ring[slot, 7 + c]
        if i + 1 == W or i + 1 == Wb or i + 1 == Wq:
            norm = window_test(n, s, q, zero, m, sd, thresholds[0], thresholds[1], thresholds[2])
            if abs(norm - thresholds[4]) <= thresholds[3]:
                res |= (1 if i + 1 == W else 0) | (2 if i + 1 == Wb else 0) | (4 if i + 1 == Wq else 0)
    return res


@njit
def _forget(keys: np.ndarray, cut: int) -> None:
    """Free the ring's slots of the blocks before ``cut``."""
    for i in range(keys.size):
        if keys[i] < cut:
            keys[i] = _FREE


class StandstillBlocks:
    """Per-frame sums of the samples and the trailing-window standstill test, one sample at a time.

    Parameters
    ----------
    rate : float
        Frame rate, Hz (one block a frame).
    tests : StandstillTests, optional
    bias_window : float
        The window of the standstills the gyro bias is taken from, s (``Wb`` blocks).
    """

    def __init__(self, rate: float, tests: StandstillTests | None = None, bias_window: float = WINDOW) -> None:
        self.rate = float(rate)
        self.tests = StandstillTests() if tests is None else tests
        self.W = self.tests.blocks(self.rate)
        self.Wb = max(1, int(round(bias_window * self.rate)))      # the bias's window, blocks
        self._thresholds = self.tests.array()
        self._work = np.zeros((5, 6))
        # the blocks held: block j in row j % R of the ring (its index in keys; _FREE: the row is free)
        self.ring = np.zeros((2 * max(self.W, self.Wb) + 4, BLOCK_SIZE))
        self._keys = np.full(self.ring.shape[0], _FREE, dtype=np.int64)
        self.open_k = -1                        # the block of the last sample added (-1: none)

    @property
    def blocks(self) -> dict[int, np.ndarray]:
        """Block index -> a copy of its float64 sums ``[n, 6 sums, 6 sums of squares]``, every block held."""
        return {int(j): self.ring[i].copy() for i, j in enumerate(self._keys.tolist()) if j != _FREE}

    @property
    def buffers(self) -> tuple[np.ndarray, np.ndarray]:
        """``(ring, keys)``: the sums' rows and the block each row holds, for a caller's compiled step
        (:func:`open_row`, :func:`add_sample`; it sets :attr:`open_k`); new arrays after the ring grows."""
        return self.ring, self._keys

    def add(self, k: int, g: Sequence[float], a: Sequence[float]) -> None:
        """Add a sample (gyro rad/s, specific force m/s^2) to block ``k``."""
        if k != self.open_k:
            self.open_block(k)
        add_sample(self.ring[k % self.ring.shape[0]], g[0], g[1], g[2], a[0], a[1], a[2])

    def windows(self, k: int, W: int | None = None, Wb: int | None = None) -> tuple[bool, bool]:
        """Whether the trailing windows of ``W`` and of ``Wb`` blocks (defaults :attr:`W`, :attr:`Wb`; 0: not
        asked) ending at frame ``k`` pass, summed newest block first."""
        r = _windows(self.ring, self._keys, k, self.W if W is None else W, self.Wb if Wb is None else Wb, 0,
                     self._thresholds, self._work)
        return r & 1 != 0, r & 2 != 0

    def frame_windows(self, k: int, bias: bool) -> tuple[bool, bool, bool]:
        """``(still, for_bias, quiet)`` of frame ``k`` in one pass: :meth:`windows` of :attr:`W` and (when ``bias``)
        :attr:`Wb` blocks, and whether the frame's own block alone passes."""
        r = _windows(self.ring, self._keys, k, self.W, self.Wb if bias else 0, 1, self._thresholds, self._work)
        return r & 1 != 0, r & 2 != 0, r & 4 != 0

    def done(self, k: int) -> None:
        """Frame ``k`` is finished: forget the blocks no later frame's windows hold."""
        cut = k - max(self.W, self.Wb) + 2
        _forget(self._keys, cut)
        if self.open_k < cut:
            self.open_k = -1

    def block(self, j: int) -> tuple[int, float, float, float]:
        """``(n, gyro sums x, y, z)`` of block ``j`` (zeros when it holds no sample)."""
        i = j % self.ring.shape[0]
        if self._keys[i] != j:
            return 0, 0.0, 0.0, 0.0
        n, x, y, z = self.ring[i, 0:4].tolist()
        return int(n), x, y, z

    def open_block(self, k: int) -> np.ndarray:
        """Block ``k`` (a new, empty one unless it holds samples) becomes the one samples are summed into."""
        i = open_row(self.ring, self._keys, k)
        if i < 0:                                   # its row holds another block: a larger ring
            held = self.blocks
            R = 2 * self.ring.shape[0]
            while len({j % R for j in [*held, k]}) <= len(held):
                R *= 2
            self.ring, self._keys = np.zeros((R, BLOCK_SIZE)), np.full(R, _FREE, dtype=np.int64)
            for j, row in held.items():
                self.ring[j % R], self._keys[j % R] = row, j
            i = open_row(self.ring, self._keys, k)
        self.open_k = k
        return self.ring[i]

    def clear(self) -> None:
        self._keys[:] = _FREE
        self.open_k = -1

    def state_dict(self) -> dict[str, Any]:
        blocks = self.blocks
        keys = sorted(blocks)
        return {"k": keys, "n": [int(blocks[k][0]) for k in keys], "sums": [blocks[k][1:].tolist() for k in keys]}

    def load_checked(self, r: Any, limit: int) -> None:
        """Resume from a :meth:`state_dict` read through ``r`` (a :class:`~imu_ground.imu.warm_start.StateReader`),
        checked (at most ``limit`` blocks, integer keys and counts, 12 finite sums each; else a ``StateError``)."""
        keys = r.state.get("k") if isinstance(r.state, dict) else None
        if not isinstance(keys, list) or len(keys) > limit:
            raise r.error("k", f"is not a list of at most {limit} block indices")
        ns = r.floats("n", (len(keys),))
        sums = r.floats("sums", (len(keys), 12)) if keys else np.zeros((0, 12))
        if any(type(k) is not int for k in keys) or (ns < 0).any() or (ns != np.round(ns)).any():
            raise r.error("k", "holds keys or counts that are not integers >= 0")
        self.load_state_dict({"k": keys, "n": ns.astype(int).tolist(), "sums": sums.tolist()})

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.clear()
        for k, n, s in zip(state["k"], state["n"], state["sums"], strict=True):
            self.open_block(int(k))[:] = [int(n), *(float(x) for x in s)]
        self.open_k = max((int(k) for k in state["k"]), default=-1)   # samples come in time order: the last is open


class CausalGyroBias:
    """Gyro bias from the standstills seen so far, or fixed.

    Parameters
    ----------
    bias : "auto" or sequence of 3 floats
        ``"auto"``: the mean rate over the blocks of every standstill so far (zero before
        the first); three floats: this bias, rad/s, never changed.

    Attributes
    ----------
    value : tuple of 3 floats
        The bias, rad/s, body frame.
    n : int
        Samples averaged (``auto``).
    """

    def __init__(self, bias: Any = "auto") -> None:
        self.auto = isinstance(bias, str)
        if self.auto and bias != "auto":
            raise ValueError(f"bias_gyro must be 'auto' or 3 numbers (rad/s), got {bias!r}")
        self.value = (0.0, 0.0, 0.0) if self.auto else tuple(float(x) for x in np.asarray(bias, float).reshape(3))
        self.n, self.s = 0, [0.0, 0.0, 0.0]
        self.last = -1                  # last block added

    def absorb(self, k: int, W: int, block) -> None:
        """Frame ``k`` ends at a standstill: add blocks ``max(last + 1, k - W + 1) .. k`` (``block(j)``: n, sums)."""
        if not self.auto:
            return
        for j in range(max(self.last + 1, k - W + 1), k + 1):
            n, *sums = block(j)
            self.n += n
            self.s = [a + b for a, b in zip(self.s, sums, strict=True)]
        self.last = k
        self.value = (self.s[0] / self.n, self.s[1] / self.n, self.s[2] / self.n)

    def new_blocks(self) -> None:
        """Block indices start again (a restart of the clock); the bias is kept."""
        self.last = -1

    def state_dict(self) -> dict[str, Any]:
        return {"auto": self.auto, "value": list(self.value), "n": self.n, "s": list(self.s), "last": self.last}

    def load_checked(self, r: Any) -> None:
        """Resume from a :meth:`state_dict` read through ``r`` (a :class:`~imu_ground.imu.warm_start.StateReader`),
        checked (the same kind, a bias of at most :data:`MAX_GYRO_BIAS`; else a ``StateError``)."""
        value = r.floats("value", (3,))
        if r.bool("auto") != self.auto or (not self.auto and value.tolist() != list(self.value)):
            raise r.error("auto", "differs from this estimator's bias_gyro")
        if np.abs(value).max() > MAX_GYRO_BIAS:
            raise r.error("value", f"holds {value.tolist()!r} rad/s, more than a gyro bias can be ({MAX_GYRO_BIAS:g})")
        self.value, self.n, self.s = tuple(value.tolist()), r.int("n"), r.floats("s", (3,)).tolist()
        self.last = r.int("last", minimum=-1)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Resume from :meth:`state_dict`, of either kind (checked as :meth:`load_checked`)."""
        from imu_ground.imu.warm_start import StateReader
        self.auto, self.value = bool(state["auto"]), tuple(state["value"])
        self.load_checked(StateReader("CausalGyroBias", state))
