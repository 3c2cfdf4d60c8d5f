"""A bad frame does not break a streaming estimator: it raises with the state unchanged, or is skipped and flagged.

Each kind of bad frame is injected into a real drive (KITTI, shared recordings). With
``on_invalid="raise"`` the frame raises a ``ValueError`` naming the problem and leaves the state
exactly as it was; with ``on_invalid="skip"`` it comes back flagged invalid. Either way the rest of
the track equals the run of the drive without that frame, to 1e-12.
"""
from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import EgoFrame, imu_to_egomotion

K = 137                                     # where the bad frame goes
FRAMES = 400


def _nan_R(d, dv, dt):
    d = d.copy()
    d[1, 2] = np.nan
    return d, dv, dt


def _nan_v(d, dv, dt):
    dv = dv.copy()
    dv[0] = np.nan
    return d, dv, dt


def _skewed(d, dv, dt):                     # orthonormal only to 1e-5
    return d + 1e-5 * np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]]), dv, dt


BAD = {
    "nan in delta_R": (_nan_R, "delta_R is not finite"),
    "nan in delta_v": (_nan_v, "delta_v is not finite"),
    "inf in delta_R": (lambda d, dv, dt: (np.full((3, 3), np.inf), dv, dt), "delta_R is not finite"),
    "delta_t = 0": (lambda d, dv, dt: (d, dv, 0.0), "delta_t must be a positive number of seconds, got 0.0"),
    "delta_t < 0": (lambda d, dv, dt: (d, dv, -dt), "delta_t must be a positive number of seconds, got -0.1"),
    "2 I": (lambda d, dv, dt: (2.0 * np.eye(3), dv, dt), r"delta_R is not a rotation: \|R\^T R - I\| = 3"),
    "reflection": (lambda d, dv, dt: (np.diag([1.0, 1.0, -1.0]) @ d, dv, dt), r"det = -1 \(must be \+1\)"),
    "not orthonormal": (_skewed, r"delta_R is not a rotation: \|R\^T R - I\| = 2e-05"),
}
MAKERS = {
    "filter": GroundNormalFilter,
    "reference_code (general path)": GroundNormalFilter.reference_code,
    "suspension": SuspensionAwareFilter,
    "suspension, online gains": lambda **kw: SuspensionAwareFilter(online_gains=True, **kw),
}


@pytest.fixture(scope="module")
def drive(shared_data):
    from imu_ground.datasets import read_kitti_imu100
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imu = read_kitti_imu100(shared_data / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz")
    em = imu_to_egomotion(imu)
    return replace(em, t=em.t[:FRAMES], delta_R=em.delta_R[:FRAMES], delta_v=em.delta_v[:FRAMES],
                   delta_t=em.delta_t[:FRAMES], stationary=em.stationary[:FRAMES], valid=em.valid[:FRAMES])


def _inject(em, kind):
    d, dv, dt = BAD[kind][0](em.delta_R[K], em.delta_v[K], float(em.delta_t[K]))
    bad = replace(em, delta_R=em.delta_R.copy(), delta_v=em.delta_v.copy(), delta_t=em.delta_t.copy())
    bad.delta_R[K], bad.delta_v[K], bad.delta_t[K] = d, dv, dt
    return bad


def _without(em, k):
    keep = np.arange(len(em)) != k
    return replace(em, t=em.t[keep], delta_R=em.delta_R[keep], delta_v=em.delta_v[keep], delta_t=em.delta_t[keep],
                   stationary=em.stationary[keep], valid=em.valid[keep])


def _state(f):
    s = [f.x.copy(), f.P.copy(), f.cumulative.copy()]
    if isinstance(f, SuspensionAwareFilter):
        s += [f.gains.copy(), f.gravity_filter.x.copy(), f.gravity_filter.P.copy()]
    return s


def _same(a, b):
    return all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("maker", sorted(MAKERS))
@pytest.mark.parametrize("kind", sorted(BAD))
def test_streaming_raise_leaves_the_state_and_skip_flags_the_frame(drive, kind, maker):
    make = MAKERS[maker]
    bad = _inject(drive, kind)
    ref = make().run(_without(drive, K))
    frames = list(bad.frames())
    # raise: a clear error, the state untouched, the next good frame continues as if nothing came
    f = make()
    got = []
    for k, fr in enumerate(frames):
        if k == K:
            before = _state(f)
            with pytest.raises(ValueError, match=BAD[kind][1]) as err:
                f.step(fr)
            assert f"frame index {K}" in str(err.value) and "on_invalid='skip'" in str(err.value)
            assert _same(before, _state(f))
            continue
        got.append(f.step(fr))
    np.testing.assert_allclose([e.pitch for e in got], ref.pitch, rtol=0, atol=1e-12)
    np.testing.assert_allclose([e.normal for e in got], ref.normal, rtol=0, atol=1e-12)
    # skip: the same numbers, the bad frame flagged invalid and holding the previous estimate
    g = make(on_invalid="skip")
    est = [g.step(fr) for fr in frames]
    assert not est[K].valid and all(e.valid for i, e in enumerate(est) if i != K)
    assert est[K].pitch == pytest.approx(est[K - 1].pitch, abs=1e-12)
    np.testing.assert_allclose([e.pitch for i, e in enumerate(est) if i != K], ref.pitch, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g.x, f.x, rtol=0, atol=1e-12)


@pytest.mark.parametrize("maker", sorted(MAKERS))
@pytest.mark.parametrize("kind", ["nan in delta_R", "delta_t = 0", "reflection"])
def test_batch_raise_names_the_frame_and_skip_holds_it(drive, kind, maker):
    make = MAKERS[maker]
    bad = _inject(drive, kind)
    ref = make().run(_without(drive, K))
    f = make()
    fresh = _state(f)
    with pytest.raises(ValueError, match=f"frame index {K}, t = .* s; 1 bad of {FRAMES}\\): .*" + BAD[kind][1]):
        f.run(bad)
    assert _same(fresh, _state(f))
    tr = make(on_invalid="skip").run(bad)
    keep = np.arange(FRAMES) != K
    assert not tr.valid[K] and np.array_equal(tr.valid[keep], drive.valid[keep])
    np.testing.assert_array_equal(tr.t, drive.t)
    for name in ("pitch", "roll", "normal", "residual", "x", "cumulative", "P"):
        np.testing.assert_allclose(getattr(tr, name)[keep], getattr(ref, name), rtol=1e-12, atol=1e-12, err_msg=name)
        np.testing.assert_array_equal(getattr(tr, name)[K], getattr(tr, name)[K - 1])


def test_bare_rotation_step_checks_the_rotation_only():
    f = GroundNormalFilter()
    with pytest.raises(ValueError, match=r"frame index 0\): delta_R is not a rotation"):
        f.step(2.0 * np.eye(3))
    assert np.array_equal(f.x, np.eye(3))
    est = GroundNormalFilter(on_invalid="skip").step(EgoFrame(so3.rotz(0.1), np.zeros(3), 0.0))
    assert not est.valid and est.pitch == 0.0 and np.array_equal(est.normal, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="on_invalid must be 'raise' or 'skip'"):
        SuspensionAwareFilter(on_invalid="ignore")


def test_step_refuses_several_rotations_as_one_frame():
    """Both streaming estimators share the frame check (the kernel's check, then frame_checks.coerce_frame):
    a batch is named as such, even a batch of one."""
    for batch in (np.stack([np.eye(3), so3.rotz(0.1)]), so3.rotz(0.1)[None]):
        for f in (GroundNormalFilter(on_invalid="skip"), SuspensionAwareFilter(on_invalid="skip")):
            with pytest.raises(ValueError, match=rf"delta_R must be one rotation, got shape \({len(batch)}, 3, 3\)"):
                f.step(batch, np.zeros(3), 0.1) if isinstance(f, SuspensionAwareFilter) else f.step(batch)


@pytest.mark.parametrize("form", ["nested list", "float32", "Fortran order", "4x4 pose", "rotation vector",
                                  "delta_v list"])
def test_step_takes_every_form_of_a_frame(form):
    """The kernels' fast path takes float64 arrays; any other form is converted and gives the same estimate."""
    phi = np.array([0.01, -0.02, 0.3])
    R = so3.exp_one(phi)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = R, [1.0, 2.0, 3.0]
    d = {"nested list": R.tolist(), "float32": R.astype(np.float32), "Fortran order": np.asfortranarray(R),
         "4x4 pose": pose, "rotation vector": phi, "delta_v list": R}[form]
    dv = [0.5, 0.0, 0.0] if form == "delta_v list" else np.array([0.5, 0.0, 0.0])
    for make in (GroundNormalFilter, SuspensionAwareFilter):
        ref, f = make(), make()
        a = ref.step(R, np.array([0.5, 0.0, 0.0]), 0.1) if make is SuspensionAwareFilter else ref.step(R)
        b = f.step(d, dv, 0.1) if make is SuspensionAwareFilter else f.step(d)
        tol = 1e-7 if form == "float32" else 1e-15
        np.testing.assert_allclose(b.normal, a.normal, rtol=0, atol=tol)
        assert b.valid
