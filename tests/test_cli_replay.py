"""``stream --replay`` and ``estimate --causal`` feed a log through one loop (:func:`live_replay.replay`)."""
import io
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from imu_ground.datasets import read_imu
from imu_ground.pipeline.estimate import speed_samples
from imu_ground.pipeline.streaming import StreamingEstimator, estimate_row, replay

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


def test_stream_replay_equals_replay_on_stamps_that_step_back(cli, tmp_path):
    df = pd.read_csv(EXAMPLE)
    t = df["t"].to_numpy(float, copy=True)
    t[3000:3050] -= 0.3                                  # the clock steps back 0.3 s, then on
    log = tmp_path / "back.csv"
    df.assign(t=t, speed=8 + 2 * np.sin(np.arange(len(df)) / 500.0)).to_csv(log, index=False)
    code, out, err = cli("stream", "--replay", log, "--speed", "speed")
    assert code == 0, err
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imu = read_imu(log, format="table", policy="recorded")
        sp, _ = speed_samples("speed", log, "table", imu)
    want = pd.DataFrame([estimate_row(f) for f in replay(StreamingEstimator(), imu.t, imu.gyro, imu.accel, sp)])
    got = pd.read_csv(io.StringIO(out))
    assert len(got) == len(want) > 500
    for name in ("t", "pitch_deg", "roll_deg", "pitch_std_deg", "road_grade_deg"):
        np.testing.assert_array_equal(got[name].to_numpy(float), want[name].to_numpy(float))
