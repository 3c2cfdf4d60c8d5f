"""``evaluate --plots``: the highlighted methods apart from the others, a roll panel where the truth has roll,
the default's 1-sigma band, the 3 m/s line labelled, units on every axis."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from imu_ground.evaluation.drives import synthetic_drives
from imu_ground.evaluation.plots import error_distribution_figure, evaluation_plots, pitch_over_time_figure
from imu_ground.evaluation.runner import evaluate


@pytest.fixture(scope="module")
def run():
    drives = synthetic_drives(1, grades=("mems",), seed=0, progress=False)
    res, tracks = evaluate(drives, progress=False, keep_tracks=True)
    d = drives[0]
    return d, res, {m: tracks[(d.name, m)] for m in dict.fromkeys(res["method"])}


def _labels(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def _close(fig) -> None:
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_pitch_roll_others_and_speed_panels(run):
    d, _, tracks = run
    fig = pitch_over_time_figure(d, tracks)
    pitch, roll, others, speed = fig.axes
    assert [a.get_ylabel() for a in fig.axes] == [
        "pitch rel. road\n(deg, + nose down)", "roll rel. road\n(deg, + left side up)",
        "pitch rel. road\n(deg, other methods)", "speed (m/s)"]
    assert speed.get_xlabel() == "time (s)"
    for ax in (pitch, roll):
        assert _labels(ax) == ["reference", "suspension 1-sigma", "suspension (default)", "paper", "naive"]
        (band,) = ax.collections                          # the default's 1-sigma band
        assert band.get_label() == "suspension 1-sigma"
    rest = _labels(others)
    assert rest[0] == "reference" and len(rest) == 1 + len(tracks) - 3
    assert not {"suspension", "paper", "naive"} & {r.split()[0] for r in rest}
    styles = {(ln.get_color(), ln.get_linestyle()) for ln in others.lines[1:]}
    assert len(styles) == len(others.lines) - 1           # each other method its own colour and line style
    assert _labels(speed) == ["speed", "3 m/s: slower frames\nnot scored"]
    for ax in fig.axes[:-1]:                               # legends sit right of the panels, off the curves
        assert ax.get_legend().get_bbox_to_anchor().x0 > ax.get_window_extent().x1 - 1
    _close(fig)


def test_methods_on_each_other_say_so(run):
    """filter, paper and ekf differ by thousandths of a degree: the later ones' legends name the earlier."""
    d, _, tracks = run
    fig = pitch_over_time_figure(d, tracks)
    rest = _labels(fig.axes[2])
    assert any(r.startswith("filter (on paper: ") and r.endswith(" deg RMS apart)") for r in rest), rest
    assert "suspension-offline" in rest                   # 0.015 deg from suspension: apart
    _close(fig)


def test_no_roll_panel_without_a_roll_truth(run):
    d, _, tracks = run
    real_like = dataclasses.replace(d, truth=d.truth.assign(roll=np.nan))
    fig = pitch_over_time_figure(real_like, {m: tracks[m] for m in ("suspension", "naive")})
    assert [a.get_ylabel().split("\n")[0] for a in fig.axes] == ["pitch rel. road", "speed (m/s)"]
    _close(fig)


def test_error_distribution_has_units_and_the_highlighted_histogram(run):
    d, _, tracks = run
    errors = {m: np.abs(np.degrees(tr.pitch - d.truth["pitch"].to_numpy())) for m, tr in tracks.items()}
    fig = error_distribution_figure(errors, "synthetic")
    hist, cdf = fig.axes
    assert hist.get_ylabel() == "density (1/deg)" and hist.get_xlabel().startswith("absolute error (deg")
    assert cdf.get_ylabel() == "fraction of frames" and cdf.get_xlabel() == "absolute error (deg)"
    assert _labels(hist) == ["suspension", "paper", "naive"]
    assert len(_labels(cdf)) == len(tracks)
    _close(fig)


def test_evaluation_plots_write_the_pictures(run, tmp_path):
    d, res, tracks = run
    out = evaluation_plots([d], res, {(d.name, m): tr for m, tr in tracks.items()}, tmp_path)
    assert {p.name for p in out} == {f"pitch_{d.name}.png", "errors_synthetic-mems.png", f"road_{d.name}.png"}
    assert all(p.read_bytes().startswith(b"\x89PNG") for p in out)
