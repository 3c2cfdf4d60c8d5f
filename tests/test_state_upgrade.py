"""A live state saved by an earlier release resumes after an upgrade.

``tests/data/live_states_closed_form_kernel.json``: :meth:`StreamingEstimator.state_dict` of the default method and
of ``paper`` after the first half of the shipped example drive, saved by the release whose ground filters ran a
closed-form kernel (commit 9854bcd, a 39-float buffer). Loaded by today's code, each continues the drive as an
uninterrupted run of today's code does.
"""
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.pipeline.streaming import StreamingEstimator

HERE = Path(__file__).parent
SAMPLES = pd.read_csv(HERE.parent / "datasets" / "fixtures" / "example_drive.csv").to_numpy()
STATES = json.loads((HERE / "data" / "live_states_closed_form_kernel.json").read_text())


def _frames(est, samples):
    out = []
    for r in samples:
        out += est.push_imu(float(r[0]), r[1:4], r[4:7])
    return out


@pytest.mark.parametrize("method", sorted(STATES))
def test_a_state_of_the_closed_form_kernel_resumes(method):
    half = len(SAMPLES) // 2
    whole = _frames(StreamingEstimator(method=method), SAMPLES)
    resumed = StreamingEstimator(method=method)
    resumed.load_state_dict(STATES[method])
    got = _frames(resumed, SAMPLES[half:])
    want = [f for f in whole if f.t >= got[0].t - 1e-9]
    assert len(got) == len(want) > 100
    assert [f.t for f in got] == pytest.approx([f.t for f in want], abs=1e-9)
    for name in ("pitch", "roll"):
        assert np.abs(np.array([getattr(f, name) for f in got]) - [getattr(f, name) for f in want]).max() < 1e-12
    assert [f.status for f in got] == [f.status for f in want]
