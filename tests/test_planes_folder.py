"""``--planes DIR``: only a folder this tool wrote is replaced, never lost, never left half-swapped."""
import json
import os
import signal
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_ground.cli import Terminated, _sigterm_as_exception
from imu_ground.pipeline.planes import PLANES_MARKER, read_kitti_planes, write_kitti_planes

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"
LEVEL = [0.0, -1.0, 0.0, 1.65]


def _estimate(cli, tmp_path, planes, *more):
    return cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "--planes", planes, *more)


def test_a_kitti_label_or_calib_folder_is_refused_untouched(tmp_path, cli, one_error):
    label = "Car 0.00 0 -1.58 587.01 173.33 614.12 200.12 1.65 1.67 3.64 -0.65 1.71 46.70 -1.59\n"
    for kind, text in (("label_2", label),
                       ("calib", "P0: 7.07e+02 0 6.04e+02 0 0 7.07e+02 1.80e+02 0 0 0 1 0\n")):
        folder = tmp_path / kind
        folder.mkdir()
        (folder / "000000.txt").write_text(text)
        (folder / "000001.txt").write_text(text)
        code, _, err = _estimate(cli, tmp_path, folder, "-o", tmp_path / "g.csv")
        assert code == 2
        one_error(err, str(folder), "000000.txt", "--planes")
        assert sorted(p.name for p in folder.iterdir()) == ["000000.txt", "000001.txt"]
        assert (folder / "000000.txt").read_text() == text
        with pytest.raises(ValueError, match="000000.txt"):                      # the library refuses too
            write_kitti_planes(folder, [LEVEL])
        assert (folder / "000000.txt").read_text() == text
    assert not (tmp_path / "g.csv").exists()


def test_an_input_log_inside_the_planes_folder_is_refused(tmp_path, cli, one_error):
    folder = tmp_path / "p"
    code, _, err = _estimate(cli, tmp_path, folder, "-o", tmp_path / "g.csv")
    assert code == 0, err
    log = folder / "000001.txt"                           # a log named like a planes file, in a folder we wrote
    log.write_bytes(EXAMPLE.read_bytes())
    code, _, err = cli("estimate", log, "--format", "table", "--camera", "kitti_cam2", "--planes", folder,
                       "-o", tmp_path / "g2.csv")
    assert code == 2
    one_error(err, str(log), "--planes")
    assert log.read_bytes() == EXAMPLE.read_bytes()


def test_a_folder_this_tool_wrote_is_replaced_and_output_inside_works_on_every_rerun(tmp_path, cli, one_error):
    folder = tmp_path / "P"
    for _ in range(3):                                    # the identical rerun, twice
        code, _, err = _estimate(cli, tmp_path, folder, "-o", folder / "o.csv", "--tum", folder / "o.tum")
        assert code == 0, err
    names = sorted(p.name for p in folder.iterdir())
    assert names[:3] == [PLANES_MARKER, "000000.txt", "000001.txt"] and names[-2:] == ["o.csv", "o.tum"]
    assert json.loads((folder / PLANES_MARKER).read_text())["frames"] == len(names) - 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["P"]          # nothing left beside it
    # a file of the user's added to it: refused, kept
    (folder / "notes.md").write_text("mine")
    code, _, err = _estimate(cli, tmp_path, folder, "-o", folder / "o.csv")
    assert code == 2
    one_error(err, "notes.md", "--planes")
    assert (folder / "notes.md").read_text() == "mine" and (folder / "o.csv").exists()


def test_the_folder_takes_its_permissions_from_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        write_kitti_planes(tmp_path / "a", [LEVEL])
        os.umask(0o027)
        write_kitti_planes(tmp_path / "b", [LEVEL])
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "a").stat().st_mode) == 0o755
    assert stat.S_IMODE((tmp_path / "b").stat().st_mode) == 0o750
    os.chmod(tmp_path / "a", 0o775)                       # a replaced folder keeps the mode it had
    write_kitti_planes(tmp_path / "a", [LEVEL, LEVEL])
    assert stat.S_IMODE((tmp_path / "a").stat().st_mode) == 0o775


def test_a_signal_between_the_two_renames_loses_neither_folder(tmp_path, monkeypatch):
    folder = tmp_path / "planes"
    write_kitti_planes(folder, [LEVEL] * 3)
    real = os.replace
    calls = []

    def replace_then_signal(src, dst):
        real(src, dst)
        calls.append((Path(src).name, Path(dst).name))
        if len(calls) == 1:                               # the old folder just moved aside
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(os, "replace", replace_then_signal)
    new = [[0.0, -1.0, 0.0, 1.5]] * 2
    with _sigterm_as_exception(), pytest.raises(Terminated):
        write_kitti_planes(folder, new)
    monkeypatch.setattr(os, "replace", real)
    assert len(calls) == 2                                # the swap was finished before the signal was acted on
    assert sorted(p.name for p in folder.iterdir()) == [PLANES_MARKER, "000000.txt", "000001.txt"]
    assert np.allclose(read_kitti_planes(folder / "000000.txt"), new[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["planes"]     # no .planes.*.tmp(.old) left


def test_a_later_run_removes_its_own_stale_leftovers_only(tmp_path):
    folder = tmp_path / "planes"
    write_kitti_planes(folder, [LEVEL])
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    marker = json.dumps({"written_by": "imu-ground", "pid": dead_pid})
    for name in (".planes.abc123.tmp.old", ".planes.def456.tmp"):          # what a killed run leaves
        d = tmp_path / name
        d.mkdir()
        (d / PLANES_MARKER).write_text(marker)
        (d / "000000.txt").write_text("x")
    live = tmp_path / ".planes.live00.tmp"                                   # a run in progress: kept
    live.mkdir()
    (live / PLANES_MARKER).write_text(json.dumps({"pid": os.getpid()}))
    foreign = tmp_path / ".planes.user.tmp"                                  # not ours: kept
    foreign.mkdir()
    (foreign / "keep.txt").write_text("mine")
    write_kitti_planes(folder, [LEVEL, LEVEL])
    assert sorted(p.name for p in tmp_path.iterdir()) == [".planes.live00.tmp", ".planes.user.tmp", "planes"]
    assert (foreign / "keep.txt").read_text() == "mine"


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc (a folder nobody can write in)")
def test_an_unwritable_planes_folder_is_named_not_the_temporary_one(tmp_path, cli, one_error):
    code, _, err = _estimate(cli, tmp_path, "/proc/imu_ground_planes", "-o", tmp_path / "g.csv")
    assert code == 2
    line = one_error(err, "/proc/imu_ground_planes", "--planes")
    assert ".tmp" not in line
    assert not (tmp_path / "g.csv").exists()


def test_what_an_interrupted_output_write_left_inside_does_not_block_the_rerun(tmp_path, cli):
    folder = tmp_path / "P"
    code, _, err = _estimate(cli, tmp_path, folder, "-o", folder / "o.csv")
    assert code == 0, err
    (folder / ".o.csv.k1ll3d.tmp").mkdir()                # the output's staging folder of a killed run
    (folder / ".o.csv.k1ll3d.tmp" / "o.csv").write_text("half")
    code, _, err = _estimate(cli, tmp_path, folder, "-o", folder / "o.csv")
    assert code == 0, err
    assert not (folder / ".o.csv.k1ll3d.tmp").exists()
