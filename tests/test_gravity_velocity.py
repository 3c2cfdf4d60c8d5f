"""GravityVelocityFilter: the scalar kernel against a plain 6x6 Kalman filter, streaming == batch,
the public building blocks, bad frames, filterpy-style state access."""
from __future__ import annotations

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.gravity_velocity import GravityVelocityFilter, egomotion_arrays
from imu_ground.imu.egomotion import EgoFrame, EgoMotion
from imu_ground.units import RENORM_EVERY


def _drive(n=400, seed=5):
    """Synthetic frames: a car-like rotation sequence, specific-force increments with gravity, standstills."""
    rng = np.random.default_rng(seed)
    d = so3.exp(rng.normal(scale=[0.004, 0.004, 0.03], size=(n, 3)))
    dt = 0.1 + rng.uniform(-0.002, 0.002, n)
    dv = (np.array([0.0, 0.0, 9.81]) + rng.normal(scale=0.1, size=(n, 3))) * dt[:, None]
    st = np.zeros(n, dtype=bool)
    dv[80:150, 0] += 1.0 * dt[80:150]        # speeds up to about 7 m/s
    st[50:70] = True
    st[148:150] = True                       # flagged while moving: the gate decides
    dv[50:70] = [0.0, 0.0, 9.81 * 0.1]
    valid = np.ones(n, dtype=bool)
    valid[120] = False
    return EgoMotion(np.cumsum(dt), d, dv, dt, st, valid)


def _reference(em, d_body, dv_body, *, sigma_nhc=0.3, sigma_zupt=0.05, q_v=0.05, q_g=1e-6, q_gap=1.0,
               q_gap_g=0.1, sigma_v0=30.0, sigma_g0=1.0, gate=100.0):
    """The model of the class docstring as a textbook Kalman filter on 6x6 matrices (numpy, Joseph form)."""
    x = np.zeros(6)
    P = np.diag([sigma_v0 ** 2] * 3 + [sigma_g0 ** 2] * 3)
    R = np.eye(3)
    xs, Ps = [], []
    for k in range(len(em.delta_t)):
        dt = em.delta_t[k]
        Rprev, R = R, R @ d_body[k]
        if (k + 1) % RENORM_EVERY == 0:
            R = so3.renormalise(R)
        if k == 0:
            x[3:] = Rprev @ dv_body[k] / dt
        F = np.eye(6)
        F[:3, 3:] = -dt * np.eye(3)
        x = F @ x + np.concatenate([Rprev @ dv_body[k], np.zeros(3)])
        qv = (q_v ** 2 + (0.0 if em.valid[k] else q_gap ** 2)) * dt
        qg = (q_g ** 2 + (0.0 if em.valid[k] else q_gap_g ** 2)) * dt
        P = F @ P @ F.T + np.diag([qv] * 3 + [qg] * 3)
        H = np.hstack([R.T, np.zeros((3, 3))])
        Rm = sigma_zupt ** 2 * np.eye(3)
        use_zupt = bool(em.stationary[k])
        if use_zupt:
            y = -H @ x
            use_zupt = y @ np.linalg.solve(H @ P @ H.T + Rm, y) <= gate
        if not use_zupt:
            H, Rm = H[1:], sigma_nhc ** 2 * np.eye(2)
        S = H @ P @ H.T + Rm
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (-H @ x)
        IKH = np.eye(6) - K @ H
        P = IKH @ P @ IKH.T + K @ Rm @ K.T
        xs.append(x.copy())
        Ps.append(P.copy())
    return np.array(xs), np.array(Ps)


@pytest.fixture(scope="module")
def drive():
    return _drive()


@pytest.mark.parametrize("extrinsic", [None, so3.rotz(0.2) @ so3.roty(-0.05) @ so3.rotx(0.03)])
def test_kernel_matches_a_plain_kalman_filter(drive, extrinsic):
    em = drive
    f = GravityVelocityFilter(extrinsic=extrinsic)
    tr = f.run(em)
    Rgs = np.eye(3) if extrinsic is None else extrinsic
    xs, Ps = _reference(em, Rgs @ em.delta_R @ Rgs.T, em.delta_v @ Rgs.T)
    np.testing.assert_allclose(tr.velocity, xs[:, :3], atol=1e-9)
    np.testing.assert_allclose(tr.gravity, xs[:, 3:], atol=1e-9)
    np.testing.assert_allclose(tr.P, Ps, rtol=1e-8, atol=1e-12)
    assert f.zupt_rejected >= 1                             # the flags at 148-149 are gated out
    np.testing.assert_array_equal(tr.P, np.swapaxes(tr.P, 1, 2))
    assert np.all(np.linalg.eigvalsh(tr.P) > 0)


def test_streaming_equals_batch_in_pieces(drive):
    em = drive
    ext = Extrinsic(so3.rotz(0.1) @ so3.roty(0.03), [0.4, 0.1, 1.1])
    a = GravityVelocityFilter(extrinsic=ext, lever_arm=ext.translation)
    est = [a.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
           for k in range(len(em.delta_t))]
    b = GravityVelocityFilter(extrinsic=ext, lever_arm=ext.translation)
    cut = 137

    def part(i, j):
        return EgoMotion(em.t[i:j], em.delta_R[i:j], em.delta_v[i:j], em.delta_t[i:j], em.stationary[i:j],
                         em.valid[i:j])
    parts = [b.run(part(0, cut)), b.run(part(cut, len(em.delta_t)))]
    for name in ("velocity", "gravity", "acceleration", "specific_force"):
        batch = np.concatenate([getattr(p, name) for p in parts])
        np.testing.assert_allclose([getattr(e, name) for e in est], batch, atol=1e-12, err_msg=name)
    np.testing.assert_allclose([e.speed for e in est], np.concatenate([p.speed for p in parts]), atol=1e-12)
    np.testing.assert_allclose(a.P, b.P, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(a.cumulative, b.cumulative, atol=1e-14)
    np.testing.assert_allclose(a.x, b.x, atol=1e-12)
    assert a.zupt_rejected == b.zupt_rejected


def test_public_building_blocks(drive):
    em = drive
    ext = so3.rotz(0.3)
    a, b = GravityVelocityFilter(extrinsic=ext), GravityVelocityFilter(extrinsic=ext)
    d, dv = a.to_body(em.delta_R, em.delta_v)
    for k in range(30):
        ge = a.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
        f, acc, speed = b.step_body(d[k].ravel().tolist(), dv[k].tolist(), float(em.delta_t[k]),
                                    bool(em.stationary[k]))
        assert speed == pytest.approx(ge.speed, abs=1e-13)
        np.testing.assert_allclose(f, ge.specific_force, atol=1e-13)
        np.testing.assert_allclose(acc, ge.acceleration, atol=1e-13)
    tr = GravityVelocityFilter(extrinsic=ext).run_body(d, dv, em.delta_t, em.stationary, em.valid)
    np.testing.assert_allclose(tr.velocity, GravityVelocityFilter(extrinsic=ext).run(em).velocity, atol=0)
    assert all(np.array_equal(p, q) for p, q in zip(egomotion_arrays(em), (em.delta_R, em.delta_v, em.delta_t,
                                                                            em.stationary, em.valid), strict=True))


def test_egoframe_input_and_bad_frames_leave_the_state_unchanged(drive):
    em = drive
    a, b = GravityVelocityFilter(), GravityVelocityFilter()
    for k in range(20):
        ea = a.step(EgoFrame(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k]))
        eb = b.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
        np.testing.assert_array_equal(ea.velocity, eb.velocity)
    x, P, R = a.x.copy(), a.P.copy(), a.cumulative.copy()
    bad_dv = em.delta_v[20].copy()
    bad_dv[1] = np.nan
    for args in ((em.delta_R[20], bad_dv, 0.1), (em.delta_R[20], em.delta_v[20], 0.0),
                 (em.delta_R[20], em.delta_v[20], -0.1)):
        with pytest.raises(ValueError, match="bad frame"):
            a.step(*args)
    np.testing.assert_array_equal(a.x, x)
    np.testing.assert_array_equal(a.P, P)
    np.testing.assert_array_equal(a.cumulative, R)
    with pytest.raises(ValueError, match="delta_R must be"):
        a.step(np.zeros(5), em.delta_v[20], 0.1)
    # the estimators' frame check (frame_checks.frame_problem): also rotations that are not rotations
    for d in (2.0 * np.eye(3), np.diag([1.0, 1.0, -1.0]), np.full((3, 3), np.nan)):
        with pytest.raises(ValueError, match="bad frame: delta_R is not"):
            a.step(d, em.delta_v[20], 0.1)
    with pytest.raises(ValueError, match="bad frame: delta_t must be a positive number"):
        a.step(em.delta_R[20], em.delta_v[20], np.inf)
    np.testing.assert_array_equal(a.x, x)
    np.testing.assert_array_equal(a.P, P)


def test_state_arrays_can_be_set_and_changed_in_place(drive):
    em = drive
    a, b = GravityVelocityFilter(), GravityVelocityFilter()
    for f in (a, b):
        f.step(em.delta_R[0], em.delta_v[0], em.delta_t[0])
    a.x[3:] = [0.0, 0.0, 9.80665]                         # in place
    b.x = np.r_[b.x[:3], 0.0, 0.0, 9.80665]               # assigned
    a.P *= 2.0
    b.P = 2.0 * b.P
    for f in (a, b):
        f.step(em.delta_R[1], em.delta_v[1], em.delta_t[1])
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    assert abs(a.x[5] - 9.80665) < 0.1
    a.reset()
    assert np.array_equal(a.x, np.zeros(6)) and np.array_equal(a.cumulative, np.eye(3))
    assert a.P[0, 0] == 30.0 ** 2 and a.P[5, 5] == 1.0


def test_filterpy_matrices_describe_the_last_update(drive):
    em = drive
    f = GravityVelocityFilter()
    for k in range(60):                                    # ends inside the standstill 50-69: a ZUPT
        f.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
    H, R, K, S, y = f.H, f.R, f.K, f.S, f.y
    np.testing.assert_allclose(S, H @ f.P_prior @ H.T + R, atol=1e-12)
    np.testing.assert_allclose(K, f.P_prior @ H.T @ np.linalg.inv(S), atol=1e-12)
    np.testing.assert_allclose(f.x, f.x_prior + K @ y, atol=1e-12)
    np.testing.assert_allclose(y, -H @ f.x_prior, atol=1e-12)
    g = GravityVelocityFilter()
    for k in range(40):                                    # moving: the non-holonomic constraint
        g.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
    H, R, K, S = g.H, g.R, g.K, g.S
    assert np.all(H[0] == 0) and np.all(K[:, 0] == 0) and R[0, 0] == 0
    np.testing.assert_allclose(S[1:, 1:], (H @ g.P_prior @ H.T + R)[1:, 1:], atol=1e-12)
    np.testing.assert_allclose(g.x, g.x_prior + K @ g.y, atol=1e-12)


def test_to_body_flat_matches_to_body():
    from imu_ground import so3
    R = so3.rotz(0.3) @ so3.rotx(-0.1)
    f = GravityVelocityFilter(extrinsic=R)
    d = so3.exp(np.array([0.01, -0.02, 0.03]))
    dv = np.array([0.5, -0.1, 0.98])
    d9, dv3 = f.to_body_flat(d.ravel().tolist(), dv.tolist())
    db, dvb = f.to_body(d, dv)
    np.testing.assert_array_equal(np.reshape(d9, (3, 3)), db)          # the same sums in the same order
    np.testing.assert_array_equal(dv3, dvb)
    np.testing.assert_allclose(db, R @ d @ R.T, atol=1e-15)
    np.testing.assert_allclose(dvb, R @ dv, atol=1e-15)
    many, many_v = f.to_body(np.stack([d, d.T]), np.stack([dv, -dv]))
    np.testing.assert_array_equal(many[0], db)
    np.testing.assert_array_equal(many_v[1], -dvb)


def test_step_sensor_is_step_body_of_to_body_flat(drive):
    em = drive
    ext = Extrinsic(so3.rotz(0.2) @ so3.rotx(0.05), [0.3, 0.0, 1.0])
    a = GravityVelocityFilter(extrinsic=ext, lever_arm=ext.translation)
    b = GravityVelocityFilter(extrinsic=ext, lever_arm=ext.translation)
    for k in range(120):
        d9, dv = em.delta_R[k].ravel().tolist(), em.delta_v[k].tolist()
        args = (float(em.delta_t[k]), bool(em.stationary[k]), bool(em.valid[k]), 3.0 if k % 4 == 0 else None)
        assert a.step_sensor(d9, dv, *args) == b.step_body(*b.to_body_flat(d9, dv), *args)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)


def test_copies_and_pickles_continue_alike(drive):
    import copy
    import pickle
    em = drive
    a = GravityVelocityFilter(extrinsic=so3.rotz(0.1), lever_arm=[0.1, 0.2, 0.3])
    for k in range(60):
        a.step(em.frame_at(k))
    b, c = copy.deepcopy(a), pickle.loads(pickle.dumps(a))
    for f in (a, b, c):
        for k in range(60, 90):
            e = f.step(em.frame_at(k), speed=4.0 if k % 3 else None)
        f.last = e
    for f in (b, c):
        np.testing.assert_array_equal(f.x, a.x)
        np.testing.assert_array_equal(f.P, a.P)
        np.testing.assert_array_equal(f.last.acceleration, a.last.acceleration)
    assert b._s is not a._s
