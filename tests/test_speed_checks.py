"""A measured speed as users give it: negative, implausible, in km/h, with millisecond times."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.cli import main
from imu_ground.datasets import read_imu

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"
TRUTH = REPO / "datasets" / "fixtures" / "example_drive_truth.csv"


@pytest.fixture(scope="module")
def truth_speed():
    tr = pd.read_csv(TRUTH)
    return tr["t"].to_numpy(), tr["speed"].to_numpy()


def _estimate(capsys, tmp_path, t, v):
    sp = tmp_path / "speed.csv"
    pd.DataFrame({"t": t, "speed": v}).to_csv(sp, index=False)
    out = tmp_path / "o.csv"
    code = main(["estimate", str(EXAMPLE), "--speed", str(sp), "-o", str(out)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err, out


def test_the_simulated_speed_in_m_per_s_passes_silently(truth_speed):
    from imu_ground.datasets.speed import check_speed
    t, v = truth_speed
    t2, v2, notes = check_speed(t, v, "speed.csv", read_imu(EXAMPLE))
    assert notes == [] and np.array_equal(v2, v) and np.array_equal(t2, t)


@pytest.mark.parametrize("v", [-10.0, "flipped"])
def test_negative_speeds_are_refused_saying_the_sign(truth_speed, tmp_path, capsys, v):
    t, true_v = truth_speed
    code, _, err, out = _estimate(capsys, tmp_path, t, -true_v if v == "flipped" else np.full_like(t, v))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--speed" in err and "negative" in err and "sign" in err and not out.exists()


def test_a_short_reverse_is_said_and_used(truth_speed, tmp_path, capsys):
    t, v = truth_speed
    v = v.copy()
    v[:20] = -1.0
    code, _, err, out = _estimate(capsys, tmp_path, t, v)
    assert code == 0 and "20 of" in err and "reversing" in err
    table = pd.read_csv(out, comment="#")
    assert np.isfinite(table["pitch_deg"]).all() and table["pitch_deg"].abs().max() < 5


def test_implausible_speeds_are_refused(truth_speed, tmp_path, capsys):
    t, v = truth_speed
    code, _, err, _ = _estimate(capsys, tmp_path, t, v * 100)
    assert code == 2 and "implausible" in err and "--speed" in err


def test_km_per_h_and_millisecond_times_are_detected_and_converted(truth_speed, tmp_path, capsys):
    t, v = truth_speed
    _, _, _, ref = _estimate(capsys, tmp_path, t, v)
    expected = pd.read_csv(ref, comment="#")
    for tt, vv, said in [(t, v * 3.6, "km/h"), (t * 1000.0, v, "milliseconds")]:
        code, _, err, out = _estimate(capsys, tmp_path, tt, vv)
        assert code == 0 and said in err
        np.testing.assert_allclose(pd.read_csv(out, comment="#")["pitch_deg"], expected["pitch_deg"], atol=1e-6)


def test_another_scale_is_said(truth_speed):
    from imu_ground.datasets.speed import check_speed
    t, v = truth_speed
    _, v2, notes = check_speed(t, v * 2.0, "speed.csv", read_imu(EXAMPLE))
    assert np.array_equal(v2, v * 2.0) and len(notes) == 1 and "check its unit" in notes[0]


def test_km_per_h_at_highway_speed_is_converted_before_the_plausibility_check(truth_speed):
    """A km/h file whose values exceed the m/s limit (100) is still told by its changes and converted."""
    from imu_ground.datasets.speed import MAX_SPEED, check_speed
    t, v = truth_speed
    fast = v + 25.0                                   # the same changes at 25-35 m/s: up to ~125 km/h
    assert (fast * 3.6).max() > MAX_SPEED
    t2, v2, notes = check_speed(t, fast * 3.6, "speed.csv", read_imu(EXAMPLE))
    np.testing.assert_allclose(v2, fast, rtol=1e-12)
    assert len(notes) == 1 and "km/h" in notes[0]
