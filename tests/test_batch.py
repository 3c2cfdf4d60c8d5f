"""``imu-ground batch`` on a local Dask cluster: one output per log (equal to estimate's), a broken log, a rerun."""
import shutil
from pathlib import Path

import pandas as pd
import pytest

from imu_ground.cli import main

pytest.importorskip("dask.distributed")

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Four small logs (the example cut in pieces, one in a sub-folder) and one broken log."""
    d = tmp_path_factory.mktemp("fleet")
    df = pd.read_csv(EXAMPLE)
    for i, (a, b) in enumerate([(0, 2000), (1500, 3500), (3000, 6001)]):
        df.iloc[a:b].to_csv(d / f"drive{i}.csv", index=False)
    (d / "sub").mkdir()
    shutil.copy(EXAMPLE, d / "sub" / "drive3.csv")
    (d / "broken.csv").write_text("t,wx,wy,wz,ax,ay,az\n0,0,0,0,0,0,9.8\n0.01,0,0,0,0,0,oops\n")
    return d


def test_batch_local_cluster_broken_log_and_rerun(fleet, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["batch", str(fleet / "*.csv"), str(fleet / "sub" / "drive3.csv"), str(fleet / "nothing*.csv"),
                 "-o", str(out), "--workers", "2"])
    stdout = capsys.readouterr().out
    assert code == 1                                              # some logs failed, the others went on
    summary = pd.read_csv(out / "summary.csv")
    assert len(summary) == 6
    by_log = summary.set_index(summary["log"].map(lambda p: Path(p).name))
    assert by_log.loc["broken.csv", "status"] == "failed" and "broken.csv" in by_log.loc["broken.csv", "error"]
    assert by_log.loc["nothing*.csv", "status"] == "failed" and "no file matches" in by_log.loc["nothing*.csv", "error"]
    ok = summary[summary["status"] == "ok"]
    assert len(ok) == 4 and (ok["format"] == "table").all() and (ok["method"] == "suspension").all()
    assert (ok["valid_share"] == 1.0).all() and ok["pitch_std_deg"].notna().all()
    assert sorted(p.name for p in out.glob("*_ground.csv")) == ["drive0_ground.csv", "drive1_ground.csv",
                                                                  "drive2_ground.csv", "drive3_ground.csv"]
    assert "4 estimated, 0 skipped (output exists), 2 failed" in stdout

    # the same bytes as `imu-ground estimate` writes
    single = tmp_path / "single.csv"
    assert main(["estimate", str(fleet / "drive1.csv"), "-o", str(single)]) == 0
    assert (out / "drive1_ground.csv").read_bytes() == single.read_bytes()

    # rerun: complete outputs are skipped, the failing log is tried again
    stamp = (out / "drive0_ground.csv").stat().st_mtime_ns
    code = main(["batch", str(fleet / "*.csv"), str(fleet / "sub" / "drive3.csv"), "-o", str(out), "--workers", "2"])
    stdout = capsys.readouterr().out
    assert code == 1
    assert "0 estimated, 4 skipped (output exists), 1 failed" in stdout
    assert (out / "drive0_ground.csv").stat().st_mtime_ns == stamp
    rerun = pd.read_csv(out / "summary.csv")
    assert rerun.loc[rerun["status"].str.startswith("skipped"), "frames"].notna().all()


def test_batch_in_process_and_name_clashes(fleet, tmp_path, capsys):
    from imu_ground.pipeline.batch import output_names, run_batch
    names = output_names([str(fleet / "drive3.csv"), str(fleet / "sub" / "drive3.csv")])
    assert len(set(names)) == 2
    table = run_batch([fleet / "drive0.csv"], tmp_path / "o", workers=0, suffix=".parquet")
    assert list(table["status"]) == ["ok"] and (tmp_path / "o" / "drive0_ground.parquet").is_file()


def test_batch_bad_options_fail_before_any_log(fleet, tmp_path, capsys):
    code = main(["batch", str(fleet / "drive0.csv"), "-o", str(tmp_path / "o"), "--workers", "0",
                 "--method", "filter", "--Q", "0.5", "--R", "2"])
    assert code == 0
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(["batch", str(fleet / "drive0.csv"), "-o", str(tmp_path / "o"), "--rate", "-3"])
    assert e.value.code == 2
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["batch", str(fleet / "drive0.csv"), "-o", str(blocker), "--workers", "0"]) == 2
    assert "give -o an output folder" in capsys.readouterr().err


def test_batch_on_a_running_dask_cluster(fleet, tmp_path, capsys):
    """--scheduler ADDRESS: the logs go to an existing dask.distributed cluster; same bytes as the local pool."""
    import logging

    from dask.distributed import LocalCluster
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster:
        remote = tmp_path / "remote"
        code = main(["batch", str(fleet / "drive0.csv"), str(fleet / "broken.csv"), "-o", str(remote),
                     "--scheduler", cluster.scheduler_address])
    assert code == 1 and "1 estimated, 0 skipped (output exists), 1 failed" in capsys.readouterr().out
    local = tmp_path / "local"
    assert main(["batch", str(fleet / "drive0.csv"), "-o", str(local), "--workers", "0"]) == 0
    assert (remote / "drive0_ground.csv").read_bytes() == (local / "drive0_ground.csv").read_bytes()


def test_worker_start_method_forks_only_in_a_single_threaded_process(monkeypatch):
    import multiprocessing
    import threading

    from imu_ground.pipeline import batch
    release = threading.Event()
    other = threading.Thread(target=release.wait)
    other.start()
    try:
        assert batch._start_method() == "spawn"          # another thread could hold a lock the child inherits
    finally:
        release.set()
        other.join()
    monkeypatch.setattr(threading, "active_count", lambda: 1)
    expected = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    assert batch._start_method() == expected


def _estimate_bytes(log: Path, tmp_path: Path) -> bytes:
    single = tmp_path / f"{log.stem}_single.csv"
    assert main(["estimate", str(log), "-o", str(single)]) == 0
    return single.read_bytes()


def test_batch_from_a_fresh_process_forks_its_workers_and_writes_estimates_bytes(fleet, tmp_path):
    import multiprocessing
    import subprocess
    import sys
    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork start method on this platform")
    code = ("import sys; from imu_ground.pipeline import batch; print(batch._start_method()); "
            "t = batch.run_batch(sys.argv[1:3], sys.argv[3], workers=2); print(','.join(t['status']))")
    logs = [fleet / "drive0.csv", fleet / "broken.csv"]
    done = subprocess.run([sys.executable, "-c", code, *map(str, logs), str(tmp_path / "out")],
                          capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["fork", "ok,failed"]      # a fresh process runs one thread: it forks
    assert (tmp_path / "out" / "drive0_ground.csv").read_bytes() == _estimate_bytes(logs[0], tmp_path)


def test_batch_with_spawned_workers_writes_estimates_bytes(fleet, tmp_path, monkeypatch):
    from imu_ground.pipeline import batch, run_batch
    monkeypatch.setattr(batch, "_start_method", lambda: "spawn")
    logs = [fleet / "drive0.csv", fleet / "drive2.csv", fleet / "broken.csv"]
    table = run_batch(logs, tmp_path / "out", workers=2)
    assert list(table["status"]) == ["ok", "ok", "failed"]
    for log in logs[:2]:
        assert (tmp_path / "out" / f"{log.stem}_ground.csv").read_bytes() == _estimate_bytes(log, tmp_path)


def test_local_pool_never_starts_more_workers_than_logs_or_four_a_core(monkeypatch):
    """``--workers 100000`` once started 4,000 processes and exhausted the memory: capped now."""
    import os
    import warnings

    from imu_ground.pipeline import batch
    with warnings.catch_warnings():
        warnings.simplefilter("error")                      # fewer logs than workers: capped without a word
        with batch._local_pool(100000, 2) as pool:
            assert pool._max_workers == 2
    monkeypatch.setattr(os, "cpu_count", lambda: 1)
    with pytest.warns(UserWarning, match=r"--workers 10 capped to 4 \(4 a CPU core of 1"):
        with batch._local_pool(10, 50, cli=True) as pool:
            assert pool._max_workers == batch.WORKERS_PER_CORE == 4
