"""A measured speed as users give it: negative, implausible, in km/h, with millisecond times; speed files with
columns by name in any order and case, unknown names, rows without a speed."""
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.cli import main
from imu_ground.datasets import read_imu
from imu_ground.datasets.report import MalformedFileError
from imu_ground.datasets.speed import frame_speed, read_speed_file

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


# ------------------------------------------------------------------------------------------ speed files
def _pitch(path):
    return pd.read_csv(path, comment="#")["pitch_deg"].to_numpy()


def test_columns_are_found_by_name_in_any_order_and_case(truth_speed, tmp_path, cli):
    """``v,time`` was read by position (time taken for the speed): a +48 deg road grade with status ok."""
    t, v = truth_speed
    plain, swapped = tmp_path / "plain.csv", tmp_path / "swapped.csv"
    pd.DataFrame({"t": t, "speed": v}).to_csv(plain, index=False)
    pd.DataFrame({"v": v, "time": t}).to_csv(swapped, index=False)
    tv = read_speed_file(swapped)
    np.testing.assert_array_equal(tv[0], t)
    np.testing.assert_array_equal(tv[1], v)
    upper = tmp_path / "upper.csv"
    pd.DataFrame({"Speed": v, "note": "x", "TIME": t}).to_csv(upper, index=False)
    np.testing.assert_array_equal(read_speed_file(upper)[1], v)
    outs = []
    for k, f in enumerate((plain, swapped)):
        outs.append(tmp_path / f"o{k}.csv")
        code, _, err = cli("estimate", EXAMPLE, "--speed", f, "-o", outs[-1])
        assert code == 0, err
    np.testing.assert_array_equal(_pitch(outs[0]), _pitch(outs[1]))


@pytest.mark.parametrize("header", [("time_s", "speed"), ("t", "wheel"), ("a", "b"), ("t", "v", "speed")])
def test_unknown_or_ambiguous_names_are_refused(truth_speed, tmp_path, cli, header):
    t, v = truth_speed
    f = tmp_path / "speed.csv"
    pd.DataFrame({h: (t if k == 0 else v) for k, h in enumerate(header)}).to_csv(f, index=False)
    with pytest.raises(MalformedFileError, match="speed"):
        read_speed_file(f)
    code, _, err = cli("estimate", EXAMPLE, "--speed", f, "-o", tmp_path / "o.csv")
    line = err.strip().splitlines()[-1]
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert f"--speed {f}" in line and "'speed' or 'v'" in line
    assert not (tmp_path / "o.csv").exists()



def _speed_lines(t, v, blank_after=None):
    rows = [f"{a:.2f},{b:.4f}" for a, b in zip(t, v, strict=True)]
    if blank_after is not None:
        rows.insert(blank_after, "")                  # a blank line: skipped, but it moves the line numbers on
    return "t,speed\n" + "\n".join(rows) + "\n"


@pytest.mark.parametrize("case, line, words", [
    ("back", 103, "9.8 s goes back from 9.9 s on line 101"),       # a blank line 102 lies between them
    ("repeat", 103, "9.9 s repeats 9.9 s on line 101"),
    ("reversed", 3, "600 step(s) back"),
    ("no time", 103, "no time in column 't'"),
])
def test_a_speed_file_whose_times_do_not_increase_is_refused_naming_the_line(truth_speed, tmp_path, cli, case,
                                                                             line, words):
    """Times that stepped back, repeated or were missing were sorted, deduplicated or dropped in silence (exit 0)."""
    t, v = truth_speed
    t = np.round(t, 2)
    if case in ("back", "repeat"):
        t = t.copy()
        t[100] = t[98 if case == "back" else 99]
    elif case == "reversed":
        t, v = t[::-1], v[::-1]
    f = tmp_path / "speed.csv"
    text = _speed_lines(t, v, blank_after=None if case == "reversed" else 100)
    if case == "no time":
        text = text.replace("\n10.00,", "\n,")
    f.write_text(text)
    with pytest.raises(MalformedFileError, match=re.escape(words)) as got:
        read_speed_file(f)
    assert got.value.line == line
    out = tmp_path / "o.csv"
    code, _, err = cli("estimate", EXAMPLE, "--speed", f, "-o", out)
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"--speed {f}, line {line}: " in err and words in err and not out.exists()


@pytest.mark.parametrize("bad, line, words", [
    ("0.20,fast", 4, "column 'speed': 'fast' is not a number"),   # was: "... is not numeric (could not convert ...)"
    ("0.20,9.8,1", 4, "3 fields, expected 2"),                    # was: pandas' own message, no line
    ("0.20", 4, "1 fields, expected 2"),                          # was: read as a NaN speed (a missing comma)
])
def test_a_bad_row_of_a_speed_file_is_named_by_its_line(tmp_path, bad, line, words):
    f = tmp_path / "speed.csv"
    f.write_text("t,speed\n0.00,9.8\n0.10,9.8\n" + bad + "\n0.30,9.8\n")
    with pytest.raises(MalformedFileError, match=re.escape(words)) as got:
        read_speed_file(f)
    assert got.value.line == line


def test_a_speed_file_with_increasing_times_and_blank_lines_is_read_as_before(truth_speed, tmp_path):
    t, v = truth_speed
    f = tmp_path / "speed.csv"
    f.write_text(_speed_lines(t, v, blank_after=100))
    got_t, got_v = read_speed_file(f)
    np.testing.assert_allclose(got_t, t, atol=5e-3)
    np.testing.assert_allclose(got_v, v, atol=5e-5)

def test_rows_without_a_speed_are_holes_counted_in_the_summary(truth_speed, tmp_path, cli):
    """100 rows of nan in a 601-row 10 Hz file: it was '600 of 600 frames' (interpolated across 10 s)."""
    t, v = truth_speed
    v = v.copy()
    v[100:200] = np.nan                       # t = 10.0 .. 19.9 s: the hole is (9.9, 20.0) s
    f = tmp_path / "speed.csv"
    pd.DataFrame({"t": t, "speed": v}).to_csv(f, index=False)
    code, out, err = cli("estimate", EXAMPLE, "--speed", f, "-o", tmp_path / "o.csv")
    assert code == 0, err
    assert f"speed {f} (499 of 600 frames)" in out.splitlines()[0]           # 101 frames end in (9.9, 20.0]
    assert "100 of 601 samples have no speed (nan)" in err and "IMU only" in err


def test_frame_speed_leaves_holes_empty_and_the_rest_as_without_them():
    """Independent reference: the frames that do not reach a hole get what the complete signal gives them."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.02, 0.3, 200))
    v = 10 + np.sin(t)
    te = np.arange(t[0] + 0.1, t[-1], 0.1)
    dt = np.full(te.size, 0.1)
    full = frame_speed(t, v, te, dt)
    holed = v.copy()
    holed[[0, 50, 51, 52, 120, 199]] = np.nan
    got = frame_speed(t, holed, te, dt)
    spans = [(-np.inf, t[1]), (t[49], t[53]), (t[119], t[121]), (t[198], np.inf)]
    reach = np.zeros(te.size, bool)
    for lo, hi in spans:
        reach |= (te - dt < hi) & (te > lo)
    assert reach.any() and (~reach).any()
    assert np.all(np.isnan(got[reach]))
    np.testing.assert_allclose(got[~reach], full[~reach], rtol=1e-12)
