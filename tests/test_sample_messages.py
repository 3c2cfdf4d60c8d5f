"""A corrupt sample or a time column that does not advance is named as such, not blamed on the
mounting or reported as an array shape."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.datasets import read_imu
from imu_ground.datasets.validation import ImuValidationError

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(scope="module")
def example():
    return pd.read_csv(EXAMPLE)


@pytest.mark.parametrize("column, value", [("ax", 1e308), ("wz", 1e308), ("az", -3e7), ("wx", 2e6)])
def test_one_absurd_sample_is_named_by_line_time_and_column(example, tmp_path, cli, column, value):
    """1e308 in ax was 'mean specific force 90.0 deg from the up axis' (--extrinsic); in wz a bad-frame error."""
    df = example.copy()
    df.loc[1234, column] = value                      # file line 1236 (header, 1-based), t = 12.34 s
    path = tmp_path / "log.csv"
    df.to_csv(path, index=False)
    out = tmp_path / "o.csv"
    code, _, err = cli("estimate", path, "-o", out)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and not out.exists(), err
    line = lines[0]
    assert str(path) in line and f"columns {column} (1 value(s)" in line and "line 1236" in line, line
    assert "t=12.340000 s" in line and "--nonfinite drop" in line and "extrinsic" not in line
    imu = read_imu(path, nonfinite="drop")           # the option the message names drops that row
    assert len(imu) == len(df) - 1 and np.abs(imu.accel).max() < 1e6


def test_a_strong_but_possible_reading_is_kept(example, tmp_path):
    df = example.copy()
    df.loc[1234, "ax"] = 150.0                         # 15 g: a pothole can do that
    path = tmp_path / "log.csv"
    df.to_csv(path, index=False)
    assert len(read_imu(path)) == len(df)


def test_all_equal_timestamps_are_said(example, tmp_path, cli):
    """Was 'too short for frames at 10 Hz (..., got t of shape (1,))'."""
    df = example.copy()
    df["t"] = 5.0
    path = tmp_path / "log.csv"
    df.to_csv(path, index=False)
    with pytest.raises(ImuValidationError, match="timestamps are equal"):
        read_imu(path)
    code, _, err = cli("estimate", path, "-o", tmp_path / "o.csv")
    line = err.strip().splitlines()[-1]
    assert code == 2 and f"{path}: all {len(df)} timestamps are equal (t = 5 s)" in line and "shape" not in line
