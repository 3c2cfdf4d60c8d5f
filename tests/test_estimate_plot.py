"""``imu-ground estimate LOG --plot FILE``: pitch and roll with their 1-sigma, the status as shading, the speed."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("matplotlib")

from imu_ground.filters.status import STATUSES
from imu_ground.pipeline.estimate import estimate_log
from imu_ground.pipeline.output import result_table
from imu_ground.pipeline.plot import STATUS_COLOURS, estimate_figure

REPO = Path(__file__).resolve().parent.parent
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"
TRUTH = REPO / "datasets" / "fixtures" / "example_drive_truth.csv"
#: The first bytes of each picture format.
MAGIC = {".png": b"\x89PNG", ".pdf": b"%PDF", ".svg": b"<?xml"}


def _one_error_line(err: str, *words: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, err)


@pytest.fixture(scope="module")
def speed_file(tmp_path_factory):
    """The example drive's true speed as a speed file (the example log itself has none)."""
    truth = pd.read_csv(TRUTH)
    path = tmp_path_factory.mktemp("speed") / "speed.csv"
    truth[["t", "speed"]].to_csv(path, index=False)
    return path


@pytest.mark.parametrize("suffix", list(MAGIC))
def test_plot_is_written_beside_the_output(tmp_path, cli, suffix):
    out, pic = tmp_path / "g.csv", tmp_path / f"g{suffix}"
    code, stdout, err = cli("estimate", EXAMPLE, "-o", out, "--plot", pic)
    assert code == 0, err
    assert out.is_file() and pic.read_bytes().startswith(MAGIC[suffix])
    assert f"wrote {out} and {pic}" in stdout
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []      # no staging left


@pytest.mark.parametrize("name", ["g.jpg", "g", "g.csv"])
def test_plot_suffix_is_checked_first(tmp_path, cli, name):
    out = tmp_path / "g.parquet"
    code, _, err = cli("estimate", EXAMPLE, "-o", out, "--plot", tmp_path / name)
    assert code == 2
    _one_error_line(err, "--plot", ".png", ".svg")
    assert not out.exists()


@pytest.mark.parametrize("flag", ["-o", "--tum"])
def test_plot_on_the_path_of_another_output_is_refused(tmp_path, cli, flag):
    pic = tmp_path / "g.png"
    args = ["-o", pic] if flag == "-o" else ["-o", tmp_path / "g.csv", "--tum", pic]
    code, _, err = cli("estimate", EXAMPLE, *args, "--plot", pic)
    assert code == 2
    _one_error_line(err, flag, "--plot", "two file names")
    assert list(tmp_path.iterdir()) == []


def test_a_failed_picture_leaves_no_output(tmp_path, cli, monkeypatch):
    """All or none: the table is not left behind when the picture fails."""
    import imu_ground.pipeline.output as output

    def broken(*args, **kwargs):
        raise RuntimeError("boom")

    monkeypatch.setattr(output, "plot_estimate", broken)
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "g.csv", "--plot", tmp_path / "g.png")
    assert code == 3, err
    assert list(tmp_path.iterdir()) == []


def _status_table(n: int = 60) -> pd.DataFrame:
    t = 0.1 * np.arange(1, n + 1)
    status = np.array(["converging"] * 10 + ["ok"] * 20 + ["standstill"] * 10 + ["gap"] * 5 + ["ok"] * 5
                      + ["degraded"] * 10, dtype=object)
    return pd.DataFrame({"t": t, "pitch_deg": 0.2 * np.sin(t), "roll_deg": 0.1 * np.cos(t),
                         "pitch_std_deg": 0.05 + 0.001 * t, "roll_std_deg": 0.04 + 0.0 * t, "status": status,
                         "valid": status != "gap"})


def _labels(fig) -> list[str]:
    return [t.get_text() for t in fig.legends[0].get_texts()]


def test_figure_shows_band_statuses_and_speed():
    table = _status_table()
    speed = np.linspace(0.0, 12.0, len(table))
    fig = estimate_figure(table, speed=speed, speed_note="a speed file", title="drive: method suspension")
    pitch, roll, *speed_axes = fig.axes
    assert pitch.get_ylabel() == "pitch (deg, + nose down)" and roll.get_ylabel() == "roll (deg, + left side up)"
    assert [a.get_ylabel() for a in speed_axes] == ["speed (m/s)", "speed (m/s)"]
    np.testing.assert_array_equal(speed_axes[0].lines[0].get_ydata(), speed)
    assert pitch.get_shared_x_axes().joined(pitch, roll)
    for ax, name in ((pitch, "pitch"), (roll, "roll")):
        (band,) = ax.collections                       # the 1-sigma band: y - s .. y + s
        y = band.get_paths()[0].vertices[:, 1]
        lo, hi = table[f"{name}_deg"] - table[f"{name}_std_deg"], table[f"{name}_deg"] + table[f"{name}_std_deg"]
        assert y.min() == pytest.approx(lo.min()) and y.max() == pytest.approx(hi.max())
        spans = [p for p in ax.patches]                 # one shaded span per run of a status other than ok
        assert len(spans) == 4
    labels = _labels(fig)
    assert labels[:3] == ["estimate, body relative to the road", "1-sigma", "speed (right axis)"]
    assert labels[3:] == ["status converging", "status ok (unshaded)", "status standstill", "status gap",
                          "status degraded"]
    assert fig._suptitle.get_text() == "drive: method suspension\nspeed: a speed file"


def test_figure_without_speed_says_why_and_has_no_speed_axis():
    table = _status_table()
    fig = estimate_figure(table, speed=None, speed_note="none (a table log has no speed signal)")
    assert len(fig.axes) == 2
    assert "speed: none (a table log has no speed signal)" in fig._suptitle.get_text()
    assert "speed (right axis)" not in _labels(fig)
    fig = estimate_figure(table, speed=np.full(len(table), np.nan), speed_note="")      # no finite speed
    assert len(fig.axes) == 2 and "speed: no speed" in fig._suptitle.get_text()


def test_every_status_has_a_shade():
    assert set(STATUS_COLOURS) == set(STATUSES)


def test_the_estimate_keeps_the_frame_speed_for_the_picture(speed_file):
    res = estimate_log(EXAMPLE, speed=str(speed_file))
    v = res.meta["frame_speed"]
    assert v.shape == (len(res.track),) and np.nanmax(v) > 5.0
    assert estimate_log(EXAMPLE).meta["frame_speed"] is None
    causal = estimate_log(EXAMPLE, speed=str(speed_file), causal=True)
    assert causal.meta["frame_speed"].shape == (len(causal.track),)
    fig = estimate_figure(result_table(res), speed=v)
    assert len(fig.axes) == 4


def test_plot_of_a_log_with_speed_has_the_speed(tmp_path, cli, speed_file, monkeypatch):
    """The CLI hands the estimate's speed to the picture (the speed axis is there)."""
    import imu_ground.pipeline.output as output
    seen = {}
    real = output.plot_estimate

    def spy(table, path, **kw):
        seen.update(kw)
        return real(table, path, **kw)

    monkeypatch.setattr(output, "plot_estimate", spy)
    code, _, err = cli("estimate", EXAMPLE, "--speed", speed_file, "-o", tmp_path / "g.csv",
                       "--plot", tmp_path / "g.png")
    assert code == 0, err
    assert np.isfinite(seen["speed"]).sum() > 100 and str(speed_file) in seen["speed_note"]
    assert "example_drive.csv: method suspension" == seen["title"]
