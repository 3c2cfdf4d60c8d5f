"""Logs and outputs as fsspec URLs (``memory://``, ``file://``, ``s3://``) and open file objects.

The library reads ``memory://`` logs and open file objects as it reads local files (the same
arrays, messages naming the source); the command line takes ``file://`` URLs, refuses
``memory://`` (another process's memory) with exit status 2, and runs a batch against a local S3
endpoint (moto's server on 127.0.0.1, started here).
"""
import gzip
import io
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground import estimate_log, read_imu
from imu_ground.datasets import storage
from imu_ground.datasets.options import OptionError
from imu_ground.datasets.report import MalformedFileError
from imu_ground.pipeline.batch import RECORD_FOLDER, run_batch
from imu_ground.pipeline.estimate import estimate_to_files

fsspec = pytest.importorskip("fsspec")

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture
def memfs():
    """An empty ``memory://`` filesystem (emptied again after the test)."""
    fs = fsspec.filesystem("memory")
    fs.store.clear()
    fs.pseudo_dirs.clear()
    fs.pseudo_dirs.append("")
    yield fs
    fs.store.clear()


def _no_copy_named(obj) -> None:
    """No text in ``obj`` names a temporary local copy."""
    assert "imu-ground-in-" not in json.dumps(obj, default=str)


# ------------------------------------------------------------------------------------------ library: reading
def test_read_imu_on_memory_urls_equals_the_local_read_and_names_the_url(memfs):
    data = EXAMPLE.read_bytes()
    memfs.pipe("/logs/a.csv", data)
    memfs.pipe("/logs/b.csv.gz", gzip.compress(data))
    local = read_imu(EXAMPLE)
    for url in ("memory://logs/a.csv", "memory://logs/b.csv.gz"):
        imu = read_imu(url)
        assert np.array_equal(imu.t, local.t) and np.array_equal(imu.gyro, local.gyro)
        assert np.array_equal(imu.accel, local.accel)
        assert imu.source == url and imu.meta["validation"].source == url
    with pytest.raises(FileNotFoundError, match="memory://logs/none.csv: no such file"):
        read_imu("memory://logs/none.csv")
    lines = data.decode().splitlines(keepends=True)
    memfs.pipe("/logs/bad.csv", "".join(lines[:100] + ["1,2\n"] + lines[100:]).encode())
    with pytest.raises(MalformedFileError) as e:
        read_imu("memory://logs/bad.csv")
    assert str(e.value).startswith("memory://logs/bad.csv, line 101:") and e.value.path == "memory://logs/bad.csv"


def test_warnings_of_a_memory_log_name_its_url_once(memfs):
    lines = EXAMPLE.read_text().splitlines(keepends=True)
    memfs.pipe("/logs/gap.csv", "".join(lines[:2000] + lines[2300:]).encode())      # a 3 s gap
    with pytest.warns(UserWarning) as caught:
        read_imu("memory://logs/gap.csv")
    texts = [str(w.message) for w in caught]
    assert any(t.startswith("memory://logs/gap.csv: ") and "gap" in t for t in texts)
    assert not any("imu-ground-in-" in t for t in texts) and len(texts) == len(set(texts))


def test_read_imu_on_open_file_objects_binary_text_and_nameless_gzip():
    local = read_imu(EXAMPLE)
    with open(EXAMPLE, "rb") as fh:
        named = read_imu(fh)
    assert named.source == str(EXAMPLE)
    text = read_imu(io.StringIO(EXAMPLE.read_text()))
    nameless = read_imu(io.BytesIO(gzip.compress(EXAMPLE.read_bytes())))      # the format from its first bytes
    for imu in (named, text, nameless):
        assert np.array_equal(imu.t, local.t) and np.array_equal(imu.gyro, local.gyro)
    assert nameless.source == "<file object>"


def test_estimate_log_on_memory_url_and_file_object_equals_local(memfs):
    memfs.pipe("/logs/a.csv", EXAMPLE.read_bytes())
    local = estimate_log(EXAMPLE)
    remote = estimate_log("memory://logs/a.csv")
    with open(EXAMPLE, "rb") as fh:
        stream = estimate_log(fh)
    for res in (remote, stream):
        assert np.array_equal(res.track.pitch, local.track.pitch, equal_nan=True)
        assert np.array_equal(res.track.roll, local.track.roll, equal_nan=True)
    assert remote.meta["source"] == "memory://logs/a.csv" and remote.egomotion.meta["source"] == "memory://logs/a.csv"
    _no_copy_named(remote.meta)


def test_unknown_protocol_and_missing_filesystem_package_are_user_errors():
    with pytest.raises(storage.StorageError, match="nosuch:// is not a storage protocol"):
        read_imu("nosuch://bucket/x.csv")
    from fsspec.registry import known_implementations
    package = known_implementations["gs"]["class"].split(".")[0]
    try:
        __import__(package)
    except ImportError:
        with pytest.raises(storage.MissingFilesystemError, match=f"gs:// needs {package}: pip install {package}"):
            read_imu("gs://bucket/x.csv")
    else:
        pytest.skip(f"{package} is installed here")


# ------------------------------------------------------------------------------------------ library: writing
def test_outputs_to_memory_urls_are_the_local_bytes_and_no_local_folder(memfs, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    estimate_to_files(EXAMPLE, [tmp_path / "local.csv", tmp_path / "local.tum"], [None, ".tum"])
    estimate_to_files(EXAMPLE, ["memory://out/y.csv", "memory://out/y.tum"], [None, ".tum"])
    assert memfs.cat("/out/y.csv") == (tmp_path / "local.csv").read_bytes()
    assert memfs.cat("/out/y.tum") == (tmp_path / "local.tum").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["local.csv", "local.tum"]      # no folder "memory:"


def test_batch_on_memory_urls_writes_records_and_resumes(memfs):
    memfs.pipe("/fleet/a.csv", EXAMPLE.read_bytes())
    memfs.pipe("/fleet/day2/b.csv.gz", gzip.compress(EXAMPLE.read_bytes()))
    memfs.pipe("/fleet/broken.csv", b"t,wx,wy,wz,ax,ay,az\n0,0,0,0,0,0,9.8\n0.01,0,0,0,0,0,oops\n")
    first = run_batch(["memory://fleet/**/*.csv*"], "memory://out", workers=0, tum=True, speed="auto")
    by_name = first.set_index(first["log"].map(storage.url_name))
    assert list(by_name.loc[["a.csv", "b.csv.gz", "broken.csv"], "status"]) == ["ok", "ok", "failed"]
    assert "memory:///fleet/broken.csv" in by_name.loc["broken.csv", "error"]
    for name in ("a_ground", "b_ground"):
        assert memfs.exists(f"/out/{name}.csv") and memfs.exists(f"/out/{name}.tum")
        record = json.loads(memfs.cat(f"/out/{RECORD_FOLDER}/{name}.csv.json"))
        assert record["row"]["status"] == "ok" and record["row"]["frames"] == by_name.loc["a.csv", "frames"]
    summary = pd.read_csv(io.BytesIO(memfs.cat("/out/summary.csv")))
    assert list(summary["status"]) == list(first["status"])

    stamp = memfs.info("/out/a_ground.csv")["created"]
    again = run_batch(["memory://fleet/**/*.csv*"], "memory://out", workers=0, tum=True, speed="auto")
    skipped = again[again["status"] == "skipped (output exists)"]
    assert len(skipped) == 2 and memfs.info("/out/a_ground.csv")["created"] == stamp
    assert np.allclose(skipped["pitch_mean_deg"], first.loc[first["status"] == "ok", "pitch_mean_deg"])

    # an output without its record (its log's upload cut short) is estimated again
    memfs.rm(f"/out/{RECORD_FOLDER}/a_ground.csv.json")
    third = run_batch(["memory://fleet/a.csv"], "memory://out", workers=0, tum=True, speed="auto")
    assert list(third["status"]) == ["ok"] and memfs.exists(f"/out/{RECORD_FOLDER}/a_ground.csv.json")

    with pytest.raises(OptionError, match="memory:// is the memory of this process"):
        run_batch(["memory://fleet/a.csv"], "memory://out", workers=2)


# ------------------------------------------------------------------------------------------ command line
def test_cli_estimate_and_batch_take_file_urls(cli, tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("a.csv", "b.csv"):
        (logs / name).write_bytes(EXAMPLE.read_bytes())
    code, out, err = cli("estimate", f"file://{logs / 'a.csv'}", "-o", f"file://{tmp_path / 'y.csv'}")
    assert code == 0, err
    assert f"wrote {tmp_path / 'y.csv'}" in out
    code, out, err = cli("batch", f"file://{logs}/*.csv", "-o", f"file://{tmp_path / 'out'}", "--workers", "0")
    assert code == 0, err
    assert "2 logs: 2 estimated" in out
    assert (tmp_path / "out" / "a_ground.csv").read_bytes() == (tmp_path / "y.csv").read_bytes()
    assert (tmp_path / "out" / "summary.csv").exists()          # a local folder: the local code path, no records
    assert not (tmp_path / "out" / RECORD_FOLDER).exists()
    code, out, err = cli("batch", f"file://{logs}/*.csv", "-o", f"file://{tmp_path / 'out'}", "--workers", "0")
    assert code == 0 and "0 estimated, 2 skipped" in out


@pytest.mark.parametrize("args, flag", [
    (["estimate", "memory://logs/a.csv"], "LOG"),
    (["estimate", str(EXAMPLE), "-o", "memory://out/y.csv"], "-o"),
    (["batch", "memory://logs/*.csv", "-o", "out"], "LOG_OR_GLOB"),
    (["stream", "--replay", "memory://logs/a.csv"], "--replay"),
])
def test_cli_refuses_memory_urls(cli, tmp_path, monkeypatch, args, flag):
    monkeypatch.chdir(tmp_path)
    code, out, err = cli(*args)
    assert code == 2 and "Traceback" not in err
    assert "memory:// is the memory of one Python process" in err and f"give {flag} " in err
    assert list(tmp_path.iterdir()) == []                      # nothing written, no folder "memory:"


def test_cli_evaluate_writes_to_file_urls(cli, tmp_path):
    code, out, err = cli("evaluate", "--synthetic", "1", "--methods", "naive", "--csv",
                         f"file://{tmp_path / 'res.csv'}", "--markdown", f"file://{tmp_path / 'res.md'}")
    assert code == 0, err
    assert (tmp_path / "res.csv").stat().st_size and (tmp_path / "res.md").stat().st_size


# ------------------------------------------------------------------------------------------ S3 (moto, 127.0.0.1)
@pytest.fixture
def s3_endpoint(monkeypatch):
    """A local S3 endpoint (moto's server, 127.0.0.1, a free port) with a bucket ``fleet``; the endpoint and
    dummy credentials reach botocore through the standard environment variables."""
    pytest.importorskip("s3fs")
    moto_server = pytest.importorskip("moto.server")
    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    env = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1",
           "AWS_ENDPOINT_URL": f"http://{host}:{port}", "AWS_EC2_METADATA_DISABLED": "true"}
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    import urllib.request
    urllib.request.urlopen(urllib.request.Request(f"http://{host}:{port}/moto-api/reset", method="POST")).close()
    import s3fs                         # (moto's state is the process's: another test's buckets are reset above)
    s3fs.S3FileSystem.clear_instance_cache()
    fs = s3fs.S3FileSystem()
    fs.mkdir("fleet")
    yield fs
    s3fs.S3FileSystem.clear_instance_cache()
    server.stop()


def test_batch_against_local_s3_endpoint(cli, s3_endpoint, tmp_path):
    fs = s3_endpoint
    fs.pipe("fleet/logs/a.csv.gz", gzip.compress(EXAMPLE.read_bytes()))
    fs.pipe("fleet/logs/day2/b.csv", EXAMPLE.read_bytes())
    fs.pipe("fleet/logs/broken.csv", b"t,wx,wy,wz,ax,ay,az\n0,0,0,0,0,0,9.8\n0.01,0,0,0,0,0,oops\n")
    args = ["batch", "s3://fleet/logs/**/*.csv*", "-o", "s3://fleet/out", "--workers", "2", "--tum"]
    code, out, err = cli(*args)
    assert code == 1, err                                        # the broken log failed, the others went on
    assert "2 estimated, 0 skipped (output exists), 1 failed" in out and "s3://fleet/logs/broken.csv" in out
    keys = set(fs.find("fleet/out"))
    assert {"fleet/out/a_ground.csv", "fleet/out/a_ground.tum", "fleet/out/b_ground.csv", "fleet/out/summary.csv",
            f"fleet/out/{RECORD_FOLDER}/a_ground.csv.json", f"fleet/out/{RECORD_FOLDER}/b_ground.csv.json"} <= keys
    assert cli("estimate", EXAMPLE, "-o", tmp_path / "single.csv")[0] == 0
    assert fs.cat("fleet/out/b_ground.csv") == (tmp_path / "single.csv").read_bytes()    # estimate's bytes
    summary = pd.read_csv(io.BytesIO(fs.cat("fleet/out/summary.csv")))
    assert sorted(summary["status"]) == ["failed", "ok", "ok"]

    stamp = fs.info("fleet/out/a_ground.csv")["LastModified"]
    code, out, err = cli(*args)
    assert code == 1 and "0 estimated, 2 skipped (output exists), 1 failed" in out
    assert fs.info("fleet/out/a_ground.csv")["LastModified"] == stamp

    code, out, err = cli("estimate", "s3://fleet/logs/a.csv.gz", "-o", "s3://fleet/y.parquet")
    assert code == 0, err
    with fs.open("fleet/y.parquet", "rb") as fh:
        assert len(pd.read_parquet(fh)) == len(pd.read_csv(tmp_path / "single.csv", comment="#"))
    code, out, err = cli("estimate", "s3://fleet/logs/a.csv.gz", "-o", "s3://nobucket/y.csv")
    assert code == 2 and "no such bucket 'nobucket'" in err
    code, out, err = cli("estimate", "s3://fleet/logs/none.csv")
    assert code == 2 and "s3://fleet/logs/none.csv: no such file or folder" in err


def test_batch_on_a_dask_cluster_writes_through_fsspec(cli, s3_endpoint, tmp_path):
    """--scheduler with an output URL: the worker uploads the output and its record, the client the summary."""
    import logging

    pytest.importorskip("dask.distributed")
    from dask.distributed import LocalCluster
    fs = s3_endpoint
    fs.pipe("fleet/logs/day2/b.csv", EXAMPLE.read_bytes())
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster:
        code, out, err = cli("batch", "s3://fleet/logs/day2/*.csv", "-o", "s3://fleet/cluster",
                             "--scheduler", cluster.scheduler_address)
    assert code == 0, err
    assert cli("estimate", EXAMPLE, "-o", tmp_path / "single.csv")[0] == 0
    assert fs.cat("fleet/cluster/b_ground.csv") == (tmp_path / "single.csv").read_bytes()
    assert fs.exists(f"fleet/cluster/{RECORD_FOLDER}/b_ground.csv.json") and fs.exists("fleet/cluster/summary.csv")


def test_cli_planes_folder_url_is_refused_before_any_work(cli, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "--planes", "s3://bucket/planes",
                         "-o", tmp_path / "y.csv")
    assert code == 2 and "give --planes a local folder" in err
    assert list(tmp_path.iterdir()) == []                      # no folder "s3:"


def test_cli_names_a_missing_filesystem_package_before_any_work(cli, tmp_path, monkeypatch):
    from fsspec.registry import known_implementations
    package = known_implementations["gs"]["class"].split(".")[0]
    try:
        __import__(package)
        pytest.skip(f"{package} is installed here")
    except ImportError:
        pass
    monkeypatch.chdir(tmp_path)
    code, out, err = cli("estimate", EXAMPLE, "-o", "gs://bucket/y.csv")
    assert code == 2 and f"gs://bucket/y.csv: gs:// needs {package}: pip install {package}" in err
    assert out == "" and list(tmp_path.iterdir()) == []
