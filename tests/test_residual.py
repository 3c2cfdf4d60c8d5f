"""The residual kernel (``filters/residual.py``): one body, :func:`~imu_ground.filters.residual.frame`, for a
streamed frame and a batch.

Synthetic frames visit every branch of the kernel (the four Shepperd branches,
identity, half turns with and without a heading twist, the sign flips, tilt
inputs small and large, the up-measurement, the cumulative rotation, an
extrinsic, the re-normalisation every RENORM_EVERY frames, zero process noise);
then bad frames, bad inputs, and real KITTI drives through both filters. The
kernel against an independent reference (the general invariant EKF) is
``test_ground.py::test_batch_fast_path_matches_plain_invariant_ekf_loop``.
"""
from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.filters import frame_checks, residual
from imu_ground.filters.frame_checks import BAD_DELTA_T, BAD_DELTA_V, BAD_ROTATION, frame_status
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.residual import BUF_LEN, ROW_LEN, ResidualKernel
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.units import RENORM_EVERY

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


def _kernel(**cfg) -> ResidualKernel:
    return ResidualKernel(0.7, 0.9, 0.05, 0.002, **cfg)


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


@pytest.mark.parametrize("zero_noise", [False, True], ids=["noise", "zero process noise"])
@pytest.mark.parametrize("tilted", [False, True], ids=["no tilt", "tilt"])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_stream_equals_batch_bit_for_bit(name, tilted, zero_noise):
    """step (frame by frame, checked) and run (a batch) are the same body: the same rows and state."""
    d = synthetic_frames(seed=4)
    q, tilt = _inputs(len(d), seed=5, zero_noise=zero_noise)
    tx, ty = tilt if tilted else (None, None)
    kb = _kernel(**CONFIGS[name])
    ob = kb.run(d, q, 1e-4, tx, ty, angles=True)
    assert ob.shape == (len(d), kb.width) == (len(d), 12 if CONFIGS[name].get("cumulative") else 8)
    ks = _kernel(**CONFIGS[name])
    rows = [residual.step(ks.buf, d[k], float(q[k]), 1e-4, None if tx is None else float(tx[k]),
                          None if ty is None else float(ty[k]), None, 1.0) for k in range(len(d))]
    assert all(isinstance(r, tuple) and len(r) == ROW_LEN for r in rows)
    np.testing.assert_array_equal(np.array(rows)[:, :kb.width], ob)
    if not CONFIGS[name].get("cumulative"):
        assert np.isnan(np.array(rows)[:, 8:]).all()
    np.testing.assert_array_equal(ks.buf, kb.buf)
    assert ks.frames == kb.frames == len(d) and len(kb.buf) == BUF_LEN
    assert kb.last is not None and kb.last == ks.last and len(kb.last) == 11
    # the tilt changes the result (it is used), the heading noise too
    if tilted and not CONFIGS[name].get("up"):
        assert not np.allclose(_kernel(**CONFIGS[name]).run(d, q, 1e-4, angles=True)[:, :4], ob[:, :4])


def test_run_without_angles_and_with_a_constant_noise():
    d = synthetic_frames(seed=6)
    k = _kernel(cumulative=True)
    o = k.run(d, 3e-4, 1e-4)
    assert np.isnan(o[:, 6:8]).all() and np.isfinite(o[:, :6]).all()
    np.testing.assert_array_equal(o, _kernel(cumulative=True).run(d, np.full(len(d), 3e-4), 1e-4))
    assert k.run(d[:0], 3e-4, 1e-4).shape == (0, 12) and k.frames == len(d)


def test_renormalisation_keeps_the_quaternions_unit():
    d = synthetic_frames(n=10 * RENORM_EVERY, seed=7)
    o = _kernel(cumulative=True).run(d, 1e-4, 1e-4)
    at = np.arange(RENORM_EVERY - 1, len(d), RENORM_EVERY)
    for cols in (slice(0, 4), slice(8, 12)):
        norms = np.linalg.norm(o[:, cols], axis=1)
        assert np.abs(norms[at] - 1.0).max() <= 2e-16 * 4
        assert np.abs(norms - 1.0).max() < 1e-12


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
def test_frame_check_and_a_bad_frame_leaves_the_state(kind):
    d, dv, dt, expected = BAD[kind]
    d = np.ascontiguousarray(d)
    assert residual.check(d, dv, dt) == expected
    assert frame_status(d.ravel().tolist(), None if dv is None else dv.tolist(), dt) == expected
    k = _kernel(cumulative=True)
    residual.step(k.buf, _GOOD, 1e-4, 1e-4, None, None, None, 1.0)
    before = k.buf.copy()
    o = residual.step(k.buf, d, 1e-4, 1e-4, None, None, dv, dt)
    if expected:
        assert o == expected and type(o) is int
        np.testing.assert_array_equal(k.buf, before)
    else:
        assert isinstance(o, tuple) and k.frames == 2


def test_batch_check_matches_the_streaming_check():
    """frame_statuses flags exactly the frames check (and frame_status) flags."""
    d = np.concatenate([synthetic_frames(seed=10)] + [np.ascontiguousarray(BAD[k][0])[None] for k in BAD])
    n = len(d)
    dv = np.zeros((n, 3))
    dt = np.full(n, 0.1)
    for i, k in enumerate(BAD, start=n - len(BAD)):
        dv[i] = 0.0 if BAD[k][1] is None else BAD[k][1]
        dt[i] = BAD[k][2]
    expected = [frame_status(d[k].ravel().tolist(), dv[k].tolist(), float(dt[k])) for k in range(n)]
    assert sum(e != 0 for e in expected) == 10
    assert [residual.check(d[k], dv[k], dt[k]) for k in range(n)] == expected
    assert frame_checks.frame_statuses(d, dv, dt).tolist() == expected
    assert frame_checks.frame_statuses(d).tolist() == [frame_status(r.ravel().tolist()) for r in d]
    with pytest.raises(ValueError, match=rf"frame index {n - len(BAD)}, t = .*; 10 bad of {n}\): delta_R is not a rot"):
        frame_checks.checked_frames(d, dv, dt, np.arange(n) * 0.1, "raise")


def test_bad_inputs_raise_what_the_filters_catch():
    k = ResidualKernel(1.0, 1.0, 0.1, 0.1)
    step, eye = residual.step, np.eye(3)
    with pytest.raises(TypeError, match="delta_R"):
        step(k.buf, eye.tolist(), 1e-4, 1e-4, None, None, None, 1.0)
    with pytest.raises(TypeError, match="delta_R"):
        step(k.buf, eye.astype(np.float32), 1e-4, 1e-4, None, None, None, 1.0)
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


FILTERS = {
    "GroundNormalFilter": GroundNormalFilter,
    "GroundNormalFilter up, extrinsic": lambda: GroundNormalFilter(measurement="up", extrinsic=RGS),
    "GroundNormalFilter.paper": GroundNormalFilter.paper,
    "SuspensionAwareFilter": SuspensionAwareFilter,
    "SuspensionAwareFilter extrinsic, online gains": lambda: SuspensionAwareFilter(extrinsic=RGS, online_gains=True),
}


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
