"""``imu-ground batch -o OUT``: one run at a time in a folder, its own outputs never read as logs."""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from imu_ground.pipeline.batch import LOCK_NAME, output_folder_lock

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture()
def logs(tmp_path):
    (tmp_path / "a").mkdir()
    shutil.copy(EXAMPLE, tmp_path / "a" / "ex.csv")
    return tmp_path


def _one_error(err, *words):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, err)
    return lines[0]


def test_a_second_run_on_the_same_folder_exits_2_naming_the_running_one(logs, cli):
    out = logs / "OUT"
    out.mkdir()
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom imu_ground.pipeline.batch import output_folder_lock\n"
         "with output_folder_lock(sys.argv[1]):\n    print('locked', flush=True)\n    time.sleep(60)\n", str(out)],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        code, _, err = cli("batch", logs / "a" / "ex.csv", "-o", out, "--workers", "0")
        assert code == 2
        _one_error(err, str(out), f"pid {holder.pid}", "started", "-o")
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME]          # nothing written, the lock kept
    finally:
        holder.kill()
        holder.wait()
    # the holder is gone (killed, its lock file left behind): the next run takes over, saying so
    code, stdout, err = cli("batch", logs / "a" / "ex.csv", "-o", out, "--workers", "0")
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


def test_a_rerun_on_a_glob_that_matches_its_own_outputs_skips_them(logs, cli):
    out = logs / "a"                                          # outputs beside the logs
    code, _, err = cli("batch", str(logs / "a" / "*.csv"), "-o", out, "--workers", "0", "--tum")
    assert code == 0, err
    for _ in range(2):
        code, stdout, err = cli("batch", str(logs / "a" / "*"), "-o", out, "--workers", "0", "--tum")
        assert code == 0, (stdout, err)
        assert "FAILED" not in stdout
        assert "1 logs: 0 estimated, 1 skipped" in stdout
        assert "ex_ground.csv" in err and "written by imu-ground" in err
    summary = pd.read_csv(out / "summary.csv")
    assert list(summary["log"]) == [str(logs / "a" / "ex.csv")]


def test_skipped_lines_show_the_recorded_format(logs, cli):
    for kind in ("csv", "parquet", "tum"):
        out = logs / f"OUT_{kind}"
        code, _, err = cli("batch", logs / "a" / "ex.csv", "-o", out, "--workers", "0", "--type", kind)
        assert code == 0, err
        code, stdout, err = cli("batch", logs / "a" / "ex.csv", "-o", out, "--workers", "0", "--type", kind)
        assert code == 0, err
        line = next(ln for ln in stdout.splitlines() if ln.startswith("skipped"))
        after = line.split(": ", 1)[1]
        assert not after.startswith(" "), line                  # no blank where the format goes
        assert after.startswith("table ") if kind != "tum" else after.startswith("(format not recorded)"), line
        if kind != "tum":
            summary = pd.read_csv(out / "summary.csv")
            assert list(summary["format"]) == ["table"] and list(summary["method"]) == ["suspension"]
