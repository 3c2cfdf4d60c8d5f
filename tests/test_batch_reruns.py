"""``imu-ground batch``: one file named twice, reruns with other settings (``--force``), ``--tum`` and ``--speed``."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from imu_ground.cli import main
from imu_ground.pipeline.batch import output_names

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
