"""The drive statistics of the 1-sigma (roughness and mean load so far): the same in a stream and a batch,
kept in the saved state, what their formula says, and IMU-only when a log has no speed."""
import json
from dataclasses import replace

import numpy as np
import pytest

from imu_ground.evaluation.simulate import simulate
from imu_ground.filters.status import (DRIVE_PRIOR_SECONDS, SLOW_SPEED, SUSPENSION_STD, AngleStd, DriveStatistics,
                                       SigmaModel)
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import imu_to_egomotion
from imu_ground.so3 import exp, rotx, rotz
from imu_ground.units import DEG


def _frames(n=300, seed=4):
    rng = np.random.default_rng(seed)
    d = exp(rng.normal(scale=0.01, size=(n, 3)))
    dt = rng.uniform(0.09, 0.11, n)
    speed = rng.uniform(0.0, 2.0 * SLOW_SPEED, n)          # about a third below the moving threshold
    stationary, valid = rng.random(n) < 0.1, rng.random(n) > 0.05
    load = rng.normal(scale=1.5, size=(n, 2))
    return d, dt, speed, stationary, valid, load


@pytest.mark.parametrize("Rgs", [None, rotz(0.3) @ rotx(-0.05)])
def test_update_frame_by_frame_equals_run_bit_for_bit(Rgs):
    d, dt, speed, st, valid, load = _frames()
    batch = DriveStatistics()
    batch.state = [1.5, 0.2, -0.1, 1e-4, 2e-4]             # continues from a state, as a resumed run does
    got = batch.run(d, dt, speed, st, valid, load, Rgs)
    one = DriveStatistics()
    one.state = [1.5, 0.2, -0.1, 1e-4, 2e-4]
    for k in range(len(dt)):
        one.update(d[k], float(dt[k]), float(speed[k]), bool(st[k]), bool(valid[k]), float(load[k, 0]),
                   float(load[k, 1]), Rgs)
        np.testing.assert_array_equal(got[k], one.state)
    assert batch.state == one.state
    moving = valid & ~st & (speed >= SLOW_SPEED)
    assert 0 < moving.sum() < len(dt) and got[-1, 0] == pytest.approx(1.5 + dt[moving].sum(), rel=1e-12)


def test_terms_are_the_mean_square_rate_and_the_mean_load_off_the_centre_with_the_prior():
    """Closed form: T moving seconds at a constant ground-frame rate (w_x, w_y) and load (u_x, u_y)."""
    w, u, dt, n = (0.02, -0.03), (0.4, 0.25), 0.1, 600
    c = AngleStd(0.5, 0.0, 0.0, 0.0, load_center=0.1)
    r = AngleStd(0.5, 0.0, 0.0, 0.0, load_center=0.2)
    d = np.repeat(exp(np.array([w[0] * dt, w[1] * dt, 0.0]))[None], n, axis=0)
    ds = DriveStatistics()
    ds.run(d, np.full(n, dt), np.full(n, 10.0), np.zeros(n, bool), np.ones(n, bool), np.tile(u, (n, 1)))
    T = n * dt
    share = T / (T + DRIVE_PRIOR_SECONDS)
    rp, dx, rr, dy = DriveStatistics.terms(ds.state, c, r)
    # (the rate from the increment's skew part: sin(theta) / theta of the rate, squared: 1 - theta^2 / 3, 4e-6 here)
    np.testing.assert_allclose([rp, rr], [w[1] ** 2 * share, w[0] ** 2 * share], rtol=1e-5)
    np.testing.assert_allclose([dx, dy], [(u[0] - 0.1) * share, (u[1] - 0.2) * share], rtol=1e-12)
    m = AngleStd(0.0, 0.0, 0.0, 0.0, rough=0.5, drive_load=0.3 * DEG)
    assert m.variance(0.0, rate_ms=rp, load_offset=dx) == pytest.approx(0.25 * rp + (0.3 * DEG * dx) ** 2, rel=1e-15)


def test_a_state_saved_before_the_drive_statistics_resumes_with_none_seen():
    m = SigmaModel()
    m.drive.state = [3.0, 1.0, 1.0, 1.0, 1.0]
    m.load_state_dict({"converged": True})
    assert m.converged and m.drive.state == [0.0] * 5
    m.load_state_dict(json.loads(json.dumps({"converged": False, "drive": [2.0, 0.5, 0.25, 1e-3, 2e-3]})))
    assert m.drive.state == [2.0, 0.5, 0.25, 1e-3, 2e-3]


@pytest.fixture(scope="module")
def mems_drive():
    sim = simulate(duration=60.0, seed=11, imu="mems", R_gs=rotz(0.02) @ rotx(0.01))
    return imu_to_egomotion(sim.imu, rate=10.0), sim.R_gs


@pytest.mark.parametrize("with_speed", [False, True], ids=["imu-only", "speed"])
def test_stream_batch_and_resume_keep_the_same_drive_statistics(mems_drive, with_speed):
    """The estimator's stream and batch give the same drive state and 1-sigma (IMU only: the estimator's own
    speed), and a stream stopped and resumed through its saved state continues bit for bit."""
    em, R = mems_drive
    speed = np.full(len(em), 9.0) if with_speed else None
    tr = SuspensionAwareFilter(extrinsic=R).run(em, speed=speed)
    whole = SuspensionAwareFilter(extrinsic=R)
    frames = list(em.frames())
    es = [whole.step(fr, speed=None if speed is None else speed[k]) for k, fr in enumerate(frames)]
    ds_batch = SuspensionAwareFilter(extrinsic=R)
    ds_batch.run(em, speed=speed)
    np.testing.assert_allclose(whole.sigma.drive.state, ds_batch.sigma.drive.state, rtol=1e-12, atol=0)
    assert whole.sigma.drive.state[0] > 20.0                           # moving seconds counted
    for name in ("pitch_std", "roll_std"):
        np.testing.assert_allclose([getattr(e, name) for e in es], getattr(tr, name), rtol=1e-12, atol=0)
    k = 250
    first = SuspensionAwareFilter(extrinsic=R)
    for j, fr in enumerate(frames[:k]):
        first.step(fr, speed=None if speed is None else speed[j])
    resumed = SuspensionAwareFilter(extrinsic=R)
    resumed.load_state_dict(json.loads(json.dumps(first.state_dict())))
    rest = [resumed.step(fr, speed=None if speed is None else speed[k + j]) for j, fr in enumerate(frames[k:])]
    assert [(e.pitch_std, e.roll_std) for e in rest] == [(e.pitch_std, e.roll_std) for e in es[k:]]
    assert resumed.sigma.drive.state == whole.sigma.drive.state


def test_the_shipped_drive_terms_widen_the_1_sigma_of_a_biased_accelerometer():
    """The shipped mean-load term: the same drive with 0.3 m/s^2 more lateral accelerometer bias (the MEMS
    grade's size), away from the load centre, ends with a wider roll 1-sigma; the roughness terms are positive."""
    assert SUSPENSION_STD[1].drive_load > 0 and SUSPENSION_STD[0].rough > 0 and SUSPENSION_STD[1].rough > 0
    sim = simulate(duration=60.0, seed=11, imu="nav", R_gs=np.eye(3))
    em = imu_to_egomotion(sim.imu, rate=10.0)
    fa = SuspensionAwareFilter()
    a = fa.run(em)
    t, _, sy = fa.sigma.drive.state[:3]
    bias = -0.3 if sy / t < SUSPENSION_STD[1].load_center else 0.3
    fb = SuspensionAwareFilter()
    b = fb.run(replace(em, delta_v=em.delta_v + np.array([0.0, bias, 0.0]) * em.delta_t[:, None]))
    tb, _, syb = fb.sigma.drive.state[:3]
    assert syb / tb - sy / t == pytest.approx(bias, abs=0.02)             # the drive's mean load took the bias
    assert b.roll_std[-1] > 1.3 * a.roll_std[-1]


def test_drive_terms_widen_the_1_sigma_but_do_not_hold_the_status_at_converging():
    """Ten minutes of a large mean load keep the roll 1-sigma above the convergence threshold; the latch compares
    the 1-sigma without the drive terms, so a converged filter is ``ok`` (the whole of KITTI's
    2011_10_03_drive_0042, 20 min, was ``converging``), frame by frame and in a batch alike."""
    from imu_ground.filters.status import CONVERGED_STD, CONVERGING, OK
    pm, rm = SUSPENSION_STD
    sm = SigmaModel()
    sm.drive.state = [600.0, 600.0 * pm.load_center, 600.0 * (rm.load_center + 3.0), 0.0, 0.0]
    a = np.array([1e-8, 1e-8])                                      # the filter's own variance: converged
    info = sm.frame(float(a[0]))
    wide = np.sqrt(sm.track(a, drive=np.array([sm.drive.state] * 2)))
    assert wide[0, 1] > CONVERGED_STD and wide[0, 1] == pytest.approx(
        np.sqrt(rm.variance(1e-8, rate_ms=0.0, load_offset=3.0 * 600.0 / (600.0 + DRIVE_PRIOR_SECONDS))), rel=1e-12)
    assert sm.converged and DriveStatistics.terms(info[11], pm, rm)[3] > 2.0     # latched, the drive term kept
    latch = sm.latch_variance(a)
    assert np.all(latch <= CONVERGED_STD ** 2)
    fresh = SigmaModel()
    codes = fresh.statuses(latch, np.zeros(2, bool), np.ones(2, bool), np.ones(2, bool))
    assert list(codes) == [OK, OK] and CONVERGING not in codes
