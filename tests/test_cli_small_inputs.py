"""Small command-line rows: Ctrl-C during the imports, negative scientific numbers, gap lengths, column order,
``.tum`` with a camera."""
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.pipeline.output import COLUMNS

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"

#: Runs the console script's own two lines (or ``python -m imu_ground``) with a SIGINT sent to the process
#: when numpy is first imported: a Ctrl-C while the command is still loading the library.
_INTERRUPT_AT_IMPORT = textwrap.dedent("""
    import os, runpy, signal, sys

    signal.signal(signal.SIGINT, signal.default_int_handler)   # as from a terminal (a background job ignores it)

    class CtrlCAtNumpy:
        def find_spec(self, name, path=None, target=None):
            if name == "numpy":
                sys.meta_path.remove(self)
                os.kill(os.getpid(), signal.SIGINT)
            return None

    sys.meta_path.insert(0, CtrlCAtNumpy())
    sys.argv = ["imu-ground", *sys.argv[1:]]
""")


@pytest.mark.parametrize("how", ["console script", "python -m"])
def test_ctrl_c_while_importing_is_one_line_and_exit_130(tmp_path, how):
    start = ("from imu_ground.cli import main\nsys.exit(main())" if how == "console script"
             else "runpy.run_module('imu_ground', run_name='__main__')")
    args = ["estimate", str(EXAMPLE), "-o", str(tmp_path / "g.csv")]
    p = subprocess.run([sys.executable, "-c", _INTERRUPT_AT_IMPORT + start, *args], capture_output=True, text=True,
                       timeout=120, cwd=tmp_path)
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert p.returncode == 130, p.stderr
    assert lines == ["imu-ground: interrupted"], p.stderr
    assert not (tmp_path / "g.csv").exists()


def test_the_console_module_imports_nothing_heavy():
    code = "import sys, imu_ground.cli; print(sorted(m for m in sys.modules if m.split('.')[0] in ('numpy', 'pandas')))"
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and p.stdout.strip() == "[]", p.stdout + p.stderr


def test_negative_numbers_in_scientific_notation_are_values(tmp_path, cli):
    code, _, err = cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "--bev", "0", "1e5", "-1e5", "1e5", "1e3",
                       "-o", tmp_path / "g.csv")
    assert code == 0, err
    table = pd.read_csv(tmp_path / "g.csv", comment="#")
    assert np.isfinite(table["bev_h00"]).all()
    from imu_ground.cli import build_parser
    a = build_parser().parse_args(["preview", "-o", "x.png", "--bev", "0", "1E+1", "-2.5e-1", "-.5e1", "1e-2"])
    assert a.bev == [0.0, 10.0, -0.25, -5.0, 0.01]
    # an option is still an option
    code, _, err = cli("estimate", EXAMPLE, "--bev", "0", "1", "-o", tmp_path / "h.csv")
    assert code == 2 and "--bev" in err


def test_every_frame_of_a_gap_says_the_gap_s_length(tmp_path, cli):
    df = pd.read_csv(EXAMPLE)
    log = tmp_path / "gap.csv"
    df[(df["t"] < 20.0) | (df["t"] >= 30.0)].to_csv(log, index=False)          # a 10 s gap
    for method in ("suspension", "filter", "naive"):
        code, _, err = cli("estimate", log, "--method", method, "-o", tmp_path / f"{method}.csv")
        assert code == 0, err
        table = pd.read_csv(tmp_path / f"{method}.csv", comment="#", keep_default_na=False)
        gap = table["status"] == "gap"
        t = table["t"].to_numpy()
        span = t[gap.to_numpy()][-1] - t[np.flatnonzero(gap.to_numpy())[0] - 1]   # the frames across the gap
        assert 10.0 <= span < 10.3
        assert set(table.loc[gap, "status_reason"]) == {f"{span:.1f} s gap in the log, integrated through"}, method


def test_the_columns_keep_their_order_with_a_camera(tmp_path, cli):
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "a.csv")
    assert code == 0, err
    code, _, err = cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "-o", tmp_path / "b.csv")
    assert code == 0, err
    a = pd.read_csv(tmp_path / "a.csv", comment="#")
    b = pd.read_csv(tmp_path / "b.csv", comment="#")
    assert list(a.columns) == list(COLUMNS)
    assert list(b.columns) == [*COLUMNS, "plane_a", "plane_b", "plane_c", "plane_d"]
    assert list(b.columns).index("valid") == list(COLUMNS).index("valid") == 10


def test_a_tum_output_with_a_camera_says_it_holds_no_plane(tmp_path, cli):
    out = tmp_path / "x.tum"
    code, _, err = cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "-o", out)
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"{out}: warning:"), err
    assert "--camera" in lines[0] and "plane" in lines[0] and ".csv" in lines[0]
    # without a camera, nothing to say
    code, _, err = cli("estimate", EXAMPLE, "-o", out)
    assert code == 0 and not err.strip(), err


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc (a folder nobody can write in)")
def test_an_unwritable_output_is_named_not_its_temporary_file(tmp_path, cli, one_error):
    for args in (("estimate", EXAMPLE, "-o", "/proc/imu_ground_x.csv"),
                 ("estimate", EXAMPLE, "-o", tmp_path / "g.csv", "--tum", "/proc/imu_ground_x.tum")):
        code, _, err = cli(*args)
        assert code == 2 and ".tmp" not in one_error(err, args[-1])
    assert not (tmp_path / "g.csv").exists()                   # all outputs or none
