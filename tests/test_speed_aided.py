"""Speed-aided mode: the velocity measurement, streaming == batch, the speed readers, ``--speed``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.cli import main
from imu_ground.datasets.speed import frame_speed, log_speed, read_speed, read_speed_file
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import EgoMotion
from imu_ground.pipeline import estimate_log

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"
TRUTH = REPO / "datasets" / "fixtures" / "example_drive_truth.csv"


@pytest.fixture(scope="module")
def drive(speed_drive):
    """A MEMS drive with stops and a misaligned mount, and its true speed per frame (frame means)."""
    return speed_drive(60.0, 5, "mems")


def piece(em: EgoMotion, a: int, b: int) -> EgoMotion:
    return EgoMotion(em.t[a:b], em.delta_R[a:b], em.delta_v[a:b], em.delta_t[a:b], em.stationary[a:b],
                     em.valid[a:b])


def test_frame_speed_is_the_mean_over_each_frame():
    t = np.array([0.0, 1.0, 2.0])
    v = np.array([0.0, 2.0, 2.0])
    out = frame_speed(t, v, np.array([0.5, 1.5, 2.0, 2.5]), np.array([0.5, 1.0, 1.0, 1.0]))
    np.testing.assert_allclose(out[:3], [0.5, 1.75, 2.0])
    assert np.isnan(out[3])                                    # beyond the signal


def test_absent_speed_is_imu_only(drive):
    em, ext, v = drive
    a = SuspensionAwareFilter(extrinsic=ext).run(em)
    b = SuspensionAwareFilter(extrinsic=ext).run(em, speed=np.full(len(em), np.nan))
    np.testing.assert_array_equal(a.pitch, b.pitch)
    c = SuspensionAwareFilter(extrinsic=ext).run(em, speed=v)
    assert np.max(np.abs(c.pitch - a.pitch)) > 1e-6            # a speed changes the estimate


def test_large_speed_noise_tends_to_imu_only(drive):
    """sigma_speed -> inf: the update tends to the non-holonomic constraint alone (frames not flagged
    stationary), the difference shrinking with every step up in sigma_speed (where the fall sets in
    depends on the drive's IMU-only velocity error); sigma_speed above 1000 m/s is refused."""
    em, ext, v = drive
    moving = EgoMotion(em.t, em.delta_R, em.delta_v, em.delta_t, np.zeros(len(em), bool), em.valid)
    a = GravityVelocityFilter(extrinsic=ext).run(moving)
    diff = [np.abs(GravityVelocityFilter(extrinsic=ext, sigma_speed=s).run(moving, speed=v).velocity
                   - a.velocity).max() for s in (0.1, 10.0, 100.0, 1e3)]
    assert diff[0] > 1.0 and all(b < a for a, b in zip(diff, diff[1:], strict=False))
    assert diff[-1] < diff[0] / 50 and diff[-1] < 0.1
    with pytest.raises(ValueError, match="sigma_speed"):
        GravityVelocityFilter(sigma_speed=1e4)


@pytest.mark.parametrize("kw", [{}, dict(online_gains=True, lever_arm=[0.3, 0.0, 1.0])])
def test_streaming_equals_batch_with_speed(drive, kw):
    em, ext, v = drive
    v = v.copy()
    v[40:60] = np.nan                                          # a dropout in the speed
    a = SuspensionAwareFilter(extrinsic=ext, **kw)
    ests = [a.step(em.frame_at(k), speed=v[k]) for k in range(len(em))]
    b = SuspensionAwareFilter(extrinsic=ext, **kw)
    h = len(em) // 3
    parts = [b.run(piece(em, 0, h), speed=v[:h]), b.run(piece(em, h, len(em)), speed=v[h:])]
    np.testing.assert_allclose([e.pitch for e in ests], np.concatenate([p.pitch for p in parts]), atol=1e-12)
    np.testing.assert_allclose([e.roll for e in ests], np.concatenate([p.roll for p in parts]), atol=1e-12)
    np.testing.assert_allclose(a.gravity_filter.x, b.gravity_filter.x, atol=1e-9)
    np.testing.assert_allclose(a.gravity_filter.P, b.gravity_filter.P, rtol=1e-9, atol=1e-15)


def test_velocity_update_is_a_kalman_update(drive):
    """The kernel's speed update against a plain numpy 6x6 Kalman update of the prior."""
    em, ext, v = drive
    f = GravityVelocityFilter(extrinsic=ext, sigma_speed=0.2)
    for k in range(30):
        f.step(em.frame_at(k))
    k = 30
    f.step(em.frame_at(k), speed=v[k] + 0.3)
    xp, Pp, Rk = f.x_prior, f.P_prior, f.cumulative
    H = np.zeros((3, 6))
    H[:, :3] = Rk.T
    Rm = np.diag([0.2 ** 2, f.sigma_nhc ** 2, f.sigma_nhc ** 2])
    S = H @ Pp @ H.T + Rm
    K = Pp @ H.T @ np.linalg.inv(S)
    y = np.array([v[k] + 0.3, 0.0, 0.0]) - H @ xp
    np.testing.assert_allclose(f.x, xp + K @ y, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(f.P, (np.eye(6) - K @ H) @ Pp, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(f.H, H, atol=1e-15)
    np.testing.assert_allclose(f.R, Rm, atol=1e-15)
    np.testing.assert_allclose(f.K, K, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(f.y, y, atol=1e-10)


def test_speed_file_and_errors(tmp_path):
    p = tmp_path / "speed.csv"
    p.write_text("t,speed\n0.0,1.0\n0.5,nan\n1.0,2.0\n")
    t, v = read_speed_file(p)
    np.testing.assert_array_equal(t, [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(v, [1.0, np.nan, 2.0])        # a row without a speed is a hole
    with pytest.raises(ValueError, match="no speed column 'wheel'"):
        read_speed_file(p, column="wheel")
    with pytest.raises(ValueError, match="carries no speed signal"):
        read_speed(EXAMPLE)


# ------------------------------------------------------------------------------------------ shared logs
def test_nuscenes_speed_on_the_imu_time_base(shared_data):
    import json
    folder = shared_data / "nuscenes_can_bus"
    t, v = read_speed(folder)
    pose = json.loads((folder / "scene-0103_pose.json").read_text())
    assert len(t) == len(pose)
    assert np.all(np.diff(t) > 0) and abs(t[0]) < 0.1 and 19.0 < t[-1] < 20.0   # ms_imu spans 19.4 s
    assert np.isclose(v[0], np.linalg.norm(pose[0]["vel"])) and 0.0 <= v.min() and v.max() < 20.0


def test_comma2k19_can_speed_matches_the_fused_velocity(shared_data):
    seg = shared_data / "comma2k19_example"
    t, v = read_speed(seg)
    assert np.all(np.diff(t) > 0) and abs(t[0]) < 0.1 and 59.0 < t[-1] < 61.0
    from imu_ground.datasets import read_imu
    t0 = read_imu(seg).meta["t0"]
    gp = seg / "global_pose"
    tg = np.load(gp / "frame_times") - t0
    vg = np.linalg.norm(np.load(gp / "frame_velocities"), axis=1)
    inside = (tg > t[0]) & (tg < t[-1])
    assert np.median(np.abs(np.interp(tg[inside], t, v) - vg[inside])) < 0.5       # same clock, same speed


def test_kitti_speed_is_horizontal(shared_data):
    path = min((shared_data / "kitti_imu100").glob("*.csv.gz"))
    from imu_ground.datasets import read_imu
    imu = read_imu(path)
    t, v = log_speed(path, "kitti_imu100", imu)
    np.testing.assert_allclose(v, np.hypot(imu.extra["ve"], imu.extra["vn"]))      # never vu
    np.testing.assert_array_equal(t, imu.t)


def test_estimate_log_auto_speed_on_nuscenes_and_comma(shared_data):
    for name, what in (("nuscenes_can_bus", "CAN bus pose"), ("comma2k19_example", "CAN speed")):
        res = estimate_log(shared_data / name, speed="auto")
        assert what in res.meta["speed"]
        assert np.isfinite(res.track.pitch[res.track.valid]).all()


# ------------------------------------------------------------------------------------------ CLI
def _run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_speed_file_on_the_example(tmp_path, capsys):
    tr = pd.read_csv(TRUTH)
    sp = tmp_path / "speed.csv"
    tr[["t", "speed"]].to_csv(sp, index=False)
    code, out, err = _run(capsys, "estimate", EXAMPLE, "-o", tmp_path / "a.csv", "--speed", sp)
    assert code == 0, err
    assert f"speed {sp}" in out.splitlines()[0]
    code, out, err = _run(capsys, "estimate", EXAMPLE, "-o", tmp_path / "b.csv")
    assert code == 0 and "speed none" in out.splitlines()[0]
    a, b = (pd.read_csv(tmp_path / n, comment="#") for n in ("a.csv", "b.csv"))
    assert len(a) == len(b) and not np.allclose(a["pitch_deg"], b["pitch_deg"])
    code, out, err = _run(capsys, "estimate", EXAMPLE, "-o", tmp_path / "c.csv", "--speed", "wheel")
    assert code != 0 and "--speed" in err and "wheel" in err


def test_cli_speed_auto_on_a_kitti_drive(shared_data, tmp_path, capsys):
    path = min((shared_data / "kitti_imu100").glob("*.csv.gz"))
    code, out, err = _run(capsys, "estimate", path, "-o", tmp_path / "a.csv", "--speed", "auto")
    assert code == 0, err
    assert "INS horizontal speed" in out.splitlines()[0]


def test_rosbag_speed_from_odometry(tmp_path):
    """A bag with an IMU topic and an odometry topic: the speed on the IMU's time base, and ``auto`` uses it."""
    pytest.importorskip("rosbags")
    import importlib.util
    spec = importlib.util.spec_from_file_location("rosbag_helpers", Path(__file__).with_name("test_rosbag.py"))
    rb = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rb)                                     # the ROS tests' bag writer
    from imu_ground.datasets import read_table
    path = rb.write_bag(rb._bag_path(tmp_path, "mcap"), "mcap", read_table(EXAMPLE), extra=rb._odometry)
    t, v = read_speed(path)
    np.testing.assert_allclose(t, np.arange(30) * 0.1, atol=1e-6)       # T0_NS is also the first IMU stamp
    assert v[0] == -2.0 and np.all(v[1:] == 10.0)
    res = estimate_log(path, speed="auto")
    assert res.meta["speed"].startswith("the log's twist / odometry topic speed (29 of")
