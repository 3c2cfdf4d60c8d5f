"""SuspensionAwareFilter and GravityVelocityFilter: streaming == batch, filterpy's Saver, validity of
covariances and rotations, a braking manoeuvre, a synthetic suite against the paper's method, and
the 30 valid KITTI drives (skipped without the shared recordings)."""
from __future__ import annotations


import numpy as np
import pandas as pd
import pytest
from filterpy.common import Saver

from imu_ground import so3
from imu_ground.datasets.speed import frame_speed
from imu_ground.evaluation.metrics import evaluate_drive, normal_angle
from imu_ground.evaluation.simulate import RoadParams, SpeedParams, simulate, simulate_suite
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.ground import GroundEstimate, GroundNormalFilter, GroundTrack
from imu_ground.filters.methods import estimate_suspension_aware
from imu_ground.filters.suspension import (
    DEFAULT_GAINS,
    SuspensionAwareFilter,
    SuspensionTrack,
)
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion

DEG = np.pi / 180.0


def piece(em: EgoMotion, a: int, b: int) -> EgoMotion:
    return EgoMotion(em.t[a:b], em.delta_R[a:b], em.delta_v[a:b], em.delta_t[a:b], em.stationary[a:b],
                     em.valid[a:b])


def truth_at(sim, em: EgoMotion) -> pd.DataFrame:
    tr = sim.truth
    idx = np.searchsorted(tr["t"].to_numpy(), em.t - 1e-6)
    return tr.iloc[idx].reset_index(drop=True)


@pytest.fixture(scope="module")
def mems_drive():
    """A MEMS drive with a misaligned mount, a lever arm and standstills."""
    sim = simulate(90.0, seed=11, imu="mems", road=RoadParams(roughness="B"), speed=SpeedParams(style="urban"),
                   R_gs=so3.rotz(0.1) @ so3.roty(0.03) @ so3.rotx(-0.02), t_gs=[0.4, 0.1, 1.1])
    em = imu_to_egomotion(sim.imu)
    return sim, em, Extrinsic(sim.R_gs, sim.t_gs)


# ----------------------------------------------------------------------------- streaming == batch
@pytest.mark.parametrize("kw", [
    {},
    dict(online_gains=True, response=(1.5, 0.5), lever_arm=[0.4, 0.1, 1.1]),
    dict(load="acceleration", q_dist=0.0),
])
def test_streaming_equals_batch(mems_drive, kw):
    sim, em, ext = mems_drive
    a = SuspensionAwareFilter(extrinsic=ext, **kw)
    ests = [a.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
            for k in range(len(em))]
    assert all(isinstance(e, GroundEstimate) for e in ests)
    b = SuspensionAwareFilter(extrinsic=ext, **kw)
    half = len(em) // 3
    parts = [b.run(piece(em, 0, half)), b.run(piece(em, half, len(em)))]     # run() continues
    assert all(isinstance(p, SuspensionTrack) and isinstance(p, GroundTrack) for p in parts)
    def cat(name):
        return np.concatenate([getattr(p, name) for p in parts])
    np.testing.assert_allclose(np.array([e.normal for e in ests]), cat("normal"), atol=1e-12)
    np.testing.assert_allclose(np.array([e.pitch for e in ests]), cat("pitch"), atol=1e-12)
    np.testing.assert_allclose(np.array([e.roll for e in ests]), cat("roll"), atol=1e-12)
    np.testing.assert_allclose(np.array([e.residual for e in ests]), cat("residual"), atol=1e-12)
    np.testing.assert_allclose(np.array([e.extrinsic for e in ests]), cat("extrinsic"), atol=1e-12)
    np.testing.assert_allclose(np.array([e.P for e in ests]), cat("P"), rtol=1e-12, atol=1e-22)
    # the streaming state is left where step() leaves it
    np.testing.assert_allclose(a.x, b.x, atol=1e-12)
    np.testing.assert_allclose(a.P, b.P, rtol=1e-12, atol=1e-22)
    np.testing.assert_allclose(a.gains, b.gains, rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(a.gravity_filter.x, b.gravity_filter.x, atol=1e-9)
    np.testing.assert_allclose(a.gravity_filter.P, b.gravity_filter.P, rtol=1e-9)
    np.testing.assert_allclose(a.cumulative, b.cumulative, atol=1e-12)
    if kw.get("online_gains"):
        assert not np.allclose(cat("gains")[0], cat("gains")[-1])       # the gains did move


def test_gravity_filter_streaming_equals_batch(mems_drive):
    _, em, ext = mems_drive
    a = GravityVelocityFilter(extrinsic=ext, lever_arm=ext.translation)
    est = [a.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
           for k in range(len(em))]
    tr = GravityVelocityFilter(extrinsic=ext, lever_arm=ext.translation).run(em)
    np.testing.assert_allclose([e.velocity for e in est], tr.velocity, atol=1e-9)
    np.testing.assert_allclose([e.specific_force for e in est], tr.specific_force, atol=1e-9)
    np.testing.assert_allclose([e.acceleration for e in est], tr.acceleration, atol=1e-9)
    # gravity is about 9.81 m/s^2 and the speed follows the truth
    assert np.abs(np.linalg.norm(tr.gravity, axis=1) - 9.81).max() < 0.3
    # with a nav-grade IMU (same trajectory) the speed follows the truth; the MEMS accelerometer bias
    # (0.2 m/s^2) makes the forward speed drift between stops: it is only observed at standstills
    nav = simulate(**{**mems_drive[0].params, "imu": "nav"})
    em_nav = imu_to_egomotion(nav.imu)
    sm = GravityVelocityFilter(extrinsic=ext).run(em_nav, smooth=True)
    truth = truth_at(nav, em_nav)["speed"].to_numpy()
    assert np.median(np.abs(sm.speed - truth)) < 0.3


# ----------------------------------------------------------------------------- filterpy interface
def test_saver_records_filterpy_attributes(mems_drive):
    _, em, ext = mems_drive
    f = SuspensionAwareFilter(extrinsic=ext, online_gains=True)
    s = Saver(f)
    g = GravityVelocityFilter(extrinsic=ext)
    sg = Saver(g)
    n = 50
    for k in range(n):
        f.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
        s.save()
        g.step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
        sg.save()
    s.to_array()
    sg.to_array()
    for name in ("x", "P", "Q", "R", "K", "S", "x_prior", "P_prior", "x_post", "P_post"):
        assert getattr(s, name).shape == (n, 3, 3), name
    assert s.y.shape == (n, 3) and s.gains.shape == (n, 2) and s.cumulative.shape == (n, 3, 3)
    np.testing.assert_allclose(s.x[-1], f.x)
    assert sg.x.shape == (n, 6) and sg.P.shape == (n, 6, 6) and sg.F.shape == (n, 6, 6)
    assert sg.Q.shape == (n, 6, 6) and sg.H.shape == (n, 3, 6) and sg.K.shape == (n, 6, 3)
    assert sg.y.shape == (n, 3) and sg.S.shape == (n, 3, 3)


def test_defaults_and_validation():
    f = SuspensionAwareFilter()
    np.testing.assert_allclose(f.gains, DEFAULT_GAINS)
    np.testing.assert_allclose(np.degrees(f.gains), [-0.25, 0.4])
    r = (0.2 * DEG) ** 2
    np.testing.assert_allclose(f.R, np.diag([r, r, 1e-6 * r]))
    assert f.load == 1.0 and f.load_share == 1.0 and not f.online_gains
    assert f.lateral == "auto"
    with pytest.raises(ValueError):
        SuspensionAwareFilter(lateral="gps")
    assert SuspensionAwareFilter(load="specific_force").load_share == 1.0
    with pytest.raises(ValueError):
        SuspensionAwareFilter(load="torque")
    with pytest.raises(ValueError):
        SuspensionAwareFilter(smoother_weight=1.5)
    with pytest.raises(ValueError):
        SuspensionAwareFilter(sigma_e=0.0)


def test_at_rest_the_normal_is_the_static_one():
    R_gs = so3.roty(0.05) @ so3.rotx(-0.03)
    f = SuspensionAwareFilter(extrinsic=R_gs)
    g_s = R_gs.T @ np.array([0.0, 0.0, 9.81])            # the IMU reads the gravity reaction, sensor frame
    for _ in range(30):
        est = f.step(np.eye(3), 0.1 * g_s, 0.1, stationary=True)
    np.testing.assert_allclose(est.normal, R_gs[2], atol=1e-12)
    assert abs(est.pitch) < 1e-12 and abs(est.roll) < 1e-12


def test_covariances_and_rotations_valid(mems_drive):
    _, em, ext = mems_drive
    for smooth in (False, True):
        tr = SuspensionAwareFilter(extrinsic=ext).run(em, smooth=smooth)
        np.testing.assert_allclose(tr.P, np.swapaxes(tr.P, 1, 2), atol=0)
        assert np.all(np.linalg.eigvalsh(tr.P) > 0)
        for M in (tr.x, tr.residual, tr.extrinsic, tr.cumulative):
            np.testing.assert_allclose(M @ np.swapaxes(M, 1, 2), np.broadcast_to(np.eye(3), M.shape), atol=1e-9)
            np.testing.assert_allclose(np.linalg.det(M), 1.0, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(tr.normal, axis=1), 1.0, atol=1e-12)
    Pg = GravityVelocityFilter(extrinsic=ext).run(em, smooth=True).P
    np.testing.assert_allclose(Pg, np.swapaxes(Pg, 1, 2), atol=0)
    assert np.all(np.linalg.eigvalsh(Pg) > 0)


def test_smoother_weight_is_a_geodesic_blend(mems_drive):
    _, em, ext = mems_drive
    fwd = SuspensionAwareFilter(extrinsic=ext, smoother_weight=0.0).run(em, smooth=True)
    rts = SuspensionAwareFilter(extrinsic=ext, smoother_weight=1.0).run(em, smooth=True)
    mix = SuspensionAwareFilter(extrinsic=ext, smoother_weight=0.25).run(em, smooth=True)
    full = so3.angle(np.swapaxes(fwd.x, 1, 2) @ rts.x)
    part = so3.angle(np.swapaxes(fwd.x, 1, 2) @ mix.x)
    big = full > 1e-4
    np.testing.assert_allclose(part[big] / full[big], 0.25, atol=1e-6)
    # the smoother uses the future: it differs from the forward pass before the last frame only
    assert full[-1] < 1e-12 and full.max() > 1e-3


# ----------------------------------------------------------------------------- accuracy, synthetic
def test_braking_keeps_the_nose_dive_that_the_paper_filter_loses():
    """3 m/s^2 braking for ~3 s: the body pitches ~0.75 deg nose down relative to the road for the whole
    manoeuvre; the paper's random walk follows it into the 'road' within a second."""
    speed = SpeedParams(v_start=15.0, start_at_rest=False,
                        plan=[(15.0, 1.0, 8.0), (5.0, 3.0, 6.0), (15.0, 1.5, 10.0)])
    sim = simulate(40.0, seed=2, imu="nav", road=RoadParams(roughness="A", grade_std=0.0, grade0=0.0, crown=0.0,
                                                              curves=False), speed=speed)
    em = imu_to_egomotion(sim.imu)
    tr = truth_at(sim, em)
    braking = (tr["acc_long"] < -2.5).to_numpy()
    assert braking.sum() > 10 and np.degrees(tr["pitch"][braking]).mean() > 0.6
    def err(p):
        return np.degrees(np.abs(p - tr["pitch"].to_numpy()))[braking].mean()
    ours = err(SuspensionAwareFilter(extrinsic=sim.R_gs).run(em).pitch)
    paper = err(GroundNormalFilter.paper(extrinsic=sim.R_gs).run(em.delta_R).pitch)
    assert ours < 0.1 < 0.4 < paper


def test_synthetic_suite_well_below_the_paper():
    """3 short drives per IMU grade (different vehicles, roads, mounts), default configuration:
    normal angle error over moving frames at least 40 % below GroundNormalFilter.paper()."""
    sims = simulate_suite(3, seed=7, duration_range=(60.0, 90.0))
    rows = []
    for sim in sims:
        em = imu_to_egomotion(sim.imu)
        tr = truth_at(sim, em)
        n_true = tr[["normal_x", "normal_y", "normal_z"]].to_numpy()
        mask = (tr["speed"] > 3.0).to_numpy() & em.valid
        ext = Extrinsic(sim.R_gs, sim.t_gs)
        err = lambda n: normal_angle(n, n_true)[mask].mean()  # noqa: E731, B023 (used in this iteration)
        rows.append(dict(grade=sim.imu_model.name,
                         paper=err(GroundNormalFilter.paper(extrinsic=ext).run(em.delta_R).normal),
                         stream=err(SuspensionAwareFilter(extrinsic=ext).run(em).normal),
                         rts=err(SuspensionAwareFilter(extrinsic=ext, smoother_weight=1.0).run(em, smooth=True).normal),
                         offline=err(SuspensionAwareFilter(extrinsic=ext).run(em, smooth=True).normal)))
    df = pd.DataFrame(rows).groupby("grade").mean()
    assert set(df.index) == {"nav", "mems"}
    assert np.all(df["stream"] <= 0.6 * df["paper"]), df
    assert np.all(df["offline"] <= 0.6 * df["paper"]), df
    # with an exact truth and a navigation-grade IMU the pure (zero-lag) smoother
    # is better still; with MEMS the smoothed gravity estimate carries the
    # accelerometer bias into the acceleration part of the load, and it is not
    assert df.loc["nav", "rts"] < df.loc["nav", "stream"], df


def test_one_call_function(mems_drive):
    sim, em, ext = mems_drive
    a = estimate_suspension_aware(em, extrinsic=ext, smooth=True, q_dist=0.05)
    b = SuspensionAwareFilter(extrinsic=ext, q_dist=0.05).run(em, smooth=True)
    np.testing.assert_array_equal(a.normal, b.normal)
    c = estimate_suspension_aware(sim.imu, extrinsic=ext)           # raw IMU: preintegrated at 10 Hz
    np.testing.assert_allclose(c.normal, SuspensionAwareFilter(extrinsic=ext).run(em).normal, atol=1e-12)


# ----------------------------------------------------------------------------- real data
@pytest.fixture(scope="module")
def kitti(kitti_drives):
    """The valid kitti_imu100 drives (the evaluation's loader), with the INS horizontal speed per frame."""
    drives, skipped = {}, {}
    for d in kitti_drives:
        if not d.valid:
            skipped[d.name] = d.reason
            continue
        em, imu = d.egomotion, d.imu
        speed = frame_speed(imu.t, np.hypot(imu.extra["ve"], imu.extra["vn"]), em.t, em.delta_t)
        drives[d.name] = (em, d.truth["pitch"].to_numpy(), d.truth["evaluate"].to_numpy(), speed)
    return drives, skipped


def _kitti_scores(drives, method) -> pd.Series:
    out = {}
    for name, (em, ref, mask, speed) in drives.items():
        out[name] = evaluate_drive(method(em, speed), ref, mask=mask, remove_mean=True)["pitch"]["mean"]
    return pd.Series(out)


@pytest.mark.shared
def test_kitti_pitch_accuracy(kitti, kitti_valid_names, kitti_faulty_names):
    drives, skipped = kitti
    assert sorted(drives) == sorted(kitti_valid_names)
    assert set(skipped) == kitti_faulty_names
    paper = _kitti_scores(drives, lambda em, v: GroundNormalFilter.paper().run(em.delta_R).pitch)
    stream = _kitti_scores(drives, lambda em, v: SuspensionAwareFilter().run(em).pitch)
    no_cross = _kitti_scores(drives, lambda em, v: SuspensionAwareFilter(cross_gain=0.0).run(em).pitch)
    speed = _kitti_scores(drives, lambda em, v: SuspensionAwareFilter().run(em, speed=v).pitch)
    online = _kitti_scores(drives, lambda em, v: SuspensionAwareFilter(online_gains=True).run(em).pitch)
    offline = _kitti_scores(drives, lambda em, v: SuspensionAwareFilter().run(em, smooth=True).pitch)
    rts = _kitti_scores(drives, lambda em, v: SuspensionAwareFilter(smoother_weight=1.0).run(em, smooth=True).pitch)
    # every variant against the published method on the same drives, whatever drives.csv lists
    for variant in (stream, no_cross, speed, online, offline):
        assert variant.mean() < 0.65 * paper.mean()
    # the pitch from the lateral load and the measured speed must not cost accuracy on this reference
    # (their gain shows on the revisit check, tests/test_revisit.py, not on the INS-grade mean)
    assert stream.mean() <= no_cross.mean() + 0.001
    assert speed.mean() <= stream.mean() + 0.001
    # the pure RTS smoother is *worse* than the forward filter against this (causal INS) reference
    assert stream.mean() < rts.mean() < paper.mean()
    # per drive: no drive more than 10 % worse than the paper's filter (the worst: 2011_09_26_drive_0091,
    # slow driving where the INS reference drifts); benchmarks/studies/tune_suspension.py prints the figures
    assert (stream / paper).max() <= 1.1 and (speed / paper).max() <= 1.1


# ----------------------------------------------------------------------------- pitch from the lateral load
def test_cross_gain_adds_pitch_from_the_lateral_load(mems_drive):
    from imu_ground.filters.gains import DEFAULT_CROSS_GAIN
    sim, em, ext = mems_drive
    tr = SuspensionAwareFilter(extrinsic=ext).run(em)
    assert DEFAULT_CROSS_GAIN < 0
    np.testing.assert_allclose(tr.suspension[:, 0], tr.gains[:, 0] * tr.load[:, 0] + DEFAULT_CROSS_GAIN * tr.load[:, 1],
                               atol=1e-15)
    off = SuspensionAwareFilter(extrinsic=ext, cross_gain=0.0).run(em)
    np.testing.assert_allclose(off.suspension, off.gains * off.load, atol=1e-15)
    assert np.max(np.abs(off.pitch - tr.pitch)) > 1e-5


def _close(got, want):
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    assert (np.isnan(got) == np.isnan(want)).all()
    ok = ~np.isnan(want)
    assert (np.abs(got[ok] - want[ok]) <= 1e-12 * np.maximum(1.0, np.abs(want[ok]))).all()


def test_step_equals_run_with_a_speed_that_drops_out(speed_drive):
    """``step`` frame by frame gives ``run``'s 1-sigma, road, status and reason (a public promise)."""
    em, ext, v = speed_drive(40.0, 2, "mems")
    v = v.copy()
    v[100:130] = np.nan                                    # the speed drops out
    tr = SuspensionAwareFilter(extrinsic=ext).run(em, speed=v)
    f = SuspensionAwareFilter(extrinsic=ext)
    es = [f.step(em.frame_at(k), speed=v[k]) for k in range(len(em))]
    for name in ("pitch_std", "roll_std", "road_grade", "road_bank", "road_grade_std", "road_bank_std"):
        _close([getattr(e, name) for e in es], getattr(tr, name))
    assert [e.status_code for e in es] == tr.status.tolist()
    assert [e.status_reason for e in es] == tr.status_reason.tolist()
    assert np.isfinite(tr.road_grade).mean() > 0.5 and np.isnan(tr.road_grade[100:130]).all()


def test_road_pass_in_a_second_thread_gives_the_same_track(speed_drive, monkeypatch):
    """A long batch runs the road's gravity pass in a second thread: the track is bit for bit the one run in
    turn, over two batches (the second starts without a speed: the running road filter goes on through it)."""
    import threading

    import imu_ground.filters.suspension as susp
    from imu_ground.filters.frame_checks import frames_of
    from imu_ground.filters.road import RoadFilter
    em, ext, v = speed_drive(60.0, 3, "mems")
    v = v.copy()
    v[:10] = np.nan                                       # the road starts at frame 10
    v[150:200] = np.nan
    v[len(em) // 2:len(em) // 2 + 20] = np.nan
    first = np.arange(len(em)) < len(em) // 2
    half = int(first.sum())
    threads = []
    original = RoadFilter.gravity_pass

    def recorded(self, *a, **k):
        threads.append(threading.current_thread() is threading.main_thread())
        return original(self, *a, **k)
    monkeypatch.setattr(RoadFilter, "gravity_pass", recorded)
    tracks = {}
    for frames in (10 ** 9, 1):
        monkeypatch.setattr(susp, "ROAD_THREAD_FRAMES", frames)
        f = SuspensionAwareFilter(extrinsic=ext)
        tracks[frames] = [f.run(frames_of(em, first), speed=v[:half]), f.run(frames_of(em, ~first), speed=v[half:])]
    assert threads == [True, True, False, False]
    for a, b in zip(*tracks.values(), strict=True):
        for name in ("pitch", "roll", "pitch_std", "roll_std", "road_grade", "road_bank", "road_grade_std",
                     "road_bank_std", "status", "status_reason"):
            x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
            assert x.dtype == y.dtype
            assert x.tolist() == y.tolist() if x.dtype == object else x.tobytes() == y.tobytes()
    first, second = tracks[1][0].road_grade, tracks[1][1].road_grade
    assert np.isnan(first[:10]).all() and np.isfinite(first[10:150]).all()
    assert np.isnan(second[:20]).all() and np.isfinite(second[20:]).all()
