"""Standstill windows from shared cumulative sums (imu/standstill.py WindowSums): same answers as without."""
import numpy as np
import pytest

from imu_ground.imu import ImuData, imu_to_egomotion
from imu_ground.imu import standstill as st
from imu_ground.imu.standstill import WindowSums, detect_standstill, estimate_gyro_bias


def _stop_and_go(n_stop: int = 600, n_move: int = 900, seed: int = 3) -> ImuData:
    """100 Hz: a stop, a drive, a stop (gyro rad/s, specific force m/s^2, FLU)."""
    rng = np.random.default_rng(seed)
    n = 2 * n_stop + n_move
    t = np.arange(n) / 100.0
    gyro = rng.normal(0.0, 1e-3, (n, 3)) + np.array([0.002, -0.001, 0.003])
    accel = rng.normal(0.0, 5e-3, (n, 3)) + np.array([0.0, 0.0, 9.81])
    move = slice(n_stop, n_stop + n_move)
    gyro[move] += rng.normal(0.0, 0.05, (n_move, 3))
    accel[move] += rng.normal(0.0, 0.5, (n_move, 3))
    return ImuData(t, gyro, accel)


def test_shared_sums_give_the_same_intervals_and_bias():
    imu = _stop_and_go()
    sums = WindowSums(imu)
    for window in (0.5, 1.0, 2.0):
        a = detect_standstill(imu, window=window)
        b = detect_standstill(imu, window=window, sums=sums)
        assert a.shape[0] == 2 and np.array_equal(a, b)
    e1, e2 = estimate_gyro_bias(imu), estimate_gyro_bias(imu, sums=sums)
    assert e1.found and np.array_equal(e1.bias, e2.bias) and np.array_equal(e1.intervals, e2.intervals)


def test_blocks_smaller_than_the_log_change_nothing(monkeypatch):
    imu = _stop_and_go()
    whole = detect_standstill(imu)
    stationary = imu_to_egomotion(imu).stationary             # computed in one block
    # the stops are known by construction: 0 .. 6 s and 15 .. 21 s; 10 Hz frames well inside them
    t = imu_to_egomotion(imu).t
    first, second, moving = (t > 0.5) & (t < 5.5), (t > 15.5) & (t < 20.5), (t > 7.0) & (t < 14.0)
    assert first.sum() >= 45 and second.sum() >= 45 and moving.sum() >= 65
    assert stationary[first].all() and stationary[second].all() and not stationary[moving].any()
    monkeypatch.setattr(st, "_BLOCK", 97)
    assert np.array_equal(detect_standstill(imu), whole)
    assert np.array_equal(imu_to_egomotion(imu).stationary, stationary)


def test_window_sums_give_each_windows_mean_and_std():
    imu = _stop_and_go(50, 40)
    end = np.minimum(np.arange(len(imu)) + 25, len(imu))
    mean, std = WindowSums(imu).stats(np.arange(len(imu)), end)
    x = np.hstack([imu.gyro, imu.accel])
    for i in (0, 17, 60, len(imu) - 1):
        np.testing.assert_allclose(mean[:, i], x[i:end[i]].mean(axis=0), rtol=0, atol=1e-12)
        np.testing.assert_allclose(std[:, i], x[i:end[i]].std(axis=0), rtol=0, atol=1e-6)   # cumulative-sum rounding


def test_sums_of_another_log_are_refused():
    imu = _stop_and_go()
    other = WindowSums(_stop_and_go(100, 100))
    with pytest.raises(ValueError, match="sums were computed for a log of 300 samples"):
        detect_standstill(imu, sums=other)
