"""The compiled standstill window statistics (imu/_standstill_native.c) against their numpy twin (imu/standstill.py).

Every output is compared to the bit (the C is the numpy formula term for term, compiled without
FMA contraction): the cumulative sums, each window's end, rate and variance tests and specific-force
norm, and the masks, intervals and bias they give, on synthetic stops with gaps and timestamp
jitter and on every shared KITTI drive. Skipped when the extension is not built (or
IMU_GROUND_PURE_PYTHON=1).
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from imu_ground import _native
from imu_ground.imu import ImuData
from imu_ground.imu import standstill as st

NATIVE = _native.STANDSTILL
pytestmark = pytest.mark.skipif(NATIVE is None, reason="C kernels not built or IMU_GROUND_PURE_PYTHON set")


def _drive(seed: int, n: int = 6000) -> ImuData:
    """100 Hz with jittered stamps, gaps (0.2-2 s), stops on a slope, slow turns and moving stretches."""
    rng = np.random.default_rng(seed)
    dt = np.full(n - 1, 0.01) + rng.normal(0.0, 5e-4, n - 1)
    dt[rng.choice(n - 1, 6, replace=False)] = rng.uniform(0.2, 2.0, 6)
    t = 1000.0 + np.concatenate([[0.0], np.cumsum(dt)])
    gyro = rng.normal(0.0, 1e-3, (n, 3)) + np.array([0.002, -0.001, 0.003])
    accel = rng.normal(0.0, 5e-3, (n, 3)) + np.array([0.3, -0.2, 9.80])
    moving = np.zeros(n, dtype=bool)
    for a in rng.choice(n - 400, 8, replace=False):
        moving[a:a + rng.integers(50, 400)] = True
    gyro[moving] += rng.normal(0.0, 0.05, (moving.sum(), 3))
    accel[moving] += rng.normal(0.0, 0.5, (moving.sum(), 3))
    turn = slice(n // 3, n // 3 + 300)
    gyro[turn, 2] += 0.08                                   # a steady turn: quiet but rotating
    return ImuData(t, gyro, accel)


def _python(monkeypatch, fn, *args, **kw):
    """``fn`` run with the numpy twin (the compiled kernel switched off for the call)."""
    with monkeypatch.context() as m:
        m.setattr(st, "_NATIVE", None)
        return fn(*args, **kw)


@pytest.mark.parametrize("seed", range(4))
def test_window_sums_equal_the_twins_to_the_bit(monkeypatch, seed):
    imu = _drive(seed)
    c, p = st.WindowSums(imu), _python(monkeypatch, st.WindowSums, imu)
    assert c._c is None and p._c is not None              # the kernel's sums only when asked for
    assert np.array_equal(c.mean, p.mean) and np.array_equal(c.c1, p.c1) and np.array_equal(c.c2, p.c2)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("window", [0.0, 0.013, 0.5, 1.0, 2.0, 7.5, 1e4])
@pytest.mark.parametrize("gravity", [None, 9.81])
def test_masks_equal_the_twins(monkeypatch, seed, window, gravity):
    imu = _drive(seed)
    kw = dict(window=window, gyro_std_max=0.004, gyro_norm_max=0.05, accel_std_max=0.04, accel_norm_tol=0.15,
              gravity=gravity, max_gap=0.1)
    sums = st.WindowSums(imu)
    c = st._standstill_mask(imu, sums=sums, **kw)
    p = _python(monkeypatch, st._standstill_mask, imu, sums=sums, **kw)
    assert c.dtype == p.dtype == bool and np.array_equal(c, p)
    if window in (1.0, 2.0) and gravity is None:
        assert 0 < c.sum() < c.size                           # stops found and moving stretches left out


def test_the_kernels_match_numpy_one_window_at_a_time():
    """Each output of quiet_windows beside a direct numpy computation of the same window (no shared code)."""
    imu = _drive(7, 1500)
    t, n = imu.t, len(imu)
    sums = st.WindowSums(imu)
    quiet, norm, end = np.empty(n, dtype=bool), np.empty(n), np.empty(n, dtype=np.int64)
    NATIVE.quiet_windows(t, sums.gyro, sums.accel, np.ascontiguousarray(sums.mean[:, 0]), 1.0, 0.1, 0.004, 0.05,
                         0.04, quiet, norm, end)
    x = np.hstack([imu.gyro, imu.accel])
    for i in range(0, n, 7):
        last = int(np.searchsorted(t, t[i] + 1.0))
        assert end[i] == min(last + 1, n)
        usable = last < n and not np.any(np.diff(t[i:end[i]]) > 0.1)
        w = x[i:end[i]]
        rate_ok = usable and np.linalg.norm(w[:, :3].mean(0)) <= 0.05 and np.all(w[:, :3].std(0) <= 0.004)
        near_edge = usable and abs(np.linalg.norm(w[:, :3].mean(0)) - 0.05) < 1e-9
        if not near_edge:
            assert quiet[i] == (rate_ok and bool(np.all(w[:, 3:].std(0) <= 0.04)))
            assert np.isnan(norm[i]) == (not rate_ok)
        if rate_ok:
            assert norm[i] == pytest.approx(np.linalg.norm(w[:, 3:].mean(0)), rel=1e-12)
    good = quiet & (np.arange(n) % 3 == 0)
    mask = np.empty(n, dtype=bool)
    NATIVE.window_union(good, end, mask)
    direct = np.zeros(n, dtype=bool)
    for i in np.flatnonzero(good):
        direct[i:end[i]] = True
    assert np.array_equal(mask, direct)


def test_bad_buffers_are_refused():
    n = 10
    c, x = np.zeros((6, n + 1)), np.zeros((n, 3))
    with pytest.raises(TypeError, match="end must be a C-contiguous"):
        NATIVE.quiet_windows(np.arange(n, dtype=float), x, x, np.zeros(6), 1.0, 0.1, 1.0, 1.0, 1.0,
                             np.empty(n, dtype=bool), np.empty(n), [0] * n)
    with pytest.raises(ValueError, match="end must hold 10 int64"):
        NATIVE.quiet_windows(np.arange(n, dtype=float), x, x, np.zeros(6), 1.0, 0.1, 1.0, 1.0, 1.0,
                             np.empty(n, dtype=bool), np.empty(n), np.empty(n, dtype=np.int32))
    with pytest.raises(ValueError, match="c1 must have 66 items"):
        NATIVE.window_sums(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(6), np.zeros((6, n)), c)


def test_every_shared_drive_gives_the_twins_bias_and_stops(monkeypatch, shared_data, kitti_index):
    from imu_ground.datasets import read_imu
    for name in kitti_index["drive"]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            imu = read_imu(shared_data / "kitti_imu100" / f"{name}.csv.gz")
        max_gap = 10.0 * float(np.median(np.diff(imu.t)))
        for window in (1.0, 2.0):
            c = st.estimate_gyro_bias(imu, window=window, max_gap=max_gap)
            p = _python(monkeypatch, st.estimate_gyro_bias, imu, window=window, max_gap=max_gap)
            assert np.array_equal(c.bias, p.bias) and np.array_equal(c.intervals, p.intervals), name
            assert np.array_equal(c.accel_mean, p.accel_mean) and c.n_samples == p.n_samples, name
