"""The suspension filter's lateral load from speed x yaw rate, the road noise per heading change, and
gravity through a timestamp gap."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import EgoMotion
from imu_ground.units import DEG


@pytest.fixture(scope="module")
def drive(speed_drive):
    """A navigation-grade drive with turns and a misaligned mount, and its true speed per frame."""
    return speed_drive(90.0, 3, "nav")


def test_lateral_load_is_speed_times_yaw_rate_where_a_speed_is_measured(drive):
    em, ext, v = drive
    acc = SuspensionAwareFilter(extrinsic=ext, lateral="accelerometer").run(em, speed=v)
    auto = SuspensionAwareFilter(extrinsic=ext).run(em, speed=v)
    gt = GravityVelocityFilter(extrinsic=ext).run(em, speed=v)
    b = gt.body_increments                                  # heading change: twist about the ground's up axis
    psi = np.arctan2(b[:, 1, 0] - b[:, 0, 1], b[:, 0, 0] + b[:, 1, 1])
    expected = v * psi / em.delta_t - gt.acceleration[:, 1]
    np.testing.assert_allclose(auto.load[:, 1] - acc.load[:, 1], expected, atol=1e-9)
    np.testing.assert_array_equal(auto.load[:, 0], acc.load[:, 0])          # forward load unchanged
    # no speed: "auto" keeps the accelerometer (an IMU-only speed drifts)
    np.testing.assert_array_equal(SuspensionAwareFilter(extrinsic=ext).run(em).roll,
                                  SuspensionAwareFilter(extrinsic=ext, lateral="accelerometer").run(em).roll)
    # the kinematic lateral acceleration is the path's: close to the true one (ground frame, m/s^2)
    moving = v > 3
    assert np.median(np.abs(v * psi / em.delta_t - gt.acceleration[:, 1])[moving]) < 0.1


def test_streaming_equals_batch_with_speed_and_turn_noise(drive):
    em, ext, v = drive
    n = 400
    batch = SuspensionAwareFilter(extrinsic=ext).run(
        EgoMotion(em.t[:n], em.delta_R[:n], em.delta_v[:n], em.delta_t[:n], em.stationary[:n], em.valid[:n]),
        speed=v[:n])
    f = SuspensionAwareFilter(extrinsic=ext)
    rolls, loads = [], []
    for k in range(n):
        rolls.append(f.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k],
                            speed=v[k]).roll)
        loads.append(f.last_load)
    np.testing.assert_allclose(np.array(loads), batch.load, atol=1e-9)
    np.testing.assert_allclose(rolls, batch.roll, atol=1e-9)


def test_road_noise_grows_with_the_heading_change():
    sigma = 0.2 * DEG
    for q_turn in (0.0, 10.0):
        f = SuspensionAwareFilter(q_turn=q_turn, q_time=0.1, q_dist=0.0)
        f.step(np.eye(3), np.array([0.0, 0.0, 0.981]), 0.1, stationary=True)
        f.step(so3.rotz(0.05), np.array([0.0, 0.0, 0.981]), 0.1)
        assert f.Q_last[0, 0] == pytest.approx((0.1 * 0.1 + q_turn * 0.05) * sigma ** 2, rel=1e-12)
    with pytest.raises(ValueError):
        SuspensionAwareFilter(q_turn=-1.0)


def test_gravity_recovers_after_a_gap_with_a_wrong_rotation(drive):
    """A rotation integrated wrongly across a gap (3 deg of roll) shifts gravity in the gyro-integrated
    frame; the gap's gravity noise lets the constraint re-estimate it, without it the error stays."""
    em, ext, v = drive
    k = 300
    d = em.delta_R.copy()
    d[k] = d[k] @ so3.rotx(3.0 * DEG)
    valid = em.valid.copy()
    valid[k] = False
    bad = EgoMotion(em.t, d, em.delta_v, em.delta_t, em.stationary, valid)

    def roll_error_deg(track_bad, track_ok):
        g_bad = np.einsum("nji,nj->ni", track_bad.cumulative, track_bad.gravity)
        g_ok = np.einsum("nji,nj->ni", track_ok.cumulative, track_ok.gravity)
        later = slice(k + 300, None)                        # 30 s after the gap
        return np.degrees(np.abs(np.arctan2(g_bad[later, 1], g_bad[later, 2])
                                 - np.arctan2(g_ok[later, 1], g_ok[later, 2]))).mean()

    ok = GravityVelocityFilter(extrinsic=ext).run(em)
    assert roll_error_deg(GravityVelocityFilter(extrinsic=ext).run(bad), ok) < 0.3
    assert roll_error_deg(GravityVelocityFilter(extrinsic=ext, q_gap_g=0.0).run(bad), ok) > 0.8
    assert math.isclose(GravityVelocityFilter().q_gap_g, 0.1)
