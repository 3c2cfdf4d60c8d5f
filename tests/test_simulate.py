"""Tests of the drive simulator: exact truth, suspension, roughness, IMU errors, fixtures."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy.signal import coherence, lsim, welch

from imu_ground import so3
from imu_ground.imu.data import ImuData
from imu_ground.evaluation.simulate import (
    GRAVITY, IMU_PRESETS, ISO8608_CLASSES, TRUTH_COLUMNS, ImuErrorModel, RoadParams, SimResult,
    SpeedParams, VehicleParams, imu_error_model, iso8608_psd, road_profile, simulate,
    simulate_suite, suspension_response,
)

DEG = math.pi / 180.0
G_W = np.array([0.0, 0.0, -GRAVITY])
R_MOUNT = so3.rotz(0.4) @ so3.roty(-0.15) @ so3.rotx(0.25)   # a clearly non-trivial extrinsic
T_MOUNT = np.array([1.1, -0.4, 1.3])

FLAT = dict(roughness=None, grade_std=0.0, crown=0.0, superelevation_max=0.0, curves=False, heading0=0.0)


def _integrate_midpoint(t, gyro, r0):
    """R_{k+1} = R_k exp((w_k + w_{k+1}) / 2 dt): all increments at once, then the products."""
    inc = so3.exp(0.5 * (gyro[1:] + gyro[:-1]) * np.diff(t)[:, None])
    out = np.empty((len(t), 3, 3))
    out[0] = r = r0
    for k, step in enumerate(inc):          # a loop over samples, in the test only
        r = r @ step
        out[k + 1] = r
    return out


@pytest.fixture(scope="module")
def rough_drive():
    """60 s, class C roughness, highway speeds, curves and grades, noise-free, tilted mount."""
    return simulate(60.0, seed=3, imu="perfect", road=RoadParams(roughness="C"),
                    speed=SpeedParams(style="highway"), R_gs=R_MOUNT, t_gs=T_MOUNT)


@pytest.fixture(scope="module")
def urban_drive():
    return simulate(90.0, seed=11, imu="mems", road=RoadParams(roughness="B"),
                    speed=SpeedParams(style="urban", stop_probability=0.3), R_gs=R_MOUNT, t_gs=T_MOUNT)


# --------------------------------------------------------------------------- API and determinism
def test_result_shape_and_columns(urban_drive):
    r = urban_drive
    assert isinstance(r, SimResult) and isinstance(r.imu, ImuData)
    assert len(r.imu) == 9001 and r.imu.rate == pytest.approx(100.0)
    assert list(r.truth.columns) == list(TRUTH_COLUMNS)
    assert len(r.truth) == 901
    np.testing.assert_allclose(r.truth["t"].to_numpy(), 0.1 * np.arange(901), atol=1e-12)
    assert r.imu.frame == "sensor" and r.imu.source == "simulated"
    assert r.imu.meta["seed"] == 11 and r.imu.meta["imu_model"] == "mems"
    np.testing.assert_allclose(r.R_gs, R_MOUNT)
    np.testing.assert_allclose(r.t_gs, T_MOUNT)
    assert r.bias_gyro.shape == r.bias_accel.shape == (9001, 3)
    assert r.R_ws.shape == (9001, 3, 3) and r.p_ws.shape == r.v_ws.shape == (9001, 3)
    assert np.isfinite(r.truth.drop(columns="stationary").to_numpy(float)).all()


def test_deterministic_for_a_seed():
    kw = dict(road=RoadParams(roughness="C"), speed=SpeedParams(style="urban"))
    a = simulate(40.0, seed=7, imu="mems", **kw)
    b = simulate(40.0, seed=7, imu="mems", **kw)
    np.testing.assert_array_equal(a.imu.gyro, b.imu.gyro)
    np.testing.assert_array_equal(a.imu.accel, b.imu.accel)
    pd.testing.assert_frame_equal(a.truth, b.truth)
    c = simulate(40.0, seed=8, imu="mems", **kw)
    assert not np.allclose(a.imu.accel, c.imu.accel)
    # another IMU grade, same seed: the same trajectory, other errors
    d = simulate(40.0, seed=7, imu="nav", **kw)
    pd.testing.assert_frame_equal(a.truth, d.truth)
    np.testing.assert_array_equal(a.imu_clean.gyro, d.imu_clean.gyro)
    assert not np.allclose(a.imu.gyro, d.imu.gyro)
    # params rerun the drive
    e = simulate(**a.params)
    np.testing.assert_array_equal(a.imu.accel, e.imu.accel)


def test_bad_arguments():
    with pytest.raises(ValueError, match="preset"):
        simulate(10.0, imu="tactical")
    with pytest.raises(ValueError, match="whole multiple"):
        simulate(10.0, imu_rate=100.0, frame_rate=30.0)
    with pytest.raises(ValueError, match="rotation"):
        simulate(10.0, R_gs=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="ISO 8608"):
        simulate(10.0, road=RoadParams(roughness="Z"))
    with pytest.raises(ValueError, match="style"):
        simulate(10.0, speed=SpeedParams(style="rally"))


# --------------------------------------------------------------------------- ground truth consistency
def test_normal_is_the_road_normal_in_the_sensor_frame(rough_drive):
    tr = rough_drive.truth
    n_s = tr[["normal_x", "normal_y", "normal_z"]].to_numpy()
    n_b = tr[["normal_body_x", "normal_body_y", "normal_body_z"]].to_numpy()
    np.testing.assert_allclose(np.linalg.norm(n_s, axis=1), 1.0, atol=1e-14)
    pitch, roll = tr["pitch"].to_numpy(), tr["roll"].to_numpy()
    e = so3.roty(pitch) @ so3.rotx(roll)                               # road <- body
    expected = np.einsum("ij,nkj,k->ni", R_MOUNT.T, e, [0.0, 0.0, 1.0])  # R_gs^T E^T e_z
    np.testing.assert_allclose(n_s, expected, atol=1e-14)
    np.testing.assert_allclose(n_b @ R_MOUNT, n_s, atol=1e-14)
    # pitch and roll back from the normal
    np.testing.assert_allclose(-np.arcsin(n_b[:, 0]), pitch, atol=1e-12)
    np.testing.assert_allclose(np.arctan2(n_b[:, 1], n_b[:, 2]), roll, atol=1e-12)
    # the same normal from the world attitude and the road frame (heading, grade, bank)
    q = tr[["qw", "qx", "qy", "qz"]].to_numpy()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    from scipy.spatial.transform import Rotation
    r_ws = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    r_wr = (so3.rotz(tr["heading"].to_numpy()) @ so3.roty(-tr["road_grade"].to_numpy())
            @ so3.rotx(tr["road_bank"].to_numpy()))
    np.testing.assert_allclose(np.einsum("nji,nj->ni", r_ws, r_wr[:, :, 2]), n_s, atol=1e-12)
    # body relative to the truth road plane: its up-axis row is the normal; the
    # small yaw it may carry (the road plane includes 10 m-smoothed roughness,
    # tilted about axes that are not the body's) is second order: the road's
    # inclination (grade, bank ~0.1 rad) times the body's tilt relative to the
    # plane (~0.01 rad), i.e. a few thousandths of a degree up to ~0.02 deg
    e_true = np.swapaxes(r_wr, 1, 2) @ r_ws @ R_MOUNT.T
    np.testing.assert_allclose(e_true[:, 2, :], n_b, atol=1e-12)
    assert np.degrees(np.abs(np.arctan2(e_true[:, 1, 0], e_true[:, 0, 0]))).max() < 0.05
    np.testing.assert_allclose(r_ws, rough_drive.R_ws[::10], atol=1e-12)
    # and the normal varies by the expected ~0.1-1 deg
    assert 0.05 < np.degrees(np.std(pitch)) < 2.0 and 0.05 < np.degrees(np.std(roll)) < 2.0


def test_noise_free_gyro_integrates_to_the_truth(rough_drive):
    r = rough_drive
    assert np.all(r.imu.gyro == r.imu_clean.gyro)          # "perfect" preset: no error at all
    est = _integrate_midpoint(r.imu.t, r.imu.gyro, r.R_ws[0])
    err = np.degrees(so3.angle(np.swapaxes(r.R_ws, 1, 2) @ est))
    assert err.max() < 0.01, err.max()
    # the trajectory really rotates (curves) and shakes: the test is not vacuous
    assert abs(r.truth["heading"].iloc[-1] - r.truth["heading"].iloc[0]) > 0.1
    assert np.degrees(np.abs(r.imu.gyro[:, :2]).max()) > 1.0


def test_specific_force_is_the_second_derivative_of_position():
    # smooth road (roughness off): finite differences at 100 Hz are accurate
    r = simulate(60.0, seed=5, imu="perfect", road=RoadParams(roughness=None),
                 speed=SpeedParams(style="urban"), R_gs=R_MOUNT, t_gs=T_MOUNT)
    h = 0.01
    a_w = np.einsum("nij,nj->ni", r.R_ws, r.imu.accel) + G_W
    d2p = (r.p_ws[2:] - 2.0 * r.p_ws[1:-1] + r.p_ws[:-2]) / h**2
    assert np.abs(d2p - a_w[1:-1]).max() < 5e-4
    dp = (r.p_ws[2:] - r.p_ws[:-2]) / (2.0 * h)
    assert np.abs(dp - r.v_ws[1:-1]).max() < 2e-4
    assert np.abs(a_w).max() > 1.0


def test_specific_force_consistent_on_a_rough_road():
    # class C at 1 kHz: the velocity increments are the integral of the acceleration. Springs only: the
    # dampers pass on the road's velocity, which jumps at the nodes of the piecewise-linear profile,
    # and no trapezoid rule integrates an acceleration that jumps inside a step.
    r = simulate(20.0, seed=3, imu="perfect", imu_rate=1000.0, road=RoadParams(roughness="C"),
                 vehicle=VehicleParams(damper_road_input=False),
                 speed=SpeedParams(style="highway", start_at_rest=False), R_gs=R_MOUNT, t_gs=T_MOUNT)
    h = 1e-3
    a_w = np.einsum("nij,nj->ni", r.R_ws, r.imu.accel) + G_W
    dv = np.diff(r.v_ws, axis=0)
    trap = 0.5 * (a_w[1:] + a_w[:-1]) * h
    assert np.abs(dv - trap).max() < 1e-4 * h
    dp = np.diff(r.p_ws, axis=0)
    assert np.abs(dp - 0.5 * (r.v_ws[1:] + r.v_ws[:-1]) * h).max() < 1e-5 * h
    assert np.abs(a_w[:, 2]).std() > 0.2          # the road shakes the car vertically


def test_heading_follows_curvature(rough_drive):
    tr = rough_drive.truth
    s, psi, kappa = tr["s"].to_numpy(), tr["heading"].to_numpy(), tr["curvature"].to_numpy()
    dpsi = np.diff(psi)
    ds = np.diff(s)
    mid = 0.5 * (kappa[1:] + kappa[:-1])
    assert np.abs(dpsi - mid * ds).max() < 1e-4
    # lateral acceleration in the road frame: v^2 kappa, up to the bank and the grade changes
    np.testing.assert_allclose(tr["acc_lat"], tr["speed"] ** 2 * kappa, rtol=0.005, atol=0.03)
    assert np.abs(tr["acc_lat"]).max() > 1.0


def test_velocity_along_the_road_and_stationary_flag(urban_drive):
    tr = urban_drive.truth
    v = tr[["vx", "vy", "vz"]].to_numpy()
    x_r = np.stack([np.cos(tr.road_grade) * np.cos(tr.heading), np.cos(tr.road_grade) * np.sin(tr.heading),
                    np.sin(tr.road_grade)], axis=1)
    along = np.einsum("ni,ni->n", v, x_r)
    # the sensor's velocity is the road velocity plus small suspension/lever-arm terms
    assert np.abs(along - tr["speed"]).max() < 0.15
    assert (tr["speed"] >= 0).all()
    assert tr["stationary"].dtype == bool
    np.testing.assert_array_equal(tr["stationary"], tr["speed"] == 0.0)


# --------------------------------------------------------------------------- suspension
@pytest.mark.parametrize("freq,damping", [(1.0, 0.3), (1.3, 0.4), (1.5, 0.5)])
def test_suspension_natural_frequency_from_impulse_response(freq, damping):
    dt = 1e-3
    u = np.zeros(20000)
    u[100] = 1.0
    x, xd, xdd = suspension_response(u, dt, freq, damping)
    y = x[101:]
    sign = np.signbit(y)
    crossings = np.flatnonzero(sign[1:] != sign[:-1])
    assert len(crossings) >= 4
    period = 2.0 * np.mean(np.diff(crossings[:6])) * dt
    f_d = freq * math.sqrt(1.0 - damping**2)
    assert 1.0 / period == pytest.approx(f_d, rel=0.01)
    # damping from the decay of successive peaks of the same sign
    peaks = np.array([np.abs(y[a:b]).max() for a, b in zip(crossings[:-1], crossings[1:], strict=True)])
    delta = np.log(peaks[0] / peaks[2])                  # one full period apart
    zeta = delta / math.sqrt(4 * math.pi**2 + delta**2)
    assert zeta == pytest.approx(damping, rel=0.03)
    # the rate and acceleration outputs are the derivatives of x
    np.testing.assert_allclose(np.gradient(x, dt)[200:-1], xd[200:-1], atol=2e-4 * np.abs(xd).max())
    np.testing.assert_allclose(np.gradient(xd, dt)[200:-1], xdd[200:-1], atol=2e-3 * np.abs(xdd).max())


def test_suspension_is_exact_for_piecewise_linear_input():
    dt = 0.01
    t = dt * np.arange(3000)
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.standard_normal(t.size)) * 1e-3
    x, xd, _ = suspension_response(u, dt, 1.3, 0.4, gain=0.7)
    w = 2 * math.pi * 1.3
    sys = ([[0.0, 1.0], [-w * w, -2 * 0.4 * w]], [[0.0], [w * w * 0.7]], np.eye(2), [[0.0], [0.0]])
    _, _, states = lsim(sys, u, t, X0=[0.7 * u[0], 0.0], interp=True)
    np.testing.assert_allclose(x, states[:, 0], atol=1e-9)
    np.testing.assert_allclose(xd, states[:, 1], atol=1e-8)
    # static gain
    xs, _, _ = suspension_response(np.ones(5000), 1e-3, 1.2, 0.35, gain=2.5)
    np.testing.assert_allclose(xs, 2.5, atol=1e-12)


def _flat_plan_drive(plan, v_start, vehicle=None, road=None, duration=None):
    duration = duration or sum(h for *_, h in plan) + 30.0
    return simulate(duration, seed=1, imu="perfect", road=road or RoadParams(**FLAT),
                    vehicle=vehicle or VehicleParams(), speed=SpeedParams(plan=plan, v_start=v_start))


def test_free_pitch_oscillation_after_a_stop_in_the_full_drive():
    veh = VehicleParams(pitch_freq=1.25, pitch_damping=0.3)
    r = simulate(30.0, seed=1, imu="perfect", frame_rate=100.0, road=RoadParams(**FLAT), vehicle=veh,
                 speed=SpeedParams(plan=[(10.0, 1.0, 2.0), (0.0, 3.0, 20.0)], v_start=10.0,
                                   ramp_time=(0.3, 0.3)))
    tr = r.truth
    still = tr["stationary"].to_numpy() & (tr["acc_long"] == 0.0).to_numpy()
    t, pitch = tr["t"].to_numpy()[still], tr["pitch"].to_numpy()[still]
    assert np.degrees(np.abs(pitch).max()) > 0.1            # the stop rocks the body
    sign = np.signbit(pitch)
    cross = np.flatnonzero(sign[1:] != sign[:-1])[:6]
    times = t[cross] - pitch[cross] * (t[cross + 1] - t[cross]) / (pitch[cross + 1] - pitch[cross])
    f_d = 0.5 / np.mean(np.diff(times))
    assert f_d == pytest.approx(1.25 * math.sqrt(1 - 0.3**2), rel=0.005)


def test_constant_braking_keeps_the_nose_down():
    veh = VehicleParams(pitch_gain_deg=0.3)
    # 30 m/s, then brake at 1.5 m/s^2 down to 2 m/s (18.7 s of constant deceleration)
    r = _flat_plan_drive([(30.0, 1.0, 5.0), (2.0, 1.5, 20.0)], v_start=30.0, vehicle=veh)
    tr = r.truth
    steady = (tr["acc_long"] == -1.5).to_numpy()
    t_steady = tr["t"][steady]
    late = steady & (tr["t"] > t_steady.min() + 5.0).to_numpy()
    assert late.sum() > 100
    np.testing.assert_allclose(tr["pitch"][late], 0.3 * DEG * 1.5, rtol=1e-6)
    np.testing.assert_allclose(tr["roll"][late], 0.0, atol=1e-12)
    # nose up when accelerating, level when cruising
    r2 = _flat_plan_drive([(5.0, 1.0, 5.0), (25.0, 1.2, 15.0)], v_start=5.0, vehicle=veh)
    tr2 = r2.truth
    acc = (tr2["acc_long"] == 1.2).to_numpy()
    late2 = acc & (tr2["t"] > tr2["t"][acc].min() + 5.0).to_numpy()
    np.testing.assert_allclose(tr2["pitch"][late2], -0.3 * DEG * 1.2, rtol=1e-6)
    cruise = (tr2["t"] > tr2["t"].iloc[-1] - 5.0).to_numpy()
    np.testing.assert_allclose(tr2["pitch"][cruise], 0.0, atol=1e-9)


def test_steady_turn_rolls_out_and_grade_loads_the_suspension():
    veh = VehicleParams(roll_gain_deg=0.45, pitch_gain_deg=0.25)
    kappa = 1.0 / 100.0
    road = RoadParams(**{**FLAT, "curve_plan": [(50.0, 30.0, 400.0, kappa)]})
    r = simulate(40.0, seed=2, imu="perfect", road=road, vehicle=veh,
                 speed=SpeedParams(plan=[(15.0, 1.0, 60.0)], v_start=15.0))
    tr = r.truth
    arc = (tr["curvature"] == kappa).to_numpy()
    late = arc & (tr["t"] > tr["t"][arc].min() + 5.0).to_numpy()
    assert late.sum() > 50
    a_lat = 15.0**2 * kappa
    np.testing.assert_allclose(tr["acc_lat"][late], a_lat, rtol=1e-9)
    np.testing.assert_allclose(tr["roll"][late], 0.45 * DEG * a_lat, rtol=1e-6)   # left turn: left side up
    # a constant 5 % uphill grade at rest: weight shifts back, nose up by K g sin(grade)
    road = RoadParams(**FLAT, grade0=0.05)
    r = simulate(20.0, seed=2, imu="perfect", road=road, vehicle=veh,
                 speed=SpeedParams(plan=[(0.0, 1.0, 20.0)], v_start=0.0))
    g_sin = GRAVITY * math.sin(math.atan(0.05))
    np.testing.assert_allclose(r.truth["pitch"], -0.25 * DEG * g_sin, rtol=1e-9)
    np.testing.assert_allclose(r.truth["road_grade"], math.atan(0.05), rtol=1e-12)
    no_load = simulate(20.0, seed=2, imu="perfect", road=road,
                       vehicle=VehicleParams(gravity_load_transfer=False),
                       speed=SpeedParams(plan=[(0.0, 1.0, 20.0)], v_start=0.0))
    np.testing.assert_allclose(no_load.truth["pitch"], 0.0, atol=1e-15)


# --------------------------------------------------------------------------- road roughness
@pytest.mark.parametrize("cls", ["A", "B", "C"])
def test_roughness_psd_follows_iso8608(cls):
    dx = 0.05
    x, hl, hr = road_profile(40000.0, cls, dx=dx, rng=123)
    assert np.allclose(np.diff(x), dx)
    f, p = welch(hl, fs=1.0 / dx, nperseg=2**14)
    band = (f >= 0.05) & (f <= 1.5)
    slope, intercept = np.polyfit(np.log(f[band]), np.log(p[band]), 1)
    assert slope == pytest.approx(-2.0, abs=0.1)
    level = math.exp(intercept + slope * math.log(0.1))
    assert level == pytest.approx(ISO8608_CLASSES[cls], rel=0.2)
    np.testing.assert_allclose(np.median(p[band] / iso8608_psd(f[band], cls)), 1.0, atol=0.15)
    # the right track has the same PSD, and is coherent with the left at long wavelengths only
    _, pr = welch(hr, fs=1.0 / dx, nperseg=2**14)
    np.testing.assert_allclose(np.median(pr[band] / p[band]), 1.0, atol=0.15)
    fc, c = coherence(hl, hr, fs=1.0 / dx, nperseg=2**14)
    low = (fc > 0.02) & (fc < 0.05)
    high = (fc > 0.8) & (fc < 2.0)
    assert c[low].mean() > 0.6 and c[high].mean() < 0.05


def test_smooth_road_and_roughness_level_order():
    x, hl, hr = road_profile(100.0, None)
    assert not hl.any() and not hr.any()
    stds = [road_profile(20000.0, c, rng=1)[1].std() for c in "ABC"]
    np.testing.assert_allclose(np.array(stds[1:]) / stds[:-1], 2.0, rtol=1e-9)   # sqrt(4)


# --------------------------------------------------------------------------- IMU errors
@pytest.mark.parametrize("grade", ["nav", "mems"])
def test_noise_statistics_match_the_preset(grade):
    model = IMU_PRESETS[grade]
    r = simulate(180.0, seed=4, imu=grade, imu_rate=200.0, frame_rate=10.0)
    for meas, clean, bias, dens, rw in (
            (r.imu.gyro, r.imu_clean.gyro, r.bias_gyro, model.gyro_noise_density, model.gyro_bias_rw),
            (r.imu.accel, r.imu_clean.accel, r.bias_accel, model.accel_noise_density, model.accel_bias_rw)):
        white = meas - clean - bias
        np.testing.assert_allclose(white.std(axis=0), dens * math.sqrt(200.0), rtol=0.03)
        assert np.abs(white.mean(axis=0)).max() < 5 * dens * math.sqrt(200.0) / math.sqrt(len(white))
        steps = np.diff(bias, axis=0)
        np.testing.assert_allclose(steps.std(axis=0), rw * math.sqrt(1 / 200.0), rtol=0.03)
    assert model.gyro_noise_std(100.0) == pytest.approx(model.gyro_noise_density * 10.0)


def test_turn_on_biases_and_custom_model():
    res = simulate_suite(0, seed=1)
    assert res == []
    b0 = np.array([simulate(5.0, seed=s, imu="mems").bias_gyro[0] for s in range(30)])
    assert b0.std() == pytest.approx(IMU_PRESETS["mems"].gyro_bias_turn_on, rel=0.3)
    custom = ImuErrorModel("mine", 1e-3, 0.0, 0.0, 2e-2, 0.0, 0.0)
    r = simulate(30.0, seed=2, imu=custom)
    assert r.imu_model is custom and imu_error_model(custom) is custom
    assert np.all(r.bias_gyro == 0.0) and np.all(r.bias_accel == 0.0)
    np.testing.assert_allclose((r.imu.accel - r.imu_clean.accel).std(), 0.2, rtol=0.05)
    assert imu_error_model(None).gyro_noise_density == 0.0
    assert IMU_PRESETS["mems"].gyro_noise_density > IMU_PRESETS["nav"].gyro_noise_density
    assert custom.scaled(2.0).accel_noise_density == 4e-2


def test_stops_measure_only_gravity_and_noise(urban_drive):
    r = urban_drive
    tr = r.truth
    st = tr["stationary"].to_numpy()
    assert st.any() and (~st).any()
    edges = np.flatnonzero(np.diff(np.r_[0, st.astype(int), 0]))
    stops = list(zip(edges[::2], edges[1::2], strict=False))
    assert len(stops) >= 2                               # initial rest + at least one stop
    t = r.imu.t
    for a, b in stops:
        t0, t1 = tr["t"].iloc[a], tr["t"].iloc[b - 1]
        assert (tr["speed"].iloc[a:b] == 0.0).all()
        assert tr["s"].iloc[a:b].nunique() == 1           # no creeping
        settled = (t >= t0 + 5.0) & (t <= t1)
        if not settled.any():
            continue
        w = r.imu_clean.gyro[settled]
        f = r.imu_clean.accel[settled]
        gravity_s = np.einsum("nji,j->ni", r.R_ws[settled], -G_W)
        assert np.abs(w).max() < 1e-5
        assert np.abs(f - gravity_s).max() < 1e-4
        np.testing.assert_allclose(np.linalg.norm(f, axis=1), GRAVITY, atol=1e-4)
        # the measured samples are that plus the error model
        err = r.imu.accel[settled] - gravity_s - r.bias_accel[settled]
        assert err.std() < 2 * IMU_PRESETS["mems"].accel_noise_std(100.0)


# --------------------------------------------------------------------------- suite
def test_suite_varied_and_reproducible():
    suite = simulate_suite(3, seed=5, grades=("nav", "mems"))
    assert len(suite) == 6
    assert [s.name for s in suite[:2]] == ["drive000_nav", "drive000_mems"]
    durations = [s.imu.duration for s in suite[::2]]
    assert all(60.0 <= d <= 180.0 for d in durations) and len(set(durations)) == 3
    # the grades of one drive share the trajectory
    pd.testing.assert_frame_equal(suite[0].truth, suite[1].truth)
    assert suite[0].imu_model.name == "nav" and suite[1].imu_model.name == "mems"
    assert not np.allclose(suite[0].imu.gyro, suite[1].imu.gyro)
    # the drives differ: their seeds, their roads (each field drawn at random) and their motion
    first, second = suite[0], suite[2]
    assert first.seed != second.seed
    assert first.params["road"].grade_std != second.params["road"].grade_std
    assert first.params["road"].crown != second.params["road"].crown
    assert first.params["vehicle"].pitch_freq != second.params["vehicle"].pitch_freq
    n = min(len(first.truth), len(second.truth))
    assert not np.allclose(first.truth["pitch"].iloc[:n], second.truth["pitch"].iloc[:n])
    # any one result reruns from its params
    again = simulate(**suite[3].params)
    np.testing.assert_array_equal(again.imu.accel, suite[3].imu.accel)
    pd.testing.assert_frame_equal(again.truth, suite[3].truth)
    # the same seed gives the same suite, another seed another one
    other = simulate_suite(1, seed=5, grades=("nav",))
    np.testing.assert_array_equal(other[0].imu.gyro, suite[0].imu.gyro)
    assert simulate_suite(1, seed=6, grades=("nav",))[0].seed != suite[0].seed


# --------------------------------------------------------------------------- shipped example
def test_example_fixture_regenerates(tmp_path):
    from imu_ground.evaluation.simulate.fixtures import EXAMPLE_SEED, FIXTURES, write_example
    paths = write_example(tmp_path)
    for kind in ("imu", "truth"):
        shipped = FIXTURES / paths[kind].name
        assert shipped.is_file(), f"missing fixture {shipped}: run python -m imu_ground.evaluation.simulate.fixtures"
        new, old = pd.read_csv(paths[kind]), pd.read_csv(shipped)
        assert list(new.columns) == list(old.columns)
        assert new.shape == old.shape
        np.testing.assert_allclose(new.to_numpy(float), old.to_numpy(float), rtol=1e-8, atol=1e-12)
    meta = json.loads((FIXTURES / "example_drive_meta.json").read_text())
    assert meta["seed"] == EXAMPLE_SEED and meta["imu_model"]["name"] == "nav"
    assert meta == json.loads(paths["meta"].read_text())
    size = sum((FIXTURES / p.name).stat().st_size for p in paths.values())
    assert size < 1.5e6


def test_example_fixture_content():
    from imu_ground.evaluation.simulate.fixtures import FIXTURES
    imu = pd.read_csv(FIXTURES / "example_drive.csv")
    truth = pd.read_csv(FIXTURES / "example_drive_truth.csv")
    assert list(imu.columns) == ["t", "wx", "wy", "wz", "ax", "ay", "az"]
    assert len(imu) == 6001 and len(truth) == 601
    np.testing.assert_allclose(np.diff(imu["t"]), 0.01, atol=1e-9)
    np.testing.assert_allclose(imu["az"].iloc[:300].mean(), GRAVITY, atol=0.05)   # at rest, FLU
    assert truth["stationary"].iloc[0] == 1 and truth["stationary"].sum() < len(truth) / 2
    n = truth[["normal_x", "normal_y", "normal_z"]].to_numpy()
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-9)


@pytest.mark.parametrize("kw, option", [
    ({"duration": float("nan")}, "duration"), ({"duration": float("inf")}, "duration"),
    ({"duration": 1e7}, "duration"), ({"duration": 0.01}, "duration"), ({"duration": 1800.0, "imu_rate": 400.0}, "duration"),
    ({"imu_rate": 2000.0}, "imu_rate"), ({"imu_rate": float("nan")}, "imu_rate"), ({"seed": -1}, "seed"),
])
def test_simulate_refuses_out_of_bounds_arguments_before_any_work(kw, option):
    """NaN passed the old ``duration <= 0`` test, 1e7 s ran without end, a negative seed was numpy's bare ValueError."""
    from imu_ground.datasets.options import OptionError
    with pytest.raises(OptionError) as got:
        simulate(**kw)
    assert got.value.option == option


def test_the_bounds_hold_their_own_limits():
    from imu_ground.evaluation.simulate.drive import MAX_DURATION_S, MAX_IMU_RATE_HZ, MAX_IMU_SAMPLES, check_rates
    assert check_rates(MAX_DURATION_S, MAX_IMU_SAMPLES / MAX_DURATION_S, 10.0, None) == 10
    assert check_rates(MAX_IMU_SAMPLES / MAX_IMU_RATE_HZ, MAX_IMU_RATE_HZ, 10.0, None) == 1
    assert check_rates(0.1, 100.0, 10.0, None) == 10                  # one frame: the shortest drive


def test_a_suite_refuses_more_drives_than_its_bound():
    from imu_ground.datasets.options import OptionError
    from imu_ground.evaluation.simulate.suite import MAX_SUITE_DRIVES
    for n in (-1, MAX_SUITE_DRIVES + 1, 2.5):
        with pytest.raises(OptionError, match="drives per IMU grade"):
            simulate_suite(n)
    assert simulate_suite(0) == []
