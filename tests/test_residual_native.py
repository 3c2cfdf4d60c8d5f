"""The compiled residual kernel (``_residual_native.c``) against its pure-Python reference (``residual.py``).

Both twins are run side by side on the same inputs: synthetic frames that visit
every branch of the kernel (the four Shepperd branches, identity, half turns
with and without a heading twist, the sign flips, tilt inputs small and large,
the up-measurement, the cumulative rotation, an extrinsic, the re-normalisation
every RENORM_EVERY frames, zero process noise), bad frames, bad inputs, and real
KITTI drives through both filters. Skipped when the extension is not built or
``IMU_GROUND_PURE_PYTHON`` is set (test_native.py is what fails then).
"""
from __future__ import annotations

import sys
import tracemalloc
import warnings
from dataclasses import replace

import numpy as np
import pytest

from imu_ground import so3
from imu_ground._native import assert_twins_equal
from imu_ground.filters import residual
from imu_ground.filters.frame_checks import BAD_DELTA_T, BAD_DELTA_V, BAD_ROTATION, frame_status
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.residual import BUF_LEN, PYTHON, ResidualKernel
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.units import RENORM_EVERY

C = residual.NATIVE
pytestmark = pytest.mark.skipif(C is None, reason="the compiled residual kernel is not built or switched off")

RGS = so3.exp_one(np.array([0.02, -0.03, 1.2]))
CONFIGS = {
    "rotation": {},
    "up": {"up": True},
    "random walk": {"follow_heading": False},
    "cumulative": {"cumulative": True},
    "extrinsic, cumulative": {"Rgs": RGS, "cumulative": True},
    "up, extrinsic, cumulative, random walk": {"up": True, "Rgs": RGS, "cumulative": True, "follow_heading": False},
}


def _half_turn(axis) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return 2.0 * np.outer(a, a) - np.eye(3)


def synthetic_frames(n: int = 3 * RENORM_EVERY + 7, seed: int = 0) -> np.ndarray:
    """Increments (n, 3, 3) mixing driving-like small rotations with every special case of the kernel."""
    rng = np.random.default_rng(seed)
    small = so3.exp(rng.normal(scale=[0.004, 0.004, 0.03], size=(n, 3)))
    special = [np.eye(3)] + [_half_turn(ax) for ax in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 2, 3])]
    # large angles, trace <= 0: the three off-trace Shepperd branches, whichever diagonal is largest
    special += [so3.exp_one(ang * np.asarray(ax, dtype=float) / np.linalg.norm(ax))
                for ang in (2.2, 2.9, np.pi - 1e-9) for ax in ([1, 0.1, 0.2], [0.1, 1, 0.2], [0.1, 0.2, 1])]
    special += [so3.exp_one(v) for v in rng.normal(scale=1.5, size=(12, 3))]
    d = small.copy()
    idx = rng.choice(np.arange(1, n), size=len(special), replace=False)
    d[idx] = special
    return np.ascontiguousarray(d)


def _trace_branches(d: np.ndarray) -> set:
    tr = np.trace(d, axis1=1, axis2=2)
    out = set()
    for r, t in zip(d, tr, strict=True):
        out.add("trace" if t > 0 else ("x" if r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2] else
                                       "y" if r[1, 1] >= r[2, 2] else "z"))
    return out


def _pair(**cfg):
    return (ResidualKernel(0.7, 0.9, 0.05, 0.002, native=True, **cfg),
            ResidualKernel(0.7, 0.9, 0.05, 0.002, native=False, **cfg))


def _inputs(n: int, seed: int = 1, zero_noise: bool = False):
    rng = np.random.default_rng(seed)
    q = np.zeros(n) if zero_noise else rng.uniform(1e-6, 1e-3, n)
    tilt = rng.normal(scale=0.01, size=(2, n))
    tilt[:, ::5] = 0.0                           # exactly zero tilt
    tilt[:, 3::7] *= 1e-3                        # |b| < 1e-4: the series branch
    tilt[:, 4::11] = rng.normal(scale=1.0, size=(2, len(tilt[0, 4::11])))   # large tilt
    return q, tilt


def test_synthetic_frames_visit_every_shepperd_branch():
    assert _trace_branches(synthetic_frames()) == {"trace", "x", "y", "z"}


@pytest.mark.parametrize("tilted", [False, True], ids=["no tilt", "tilt"])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_step_matches_python_frame_by_frame(name, tilted):
    d = synthetic_frames()
    q, tilt = _inputs(len(d))
    kc, kp = _pair(**CONFIGS[name])
    for k in range(len(d)):
        tx, ty = (float(tilt[0, k]), float(tilt[1, k])) if tilted else (None, None)
        oc = C.step(kc.buf, d[k], float(q[k]), 1e-4, tx, ty, None, 1.0)
        op = PYTHON.step(kp.buf, d[k], float(q[k]), 1e-4, tx, ty, None, 1.0)
        assert len(oc) == len(op) == (12 if CONFIGS[name].get("cumulative") else 8)
        assert_twins_equal(oc, op, f"step {k}")
    assert_twins_equal(np.array(kc.buf), np.array(kp.buf), "state")
    assert kc.frames == kp.frames == len(d)
    assert kc.last is not None
    assert_twins_equal(kc.last, kp.last, "last output")


@pytest.mark.parametrize("zero_noise", [False, True], ids=["noise", "zero process noise"])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_run_matches_python_and_the_stream(name, zero_noise):
    d = synthetic_frames(seed=4)
    q, tilt = _inputs(len(d), seed=5, zero_noise=zero_noise)
    kc, kp = _pair(**CONFIGS[name])
    oc = kc.run(d, q, 1e-4, tilt[0], tilt[1], angles=True)
    op = kp.run(d, q, 1e-4, tilt[0], tilt[1], angles=True)
    assert oc.shape == op.shape == (len(d), kc.width)
    assert_twins_equal(oc, op, "run")
    assert_twins_equal(np.array(kc.buf), np.array(kp.buf), "state")
    # streaming == batch: the same C kernel frame by frame gives the same rows, bit for bit
    ks = ResidualKernel(0.7, 0.9, 0.05, 0.002, native=True, **CONFIGS[name])
    rows = [C.step(ks.buf, d[k], float(q[k]), 1e-4, float(tilt[0, k]), float(tilt[1, k]), None, 1.0)
            for k in range(len(d))]
    np.testing.assert_array_equal(np.array(rows), oc)
    np.testing.assert_array_equal(np.array(ks.buf), np.array(kc.buf))


def test_run_without_angles_and_with_a_constant_noise():
    d = synthetic_frames(seed=6)
    kc, kp = _pair(cumulative=True)
    oc, op = kc.run(d, 3e-4, 1e-4), kp.run(d, 3e-4, 1e-4)
    assert np.isnan(oc[:, 6:8]).all()
    assert_twins_equal(oc, op, "run without angles")
    assert kc.run(d[:0], 3e-4, 1e-4).shape == (0, 12) and kc.frames == len(d)


def test_renormalisation_keeps_the_quaternions_unit():
    d = synthetic_frames(n=10 * RENORM_EVERY, seed=7)
    kc, _ = _pair(cumulative=True)
    o = kc.run(d, 1e-4, 1e-4)
    at = np.arange(RENORM_EVERY - 1, len(d), RENORM_EVERY)
    for cols in (slice(0, 4), slice(8, 12)):
        norms = np.linalg.norm(o[:, cols], axis=1)
        assert np.abs(norms[at] - 1.0).max() <= 2e-16 * 4
        assert np.abs(norms - 1.0).max() < 1e-12


def test_the_kernel_twin_is_the_reference_loop():
    """PYTHON.run is residual.advance (the documented reference) on the same buffer layout."""
    d = synthetic_frames(seed=8)
    q, tilt = _inputs(len(d), seed=9)
    kc, kp = _pair()
    rows = kp.advance(d.reshape(-1, 9).tolist(), q.tolist(), 1e-4, tilt[0].tolist(), tilt[1].tolist())
    assert_twins_equal(kc.run(d, q, 1e-4, tilt[0], tilt[1], angles=True), np.array(rows), "run against advance")
    assert len(kc.buf) == BUF_LEN == C.BUF_LEN


# ----------------------------------------------------------------------------------- bad frames and bad inputs
_GOOD = so3.exp_one(np.array([0.01, -0.02, 0.3]))
BAD = {
    "not orthonormal": (_GOOD * 1.001, None, 0.1, BAD_ROTATION),
    "reflection": (_GOOD @ np.diag([1.0, 1.0, -1.0]), None, 0.1, BAD_ROTATION),
    "NaN": (np.where(np.eye(3) > 0, np.nan, _GOOD), None, 0.1, BAD_ROTATION),
    "inf": (np.full((3, 3), np.inf), None, 0.1, BAD_ROTATION),
    "delta_v NaN": (_GOOD, np.array([0.0, np.nan, 0.0]), 0.1, BAD_DELTA_V),
    "delta_v overflow": (_GOOD, np.array([1e308, 1e308, 0.0]), 0.1, BAD_DELTA_V),
    "delta_t zero": (_GOOD, np.zeros(3), 0.0, BAD_DELTA_T),
    "delta_t negative": (_GOOD, None, -0.05, BAD_DELTA_T),
    "delta_t NaN": (_GOOD, None, float("nan"), BAD_DELTA_T),
    "delta_t inf": (_GOOD, None, float("inf"), BAD_DELTA_T),
    "good": (_GOOD, np.array([0.1, 0.0, 0.0]), 0.1, 0),
    "good, slightly off": (_GOOD + 2e-7 * np.eye(3), None, 0.1, 0),
}


@pytest.mark.parametrize("kind", list(BAD))
def test_frame_check_matches_and_a_bad_frame_leaves_the_state(kind):
    d, dv, dt, expected = BAD[kind]
    d = np.ascontiguousarray(d)
    assert C.check(d, dv, dt) == PYTHON.check(d, dv, dt) == expected
    assert frame_status(d.ravel().tolist(), None if dv is None else dv.tolist(), dt) == expected
    kc, kp = _pair(cumulative=True)
    C.step(kc.buf, _GOOD, 1e-4, 1e-4, None, None, None, 1.0)
    PYTHON.step(kp.buf, _GOOD, 1e-4, 1e-4, None, None, None, 1.0)
    before = np.array(kc.buf)
    oc = C.step(kc.buf, d, 1e-4, 1e-4, None, None, dv, dt)
    op = PYTHON.step(kp.buf, d, 1e-4, 1e-4, None, None, dv, dt)
    if expected:
        assert_twins_equal(oc, op, "status")
        assert oc == expected and type(oc) is int
        np.testing.assert_array_equal(np.array(kc.buf), before)
    else:
        assert isinstance(oc, tuple)
        assert_twins_equal(oc, op, "step")


def test_batch_check_matches_the_streaming_check(monkeypatch):
    """check_many flags exactly the frames check (and the Python frame_status) flags; the numpy fallback
    of frame_checks.frame_statuses agrees on them."""
    from imu_ground.filters import frame_checks
    d = np.concatenate([synthetic_frames(seed=10)] + [np.ascontiguousarray(BAD[k][0])[None] for k in BAD])
    n = len(d)
    dv = np.zeros((n, 3))
    dt = np.full(n, 0.1)
    for i, k in enumerate(BAD, start=n - len(BAD)):
        dv[i] = 0.0 if BAD[k][1] is None else BAD[k][1]
        dt[i] = BAD[k][2]
    out = np.full(n, 255, dtype=np.uint8)
    bad = C.check_many(d, dv, dt, out)
    expected = [frame_status(d[k].ravel().tolist(), dv[k].tolist(), float(dt[k])) for k in range(n)]
    assert out.tolist() == expected and bad == sum(e != 0 for e in expected) == 10
    assert [C.check(d[k], dv[k], dt[k]) for k in range(n)] == expected
    assert frame_checks.frame_statuses(d, dv, dt).tolist() == expected
    monkeypatch.setattr(frame_checks, "_NATIVE", None)
    assert frame_checks.frame_statuses(d, dv, dt).tolist() == expected
    with pytest.raises(ValueError, match=rf"frame index {n - len(BAD)}, t = .*; 10 bad of {n}\): delta_R is not a rot"):
        frame_checks.checked_frames(d, dv, dt, np.arange(n) * 0.1, "raise")


@pytest.mark.parametrize("impl", ["C", "Python"])
def test_bad_inputs_raise_what_the_filters_catch(impl):
    k = ResidualKernel(1.0, 1.0, 0.1, 0.1, native=impl == "C")
    step, eye = k.impl.step, np.eye(3)
    with pytest.raises(TypeError, match="delta_R"):
        step(k.buf, eye.tolist(), 1e-4, 1e-4, None, None, None, 1.0)
    with pytest.raises(TypeError, match="delta_R"):
        step(k.buf, eye.astype(np.float32), 1e-4, 1e-4, None, None, None, 1.0)
    if impl == "C":                              # (the Python twin reads any layout)
        with pytest.raises(TypeError, match="delta_R"):
            step(k.buf, np.asfortranarray(_GOOD), 1e-4, 1e-4, None, None, None, 1.0)
    with pytest.raises(ValueError, match="delta_R"):
        step(k.buf, np.eye(4), 1e-4, 1e-4, None, None, None, 1.0)
    with pytest.raises(ValueError, match="delta_R"):
        step(k.buf, eye[None], 1e-4, 1e-4, None, None, None, 1.0)
    with pytest.raises(ValueError, match="delta_v"):
        step(k.buf, eye, 1e-4, 1e-4, None, None, np.zeros(4), 1.0)
    with pytest.raises(TypeError, match="delta_v"):
        step(k.buf, eye, 1e-4, 1e-4, None, None, [0.0, 0.0, 0.0], 1.0)
    assert k.frames == 0


def test_the_compiled_entry_points_check_their_buffers():
    eye = np.eye(3)
    with pytest.raises(ValueError, match="buf"):
        C.step(np.zeros(BUF_LEN - 1), eye, 1e-4, 1e-4, None, None, None, 1.0)
    with pytest.raises(TypeError, match="buf"):
        C.step(bytes(8 * BUF_LEN), eye, 1e-4, 1e-4, None, None, None, 1.0)       # read-only
    with pytest.raises(TypeError, match="8 arguments"):
        C.step(np.zeros(BUF_LEN), eye)
    k = ResidualKernel(1.0, 1.0, 0.1, 0.1, cumulative=True, native=True)
    d = synthetic_frames()[:10]
    with pytest.raises(ValueError, match="out"):
        C.run(k.buf, d, 1e-4, 1e-4, None, None, np.empty((10, 8)), False)
    with pytest.raises(ValueError, match="q_h"):
        C.run(k.buf, d, np.zeros(9), 1e-4, None, None, np.empty((10, 12)), False)
    with pytest.raises(ValueError, match="delta_R"):
        C.run(k.buf, np.zeros(10), 1e-4, 1e-4, None, None, np.empty((0, 12)), False)
    assert k.frames == 0


def test_no_leaks_over_many_calls():
    k = ResidualKernel(1.0, 1.0, 0.1, 0.1, cumulative=True, native=True)
    d, dv, buf = _GOOD, np.zeros(3), k.buf
    bad = BAD["NaN"][0]
    refs = [sys.getrefcount(x) for x in (d, dv, buf, bad)]
    for _ in range(1000):                        # warm up (free lists, caches)
        C.step(buf, d, 1e-6, 1e-6, 0.001, 0.002, dv, 0.1)
    tracemalloc.start()
    try:
        snap0 = tracemalloc.take_snapshot()
        for _ in range(100_000):
            C.step(buf, d, 1e-6, 1e-6, 0.001, 0.002, dv, 0.1)
            C.step(buf, bad, 1e-6, 1e-6, None, None, None, 1.0)
            C.check(d, dv, 0.1)
        grown = sum(s.size_diff for s in tracemalloc.take_snapshot().compare_to(snap0, "filename"))
    finally:
        tracemalloc.stop()
    assert grown < 10_000
    assert [sys.getrefcount(x) for x in (d, dv, buf, bad)] == refs
    # the many-frame entries, with and without errors: every buffer they take is released
    frames, q, out, status = synthetic_frames()[:20], np.full(20, 1e-6), np.empty((20, 12)), np.empty(20, np.uint8)
    arrays = (frames, q, out, status, buf)
    refs = [sys.getrefcount(x) for x in arrays]
    for _ in range(2000):
        C.run(buf, frames, q, 1e-6, q, q, out, True)
        C.check_many(frames, None, q, status)
        with pytest.raises(ValueError):
            C.run(buf, frames, q, 1e-6, q, q[:5], out, True)
        with pytest.raises(ValueError):
            C.check_many(frames, None, q, status[:5])
    assert [sys.getrefcount(x) for x in arrays] == refs


# ----------------------------------------------------------------------------------- real drives, whole filters
@pytest.fixture(scope="module")
def kitti(shared_data):
    from imu_ground.datasets import read_kitti_imu100
    from imu_ground.imu import imu_to_egomotion
    out = []
    for name in ("2011_09_26_drive_0009", "2011_09_30_drive_0016", "2011_10_03_drive_0042"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            em = imu_to_egomotion(read_kitti_imu100(shared_data / "kitti_imu100" / f"{name}.csv.gz"))
        n = min(len(em), 3000)
        out.append(replace(em, t=em.t[:n], delta_R=em.delta_R[:n], delta_v=em.delta_v[:n], delta_t=em.delta_t[:n],
                           stationary=em.stationary[:n], valid=em.valid[:n]))
    return out


def _python_kernel(monkeypatch):
    monkeypatch.setattr(residual, "NATIVE", None)


FILTERS = {
    "GroundNormalFilter": GroundNormalFilter,
    "GroundNormalFilter up, extrinsic": lambda: GroundNormalFilter(measurement="up", extrinsic=RGS),
    "GroundNormalFilter.paper": GroundNormalFilter.paper,
    "SuspensionAwareFilter": SuspensionAwareFilter,
    "SuspensionAwareFilter extrinsic, online gains": lambda: SuspensionAwareFilter(extrinsic=RGS, online_gains=True),
}


@pytest.mark.parametrize("name", list(FILTERS))
def test_filters_on_kitti_equal_with_either_kernel(kitti, name, monkeypatch):
    make = FILTERS[name]
    for em in kitti:
        fc = make()
        assert fc._kernel.native
        tc = fc.run(em)
        sc = [make().step(fr) for fr in list(em.frames())[:1]]      # a fresh one-frame stream
        with monkeypatch.context() as m:
            _python_kernel(m)
            fp = make()
            assert not fp._kernel.native
            tp = fp.run(em)
            sp = [make().step(fr) for fr in list(em.frames())[:1]]
        for field in ("normal", "pitch", "roll", "residual", "P", "x"):
            assert_twins_equal(getattr(tc, field), getattr(tp, field), field)
        assert_twins_equal(sc[0].normal, sp[0].normal, "one step's normal")


@pytest.mark.parametrize("name", list(FILTERS))
def test_streaming_equals_batch_on_kitti(kitti, name):
    make = FILTERS[name]
    em = kitti[0]
    tb = make().run(em)
    f = make()
    est = [f.step(fr) for fr in em.frames()]
    np.testing.assert_allclose(np.array([e.normal for e in est]), tb.normal, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array([e.pitch for e in est]), tb.pitch, rtol=0, atol=1e-12)
    np.testing.assert_allclose(est[-1].residual, tb.residual[-1], rtol=0, atol=1e-12)
