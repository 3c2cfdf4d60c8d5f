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


def test_the_stops_are_found_and_the_drive_is_not():
    imu = _stop_and_go()
    stationary = imu_to_egomotion(imu).stationary             # computed in one block
    # the stops are known by construction: 0 .. 6 s and 15 .. 21 s; 10 Hz frames well inside them
    t = imu_to_egomotion(imu).t
    first, second, moving = (t > 0.5) & (t < 5.5), (t > 15.5) & (t < 20.5), (t > 7.0) & (t < 14.0)
    assert first.sum() >= 45 and second.sum() >= 45 and moving.sum() >= 65
    assert stationary[first].all() and stationary[second].all() and not stationary[moving].any()


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


def test_the_kernels_match_numpy_one_window_at_a_time():
    """Each output of the window pass beside a direct numpy computation of the same window (no shared code)."""
    imu = _drive(7, 1500)
    t, n = imu.t, len(imu)
    sums = st.WindowSums(imu)
    norm, end = np.empty(n), np.empty(n, dtype=np.int64)
    st._quiet_windows(t, sums.gyro, sums.accel, np.ascontiguousarray(sums.mean[:, 0]), 1.0, 0.1, 0.004, 0.05,
                      0.04, norm, end)
    quiet = ~np.isnan(norm)
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
        if quiet[i]:
            assert norm[i] == pytest.approx(np.linalg.norm(w[:, 3:].mean(0)), rel=1e-12)
    good = quiet & (np.arange(n) % 3 == 0)
    mask = np.empty(n, dtype=bool)
    st._window_union(good, end, mask)
    direct = np.zeros(n, dtype=bool)
    for i in np.flatnonzero(good):
        direct[i:end[i]] = True
    assert np.array_equal(mask, direct)


def test_a_negative_window_is_refused():
    with pytest.raises(ValueError, match="standstill window must be >= 0 s"):
        detect_standstill(_stop_and_go(100, 100), window=-1.0)
