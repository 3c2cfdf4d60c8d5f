"""The compiled batch preintegration without uncertainty (imu/_preint_batch_native.c) against its numpy twin.

``preint_batch.preintegrate(..., uncertainty=False)`` with the kernel and with the numpy blocks
(imu/preint_batch.py ``_blocks_kernel``) must give the same frames to the bit: the C is the numpy
formula term for term (the padded lanes and the Hillis-Steele bracketing included), compiled
without FMA contraction. Checked on synthetic logs over every branch (small and large rotations,
both holds, boundaries between samples, frames cut into several blocks, gaps, biases) and on every
shared KITTI drive through ``imu_to_egomotion``. Where a platform's libm ``sin`` differed from
numpy's in the last bit the twin rule would still hold (:func:`imu_ground._native.assert_twins_equal`).
Skipped when the extension is not built (or IMU_GROUND_PURE_PYTHON=1).
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from imu_ground import _native
from imu_ground.imu import imu_to_egomotion
from imu_ground.imu import preint_batch as pb

NATIVE = _native.PREINT_BATCH
pytestmark = pytest.mark.skipif(NATIVE is None, reason="C kernels not built or IMU_GROUND_PURE_PYTHON set")

FIELDS = ("t_start", "t_end", "delta_t", "delta_R", "delta_v", "delta_p", "valid", "n_intervals")


def _log(seed: int, n: int = 4000, rate: float = 100.0, scale: float = 1.0):
    """(t, gyro, accel): jittered stamps with two gaps, rates from zero (series branch) to several rad/s."""
    rng = np.random.default_rng(seed)
    dt = np.full(n - 1, 1.0 / rate) * rng.uniform(0.7, 1.3, n - 1)
    dt[[n // 4, n // 2]] = [0.35, 1.2]
    t = 50.0 + np.concatenate([[0.0], np.cumsum(dt)])
    gyro = rng.normal(0.0, 0.3, (n, 3)) * scale
    gyro[: n // 5] = 0.0                                # zero rotation: the series branch exactly
    gyro[n // 5: n // 4] *= 1e-6                        # tiny rotations
    gyro[-200:] *= 20.0                                 # fast spins
    accel = rng.normal(0.0, 1.0, (n, 3)) + np.array([0.2, -0.1, 9.81])
    return t, gyro, accel


def _both(monkeypatch, *args, **kw):
    c = pb.preintegrate(*args, uncertainty=False, **kw)
    with monkeypatch.context() as m:
        m.setattr(pb, "_NATIVE", None)
        p = pb.preintegrate(*args, uncertainty=False, **kw)
    return c, p


def _assert_same(c, p):
    for f in FIELDS:
        a, b = np.asarray(getattr(c, f)), np.asarray(getattr(p, f))
        assert a.shape == b.shape and a.dtype == b.dtype, f
        assert np.array_equal(a, b), f"{f}: largest difference {np.max(np.abs(a - b))}"
    assert c.covariance is None and p.covariance is None


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("hold", ["midpoint", "left"])
@pytest.mark.parametrize("frames", ["rate10", "rate3.7", "every7", "explicit"])
def test_frames_equal_the_twins_to_the_bit(monkeypatch, seed, hold, frames):
    t, gyro, accel = _log(seed)
    kw = dict(hold=hold, on_gap="flag", max_gap=0.1, bias_gyro=[0.01, -0.02, 0.005], bias_accel=[0.1, 0.0, -0.05])
    if frames.startswith("rate"):
        kw["rate"] = float(frames[4:])
    elif frames == "every7":
        kw["every"] = 7
    else:                                               # uneven frames, one of them long (several blocks)
        rng = np.random.default_rng(seed + 10)
        inner = np.sort(rng.uniform(t[0], t[-1], 60))
        inner = inner[(inner > t[0] + 5.0) | (inner < t[0] + 0.5)]
        kw["frame_times"] = np.concatenate([[t[0]], inner, [t[-1]]])
        kw["frame_times"] = kw["frame_times"][np.concatenate([[True], np.diff(kw["frame_times"]) > 0.05])]
    c, p = _both(monkeypatch, (t, gyro, accel), **kw)
    _assert_same(c, p)
    assert not c.valid.all() and c.valid.any()          # the gaps flagged, the rest kept


def test_one_long_frame_is_cut_into_blocks_and_merged(monkeypatch):
    t, gyro, accel = _log(5, n=3000)
    T = np.concatenate([t[[0, 10, 20]], [t[-1]]])       # two short frames, then one of ~2980 intervals
    c, p = _both(monkeypatch, (t, gyro, accel), T, max_gap=10.0)
    _assert_same(c, p)
    c_full = pb.preintegrate((t, gyro, accel), T, max_gap=10.0, uncertainty=True)   # the numpy path with covariance
    np.testing.assert_allclose(c.delta_R, c_full.delta_R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c.delta_v, c_full.delta_v, rtol=0, atol=1e-9)


def test_the_kernel_against_a_plain_sequential_product():
    """An independent reference: each block's delta_R, delta_v, delta_p by a plain loop (equal to rounding)."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(1)
    K, lanes = 40, 16
    dt = rng.uniform(0.005, 0.015, K)
    kv = np.vstack([rng.normal(0, 0.5, (3, K + 1)), rng.normal(0, 2.0, (3, K + 1))])
    start, stop = np.array([0, 16, 30], dtype=np.int64), np.array([16, 30, 40], dtype=np.int64)
    T, R, v, p = np.empty(3), np.empty((3, 3, 3)), np.empty((3, 3)), np.empty((3, 3))
    bias = np.array([0.01, 0.02, -0.01, 0.1, -0.1, 0.0])
    # the knots as 44 samples with knots 5, 17 and 33 inserted as boundaries (values in yb), from knot 2 on
    ins = np.array([5, 17, 33])
    samples = np.delete(np.hstack([np.zeros((6, 2)), kv, np.zeros((6, 1))]), ins + 2, axis=1)
    ki = ins + 2 - np.arange(3)
    NATIVE.blocks(dt, np.ascontiguousarray(samples[:3].T), np.ascontiguousarray(samples[3:].T), ki.astype(np.int64),
                  np.ascontiguousarray(kv[:, ins]), 2, start, stop, lanes, bias, True, T, R, v, p)
    for b in range(3):
        Rk, vk, pk = np.eye(3), np.zeros(3), np.zeros(3)
        for j in range(start[b], stop[b]):
            h = (kv[:, j] + kv[:, j + 1]) * 0.5 - bias
            a = Rk @ h[3:] * dt[j]
            pk = pk + vk * dt[j] + 0.5 * a * dt[j]
            vk = vk + a
            Rk = Rk @ Rotation.from_rotvec(h[:3] * dt[j]).as_matrix()
        assert T[b] == pytest.approx(dt[start[b]:stop[b]].sum(), abs=1e-15)
        np.testing.assert_allclose(R[b], Rk, rtol=0, atol=1e-14)
        np.testing.assert_allclose(v[b], vk, rtol=0, atol=1e-13)
        np.testing.assert_allclose(p[b], pk, rtol=0, atol=1e-14)


def test_bad_blocks_are_refused():
    dt, x, none = np.full(10, 0.01), np.zeros((11, 3)), np.zeros(0, dtype=np.int64)
    out = (np.empty(1), np.empty((1, 3, 3)), np.empty((1, 3)), np.empty((1, 3)))
    with pytest.raises(ValueError, match="block 0: intervals"):
        NATIVE.blocks(dt, x, x, none, np.zeros((6, 0)), 0, np.array([0]), np.array([12]), 16, np.zeros(6), True, *out)
    with pytest.raises(ValueError, match="block 0: intervals"):
        NATIVE.blocks(dt, x, x, none, np.zeros((6, 0)), 0, np.array([0]), np.array([9]), 4, np.zeros(6), True, *out)
    with pytest.raises(ValueError, match="knots \\[1, 11\\] outside the 11 samples"):
        NATIVE.blocks(dt, x, x, none, np.zeros((6, 0)), 1, np.array([0]), np.array([9]), 16, np.zeros(6), True, *out)
    with pytest.raises(ValueError, match="ki must be sorted sample indices"):
        NATIVE.blocks(dt, x, x, np.array([3, 2]), np.zeros((6, 2)), 0, np.array([0]), np.array([9]), 16,
                      np.zeros(6), True, *out)


def test_every_shared_drive_gives_the_twins_frames(monkeypatch, shared_data, kitti_index):
    from imu_ground.datasets import read_imu
    for name in kitti_index["drive"]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            imu = read_imu(shared_data / "kitti_imu100" / f"{name}.csv.gz")
        c = imu_to_egomotion(imu)
        with monkeypatch.context() as m:
            m.setattr(pb, "_NATIVE", None)
            p = imu_to_egomotion(imu)
        for f in ("t", "delta_R", "delta_v", "delta_t", "valid", "stationary"):
            assert np.array_equal(getattr(c, f), getattr(p, f)), (name, f)
