"""Offline runs on inputs a user gives by mistake (issue 38): gaps past the live limit, forced units that make
a log absurd, outputs over inputs or over files the tool did not write, a speed off the log's clock."""
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.cli import main

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


def _example() -> pd.DataFrame:
    return pd.read_csv(EXAMPLE, comment="#")


@pytest.fixture()
def jump_log(tmp_path):
    """The example drive with its second half stamped 4000 s later (more than the live limit, an hour at 10 Hz)."""
    df = _example()
    half = len(df) // 2
    df.loc[half:, "t"] += 4000.0
    path = tmp_path / "jump.csv"
    df.to_csv(path, index=False)
    return path, half


# ------------------------------------------------------------------------------------------ 9. long gaps
def test_a_gap_past_the_live_limit_starts_a_new_segment_as_live(jump_log, tmp_path, capsys):
    """Before: 40,600 frames (one gap frame a period; a day's gap 864,600, a 1e6 s one a MemoryError)."""
    path, half = jump_log
    out, causal = tmp_path / "out.csv", tmp_path / "causal.csv"
    assert main(["estimate", str(path), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "new segment" in err and "line 3001" in err and "t = 29.990 s" in err and "4000.010 s" in err
    table = pd.read_csv(out, comment="#")
    assert len(table) < 2 * half / 10 and table["valid"].all()      # bounded by the log, not by the gap
    after = table[table["t"] > 4000]
    assert "a new segment from t = 4030.000 s" in after["status_reason"].iloc[0]
    assert main(["estimate", str(path), "--causal", "-o", str(causal)]) == 0
    assert np.array_equal(table["t"].to_numpy(), pd.read_csv(causal, comment="#")["t"].to_numpy())


def test_a_gap_under_the_limit_is_integrated_through_as_before(tmp_path):
    from imu_ground.datasets import read_imu
    from imu_ground.imu import imu_to_egomotion
    from imu_ground.imu.preint_frames import segment_frame_times
    df = _example()
    df.loc[len(df) // 2:, "t"] += 30.0
    path = tmp_path / "short_gap.csv"
    df.to_csv(path, index=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imu = read_imu(path)
    assert segment_frame_times(imu.t, 10.0, 3600.0) is None
    a, b = imu_to_egomotion(imu, rate=10.0), imu_to_egomotion(imu, rate=10.0, segment_gap=3600.0)
    assert len(a) == len(b) and (~a.valid).sum() == 301 and np.array_equal(a.delta_R, b.delta_R)
    # with a limit under the gap, the frames start again after it: those of each half alone
    c = imu_to_egomotion(imu, rate=10.0, segment_gap=10.0)
    assert c.meta["segment_cuts"] == [len(df) // 2 - 1] and c.valid.all() and len(c) == len(a) - 301


# ------------------------------------------------------------------------------------------ 10, 13. forced units
@pytest.mark.parametrize("scale, unit, given", [(1e9, "ns", "s"), (1e3, "ms", "s"), (1e6, "us", "ms")])
def test_a_forced_time_unit_that_makes_the_log_absurd_is_refused_naming_the_flag(tmp_path, capsys, scale, unit,
                                                                                 given):
    """Before: ns read as s tried to allocate 4.37 TiB (exit 3); ms as s made 600,000 frames of 10 s (1 GB)."""
    df = _example()
    df["t"] = (1.7e18 * (unit == "ns") + df["t"] * scale).round().astype("int64")
    path = tmp_path / f"{unit}.csv"
    df.to_csv(path, index=False)
    assert main(["estimate", str(path), "--time-unit", given, "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--time-unit {given}" in err and f"--time-unit {unit}" in err
    assert not (tmp_path / "o.csv").exists()
    assert main(["estimate", str(path), "--time-unit", unit, "-o", str(tmp_path / "o.csv")]) == 0


def test_a_forced_gyro_unit_the_data_contradict_is_warned_as_the_accel_unit_is(tmp_path, capsys):
    """Before: --accel-unit g on m/s^2 data was warned about, --gyro-unit deg/s on rad/s data was not."""
    for flag in (["--accel-unit", "g"], ["--gyro-unit", "deg/s"]):
        assert main(["estimate", str(EXAMPLE), *flag, "-o", str(tmp_path / "o.csv")]) == 0
        err = capsys.readouterr().err
        assert "warning" in err, flag
    assert "--gyro-unit deg/s given, but the data read as rad/s" in err
    df = _example()
    df[["wx", "wy", "wz"]] = np.degrees(df[["wx", "wy", "wz"]]) * 40      # turns a car makes, in deg/s
    path = tmp_path / "deg.csv"
    df.to_csv(path, index=False)
    assert main(["estimate", str(path), "--gyro-unit", "rad/s", "-o", str(tmp_path / "o.csv")]) == 0
    assert "--gyro-unit rad/s given, but the data read as deg/s" in capsys.readouterr().err
    assert main(["estimate", str(path), "--gyro-unit", "deg/s", "-o", str(tmp_path / "o.csv")]) == 0
    assert "given, but" not in capsys.readouterr().err
