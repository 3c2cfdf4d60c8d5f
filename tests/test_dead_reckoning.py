"""Tests of standstill detection / gyro-bias initialisation and dead reckoning."""
from __future__ import annotations

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.imu.data import ImuData
from imu_ground.imu.dead_reckoning import (
    attitude_from_accel,
    dead_reckon,
    dead_reckon_imu,
)
from imu_ground.imu.preintegration import preintegrate
from imu_ground.imu.standstill import detect_standstill, estimate_gyro_bias
from imu_ground.units import GRAVITY


# ---------------------------------------------------------------------------
# a synthetic vehicle: Euler angles and position analytic, IMU from them
# ---------------------------------------------------------------------------
def euler_traj(t):
    """roll, pitch, yaw and their rates; position, velocity, acceleration (nav, z up)."""
    phi = 0.05 * np.sin(0.7 * t)
    th = 0.03 * np.cos(0.5 * t) + 0.02
    psi = 0.3 * t + 0.2 * np.sin(0.4 * t)
    dphi = 0.035 * np.cos(0.7 * t)
    dth = -0.015 * np.sin(0.5 * t)
    dpsi = 0.3 + 0.08 * np.cos(0.4 * t)
    p = np.stack([10 * np.sin(0.3 * t), 8 * (1 - np.cos(0.3 * t)) + 2 * t, 0.5 * np.sin(0.2 * t)], 1)
    v = np.stack([3 * np.cos(0.3 * t), 2.4 * np.sin(0.3 * t) + 2, 0.1 * np.cos(0.2 * t)], 1)
    a = np.stack([-0.9 * np.sin(0.3 * t), 0.72 * np.cos(0.3 * t), -0.02 * np.sin(0.2 * t)], 1)
    return (phi, th, psi), (dphi, dth, dpsi), p, v, a


def simulate(rate_hz=200.0, T=10.0, g=GRAVITY):
    n = int(round(T * rate_hz)) + 1
    t = np.linspace(0.0, T, n)
    (phi, th, psi), (dphi, dth, dpsi), p, v, a = euler_traj(t)
    R = so3.rotz(psi) @ so3.roty(th) @ so3.rotx(phi)               # body -> nav
    # body rates of R = Rz(psi) Ry(theta) Rx(phi)
    w = np.stack([dphi - dpsi * np.sin(th),
                  dth * np.cos(phi) + dpsi * np.cos(th) * np.sin(phi),
                  -dth * np.sin(phi) + dpsi * np.cos(th) * np.cos(phi)], 1)
    f = np.einsum("nji,nj->ni", R, a + [0.0, 0.0, g])               # specific force, body
    return ImuData(t, w, f), R, v, p


# ---------------------------------------------------------------------------
# attitude from the accelerometer, dead reckoning algebra
# ---------------------------------------------------------------------------
def test_attitude_from_accel_recovers_roll_and_pitch():
    rng = np.random.default_rng(0)
    for _ in range(20):
        roll, pitch = rng.uniform(-0.5, 0.5, 2)
        R = so3.roty(pitch) @ so3.rotx(roll)
        f = R.T @ [0.0, 0.0, GRAVITY]
        np.testing.assert_allclose(attitude_from_accel(f), R, atol=1e-14)
        np.testing.assert_allclose(attitude_from_accel(3 * f, yaw=0.4), so3.rotz(0.4) @ R, atol=1e-14)
    with pytest.raises(ValueError):
        attitude_from_accel([0.0, 0.0, 0.0])


def test_dead_reckon_equals_sequential_equations():
    imu, R, v, p = simulate(100.0, 5.0)
    fd = preintegrate(imu, rate=10.0)
    R0 = so3.exp([0.1, -0.2, 0.3])
    v0, p0 = np.array([1.0, 2.0, 0.1]), np.array([5.0, -3.0, 1.0])
    nav = dead_reckon(fd, R0, v0, p0, gravity=9.8)
    g = np.array([0.0, 0.0, -9.8])
    Rk, vk, pk = R0, v0, p0
    for k in range(len(fd)):
        T = fd.delta_t[k]
        Rk, vk, pk = (Rk @ fd.delta_R[k], vk + g * T + Rk @ fd.delta_v[k],
                      pk + vk * T + 0.5 * g * T * T + Rk @ fd.delta_p[k])
        np.testing.assert_allclose(nav.R[k + 1], Rk, atol=1e-13)
        np.testing.assert_allclose(nav.v[k + 1], vk, atol=1e-12)
        np.testing.assert_allclose(nav.p[k + 1], pk, atol=1e-11)
    np.testing.assert_allclose(nav.t, np.concatenate([fd.t_start[:1], fd.t_end]))
    assert nav.valid.all() and len(nav) == len(fd) + 1


def test_dead_reckoning_follows_synthetic_trajectory():
    errs = []
    for rate in (200.0, 400.0, 800.0):
        imu, R, v, p = simulate(rate, 10.0)
        per_sample = dead_reckon(preintegrate(imu, every=1), R[0], v[0], p[0])
        frames = dead_reckon(preintegrate(imu, every=int(rate // 10)), R[0], v[0], p[0])
        # frames whose boundaries are samples compose exactly: same states
        k = int(rate // 10)
        np.testing.assert_allclose(frames.R, per_sample.R[::k], atol=1e-12)
        np.testing.assert_allclose(frames.v, per_sample.v[::k], atol=1e-9)
        np.testing.assert_allclose(frames.p, per_sample.p[::k], atol=1e-9)
        att = np.degrees(so3.angle(np.swapaxes(per_sample.R, 1, 2) @ R))
        errs.append((att.max(), np.abs(per_sample.v - v).max(), np.abs(per_sample.p - p).max()))
    errs = np.array(errs)
    assert errs[-1, 0] < 1e-4            # deg: the rotation is second order (midpoint hold)
    assert errs[-1, 1] < 5e-3 and errs[-1, 2] < 2e-2          # m/s, m after 10 s at 800 Hz
    assert np.all(errs[1:, 1:] < 0.6 * errs[:-1, 1:])         # converging with the rate
    # roll/pitch/yaw read-out uses the same convention as the simulator
    nav = dead_reckon(preintegrate(imu, rate=10.0), R[0], v[0], p[0])
    rpy = nav.roll_pitch_yaw
    (phi, th, psi), *_ = euler_traj(nav.t)
    np.testing.assert_allclose(rpy[:, 0], phi, atol=1e-4)
    np.testing.assert_allclose(rpy[:, 1], th, atol=1e-4)
    np.testing.assert_allclose(np.unwrap(rpy[:, 2]), psi, atol=1e-4)


def test_dead_reckon_bias_correction():
    imu, R, v, p = simulate(200.0, 4.0)
    bg, ba = np.array([0.004, -0.003, 0.002]), np.array([0.05, -0.02, 0.03])
    biased = ImuData(imu.t, imu.gyro + bg, imu.accel + ba)
    fd0 = preintegrate(biased, rate=10.0)
    corrected = dead_reckon(fd0, R[0], v[0], p[0], bias_gyro=bg, bias_accel=ba)
    exact = dead_reckon(preintegrate(biased, rate=10.0, bias_gyro=bg, bias_accel=ba), R[0], v[0], p[0])
    raw = dead_reckon(fd0, R[0], v[0], p[0])
    assert np.abs(corrected.p - exact.p).max() < 1e-3 * np.abs(raw.p - exact.p).max()
    assert np.abs(corrected.v - exact.v).max() < 1e-3 * np.abs(raw.v - exact.v).max()


# ---------------------------------------------------------------------------
# standstill and gyro bias
# ---------------------------------------------------------------------------
def stop_and_go(seed=1, bias=(0.01, -0.02, 0.005), n_gyro=5e-4, n_acc=0.01):
    """0-4 s rest (tilted), 4-14 s driving, 14-18 s rest, 18-20 s driving, 100 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, 20.0, 0.01)
    n = t.size
    Rrest = so3.roty(0.03) @ so3.rotx(-0.02)
    gyro = np.zeros((n, 3))
    accel = np.tile(Rrest.T @ [0.0, 0.0, GRAVITY], (n, 1))
    for a, b in ((4.0, 14.0), (18.0, 20.0)):
        m = (t >= a) & (t < b)
        s = t[m] - a
        gyro[m] = np.stack([0.05 * np.sin(3 * s), 0.04 * np.sin(2 * s), 0.1 + 0.2 * np.sin(0.5 * s)], 1)
        accel[m] += np.stack([1.0 + np.sin(s), 0.5 * np.sin(1.3 * s), 0.3 * np.sin(5 * s)], 1)
    gyro += np.asarray(bias) + rng.normal(0, n_gyro, (n, 3))
    accel += rng.normal(0, n_acc, (n, 3))
    return ImuData(t, gyro, accel), Rrest


def test_standstill_detection_and_bias():
    imu, Rrest = stop_and_go()
    iv = detect_standstill(imu)
    assert iv.shape == (2, 2)
    np.testing.assert_allclose(iv, [[0.0, 3.99], [14.0, 17.99]], atol=0.05)
    est = estimate_gyro_bias(imu)
    assert est.found and est.n_samples == pytest.approx(800, abs=10)
    np.testing.assert_array_equal(est.intervals, iv)
    assert np.all(np.abs(est.bias - [0.01, -0.02, 0.005]) < 5 * 5e-4 / np.sqrt(800))
    assert np.all(np.abs(est.bias - [0.01, -0.02, 0.005]) < 4 * est.bias_std + 1e-12)
    g_true = Rrest.T @ [0.0, 0.0, -1.0]
    for g in (est.gravity_body, *est.gravity_body_per_interval):
        assert np.degrees(np.arccos(g @ g_true)) < 0.05
    R0 = attitude_from_accel(est.accel_mean[0])
    assert np.degrees(so3.angle(R0.T @ Rrest)) < 0.05


def test_no_standstill_while_moving():
    imu, _ = stop_and_go()
    moving = imu.select((imu.t >= 4.5) & (imu.t < 13.5))
    est = estimate_gyro_bias(moving)
    assert not est.found and np.all(est.bias == 0) and np.all(np.isnan(est.gravity_body))
    assert detect_standstill(moving).shape == (0, 2)
    with pytest.raises(ValueError, match="does not start at rest"):
        dead_reckon_imu(moving)
    # a steady turn with |accel| = g is rejected by the mean-rate limit
    t = np.arange(0, 5, 0.01)
    turn = ImuData(t, np.tile([0.0, 0.0, 0.2], (t.size, 1)), np.tile([0.0, 0.0, GRAVITY], (t.size, 1)))
    assert not estimate_gyro_bias(turn).found


def test_dead_reckon_imu_at_rest_stays_put():
    imu, Rrest = stop_and_go(n_gyro=0.0, n_acc=0.0)
    rest = imu.select(imu.t < 4.0)
    nav = dead_reckon_imu(rest, rate=10.0)
    np.testing.assert_allclose(nav.R, np.broadcast_to(Rrest, nav.R.shape), atol=1e-9)
    assert np.abs(nav.v).max() < 1e-9 and np.abs(nav.p).max() < 1e-9
    noisy, _ = stop_and_go(seed=3)
    nav = dead_reckon_imu(noisy.select(noisy.t < 4.0))
    assert np.abs(nav.p[-1]).max() < 0.05             # m after 4 s with noise and bias removed
    assert np.degrees(so3.angle(nav.R[-1].T @ Rrest)) < 0.1


# ---------------------------------------------------------------------------
# real data
# ---------------------------------------------------------------------------
def _load_kitti(path):
    import warnings

    from imu_ground.datasets import read_kitti_imu100
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # the dropped out-of-order samples are reported
        imu = read_kitti_imu100(path)
    d = imu.to_dataframe()
    return imu, d


@pytest.mark.shared
def test_kitti_standstill_gravity_and_bias(shared_data):
    """Detected standstill is a real stop (GPS speed), gravity agrees with the OXTS attitude."""
    found, report = 0, []
    for f in sorted((shared_data / "kitti_imu100").glob("*.csv.gz")):
        imu, d = _load_kitti(f)
        est = estimate_gyro_bias(imu)
        if not est.found:
            continue
        found += 1
        speed = np.hypot(d["ve"].to_numpy(), d["vn"].to_numpy())
        for k, (a, b) in enumerate(est.intervals):
            m = (imu.t >= a) & (imu.t <= b)
            assert speed[m].max() < 0.3, (f.name, a, b)
            R = (so3.rotz(d["yaw"].to_numpy()[m]) @ so3.roty(d["pitch"].to_numpy()[m])
                 @ so3.rotx(d["roll"].to_numpy()[m]))
            down = -np.swapaxes(R, 1, 2)[:, :, 2].mean(axis=0)
            down /= np.linalg.norm(down)
            ang = np.degrees(np.arccos(np.clip(est.gravity_body_per_interval[k] @ down, -1, 1)))
            assert ang < 0.2, (f.name, ang)
        assert np.linalg.norm(est.bias) < 2e-3
        report.append(f"{f.name[:21]} {est.intervals.shape[0]} interval(s) "
                      f"{np.sum(est.intervals[:, 1] - est.intervals[:, 0]):.1f} s, "
                      f"|bias| {np.linalg.norm(est.bias):.1e} rad/s")
    print("\n" + "\n".join(report))
    assert found >= 8


@pytest.mark.shared
def test_kitti_dead_reckoned_tilt_from_rest(shared_data):
    """Drives that start at rest: attitude from the accelerometer, bias from the stop,
    then gyro-only roll and pitch over the next 60 s against the OXTS."""
    errs = []
    for f in sorted((shared_data / "kitti_imu100").glob("*.csv.gz")):
        imu, d = _load_kitti(f)
        est = estimate_gyro_bias(imu)
        if not est.found or est.intervals[0, 0] > imu.t[0] + 1.0:
            continue
        seg = imu.select(imu.t <= imu.t[0] + 60.0)
        nav = dead_reckon_imu(seg, rate=10.0, bias_gyro=est.bias, on_gap="flag")
        i = np.searchsorted(imu.t, nav.t)
        rpy = nav.roll_pitch_yaw
        e = np.degrees(np.abs(np.stack([rpy[:, 0] - d["roll"].to_numpy()[i],
                                        rpy[:, 1] - d["pitch"].to_numpy()[i]], 1)))
        errs.append(e[nav.valid].max())
    print(f"\nKITTI gyro-only tilt over 60 s from rest: {len(errs)} drives, max error per drive "
          f"{np.round(errs, 3).tolist()} deg")
    assert len(errs) >= 4
    assert np.median(errs) < 0.5


def test_accelerometer_bias_does_not_hide_the_stops():
    """A MEMS accelerometer's bias moves |f| at rest away from 9.81; the stops must still be found."""
    from imu_ground.evaluation.simulate import simulate
    from imu_ground.imu.standstill import detect_standstill, estimate_gyro_bias
    sim = simulate(60.0, seed=2, imu="perfect")
    stopped = sim.truth["stationary"].to_numpy()
    assert stopped.any()
    bg = np.array([0.01, -0.02, 0.015])                       # rad/s, MEMS-like turn-on bias
    imu = ImuData(sim.imu.t, sim.imu.gyro + bg, sim.imu.accel + np.array([0.1, -0.1, 0.3]))
    assert len(detect_standstill(imu, gravity=9.80665)) == 0      # against nominal g: nothing found
    found = detect_standstill(imu)
    assert len(found) >= 1
    est = estimate_gyro_bias(imu)
    np.testing.assert_allclose(est.bias, bg, atol=1e-4)
    # every detected standstill is a true stop: the car moves at most a creep (a gentle start's
    # first few tenths of a second, which no IMU detector can tell from rest), and it covers the stop
    t, speed = sim.truth["t"].to_numpy(), sim.truth["speed"].to_numpy()
    for a, b in found:
        inside = (t >= a) & (t <= b)
        assert speed[inside].max() < 0.02, (a, b, speed[inside].max())
        assert stopped[inside].sum() >= int((b - a) * 10) - 5
