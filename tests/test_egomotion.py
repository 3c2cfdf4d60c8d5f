"""Tests of imu_ground.imu.egomotion: the EgoFrame/EgoMotion contract and the IMU front-end."""
from __future__ import annotations

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.imu import EgoFrame, EgoMotion, ImuData, imu_to_egomotion, preintegrate
from imu_ground.units import DEFAULT_FRAME_RATE, GRAVITY


def drive(n=3000, seed=0, rest=300, dt=0.01):
    """A log at rest for ``rest`` samples, then turning and accelerating (FLU body frame)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    moving = (np.arange(n) >= rest)[:, None]
    gyro = np.array([1e-3, -2e-3, 5e-4]) + rng.normal(0, 1e-4, (n, 3))
    gyro = gyro + moving * 0.2 * np.sin(t[:, None] * [0.5, 0.9, 0.3] + [0.0, 1.0, 2.0])
    accel = np.array([0.0, 0.0, GRAVITY]) + rng.normal(0, 1e-3, (n, 3))
    accel = accel + moving * np.cos(t[:, None] * [0.7, 0.4, 1.1])
    return ImuData(t, gyro, accel, frame="FLU", source="test")


def test_egoframe_fields_and_defaults():
    f = EgoFrame(np.eye(3), np.zeros(3), 0.1)
    assert f.stationary is False and f.valid is True and np.isnan(f.t)
    assert EgoFrame._fields == ("delta_R", "delta_v", "delta_t", "stationary", "valid", "t")


def test_imu_to_egomotion_matches_preintegration_with_standstill_bias():
    imu = drive()
    ego = imu_to_egomotion(imu, rate=20.0)
    assert ego.rate == 20.0 and ego.has_accel and ego.frame == "FLU"
    # the bias comes from the standstill at the start: close to the true one
    np.testing.assert_allclose(ego.bias_gyro, [1e-3, -2e-3, 5e-4], atol=2e-5)
    fd = preintegrate(imu, rate=20.0, bias_gyro=ego.bias_gyro, on_gap="flag",
                      max_gap=ego.meta["max_gap"], uncertainty=False)
    np.testing.assert_array_equal(ego.delta_R, fd.delta_R)
    np.testing.assert_array_equal(ego.delta_v, fd.delta_v)
    np.testing.assert_array_equal(ego.t, fd.t_end)
    np.testing.assert_allclose(ego.delta_t, 0.05, rtol=1e-9)
    # stationary exactly in the frames that end inside the detected standstill
    lo, hi = ego.meta["standstill_intervals"][0]
    np.testing.assert_array_equal(ego.stationary, (ego.t >= lo) & (ego.t <= hi))
    assert ego.stationary[:10].all() and not ego.stationary[-10:].any()
    # R_k = R_{k-1} @ delta_R_k: the increments compose to the whole log's rotation
    whole = preintegrate(imu, frame_times=[fd.t_start[0], fd.t_end[-1]], bias_gyro=ego.bias_gyro)
    P = np.eye(3)
    for dR in ego.delta_R:
        P = P @ dR
    np.testing.assert_allclose(P, whole.delta_R[0], atol=1e-12)


def test_specific_force_at_rest_points_up():
    ego = imu_to_egomotion(drive(), bias_gyro=None)
    f = ego.specific_force[ego.stationary]
    np.testing.assert_allclose(f, np.broadcast_to([0.0, 0.0, GRAVITY], f.shape), atol=2e-3)
    assert np.all(ego.bias_gyro == 0)


def test_frames_and_frame_at_are_views_of_the_arrays():
    ego = imu_to_egomotion(drive(600), rate=10.0)
    frames = list(ego.frames())
    assert len(frames) == len(ego) > 0
    k = 3
    f = ego.frame_at(k)
    assert frames[k].t == f.t == ego.t[k] and f.delta_t == ego.delta_t[k]
    assert f.delta_R.base is not None and np.shares_memory(f.delta_R, ego.delta_R)
    assert isinstance(f.stationary, bool) and isinstance(f.valid, bool)


def test_gaps_flag_frames_invalid():
    imu = drive(1200)
    t = imu.t.copy()
    t[700:] += 0.5
    ego = imu_to_egomotion(ImuData(t, imu.gyro, imu.accel), rate=10.0)
    assert ego.meta["invalid_frames"] == int((~ego.valid).sum()) > 0
    bad = ego.t[~ego.valid]
    assert bad.min() > t[699] and bad.min() <= t[699] + 0.1 + 1e-9


def test_explicit_frame_times_set_the_rate():
    imu = drive(1000)
    T = imu.t[::25]
    ego = imu_to_egomotion(imu, frame_times=T)
    assert ego.rate == pytest.approx(4.0)
    np.testing.assert_allclose(ego.t, T[1:])


def test_bias_option_is_checked():
    with pytest.raises(ValueError, match="bias_gyro"):
        imu_to_egomotion(drive(400), bias_gyro="median")


def test_from_rotations():
    rng = np.random.default_rng(1)
    dR = so3.exp(rng.normal(0, 0.01, (5, 3)))
    ego = EgoMotion.from_rotations(dR)
    assert ego.rate == DEFAULT_FRAME_RATE and not ego.has_accel
    np.testing.assert_allclose(ego.t, np.arange(1, 6) / DEFAULT_FRAME_RATE)
    np.testing.assert_allclose(ego.delta_t, 1.0 / DEFAULT_FRAME_RATE)
    assert not ego.stationary.any() and ego.valid.all() and np.all(ego.delta_v == 0)
    t = np.array([0.0, 0.05, 0.1, 0.15, 0.2])
    ego = EgoMotion.from_rotations(dR, t=t)
    assert ego.rate == pytest.approx(20.0)
    np.testing.assert_allclose(ego.delta_t, 0.05)
    assert EgoMotion.from_rotations(np.zeros((0, 3, 3))).delta_R.shape == (0, 3, 3)
