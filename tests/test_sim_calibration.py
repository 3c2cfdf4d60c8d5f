"""The simulator's defaults calibrated to the real drives (band powers, method ranking): roughness spectrum, cross-slope
in street curves, traffic-like speed profiles, a weighted style mix; all reproducible by seed."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch

from imu_ground.evaluation.simulate import (ISO8608_CLASSES, ISO8608_N0, RoadParams, SpeedParams, VehicleParams,
                                            iso8608_psd, road_profile, simulate, simulate_suite)
from imu_ground.evaluation.simulate.road import LONG_WAVINESS


def test_default_road_has_two_slopes_within_its_band():
    dx = 0.05
    p_road = RoadParams()
    x, hl, _ = road_profile(60000.0, "C", dx=dx, rng=7, waviness=p_road.waviness)
    f, p = welch(hl, fs=1.0 / dx, nperseg=2**15)
    short = (f >= 0.2) & (f <= 2.0)
    long = (f >= 0.02) & (f <= 0.08)
    assert np.polyfit(np.log(f[short]), np.log(p[short]), 1)[0] == pytest.approx(-2.0, abs=0.1)
    assert np.polyfit(np.log(f[long]), np.log(p[long]), 1)[0] == pytest.approx(-LONG_WAVINESS, abs=0.3)
    np.testing.assert_allclose(np.median(p[short] / iso8608_psd(f[short], "C", p_road.waviness)), 1.0, atol=0.15)
    outside = f > 1.2 * p_road.band[1]
    assert p[outside].max() < 1e-3 * iso8608_psd(np.array([p_road.band[1]]), "C", p_road.waviness)[0]
    # the level at n0 is the class's, whatever the waviness
    assert iso8608_psd(np.array([ISO8608_N0]), "C", (2.0, 1.5))[0] == pytest.approx(ISO8608_CLASSES["C"])


def test_street_curves_keep_the_crown_fast_curves_are_banked():
    plan = [(100.0, 15.0, 30.0, 1.0 / 25.0)]                     # a left turn, radius 25 m
    slow = simulate(40.0, seed=1, imu="perfect", road=RoadParams(roughness=None, crown=0.025, curve_plan=plan),
                    speed=SpeedParams(plan=[(8.0, 1.0, 100.0)]))
    np.testing.assert_allclose(slow.truth["road_bank"], np.arctan(0.025), atol=1e-12)
    fast = simulate(40.0, seed=1, imu="perfect", road=RoadParams(roughness=None, crown=0.025, curve_plan=plan),
                    speed=SpeedParams(plan=[(20.0, 2.0, 100.0)]))
    in_curve = (fast.truth["s"] > 120.0) & (fast.truth["s"] < 140.0)
    assert (fast.truth["road_bank"][in_curve] < 0).all()        # inside (left) edge lower


def test_urban_speed_profile_is_traffic_like():
    sim = simulate(600.0, seed=2, imu="perfect", road=RoadParams(roughness=None),
                   speed=SpeedParams(style="urban", start_at_rest=False))
    tr = sim.truth
    moving = tr["speed"].to_numpy() > 3.0
    acc = np.abs(tr["acc_long"].to_numpy()[moving])
    assert 0.25 < acc.mean() < 0.8                              # real drives: 0.5 m/s^2 while moving
    assert np.percentile(acc, 95) < 2.3
    changes = np.flatnonzero(np.diff((acc > 0.05).astype(int)) == 1)
    assert len(changes) > 600.0 / 20.0                          # a speed change every few seconds
    assert 4.0 < tr["speed"].to_numpy()[moving].mean() < 14.0


def test_style_mix_weights_and_reproducible_by_seed():
    a = simulate_suite(6, seed=3, grades=("nav",), duration_range=(10.0, 20.0), styles={"urban": 1.0, "highway": 0.0})
    assert {r.params["speed"].style for r in a} == {"urban"}
    b = simulate_suite(6, seed=3, grades=("nav",), duration_range=(10.0, 20.0), styles={"urban": 1.0, "highway": 0.0})
    for ra, rb in zip(a, b, strict=True):
        np.testing.assert_array_equal(ra.imu.gyro, rb.imu.gyro)
    one = simulate(30.0, seed=9)
    np.testing.assert_array_equal(one.imu.accel, simulate(30.0, seed=9).imu.accel)
    assert not np.array_equal(one.imu.accel, simulate(30.0, seed=10).imu.accel)


@pytest.mark.parametrize("freq_ratio", [0.5, 1.0, 2.5])
def test_dampers_pass_on_the_road_velocity(freq_ratio):
    """A sinusoidal road under all four wheels at speed: the heave follows the base-excited quarter car
    ``(1 + j 2 zeta r) / (1 - r^2 + j 2 zeta r)``; without the damper input, ``1 / (1 - r^2 + j 2 zeta r)``."""
    from imu_ground.evaluation.simulate.vehicle import body_motion
    from imu_ground.evaluation.simulate.smooth import Piecewise
    f0, zeta, v, amp = 1.2, 0.4, 10.0, 0.01
    f = freq_ratio * f0
    dt = 1e-3
    t = np.arange(0.0, 40.0, dt)
    x = np.arange(-20.0, 450.0, 0.01)
    h = amp * np.sin(2 * np.pi * f / v * x)
    layout = tuple(Piecewise(0.0, 0.0, []) for _ in range(3))
    late = (t > 30.0) & (t < 39.9)
    for damper in (True, False):
        veh = VehicleParams(heave_freq=f0, heave_damping=zeta, pitch_gain_deg=0.0, roll_gain_deg=0.0,
                            damper_road_input=damper)
        _, _, (z, zd, zdd) = body_motion(veh, np.zeros_like(t), np.full_like(t, v), v * t, dt, layout, (x, h, h))
        r, k = freq_ratio, 2 * np.pi * f / v
        l_r, l_f = veh.rear_axle_to_ref, veh.wheelbase - veh.rear_axle_to_ref
        wheels = abs(l_r * np.exp(1j * k * l_f) + l_f * np.exp(-1j * k * l_r)) / veh.wheelbase   # the axles' average
        num = abs(1 + 2j * zeta * r) if damper else 1.0
        gain = wheels * num / abs(1 - r * r + 2j * zeta * r)
        assert np.abs(z[late]).max() == pytest.approx(gain * amp, rel=0.01)
        np.testing.assert_allclose(np.gradient(z, dt)[late], zd[late], atol=2e-3 * gain * amp * 2 * np.pi * f)
