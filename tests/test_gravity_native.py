"""The gravity/velocity filter's C kernel (``_gravity_native``) against its pure-Python twin (``gravity_kernel``).

Both kernels run in the same process (``GravityVelocityFilter.kernel`` set per instance),
held to the twin rule (:func:`imu_ground._native.assert_twins_equal`), streaming and batch,
on real KITTI drives and on synthetic frames
with standstills, gated standstill flags, gaps, speed-aided frames with NaN speed, a
lever arm and an extrinsic, the small-angle and near-pi branches of the rotation
log/exp, zero process noise; streaming == batch; the smoother's path; the C entry
points' argument errors and their reference counting.
"""
from __future__ import annotations

import sys
import tracemalloc
import warnings

import numpy as np
import pytest

from imu_ground import so3
from imu_ground._native import GRAVITY as NATIVE
from imu_ground._native import assert_twins_equal
from imu_ground.filters import gravity_kernel
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion

pytestmark = pytest.mark.skipif(NATIVE is None, reason="the C kernel is not built (or IMU_GROUND_PURE_PYTHON=1)")

FIELDS = ("velocity", "gravity", "acceleration", "specific_force", "speed", "P", "cumulative", "body_increments")
KITTI = ("2011_09_26_drive_0009", "2011_09_28_drive_0039", "2011_09_30_drive_0016")


def _pair(**kw):
    """The same filter on the C and on the Python kernel."""
    c, p = GravityVelocityFilter(**kw), GravityVelocityFilter(**kw)
    c.kernel, p.kernel = NATIVE, gravity_kernel
    c.reset()
    p.reset()
    assert type(c._s) is np.ndarray and type(p._s) is list
    return c, p


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


def _compare_everything(em, speed, kw, what):
    """C against Python, step and run (also with the smoother): the twin rule; C step == C run bit for bit
    (one kernel for both)."""
    c, p = _pair(**kw)
    n = len(em)
    sp = [None] * n if speed is None else speed
    stream = []
    for k in range(n):
        fr = (em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
        ec, ep = c.step(*fr, speed=sp[k]), p.step(*fr, speed=sp[k])
        for name in ("velocity", "gravity", "acceleration", "specific_force", "speed"):
            assert_twins_equal(getattr(ec, name), getattr(ep, name), f"{what}: step {k} {name}")
        assert_twins_equal(c._s[:66], p._s[:66], f"{what}: state after step {k}")
        stream.append(ec)
    for name in ("x", "P", "cumulative", "x_prior", "P_prior", "F", "Q", "H", "R", "K", "y", "S"):
        assert_twins_equal(getattr(c, name), getattr(p, name), f"{what}: {name}")
    assert c.zupt_rejected == p.zupt_rejected
    for smooth in (False, True):
        rc, rp = _pair(**kw)
        tc, tp = rc.run(em, smooth=smooth, speed=speed), rp.run(em, smooth=smooth, speed=speed)
        for name in FIELDS:
            assert_twins_equal(getattr(tc, name), getattr(tp, name), f"{what}: run(smooth={smooth}) {name}")
        assert_twins_equal(rc._s[:66], rp._s[:66], f"{what}: state after run")
        assert_twins_equal(rc.K, rp.K, f"{what}: K after run")
        assert rc.zupt_rejected == c.zupt_rejected
        if not smooth:                  # one C kernel for both: streaming == batch bit for bit
            np.testing.assert_array_equal(rc._s, c._s, err_msg=f"{what}: C run == C step (the whole buffer)")
            for name in ("velocity", "gravity", "acceleration", "specific_force", "speed"):
                np.testing.assert_array_equal([getattr(e, name) for e in stream], getattr(tc, name),
                                              err_msg=f"{what}: C stream == C run, {name}")
    return c


@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("with_speed", [False, True], ids=["imu only", "speed aided"])
def test_c_equals_python_on_synthetic_frames(config, with_speed):
    em = _synthetic()
    f = _compare_everything(em, _speed(len(em)) if with_speed else None, CONFIGS[config], config)
    assert f.zupt_rejected >= (0 if with_speed else 1)


@pytest.mark.parametrize("drive", KITTI)
def test_c_equals_python_on_kitti_drives(shared_data, drive):
    from imu_ground.datasets import read_kitti_imu100
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imu = read_kitti_imu100(shared_data / "kitti_imu100" / f"{drive}.csv.gz")
    em = imu_to_egomotion(imu)
    assert len(em) > 100
    kw = dict(extrinsic=Extrinsic(so3.rotz(0.02), [0.0, 0.3, 0.9]), lever_arm=[0.0, 0.3, 0.9])
    _compare_everything(em, None, kw, drive)
    ref = GravityVelocityFilter(**kw).run(em)
    speed = ref.speed + 0.3
    speed[::3] = np.nan
    _compare_everything(em, speed, kw, drive + " with speed")


def test_to_body_c_equals_python():
    c, p = _pair(**CONFIGS["extrinsic, lever arm"])
    em = _synthetic()
    for k in range(0, len(em), 7):
        d9, dv = em.delta_R[k].ravel().tolist(), em.delta_v[k].tolist()
        got = NATIVE.to_body(c._s, d9, dv)
        for part, py in zip(got, gravity_kernel.to_body(p._s, d9, dv), strict=True):
            assert_twins_equal(part, py, "to_body")
        assert got == c.to_body_flat(d9, dv)
        np.testing.assert_array_equal(np.reshape(got[0], (3, 3)), c.to_body(em.delta_R[k], em.delta_v[k])[0])
    plain = _state()
    assert NATIVE.to_body(plain, d9, dv) == (tuple(d9), tuple(dv))    # no extrinsic: unchanged


def test_run_continues_the_stream_and_pieces_equal_the_whole():
    em = _synthetic()
    sp = _speed(len(em))
    kw = CONFIGS["extrinsic, lever arm"]
    whole = GravityVelocityFilter(**kw)
    whole.kernel = NATIVE
    whole.reset()
    tw = whole.run(em, speed=sp)
    parts = GravityVelocityFilter(**kw)
    parts.kernel = NATIVE
    parts.reset()
    cut = 211
    for k in range(cut):
        parts.step(em.frame_at(k), speed=sp[k])
    rest = EgoMotion(em.t[cut:], em.delta_R[cut:], em.delta_v[cut:], em.delta_t[cut:], em.stationary[cut:],
                     em.valid[cut:])
    tr = parts.run(rest, speed=sp[cut:])
    for name in ("velocity", "gravity", "acceleration", "P", "cumulative"):
        np.testing.assert_array_equal(getattr(tr, name), getattr(tw, name)[cut:], err_msg=name)
    np.testing.assert_array_equal(parts._s, whole._s)


def test_full_covariance_layout_matches_the_python_index():
    c, p = _pair()
    em = _head(_synthetic(), 40)
    tc, tp = c.run(em), p.run(em)
    np.testing.assert_array_equal(tc.P, np.swapaxes(tc.P, 1, 2))
    assert_twins_equal(tc.P, tp.P, "P")
    assert np.all(tc.P[:, 0, 3] != 0) and np.all(tc.P[:, 1, 2] != 0)     # the cross terms are filled


def test_empty_run_and_state_arrays_set_by_the_caller():
    c, p = _pair()
    em = _head(_synthetic(), 30)
    for f in (c, p):
        t0 = f.run(_head(em, 0))
        assert t0.velocity.shape == (0, 3) and t0.P.shape == (0, 6, 6)
        f.step(em.frame_at(0))
        f.x[3:] = [0.0, 0.0, 9.80665]                      # in place, seen by the next frame
        f.P = 2.0 * f.P
        f.cumulative = so3.rotz(0.1)
    tc, tp = c.run(em), p.run(em)
    for name in FIELDS:
        assert_twins_equal(getattr(tc, name), getattr(tp, name), name)


# ------------------------------------------------------------------------------------- the C entry points
def _state():
    f = GravityVelocityFilter()
    f.kernel = NATIVE
    f.reset()
    return f._s


def test_argument_errors_name_the_argument():
    s = _state()
    d9, dv = np.eye(3).ravel().tolist(), [0.0, 0.0, 0.981]
    with pytest.raises(ValueError, match="state must have 126 items"):
        NATIVE.step_frame(s[:-1].copy(), d9, dv, 0.1, False, True, None)
    with pytest.raises(TypeError, match="state must hold float64"):
        NATIVE.step_frame(s.astype(np.float32), d9, dv, 0.1, False, True, None)
    with pytest.raises(TypeError, match="state"):
        NATIVE.step_frame(list(s), d9, dv, 0.1, False, True, None)
    with pytest.raises(ValueError, match="d9 must have 9 floats"):
        NATIVE.step_frame(s, d9[:8], dv, 0.1, False, True, None)
    with pytest.raises(TypeError, match=r"dv3\[1\] must be a float"):
        NATIVE.step_frame(s, d9, [0.0, "x", 1.0], 0.1, False, True, None)
    with pytest.raises(TypeError, match="expects 7 or 8 arguments"):
        NATIVE.step_sensor(s, d9, dv, 0.1)
    with pytest.raises(ValueError, match="out must have 12 items"):
        NATIVE.step_sensor(s, d9, dv, 0.1, False, True, None, np.empty(11))
    with pytest.raises(TypeError):
        NATIVE.step_frame(s, d9, dv, "0.1", False, True, None)
    p = GravityVelocityFilter()
    p.kernel = gravity_kernel
    p.reset()
    for dt in (0.0, -0.1, np.nan):
        for k in (NATIVE.step_frame, NATIVE.step_sensor):
            with pytest.raises(ValueError, match="dt must be > 0"):
                k(s, d9, dv, dt, False, True, None)
        with pytest.raises(ValueError, match="dt must be > 0"):
            gravity_kernel.step_sensor(p._s, d9, dv, dt, False, True, None)
    assert p._s[36] == 0.0
    assert s[36] == 0.0                                    # nothing was processed
    NATIVE.step_frame(s, np.eye(3).ravel(), np.array(dv), 0.1, False, True, 3.0)    # buffers are fine too
    assert s[36] == 1.0
    out = np.full(12, np.nan)
    v = NATIVE.step_frame(s, d9, dv, 0.1, False, True, None, out)
    np.testing.assert_array_equal(out[:6], s[:6])
    assert v == np.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) and np.all(np.isfinite(out))
    assert s[36] == 2.0
    s[36] = 1.0
    n = 5
    out = [np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 6, 6)), np.empty((n, 3, 3)), np.empty((n, 3)),
           np.empty((n, 3)), np.empty(n), None, None]
    ins = [np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), np.full(n, 0.1), np.zeros(n, bool), np.ones(n, bool), None]
    with pytest.raises(ValueError, match="dv must have 15 items"):
        NATIVE.run_frames(s, ins[0], np.zeros((n, 2)), *ins[2:], *out)
    with pytest.raises(TypeError, match="stationary must hold bool"):
        NATIVE.run_frames(s, *ins[:3], np.zeros(n), *ins[4:], *out)
    with pytest.raises(TypeError, match="writable"):
        ro = np.empty((n, 3))
        ro.flags.writeable = False
        NATIVE.run_frames(s, *ins, ro, *out[1:])
    with pytest.raises(TypeError, match="run_frames expects 16 arguments"):
        NATIVE.run_frames(s, *ins)
    assert s[36] == 1.0
    NATIVE.run_frames(s, *ins, *out)
    assert s[36] == 1.0 + n


def test_no_leaks_and_reference_counts_unchanged():
    s = _state()
    d9, dv = so3.exp(np.array([0.01, -0.02, 0.03])).ravel().tolist(), [0.1, 0.0, 0.981]
    dt, speed = 0.1, 4.0
    n = 5
    ins = [np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), np.full(n, 0.1), np.zeros(n, bool), np.ones(n, bool),
           np.full(n, 2.0)]
    outs = [np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 6, 6)), np.empty((n, 3, 3)), np.empty((n, 3)),
            np.empty((n, 3)), np.empty(n), np.empty((n, 27)), np.empty((n, 3, 3))]
    watched = [s, d9, dv, dt, speed, *ins, *outs]
    before = [sys.getrefcount(o) for o in watched]
    for _ in range(1000):                                  # warm up the allocators
        NATIVE.step_sensor(s, d9, dv, dt, False, True, speed)
    tracemalloc.start()
    try:
        snap = tracemalloc.take_snapshot()
        e = np.empty(12)
        for _ in range(100_000):
            NATIVE.step_sensor(s, d9, dv, dt, False, True, speed)
            NATIVE.step_sensor(s, d9, dv, dt, True, False, None, e)
            NATIVE.to_body(s, d9, dv)
        for _ in range(1000):
            NATIVE.run_frames(s, *ins, *outs)
        for _ in range(1000):                              # error paths release what they took
            with pytest.raises(ValueError):
                NATIVE.run_frames(s, ins[0], ins[1], ins[2], ins[3], ins[4], np.ones(n + 1), *outs)
        grown = sum(st.size_diff for st in tracemalloc.take_snapshot().compare_to(snap, "filename"))
    finally:
        tracemalloc.stop()
    assert grown < 64 * 1024, f"{grown} bytes kept after 1e5 steps"
    assert [sys.getrefcount(o) for o in watched] == before


def test_runs_in_threads_equal_one_run():
    """run_frames releases the GIL: concurrent runs on their own filters give the single run's numbers."""
    from concurrent.futures import ThreadPoolExecutor
    em = _synthetic()
    kw = CONFIGS["extrinsic, lever arm"]

    def one(_):
        f = GravityVelocityFilter(**kw)
        f.kernel = NATIVE
        f.reset()
        return f.run(em, speed=_speed(len(em)))
    ref = one(0)
    with ThreadPoolExecutor(4) as pool:
        tracks = list(pool.map(one, range(8)))
    for tr in tracks:
        for name in FIELDS:
            np.testing.assert_array_equal(getattr(tr, name), getattr(ref, name), err_msg=name)
