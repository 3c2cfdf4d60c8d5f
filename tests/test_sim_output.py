"""The simulator's files: one writer (``SimResult.to_csv``) for the Python API and the ``simulate`` CLI."""
from __future__ import annotations

import numpy as np
import pandas as pd

from imu_ground.evaluation.simulate import TRUTH_ANGLES, TRUTH_COLUMNS, simulate


def test_to_csv_writes_angles_in_degrees(tmp_path):
    sim = simulate(20.0, seed=3, imu="nav")
    sim.to_csv(tmp_path / "imu.csv", tmp_path / "truth.csv")
    imu = pd.read_csv(tmp_path / "imu.csv")
    truth = pd.read_csv(tmp_path / "truth.csv")
    assert list(imu.columns) == ["t", "wx", "wy", "wz", "ax", "ay", "az"]
    np.testing.assert_allclose(imu["wy"], sim.imu.gyro[:, 1], rtol=1e-9, atol=1e-15)   # rad/s, unchanged
    assert list(truth.columns) == [TRUTH_ANGLES.get(c, c) for c in TRUTH_COLUMNS]
    assert "pitch" not in truth.columns and {"pitch_deg", "roll_deg"} <= set(truth.columns)
    for rad, deg in TRUTH_ANGLES.items():
        np.testing.assert_allclose(truth[deg], np.degrees(sim.truth[rad]), rtol=1e-9, atol=1e-12)
    assert truth["stationary"].isin([0, 1]).all()
    np.testing.assert_allclose(truth["normal_z"], sim.truth["normal_z"], rtol=1e-9)


def test_cli_writes_what_to_csv_writes(tmp_path):
    from imu_ground.cli import main
    assert main(["simulate", "-o", str(tmp_path / "s.csv"), "--duration", "15", "--seed", "4"]) == 0
    sim = simulate(15.0, seed=4, imu="nav")
    sim.to_csv(tmp_path / "api.csv", tmp_path / "api_truth.csv")
    assert (tmp_path / "s.csv").read_bytes() == (tmp_path / "api.csv").read_bytes()
    assert (tmp_path / "s_truth.csv").read_bytes() == (tmp_path / "api_truth.csv").read_bytes()
