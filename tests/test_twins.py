"""The one-frame / whole-track twins that speed keeps apart agree: to 1e-12 relative (max(1, |value|)), NaN in the
same places, codes and texts exactly.

- the status: one definition (``frame_status_code``), the batch looks every frame up in it;
- the road's grade, bank and 1-sigma: ``road_one`` (plain floats, the streaming step) and ``road_angles`` /
  ``road_std`` (vectorised);
- the 1-sigma: ``SigmaModel.frame`` and ``SigmaModel.track`` (the same ``AngleStd.variance``);
- the whole suspension-aware filter, ``step`` against ``run``, with a measured speed that drops out;
- the mount monitor, ``update`` frame by frame against ``run`` over a batch.
"""
import itertools
import json
import math

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.filters.mount_monitor import MountMonitor
from imu_ground.filters.road import road_angles, road_one, road_std
from imu_ground.filters.status import (CONVERGED_STD, INVALID, SUSPENSION_STD, SigmaModel, frame_status_code,
                                       track_statuses)
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.units import DEG


def _close(got, want):
    got, want = np.asarray(got, dtype=float), np.asarray(want, dtype=float)
    assert (np.isnan(got) == np.isnan(want)).all()
    ok = ~np.isnan(want)
    assert (np.abs(got[ok] - want[ok]) <= 1e-12 * np.maximum(1.0, np.abs(want[ok]))).all()


def test_batch_statuses_are_the_frame_rule_of_every_frame():
    combos = np.array(list(itertools.product((0, 1), repeat=5)), dtype=bool)   # converged, still, valid, deg, good
    var_max = np.where(combos[:, 0], 0.0, 1.0)
    for start in (False, True):
        codes, _ = track_statuses(np.full(len(combos), 1.0), combos[:, 1], combos[:, 2], combos[:, 4], start,
                                  combos[:, 3])
        want = [frame_status_code(start, s, v, d) if g else INVALID for _, s, v, d, g in combos]
        assert codes.tolist() == want
    for k in range(len(combos)):                    # each frame alone, the latch from its own variance
        code, latch = track_statuses(var_max[k:k + 1], combos[k:k + 1, 1], combos[k:k + 1, 2], combos[k:k + 1, 4],
                                     False, combos[k:k + 1, 3])
        c, s, v, d, g = combos[k]
        assert code[0] == (frame_status_code(bool(c), s, v, d) if g else INVALID)


def test_road_one_equals_the_vectorised_road():
    rng = np.random.default_rng(4)
    n = 200
    E = so3.exp(rng.normal(scale=0.05, size=(n, 3)))
    R = so3.exp(rng.normal(scale=1.0, size=(n, 3)))
    g = np.array([0.0, 0.0, 9.81]) + rng.normal(scale=0.2, size=(n, 3))
    A = rng.normal(scale=0.01, size=(n, 3, 3))
    P = A @ np.swapaxes(A, 1, 2) + 1e-6 * np.eye(3)
    ps, rs = rng.uniform(0.001, 0.01, n), rng.uniform(0.001, 0.01, n)
    grade, bank = road_angles(E, g, R)
    gs, bs = road_std(ps, rs, P, g, R)
    q = so3.quat_from_matrix(E)                            # (w, x, y, z)
    one = np.array([road_one(q[k], g[k], R[k].ravel(), P[k][np.triu_indices(3)]) for k in range(n)])
    _close(one[:, 0], grade)
    _close(one[:, 1], bank)
    _close(np.sqrt(ps ** 2 + one[:, 2]), gs)
    _close(np.sqrt(rs ** 2 + one[:, 3]), bs)


def test_sigma_model_frame_equals_track():
    rng = np.random.default_rng(7)
    n = 100
    a = rng.uniform(1e-8, 1e-5, n)
    load, gains = rng.normal(scale=2.0, size=(n, 2)), rng.normal(scale=0.01, size=(n, 2))
    cov = np.zeros((n, 6, 6))
    cov[:, 3, 3], cov[:, 4, 4] = rng.uniform(0, 1e-3, n), rng.uniform(0, 1e-3, n)
    yaw = rng.normal(scale=0.2, size=n)
    s, cross = 0.3, 0.004
    track = SigmaModel(SUSPENSION_STD, CONVERGED_STD, s, cross).track(a, load, gains, cov, yaw)
    m = SigmaModel(SUSPENSION_STD, CONVERGED_STD, s, cross)
    h = 0.5 * (1.0 - s) ** 2
    for k in range(n):
        w = (h * (gains[k, 0] ** 2 + cross ** 2), h * gains[k, 1] ** 2)    # the suspension model's tilt weights
        info = m.frame(a[k], load[k, 0], load[k, 1], cov[k, 3, 3] + cov[k, 4, 4], w, 0.1, None, abs(yaw[k]))
        pm, rm = info[:2]
        _close([pm.variance(*info[2:5], info[5], info[10]), rm.variance(*info[2:5], info[6], info[10])], track[k])


def test_suspension_filter_step_equals_run_with_a_speed(speed_drive):
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


@pytest.mark.parametrize("turn_at", [250.0, None])
def test_mount_monitor_run_equals_update_frame_by_frame(turn_at):
    t = np.arange(1, 4001) * 0.1
    rng = np.random.default_rng(1)
    drift = np.cumsum(rng.normal(scale=2e-5, size=(len(t), 2)), axis=0)     # the gyro-integrated frame's walk
    tilt = np.column_stack([drift, np.zeros(len(t))])
    if turn_at is not None:
        tilt[t >= turn_at, 1] += 1.0 * DEG * np.minimum(1.0, (t[t >= turn_at] - turn_at) / 3.0)
    g = so3.exp(tilt) @ np.array([0.0, 0.0, 9.81])
    g[:50] = np.nan                                         # no road filter yet
    usable = np.ones(len(t), dtype=bool)
    usable[900:905] = False                                 # a gap
    batch = MountMonitor()
    got = batch.run(t, g, usable)
    m = MountMonitor()
    want = [m.update(float(t[k]), None if math.isnan(g[k, 0]) else tuple(g[k]), bool(usable[k])) is not None
            for k in range(len(t))]
    assert got.tolist() == want
    assert json.dumps(batch.state_dict()) == json.dumps(m.state_dict())
    assert got.any() == (turn_at is not None)


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
