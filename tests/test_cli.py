"""The ``imu-ground`` command: bad input (one line naming the file and the flag, exit status 2, no partial
file), the default method, and the conveniences."""
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.cli import build_parser
from imu_ground.pipeline.output import COLUMNS

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"
TRUTH = REPO / "datasets" / "fixtures" / "example_drive_truth.csv"



def one_error_line(err, *words):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines and "Traceback" not in err
    last = lines[-1]
    assert "error" in last, err
    for w in words:
        assert w in last, (w, err)
    return last


@pytest.fixture(scope="module")
def gap_log(tmp_path_factory):
    df = pd.read_csv(EXAMPLE)
    t = df["t"].to_numpy()
    path = tmp_path_factory.mktemp("gap") / "gap.csv"
    df[~((t > 20.0) & (t < 23.0))].to_csv(path, index=False)
    return path


def _poses(n=120, rate=10.0, seed=1):
    """A smooth camera-like trajectory: world <- sensor rotations and positions."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(seed)
    rv = np.cumsum(rng.normal(0, 0.002, (n, 3)), axis=0)
    return Rotation.from_rotvec(rv).as_matrix(), np.cumsum(np.ones((n, 3)), axis=0), np.arange(n) / rate


# ------------------------------------------------------------------------------------------ estimate
def test_estimate_on_the_shipped_example(tmp_path, cli):
    out, tum = tmp_path / "g.csv", tmp_path / "g.tum"
    code, stdout, err = cli("estimate", EXAMPLE, "-o", out, "--tum", tum)
    assert code == 0, err
    df = pd.read_csv(out, comment="#")
    assert list(df.columns) == list(COLUMNS)
    assert len(df) == len(pd.read_csv(TRUTH)) - 1
    assert np.allclose(np.linalg.norm(df[["normal_x", "normal_y", "normal_z"]].to_numpy(), axis=1), 1.0)
    assert np.loadtxt(tum).shape == (len(df), 8)
    first = stdout.splitlines()[0]
    assert first.startswith("table log") and "method suspension" in first     # the detected format, first
    assert "wrote" in stdout.splitlines()[-1]


def test_default_method_beats_the_constant_normal_on_the_example(tmp_path, cli):
    """The README's first command, scored against the example's truth: the default method beats a constant normal."""
    from imu_ground.evaluation.metrics import normal_angle
    out = tmp_path / "example_ground.csv"
    assert cli("estimate", EXAMPLE, "-o", out)[0] == 0
    est = pd.read_csv(out, comment="#")
    truth = pd.read_csv(TRUTH).iloc[1:].reset_index(drop=True)
    assert np.allclose(est["t"], truth["t"])
    n_true = truth[["normal_x", "normal_y", "normal_z"]].to_numpy()
    moving = truth["speed"].to_numpy() > 3.0
    err_est = normal_angle(est[["normal_x", "normal_y", "normal_z"]].to_numpy(), n_true)[moving].mean()
    err_const = normal_angle(np.tile([0.0, 0.0, 1.0], (len(truth), 1)), n_true)[moving].mean()
    assert err_est < err_const
    err_filter = None
    assert cli("estimate", EXAMPLE, "-o", tmp_path / "f.csv", "--method", "filter")[0] == 0
    f = pd.read_csv(tmp_path / "f.csv", comment="#")
    err_filter = normal_angle(f[["normal_x", "normal_y", "normal_z"]].to_numpy(), n_true)[moving].mean()
    assert err_est < err_filter                     # the default is the better method here


def test_output_equal_to_the_input_is_refused(tmp_path, cli):
    log = tmp_path / "drive.csv"
    log.write_bytes(EXAMPLE.read_bytes())
    code, _, err = cli("estimate", log, "-o", log)
    assert code == 2
    one_error_line(err, "drive.csv", "input log")
    assert log.read_bytes() == EXAMPLE.read_bytes()


def test_a_failed_second_output_leaves_no_first_output(tmp_path, cli):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    out = tmp_path / "g.csv"
    code, _, err = cli("estimate", EXAMPLE, "-o", out, "--tum", blocker / "poses.tum")
    assert code == 2
    one_error_line(err, "poses.tum", "--tum")
    assert not out.exists()


def test_tum_into_a_missing_folder_creates_it(tmp_path, cli):
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "g.csv", "--tum", tmp_path / "new" / "p.tum")
    assert code == 0, err
    assert (tmp_path / "new" / "p.tum").is_file() and (tmp_path / "g.csv").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.csv", "new"]      # no temporary left


@pytest.mark.parametrize("target", ["folder", "under_file"])
def test_output_folder_or_under_a_file_is_one_line(tmp_path, target, cli):
    (tmp_path / "f.csv").write_text("x")
    out = tmp_path if target == "folder" else tmp_path / "f.csv" / "g.csv"
    code, _, err = cli("estimate", EXAMPLE, "-o", out)
    assert code == 2
    one_error_line(err, str(out), "-o")


@pytest.mark.parametrize("flag,value", [("--Q", "-1"), ("--R", "0"), ("--rate", "0"), ("--Q", "nan")])
def test_noise_and_rate_must_be_positive(tmp_path, flag, value, cli):
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "g.csv", flag, value)
    assert code == 2
    one_error_line(err, flag, value)
    assert len(err.strip().splitlines()) == 1                    # no usage block, one line
    assert not (tmp_path / "g.csv").exists()


def test_library_checks_the_same_options():
    from imu_ground.pipeline import OptionError, estimate_log
    for kw, name in (({"Q": -1.0, "method": "filter"}, "Q"), ({"R": 0.0, "method": "filter"}, "R"),
                     ({"rate": 1000.0}, "rate")):
        with pytest.raises(OptionError) as e:
            estimate_log(EXAMPLE, **kw)
        assert f"{name} " in str(e.value) and f"--{name}" in e.value.cli_message()


def test_rate_above_the_imu_rate_is_refused(tmp_path, cli):
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "g.csv", "--rate", "1000")
    assert code == 2
    one_error_line(err, "--rate", "100 Hz", "example_drive.csv")


def test_noise_of_a_method_that_does_not_use_it_is_refused(tmp_path, cli):
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "g.csv", "--Q", "0.1")
    assert code == 2
    one_error_line(err, "--Q", "--method filter")
    assert cli("estimate", EXAMPLE, "-o", tmp_path / "g.csv", "--Q", "0.1", "--method", "filter")[0] == 0


def test_bad_input_is_one_line_naming_file_and_line(tmp_path, cli):
    code, _, err = cli("estimate", tmp_path / "missing.csv")
    assert code == 2
    one_error_line(err, "missing.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("t,wx,wy,wz,ax,ay,az\n0,0,0,0,0,0,9.8\n0.01,0,0,0,0,0,x\n")
    code, _, err = cli("estimate", bad, "-o", tmp_path / "g.csv")
    assert code == 2
    one_error_line(err, "bad.csv", "3")
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "g.xlsx")
    assert code == 2
    one_error_line(err, "g.xlsx", ".csv")


def test_gaps_summary_valid_frames_nan_in_csv_and_tum_without_them(gap_log, tmp_path, cli):
    out, tum = tmp_path / "g.csv", tmp_path / "g.tum"
    code, stdout, _ = cli("estimate", gap_log, "-o", out, "--tum", tum)
    assert code == 0
    df = pd.read_csv(out, comment="#")
    invalid = df["valid"].to_numpy() == 0
    assert invalid.sum() >= 25 and df.loc[invalid, "pitch_deg"].isna().all()
    ok = ~invalid
    p = df.loc[ok, "pitch_deg"]
    assert f"pitch {p.mean():+.3f} +- {p.std(ddof=0):.3f} deg" in stdout
    assert f"over the {ok.sum()} valid frames" in stdout
    assert len(np.loadtxt(tum)) == ok.sum()


# ------------------------------------------------------------------------------------------ pose files
def _write_kitti(path, R, p, index=False):
    rows = np.concatenate([R, p[:, :, None]], axis=2).reshape(len(R), 12)
    if index:
        rows = np.column_stack([np.arange(len(R)), rows])
    np.savetxt(path, rows, fmt="%.12e")


def test_kitti_and_tum_pose_files_are_accepted(tmp_path, cli):
    from scipy.spatial.transform import Rotation
    R, p, t = _poses()
    kitti, tum = tmp_path / "00.txt", tmp_path / "traj.txt"
    _write_kitti(kitti, R, p)
    np.savetxt(tum, np.column_stack([t, p, Rotation.from_matrix(R).as_quat()]), fmt="%.12f")
    code, stdout, err = cli("estimate", kitti, "-o", tmp_path / "k.csv", "--extrinsic", "kitti_cam0")
    assert code == 0, err
    assert stdout.startswith("kitti_poses pose file") and "method filter" in stdout
    k = pd.read_csv(tmp_path / "k.csv", comment="#")
    assert len(k) == len(R) - 1 and np.allclose(k["t"], np.arange(1, len(R)) / 10.0)
    code, stdout, err = cli("estimate", tum, "-o", tmp_path / "t.csv", "--format", "tum")
    assert code == 0, err
    assert np.allclose(pd.read_csv(tmp_path / "t.csv", comment="#")["t"], t[1:])
    code, _, err = cli("estimate", kitti, "-o", tmp_path / "r.csv", "--rate", "20")
    assert code == 0 and np.allclose(pd.read_csv(tmp_path / "r.csv", comment="#")["t"].iloc[0], 0.05)
    code, _, err = cli("estimate", kitti, "-o", tmp_path / "s.csv", "--method", "suspension")
    assert code == 2
    one_error_line(err, "--method", "accelerometer")


def test_a_pose_file_where_an_imu_log_is_needed_says_so(tmp_path, cli):
    R, p, _ = _poses()
    kitti = tmp_path / "00.txt"
    _write_kitti(kitti, R, p)
    code, _, err = cli("calibrate", kitti, "-o", tmp_path / "car.txt")
    assert code == 2
    one_error_line(err, "00.txt", "pose file", "IMU log")


def test_real_kitti_odometry_poses(shared_data, tmp_path, cli):
    poses = shared_data / "kitti_odometry" / "poses" / "00.txt"
    code, _stdout, err = cli("estimate", poses, "--extrinsic", "kitti_cam0", "-o", tmp_path / "00.csv")
    assert code == 0, err
    df = pd.read_csv(tmp_path / "00.csv", comment="#")
    assert len(df) == len(poses.read_text().splitlines()) - 1
    assert df["pitch_deg"].abs().max() < 10.0                     # camera axes mapped to the ground frame


# ------------------------------------------------------------------------------------------ conveniences
def test_version_and_python_dash_m(cli):
    from importlib.metadata import version

    from imu_ground._jit import DISABLE_JIT_ENV, JIT_ENABLED
    __version__ = version("imu-ground")
    mode = "loops compiled by numba" if JIT_ENABLED else "loops interpreted"
    code, out, _ = cli("--version")
    assert code == 0 and out.strip().startswith(f"imu-ground {__version__}, {mode}")
    r = subprocess.run([sys.executable, "-m", "imu_ground", "--version"], capture_output=True, text=True, check=False)
    assert r.returncode == 0 and r.stdout.strip() == out.strip()
    # the switch is reported: the version line tells how the loops run
    r = subprocess.run([sys.executable, "-m", "imu_ground", "--version"], capture_output=True, text=True, check=False,
                       env={**os.environ, DISABLE_JIT_ENV: "1"})
    assert r.stdout.strip() == f"imu-ground {__version__}, loops interpreted: {DISABLE_JIT_ENV} is set"


def _subparsers(parser):
    import argparse
    act = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return act.choices


def test_every_option_has_help_and_method_lists_the_methods():
    from imu_ground.pipeline.estimate import available_methods
    for name, sub in _subparsers(build_parser()).items():
        for action in sub._actions:
            assert str(action.help or "").strip(), (name, action.option_strings or action.dest)
    help_text = _subparsers(build_parser())["estimate"].format_help()
    for method, (description, _) in available_methods().items():
        assert method in help_text and " ".join(description.split()[:3]) in " ".join(help_text.split())
    from imu_ground.evaluation.runner import METHODS
    ev = " ".join(_subparsers(build_parser())["evaluate"].format_help().split())
    assert all(m in ev for m in METHODS)


def test_reader_flags_come_from_the_options_table():
    from imu_ground.datasets.options import READER_OPTIONS
    for cmd in ("estimate", "calibrate", "batch"):
        flags = {s for a in _subparsers(build_parser())[cmd]._actions for s in a.option_strings}
        assert {o.flag for o in READER_OPTIONS.values()} <= flags, cmd


def test_progress_bars_only_on_a_terminal(tmp_path, monkeypatch, cli):
    from imu_ground.cli._common import progress_enabled
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "g.csv")
    assert code == 0 and err == ""                               # stderr is not a terminal here
    args = build_parser().parse_args(["estimate", str(EXAMPLE)])
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert progress_enabled(args)
    args = build_parser().parse_args(["estimate", str(EXAMPLE), "--no-progress"])
    assert not progress_enabled(args)


def test_warnings_are_one_line_naming_the_file(tmp_path, cli):
    df = pd.read_csv(EXAMPLE)
    log = tmp_path / "dup.csv"
    pd.concat([df.iloc[:500], df.iloc[499:500], df.iloc[500:]]).to_csv(log, index=False)   # a repeated sample
    code, _, err = cli("estimate", log, "-o", tmp_path / "g.csv")
    assert code == 0
    lines = err.strip().splitlines()
    assert lines and all(ln.startswith(f"{log}: warning: ") for ln in lines), err
    assert "warnings.warn" not in err


def test_simulate_truth_names_its_angle_units(tmp_path, cli):
    sim = tmp_path / "s.csv"
    code, _, err = cli("simulate", "-o", sim, "--duration", "20", "--seed", "3", "--imu", "mems")
    assert code == 0, err
    truth = pd.read_csv(tmp_path / "s_truth.csv")
    assert {"pitch_deg", "roll_deg", "pitch_rate_deg_s"} <= set(truth.columns) and "pitch" not in truth.columns
    assert truth["pitch_deg"].abs().max() < 10.0
    assert cli("estimate", sim, "-o", tmp_path / "e.csv")[0] == 0


def test_evaluate_without_plots(tmp_path, cli):
    """evaluate without --plots runs (it once failed with 'too many values to unpack' on every such run)."""
    csv = tmp_path / "r.csv"
    code, out, err = cli("evaluate", "--synthetic", "1", "--grades", "mems", "--methods", "naive,paper",
                         "--csv", csv, "--per-drive")
    assert code == 0, err
    assert "synthetic-mems" in out and "per drive" in out
    assert set(pd.read_csv(csv)["method"]) == {"naive", "paper"}


def test_evaluate_bad_options_are_one_line(cli):
    code, _, err = cli("evaluate")
    assert code == 2
    one_error_line(err, "--real", "--synthetic")
    code, _, err = cli("evaluate", "--synthetic", "1", "--methods", "nope")
    assert code == 2
    one_error_line(err, "--methods", "nope")


def test_evaluate_synthetic_tables_and_plots(tmp_path, cli):
    pytest.importorskip("matplotlib")
    md, plots = tmp_path / "t.md", tmp_path / "plots"
    code, _out, err = cli("evaluate", "--synthetic", "1", "--grades", "nav", "--methods", "naive,paper",
                         "--markdown", md, "--plots", plots)
    assert code == 0, err
    assert md.read_text().startswith("| set | method |")
    assert any(p.name.startswith("pitch_") for p in plots.glob("*.png"))
