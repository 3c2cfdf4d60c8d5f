"""Online re-estimation of a mount that moved (``recalibrate_online``): after the mount monitor's alarm the
static rotation is corrected and the sensor-frame normal returns to the truth; the same in stream and batch,
through a warm start, and nothing happens without an alarm or without the flag."""
from __future__ import annotations

import json
import math
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from imu_ground.evaluation.simulate import remounted, simulate
from imu_ground.filters.estimator import pitch_roll_from_normal
from imu_ground.filters.recalibration import WINDOW
from imu_ground.filters.status import DEGRADED, OK
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.so3 import rotx, roty

DEG = math.pi / 180.0
AT = 120.0
EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(scope="module")
def remount(with_true_speed):
    """A synthetic navigation-grade drive whose sensor turns by 1 deg in pitch and 0.5 deg in roll at 120 s."""
    sim = simulate(duration=240.0, seed=2, imu="nav")
    return with_true_speed(remounted(sim, AT, rotx(0.5 * DEG) @ roty(1.0 * DEG)))


def _normal_error(d, tr) -> np.ndarray:
    """(F, 2) pitch and roll of the estimated sensor-frame normal minus the truth's, deg."""
    truth = pitch_roll_from_normal(d.truth[["normal_x", "normal_y", "normal_z"]].to_numpy())
    est = pitch_roll_from_normal(tr.normal)
    return np.column_stack([est[0] - truth[0], est[1] - truth[1]]) / DEG


def test_the_mount_is_re_estimated_and_the_normal_returns_to_the_truth(remount):
    d, sp = remount
    f = SuspensionAwareFilter(extrinsic=d.extrinsic, recalibrate_online=True)
    tr = f.run(d.egomotion, speed=sp)
    t = d.egomotion.t
    deg = np.flatnonzero(tr.status == DEGRADED)
    assert len(deg) and AT < t[deg[0]] <= AT + 20.0                     # flagged as without the flag ...
    t_alarm, t_fixed = t[deg[0]], t[deg[-1] + 1]
    assert t_fixed - t_alarm == pytest.approx(WINDOW, abs=0.5)          # ... re-estimated WINDOW s later
    assert not (tr.status[deg[-1] + 1:] == DEGRADED).any()
    after = np.flatnonzero(tr.status[deg[-1] + 1:] == OK) + deg[-1] + 1
    assert len(after) and all(r.startswith("mount re-estimated online") for r in tr.status_reason[after])
    # the change (body frame): 1 deg pitch, 0.5 deg roll
    np.testing.assert_allclose(f.recalibrator.delta[:2] / DEG, [0.5, 1.0], atol=0.1)
    err = _normal_error(d, tr)
    moving = d.truth["evaluate"].to_numpy(bool)
    before, fixed = moving & (t > 60.0) & (t < AT), moving & (t > t_fixed)
    assert np.abs(err[before].mean(axis=0)).max() < 0.1
    assert np.abs(err[fixed].mean(axis=0)).max() < 0.1                   # within 0.1 deg of the truth again
    plain = SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion, speed=sp)
    assert np.abs(_normal_error(d, plain)[fixed].mean(axis=0)).max() > 0.5  # (without: off by the change)


def test_without_the_flag_it_stays_degraded(remount):
    d, sp = remount
    tr = SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion, speed=sp)
    deg = tr.status == DEGRADED
    first = np.argmax(deg)
    assert deg.any() and deg[first:][d.egomotion.valid[first:]].all()


def test_stream_equals_batch_and_a_warm_start_resumes_across_the_re_estimation(remount):
    d, sp = remount
    frames = list(d.egomotion.frames())
    whole = SuspensionAwareFilter(extrinsic=d.extrinsic, recalibrate_online=True).run(d.egomotion, speed=sp)
    alarm = int(np.argmax(whole.status == DEGRADED))
    for stop in (alarm + 40, alarm + 200):                               # during the window, after the fix
        a = SuspensionAwareFilter(extrinsic=d.extrinsic, recalibrate_online=True)
        es = [a.step(frames[i], speed=sp[i]) for i in range(stop)]
        b = SuspensionAwareFilter(extrinsic=d.extrinsic, recalibrate_online=True)
        b.load_state_dict(json.loads(json.dumps(a.state_dict())))
        es += [b.step(frames[i], speed=sp[i]) for i in range(stop, len(frames))]
        np.testing.assert_allclose([e.pitch for e in es], whole.pitch, rtol=0, atol=1e-12)
        np.testing.assert_allclose([e.roll for e in es], whole.roll, rtol=0, atol=1e-12)
        np.testing.assert_allclose([e.normal for e in es], whole.normal, rtol=0, atol=1e-12)
        np.testing.assert_allclose([e.road_grade for e in es], whole.road_grade, rtol=0, atol=1e-12)
        assert [e.status_code for e in es] == whole.status.tolist()
        assert [e.status_reason for e in es] == whole.status_reason.tolist()
    with pytest.raises(ValueError):                                      # a state with the flag into one without
        SuspensionAwareFilter(extrinsic=d.extrinsic).load_state_dict(a.state_dict())


def test_the_flag_changes_nothing_without_an_alarm(with_true_speed):
    d, sp = with_true_speed(simulate(duration=240.0, seed=2, imu="nav"))
    plain = SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion, speed=sp)
    f = SuspensionAwareFilter(extrinsic=d.extrinsic, recalibrate_online=True)
    tr = f.run(d.egomotion, speed=sp)
    assert f.recalibrator.count == 0
    for name in ("pitch", "roll", "normal", "road_grade", "road_bank", "pitch_std"):
        np.testing.assert_allclose(getattr(tr, name), getattr(plain, name), rtol=0, atol=1e-9)
    assert tr.status.tolist() == plain.status.tolist()
    with pytest.raises(ValueError, match="smooth"):
        f.run(d.egomotion, smooth=True)


def test_no_alarm_and_no_re_estimation_on_the_shared_drives(shared_data, kitti_index):
    from imu_ground.pipeline import estimate_log
    for name in kitti_index["drive"]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tr = estimate_log(shared_data / "kitti_imu100" / f"{name}.csv.gz", speed="auto",
                              recalibrate_online=True).track
        assert not (tr.status == DEGRADED).any(), name
        assert not any(r.startswith("mount re-estimated") for r in tr.status_reason), name


def _true_speed_file(folder: Path) -> Path:
    """The example drive's true speed as a speed file (``t,speed``)."""
    speed = folder / "speed.csv"
    truth = np.genfromtxt(EXAMPLE.with_name("example_drive_truth.csv"), delimiter=",", names=True)
    np.savetxt(speed, np.c_[truth["t"], truth["speed"]], delimiter=",", header="t,speed", comments="")
    return speed


def test_cli_flag(tmp_path):
    log = str(EXAMPLE)
    speed = _true_speed_file(tmp_path)
    cmd = [sys.executable, "-m", "imu_ground", "estimate", log, "--recalibrate-online", "-o"]
    ok = subprocess.run(cmd + [str(tmp_path / "a.csv"), "--speed", str(speed)], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    assert (tmp_path / "a.csv").is_file()
    for method in ("filter", "suspension-offline"):
        bad = subprocess.run(cmd + [str(tmp_path / "b.csv"), "--method", method], capture_output=True, text=True)
        assert bad.returncode == 2
        lines = bad.stderr.strip().splitlines()
        assert len(lines) == 1 and "--recalibrate-online" in lines[0] and log in lines[0], bad.stderr
        assert not (tmp_path / "b.csv").exists()


@pytest.mark.parametrize("speed", ["none", "auto"])        # auto: a table log without a speed column
def test_without_a_speed_it_is_refused_naming_speed(tmp_path, cli, speed):
    """Was accepted silently (the help says it needs a speed), the mount never watched."""
    out = tmp_path / "o.csv"
    code, _, err = cli("estimate", EXAMPLE, "--recalibrate-online", "--speed", speed, "-o", out)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and not out.exists()
    assert str(EXAMPLE) in lines[0] and "needs a measured speed" in lines[0] and "--speed FILE" in lines[0]


def test_a_log_shorter_than_the_monitor_needs_is_warned_about(tmp_path, cli):
    """The 60 s example with its true speed: the monitor judges from 120 s, so it can never act."""
    speed = _true_speed_file(tmp_path)
    code, _, err = cli("estimate", EXAMPLE, "--recalibrate-online", "--speed", speed, "-o", tmp_path / "o.csv")
    assert code == 0, err
    warning = [ln for ln in err.splitlines() if "--recalibrate-online" in ln]
    assert len(warning) == 1 and warning[0].startswith(f"{EXAMPLE}: warning:") and "cannot act" in warning[0]
    assert "120 s" in warning[0] and "59.9 s" in warning[0]
