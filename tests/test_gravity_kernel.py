"""The gravity/velocity kernel (``filters/gravity_kernel.py``): one body, ``frame``, for a streamed frame and a
drive.

Synthetic frames visit every branch (standstills and flags the gate rejects, a gap, identity and half-turn
increments, a measured speed that drops out, an extrinsic with a lever arm, zero noise, a tight gate); then
KITTI drives. A stream equals a run bit for bit (state buffer included), pieces equal the whole, the smoother
and the frame forces are finite, and threads give the single run's numbers.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.filters import gravity_kernel
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion

FIELDS = ("velocity", "gravity", "acceleration", "specific_force", "speed", "P", "cumulative", "body_increments")
KITTI = ("2011_09_26_drive_0009", "2011_09_28_drive_0039", "2011_09_30_drive_0016")


def _synthetic(n=600, seed=7):
    """Car-like frames with standstills, flags while moving, a gap, identity and half-turn increments."""
    rng = np.random.default_rng(seed)
    d = so3.exp(rng.normal(scale=[0.004, 0.004, 0.03], size=(n, 3)))
    dt = 0.1 + rng.uniform(-0.002, 0.002, n)
    dv = (np.array([0.0, 0.0, 9.81]) + rng.normal(scale=0.1, size=(n, 3))) * dt[:, None]
    dv[80:150, 0] += 1.0 * dt[80:150]
    st = np.zeros(n, dtype=bool)
    st[50:70] = True
    st[148:150] = True                      # flagged while moving: the gate rejects them
    dv[50:70] = [0.0, 0.0, 9.81 * 0.1]
    d[50:60] = np.eye(3)                    # exact identity: the small-angle series
    d[300] = so3.exp(np.array([0.0, 0.0, np.pi - 1e-9]))     # near pi: the log's other branch
    d[301] = so3.exp(np.array([0.3, -2.9, 0.2]))
    d[302] = so3.exp(np.array([1e-6, -2e-6, 3e-7]))          # below so3's small angle
    valid = np.ones(n, dtype=bool)
    valid[120] = valid[400:405] = False
    dt[400] = 1.7                           # a long gap
    return EgoMotion(np.cumsum(dt), d, dv, dt, st, valid)


def _head(em, n):
    return EgoMotion(em.t[:n], em.delta_R[:n], em.delta_v[:n], em.delta_t[:n], em.stationary[:n], em.valid[:n])


def _speed(n, seed=3):
    rng = np.random.default_rng(seed)
    sp = np.abs(rng.normal(5.0, 2.0, n))
    sp[rng.uniform(size=n) < 0.5] = np.nan
    sp[50:70] = 0.0
    return sp


CONFIGS = {
    "default": {},
    "extrinsic, lever arm": dict(extrinsic=Extrinsic(so3.rotz(0.1) @ so3.roty(0.03) @ so3.rotx(-0.02),
                                                     [0.4, 0.1, 1.1]), lever_arm=[0.4, 0.1, 1.1], q_gap_g=0.0),
    "zero noise, gravity given": dict(q_v=0.0, q_g=0.0, q_gap=0.0, q_gap_g=0.0, g0=[0.0, 0.0, 9.81],
                                      v0=[1.0, 0.0, 0.0]),
    "tight gate, speed noise": dict(zupt_gate=0.5, sigma_speed=0.5, R0=so3.rotx(0.2)),
}


def _stream_equals_run(em, speed, kw, what):
    """step frame by frame == run (the same kernel), bit for bit, the whole buffer too; the smoother is finite."""
    c = GravityVelocityFilter(**kw)
    n = len(em)
    sp = [None] * n if speed is None else speed
    stream = []
    for k in range(n):
        fr = (em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
        stream.append(c.step(*fr, speed=sp[k]))
    for name in ("x", "P", "cumulative", "x_prior", "P_prior", "F", "Q", "H", "R", "K", "y", "S"):
        assert np.all(np.isfinite(getattr(c, name))), f"{what}: {name}"
    for smooth in (False, True):
        rc = GravityVelocityFilter(**kw)
        tc = rc.run(em, smooth=smooth, speed=speed)
        for name in FIELDS:
            assert np.all(np.isfinite(getattr(tc, name))), f"{what}: run(smooth={smooth}) {name}"
        assert rc.zupt_rejected == c.zupt_rejected
        if not smooth:
            np.testing.assert_array_equal(rc._s, c._s, err_msg=f"{what}: run == step (the whole buffer)")
            for name in ("velocity", "gravity", "acceleration", "specific_force", "speed"):
                np.testing.assert_array_equal([getattr(e, name) for e in stream], getattr(tc, name),
                                              err_msg=f"{what}: stream == run, {name}")
            forward = tc
        else:                           # the smoother's forces: the same frame_forces on the smoothed gravity
            np.testing.assert_array_equal(tc.cumulative, forward.cumulative)
            assert not np.array_equal(tc.gravity, forward.gravity)
    return c


@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("with_speed", [False, True], ids=["imu only", "speed aided"])
def test_stream_equals_run_on_synthetic_frames(config, with_speed):
    em = _synthetic()
    f = _stream_equals_run(em, _speed(len(em)) if with_speed else None, CONFIGS[config], config)
    assert f.zupt_rejected >= (0 if with_speed else 1)


@pytest.mark.parametrize("drive", KITTI)
def test_stream_equals_run_on_kitti_drives(shared_data, drive):
    from imu_ground.datasets import read_kitti_imu100
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imu = read_kitti_imu100(shared_data / "kitti_imu100" / f"{drive}.csv.gz")
    em = _head(imu_to_egomotion(imu), 1500)
    assert len(em) > 100
    kw = dict(extrinsic=Extrinsic(so3.rotz(0.02), [0.0, 0.3, 0.9]), lever_arm=[0.0, 0.3, 0.9])
    ref = GravityVelocityFilter(**kw).run(em)
    speed = ref.speed + 0.3
    speed[::3] = np.nan
    _stream_equals_run(em, speed, kw, drive + " with speed")


def test_to_body_is_the_vectorised_to_body():
    f = GravityVelocityFilter(**CONFIGS["extrinsic, lever arm"])
    em = _synthetic()
    for k in range(0, len(em), 7):
        d9, dv = em.delta_R[k].ravel().tolist(), em.delta_v[k].tolist()
        got = gravity_kernel.to_body(f._s, d9, dv)
        assert got == f.to_body_flat(d9, dv)
        np.testing.assert_array_equal(np.reshape(got[0], (3, 3)), f.to_body(em.delta_R[k], em.delta_v[k])[0])
        np.testing.assert_array_equal(got[1], f.to_body(em.delta_R[k], em.delta_v[k])[1])
    plain = GravityVelocityFilter()._s
    assert gravity_kernel.to_body(plain, d9, dv) == (tuple(d9), tuple(dv))    # no extrinsic: unchanged


def test_run_continues_the_stream_and_pieces_equal_the_whole():
    em = _synthetic()
    sp = _speed(len(em))
    kw = CONFIGS["extrinsic, lever arm"]
    whole = GravityVelocityFilter(**kw)
    tw = whole.run(em, speed=sp)
    parts = GravityVelocityFilter(**kw)
    cut = 211
    for k in range(cut):
        parts.step(em.frame_at(k), speed=sp[k])
    rest = EgoMotion(em.t[cut:], em.delta_R[cut:], em.delta_v[cut:], em.delta_t[cut:], em.stationary[cut:],
                     em.valid[cut:])
    tr = parts.run(rest, speed=sp[cut:])
    for name in ("velocity", "gravity", "acceleration", "P", "cumulative"):
        np.testing.assert_array_equal(getattr(tr, name), getattr(tw, name)[cut:], err_msg=name)
    np.testing.assert_array_equal(parts._s, whole._s)


def test_full_covariance_layout():
    tc = GravityVelocityFilter().run(_head(_synthetic(), 40))
    np.testing.assert_array_equal(tc.P, np.swapaxes(tc.P, 1, 2))
    assert np.all(tc.P[:, 0, 3] != 0) and np.all(tc.P[:, 1, 2] != 0)     # the cross terms are filled
    assert np.all(np.linalg.eigvalsh(tc.P) > 0)


def test_empty_run_and_state_arrays_set_by_the_caller():
    em = _head(_synthetic(), 30)
    f, g = GravityVelocityFilter(), GravityVelocityFilter()
    t0 = f.run(_head(em, 0))
    assert t0.velocity.shape == (0, 3) and t0.P.shape == (0, 6, 6)
    f.step(em.frame_at(0))
    g.step(em.frame_at(0))
    f.x[3:] = [0.0, 0.0, 9.80665]                      # in place, seen by the next frame
    f.P = 2.0 * f.P
    f.cumulative = so3.rotz(0.1)
    tf, tg = f.run(em), g.run(em)
    assert not np.array_equal(tf.gravity, tg.gravity) and not np.array_equal(tf.cumulative, tg.cumulative)
    np.testing.assert_allclose(so3.rotz(0.1) @ em.delta_R[0], tf.cumulative[0], atol=1e-15)


def test_bad_dt_leaves_the_state():
    s = GravityVelocityFilter()._s
    d9, dv = np.eye(3).ravel().tolist(), [0.0, 0.0, 0.981]
    for dt in (0.0, -0.1, np.nan):
        for step in (gravity_kernel.step_frame, gravity_kernel.step_sensor):
            with pytest.raises(ValueError, match="dt must be > 0"):
                step(s, d9, dv, dt, False, True, None)
    assert s[36] == 0.0                                    # nothing was processed
    gravity_kernel.step_frame(s, np.eye(3), np.array(dv), 0.1, False, True, 3.0)    # arrays are fine too
    assert s[36] == 1.0
    out = np.full(12, np.nan)
    v = gravity_kernel.step_frame(s, d9, dv, 0.1, False, True, None, out)
    np.testing.assert_array_equal(out[:6], s[:6])
    assert v == np.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) and np.all(np.isfinite(out))


def test_runs_in_threads_equal_one_run():
    """The compiled run releases the GIL: concurrent runs on their own filters give the single run's numbers."""
    from concurrent.futures import ThreadPoolExecutor
    em = _synthetic()
    kw = CONFIGS["extrinsic, lever arm"]

    def one(_):
        return GravityVelocityFilter(**kw).run(em, speed=_speed(len(em)))
    ref = one(0)
    with ThreadPoolExecutor(4) as pool:
        tracks = list(pool.map(one, range(8)))
    for tr in tracks:
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(tr, name), getattr(ref, name), err_msg=name)
