"""The command line's exits on input users produce: two outputs on one path, signals, a closed pipe, methods, rates."""
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from imu_ground.cli import main

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


def test_one_path_for_both_outputs_is_refused(tmp_path, capsys):
    same = tmp_path / "same.csv"
    assert main(["estimate", str(EXAMPLE), "-o", str(same), "--tum", str(same)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "-o and --tum" in err and str(same) in err
    assert not same.exists()


def test_closed_stdout_pipe_exits_quietly(tmp_path):
    p = subprocess.Popen([sys.executable, "-m", "imu_ground", "estimate", str(EXAMPLE), "-o", str(tmp_path / "x.csv")],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()                        # the reader went away, as `| head -1` does once it has its line
    err = p.stderr.read().decode()
    p.wait(timeout=120)
    assert err == "" and p.returncode == 141
    assert (tmp_path / "x.csv").is_file()    # the output was written before the summary lines


def test_sigterm_while_writing_leaves_no_temporary_folder(tmp_path):
    """The CSV writer is slowed down in the child so the signal lands while the file is being written."""
    marker = tmp_path / "writing"
    script = textwrap.dedent(f"""
        import sys, time
        from pathlib import Path
        import imu_ground.pipeline.output as output
        real = output._WRITERS[".csv"]
        def slow(path, table, meta):
            real(path, table, meta)
            Path({str(marker)!r}).write_text("x")
            time.sleep(60)
        output._WRITERS[".csv"] = slow
        from imu_ground.cli import main
        sys.exit(main(["estimate", {str(EXAMPLE)!r}, "-o", {str(tmp_path / "out.csv")!r}]))
    """)
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not marker.exists() and time.monotonic() < deadline and p.poll() is None:
        time.sleep(0.05)
    assert marker.exists(), p.communicate()
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 143 and "terminated" in err
    assert sorted(x.name for x in tmp_path.iterdir()) == ["writing"]       # no .out.csv.XXXX.tmp, no out.csv


def test_method_naive_is_the_static_extrinsics_constant_normal(tmp_path, capsys):
    from imu_ground.evaluation.baselines import ConstantNormal
    from imu_ground.filters import Extrinsic
    from imu_ground.filters.extrinsics import save_extrinsic
    from imu_ground.pipeline import estimate_log
    out = tmp_path / "naive.csv"
    ext = tmp_path / "tilted.txt"
    R = Extrinsic(Rotation.from_euler("xy", [4, -7], degrees=True).as_matrix())
    save_extrinsic(R, ext)
    assert main(["estimate", str(EXAMPLE), "--method", "naive", "--extrinsic", str(ext), "-o", str(out)]) == 0
    table = pd.read_csv(out, comment="#")
    res = estimate_log(EXAMPLE)
    ref = ConstantNormal(R).run(res.egomotion)                    # the evaluation's baseline, separately
    np.testing.assert_allclose(table[["normal_x", "normal_y", "normal_z"]].to_numpy(), ref.normal, atol=1e-8)
    np.testing.assert_allclose(table["pitch_deg"], 0.0, atol=1e-9)
    np.testing.assert_allclose(table[["normal_x", "normal_y", "normal_z"]].to_numpy()[0], R.rotation[2], atol=1e-8)


def test_simulate_rate(tmp_path, capsys):
    out = tmp_path / "fast.csv"
    assert main(["simulate", "-o", str(out), "--duration", "3", "--rate", "400"]) == 0
    t = pd.read_csv(out)["t"].to_numpy()
    np.testing.assert_allclose(np.diff(t), 1 / 400, atol=1e-9)
    assert main(["simulate", "-o", str(tmp_path / "bad.csv"), "--duration", "3", "--rate", "95"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--rate 95" in err



@pytest.mark.parametrize("args, said", [
    (["--duration", "1e7"], "--duration 1e+07: over the simulator's longest drive, 3600 s"),   # ran without end
    (["--duration", "0.05"], "--duration 0.05: shorter than one frame"),                       # one sample, exit 0
    (["--duration", "3600", "--rate", "200"], "--duration 3600 at 200 Hz: 720000 IMU samples"),
    (["--rate", "1e6", "--duration", "1"], "--rate 1e+06: over the simulator's highest IMU rate"),
    (["--duration", "nan"], "argument --duration"),
    (["--rate", "-100"], "argument --rate"),
    (["--seed", "-1"], "argument --seed: must be >= 0"),                                      # exit 3: numpy's error
])
def test_simulate_refuses_out_of_bounds_flags_in_one_line(tmp_path, cli, args, said):
    out = tmp_path / "s.csv"
    code, _, err = cli("simulate", "-o", out, *args)
    assert code == 2 and len(err.strip().splitlines()) == 1 and said in err, err
    assert not out.exists() and not (tmp_path / "s_truth.csv").exists()


@pytest.mark.parametrize("args, said", [
    (["--synthetic", "101"], "--synthetic 101: a suite has 0 to 100 drives"),
    (["--synthetic", "1", "--grades", "nav,mems,nav"], "--grades: nav given twice"),   # counted twice in the summary
    (["--synthetic", "1", "--seed", "-2"], "argument --seed: must be >= 0"),
    (["--synthetic", "1", "--methods", "naive,naive"], "--methods: naive given twice"),  # 'drives 2' of one drive
    (["--synthetic", "1", "--methods", ""], "--methods: names no method"),                 # ran every method
    (["--synthetic", "1", "--methods", " , "], "--methods: names no method"),
    (["--real", EXAMPLE], f"--real {EXAMPLE}: is a file"),                              # said 'folder not found'
    (["--synthetic", "1", "--plots", EXAMPLE], f"{EXAMPLE}: is a file; give --plots a folder"),  # 'File exists', late
])
def test_evaluate_refuses_bad_suites_and_paths_in_one_line(cli, args, said):
    code, _, err = cli("evaluate", *args)
    assert code == 2 and len(err.strip().splitlines()) == 1 and said in err, err


def test_evaluate_refuses_a_method_given_twice_in_the_library():
    from imu_ground.datasets.options import OptionError
    from imu_ground.evaluation.runner import check_methods, evaluate
    with pytest.raises(OptionError, match="naive given twice"):
        evaluate([], ["naive", "paper", "naive"], progress=False)
    with pytest.raises(OptionError, match="unknown kalman"):
        check_methods(["kalman"])
    assert check_methods(["paper", "naive"]) == ["paper", "naive"]
    with pytest.raises(OptionError, match="names no method"):
        check_methods([])

def test_suspension_step_on_a_bare_rotation_says_what_it_needs():
    from imu_ground.filters import SuspensionAwareFilter
    with pytest.raises(ValueError, match="EgoFrame.*accelerometer"):
        SuspensionAwareFilter().step(np.eye(3))


@pytest.fixture()
def frd_log(tmp_path):
    """The example drive as a z-down (FRD: x forward, y right, z down) sensor records it."""
    d = pd.read_csv(EXAMPLE)
    d[["wy", "wz", "ay", "az"]] *= -1
    path = tmp_path / "frd.csv"
    d.to_csv(path, index=False)
    return path


def test_a_z_down_sensor_without_extrinsic_is_refused_naming_extrinsic(frd_log, tmp_path, capsys):
    assert main(["estimate", str(frd_log), "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(frd_log) in err and "--extrinsic" in err
    assert "deg from the up axis" in err and not (tmp_path / "o.csv").exists()
    # with its calibration (found from the same log) it runs, and gives the FLU log's normal
    cal = tmp_path / "frd.txt"
    assert main(["calibrate", str(frd_log), "-o", str(cal)]) == 0
    assert main(["estimate", str(frd_log), "--extrinsic", str(cal), "-o", str(tmp_path / "o.csv")]) == 0


def test_a_camera_extrinsic_on_an_imu_log_is_refused(tmp_path, capsys):
    assert main(["estimate", str(EXAMPLE), "--extrinsic", "kitti_cam0", "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--extrinsic" in err and "kitti_cam0" in err


def test_a_tilted_extrinsic_is_warned_with_its_angle(tmp_path, capsys):
    from imu_ground.filters import Extrinsic
    from imu_ground.filters.extrinsics import save_extrinsic
    from imu_ground.pipeline.input_checks import gravity_angle
    ext = tmp_path / "tilted.txt"
    save_extrinsic(Extrinsic(Rotation.from_euler("x", 25, degrees=True).as_matrix()), ext)
    assert main(["estimate", str(EXAMPLE), "--extrinsic", str(ext), "-o", str(tmp_path / "o.csv")]) == 0
    err = capsys.readouterr().err
    angle = gravity_angle(pd.read_csv(EXAMPLE)[["ax", "ay", "az"]].to_numpy(), str(ext))
    assert 20 < angle < 30 and f"{angle:.1f} deg from the up axis" in err


@pytest.mark.parametrize("args", [["estimate", EXAMPLE, "--causal", "--rate", "200", "-o", "OUT"],
                                  ["stream", "--replay", EXAMPLE, "--rate", "200"],
                                  ["stream", "--replay", EXAMPLE, "--rate", "1e9"]])
def test_live_runs_refuse_a_frame_rate_above_the_logs_as_the_batch_run_does(tmp_path, cli, args):
    """``--causal`` and ``stream --replay`` made 200 Hz frames of a 100 Hz log (1e9 Hz: no end); the batch run refused."""
    out = tmp_path / "o.csv"
    code, stdout, err = cli(*[out if x == "OUT" else x for x in args])
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    said = ("above the live path's highest frame rate of 1000 Hz" if "1e9" in args   # (any log: refused first)
            else "above the IMU's own sample rate of 100 Hz")
    assert "--rate" in err and said in err and stdout == ""
    assert not out.exists()


def test_preview_of_a_missing_log_says_it_is_missing(tmp_path, cli):
    """It said the log needs its images."""
    code, _, err = cli("preview", tmp_path / "nope.csv", "-o", tmp_path / "p.png")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "nope.csv: no such file" in err, err
