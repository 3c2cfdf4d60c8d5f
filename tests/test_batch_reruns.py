"""``imu-ground batch``: one file named twice, reruns with other settings (``--force``), ``--tum`` and ``--speed``;
one run at a time in a folder (its lock), its own outputs never read as logs."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from imu_ground.cli import main
from imu_ground.pipeline.batch import LOCK_NAME, output_folder_lock, output_names

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture()
def log_dir(tmp_path):
    (tmp_path / "a").mkdir()
    shutil.copy(EXAMPLE, tmp_path / "a" / "ex.csv")
    return tmp_path


def _cli(cwd, *args):
    """``imu-ground`` in a subprocess: (exit status, stdout, stderr)."""
    p = subprocess.run([sys.executable, "-m", "imu_ground", *args], cwd=cwd, capture_output=True, text=True,
                       timeout=300)
    return p.returncode, p.stdout, p.stderr


def test_one_file_named_twice_is_estimated_once_inside_the_output_folder(log_dir):
    code, out, err = _cli(log_dir, "batch", "a/ex.csv", "a/../a/ex.csv", "-o", "OUT", "--workers", "0")
    assert code == 0, err
    assert sorted(p.name for p in (log_dir / "OUT").iterdir()) == ["ex_ground.csv", "summary.csv"]
    assert "duplicate a/../a/ex.csv: the same file as a/ex.csv" in out
    summary = pd.read_csv(log_dir / "OUT" / "summary.csv")
    assert list(summary["status"]) == ["ok", "duplicate"]


def test_output_names_are_never_paths():
    names = output_names(["/x/ex.csv", "/x/ex.csv", "ex.csv"])
    assert all(os.sep not in n and not n.startswith("/") for n in names)
    assert len(set(names)) == 3


def test_rerun_with_another_method_refuses_naming_force_then_force_replaces(log_dir, capsys):
    out = log_dir / "OUT"
    log = str(log_dir / "a" / "ex.csv")
    assert main(["batch", log, "-o", str(out), "--workers", "0"]) == 0
    first = (out / "ex_ground.csv").read_bytes()
    capsys.readouterr()
    assert main(["batch", log, "-o", str(out), "--workers", "0", "--method", "filter"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--force" in err and "method auto -> filter" in err
    assert (out / "ex_ground.csv").read_bytes() == first                     # nothing touched
    assert main(["batch", log, "-o", str(out), "--workers", "0", "--method", "filter", "--force"]) == 0
    assert "method filter" in (out / "ex_ground.csv").read_text().splitlines()[0]
    capsys.readouterr()
    # the same settings again: kept
    assert main(["batch", log, "-o", str(out), "--workers", "0", "--method", "filter"]) == 0
    assert "1 skipped (output exists)" in capsys.readouterr().out


def test_batch_tum_and_speed_as_estimate(log_dir, capsys):
    out = log_dir / "OUT"
    log = log_dir / "a" / "ex.csv"
    speed = log_dir / "speed.csv"
    speed.write_text("t,speed\n0,10\n100,10\n")
    assert main(["batch", str(log), "-o", str(out), "--workers", "0", "--tum", "--speed", str(speed)]) == 0
    assert (out / "ex_ground.tum").is_file()
    single = log_dir / "single.csv"
    assert main(["estimate", str(log), "-o", str(single), "--speed", str(speed)]) == 0
    assert (out / "ex_ground.csv").read_bytes() == single.read_bytes()
    assert "speed.csv" in (out / "ex_ground.csv").read_text().splitlines()[1]


def test_a_second_run_on_the_same_folder_exits_2_naming_the_running_one(log_dir, cli, one_error):
    out = log_dir / "OUT"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom imu_ground.pipeline.batch import output_folder_lock\n"
         "with output_folder_lock(sys.argv[1]):\n    print('locked', flush=True)\n    time.sleep(60)\n", str(out)],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        code, _, err = cli("batch", log_dir / "a" / "ex.csv", "-o", out, "--workers", "0")
        assert code == 2
        one_error(err, str(out), f"pid {holder.pid}", "started", "-o")
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]          # nothing written, the lock kept
    finally:
        holder.kill()
        holder.wait()
    # the holder is gone (killed, its lock file left behind): the next run takes over, saying so
    code, stdout, err = cli("batch", log_dir / "a" / "ex.csv", "-o", out, "--workers", "0")
    assert code == 0, err
    assert f"pid {holder.pid}" in err and "no longer runs" in err and "Traceback" not in err
    assert sorted(p.name for p in out.iterdir()) == ["ex_ground.csv", "summary.csv"]   # lock removed at the end


def test_a_stale_lock_file_of_a_dead_process_is_taken_over(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (tmp_path / LOCK_NAME).write_text(json.dumps({"pid": int(dead.stdout), "started": "yesterday"}))
    with pytest.warns(UserWarning, match=f"pid {int(dead.stdout)}.*no longer runs"):
        with output_folder_lock(tmp_path) as path:
            assert json.loads(path.read_text())["pid"] == os.getpid()
    assert not (tmp_path / LOCK_NAME).exists()


def test_a_rerun_on_a_glob_that_matches_its_own_outputs_skips_them(log_dir, cli):
    out = log_dir / "a"                                          # outputs beside the logs
    code, _, err = cli("batch", str(log_dir / "a" / "*.csv"), "-o", out, "--workers", "0", "--tum")
    assert code == 0, err
    for _ in range(2):
        code, stdout, err = cli("batch", str(log_dir / "a" / "*"), "-o", out, "--workers", "0", "--tum")
        assert code == 0, (stdout, err)
        assert "FAILED" not in stdout
        assert "1 logs: 0 estimated, 1 skipped" in stdout
        assert "ex_ground.csv" in err and "written by imu-ground" in err
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary["log"]) == [str(log_dir / "a" / "ex.csv")]


def test_skipped_lines_show_the_recorded_format(log_dir, cli):
    for kind in ("csv", "parquet", "tum"):
        out = log_dir / f"OUT_{kind}"
        code, _, err = cli("batch", log_dir / "a" / "ex.csv", "-o", out, "--workers", "0", "--type", kind)
        assert code == 0, err
        code, stdout, err = cli("batch", log_dir / "a" / "ex.csv", "-o", out, "--workers", "0", "--type", kind)
        assert code == 0, err
        line = next(ln for ln in stdout.splitlines() if ln.startswith("skipped"))
        after = line.split(": ", 1)[1]
        assert not after.startswith(" "), line                  # no blank where the format goes
        assert after.startswith("table ") if kind != "tum" else after.startswith("(format not recorded)"), line
        if kind != "tum":
            summary = pd.read_csv(out / "summary.csv")
            assert list(summary["format"]) == ["table"] and list(summary["method"]) == ["suspension"]
