"""The retime policy: jittered stamps back on the sample clock, real dropouts kept as gaps."""
from __future__ import annotations

import gzip
import warnings

import numpy as np
import pandas as pd
import pytest
from imu_ground.datasets import read_imu, read_kitti_imu100
from imu_ground.datasets.timestamps import retime
from imu_ground.datasets.validation import (
    GapWarning,
    ImuValidationError,
    TimestampWarning,
    validate,
)

from imu_ground.imu.data import ImuData


def kitti_jitter(n=3000, dt=0.01, dropout_at=2000, dropout=1.6, seed=0):
    """Stamps as KITTI OXTS writes them: steady samples, stamps jumping ahead then back, one real dropout."""
    t = np.arange(n) * dt
    rng = np.random.default_rng(seed)
    for start in rng.choice(np.arange(50, dropout_at - 100), 8, replace=False):
        lead = 0.05 * rng.integers(1, 5)            # jumps ahead by 0.05-0.2 s ...
        for j in range(round(lead / 0.05)):    # ... then catches up 0.05 s every 6 samples
            t[start + 6 * j: start + 6 * (j + 1)] += lead - 0.05 * j
    t[dropout_at:] += dropout
    return t + rng.normal(0, 2e-5, n)


def imu_of(t):
    n = t.size
    return ImuData(t, np.tile([0.001, 0.0, 0.01], (n, 1)), np.tile([0.0, 0.0, 9.81], (n, 1)),
                   extra=pd.DataFrame({"k": np.arange(n)}), source="log.csv")


def test_retime_restores_the_sample_clock_and_keeps_the_dropout():
    t = kitti_jitter()
    with pytest.warns(TimestampWarning, match=r"retimed on the sample index at 100 Hz, nothing dropped.*"
                                              r"1 dropout\(s\) kept as gaps \(before rows \[2000\]\)"), \
            pytest.warns(GapWarning, match=r"longest 1\.61 s"):
        out, rep = validate(imu_of(t))
    assert len(out) == t.size and rep.n_dropped == 0 and rep.retimed
    np.testing.assert_array_equal(out.extra["k"], np.arange(t.size))  # same samples, same order
    truth = np.arange(t.size) * 0.01
    truth[2000:] += 1.6
    assert np.abs(out.t - truth).max() < 1e-5
    assert rep.retime_rate == pytest.approx(100.0, rel=1e-6)
    assert rep.retime_shift_max == pytest.approx(np.abs(out.t - t).max())
    assert rep.retime_shift_rms == pytest.approx(np.sqrt(np.mean((out.t - t) ** 2)))
    np.testing.assert_array_equal(rep.retime_dropout_index, [2000])
    assert rep.n_gaps == 1 and rep.gap_index[0] == 1999
    assert "retimed at 100 Hz" in rep.summary()


def test_drop_sort_strict_still_available():
    t = kitti_jitter(dropout=0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dropped = validate(imu_of(t), policy="drop")[1]
        in_order = validate(imu_of(t), policy="sort")[0]
    assert dropped.n_dropped > 0 and not dropped.retimed
    assert np.all(np.diff(in_order.t) > 0)
    with pytest.raises(ImuValidationError, match=r"not strictly increasing.*policy='retime'") as e:
        validate(imu_of(t), policy="strict")
    assert "--policy retime" in e.value.cli_message()


def test_increasing_stamps_are_left_exactly_as_they_are():
    t = np.arange(500) * 0.01 + np.random.default_rng(3).normal(0, 1e-4, 500)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, rep = validate(imu_of(t))
    np.testing.assert_array_equal(out.t, t)
    assert not rep.retimed and rep.retime_shift_max == 0.0


def test_unsteady_rate_falls_back_to_drop_and_says_why():
    rng = np.random.default_rng(4)
    t = np.cumsum(rng.uniform(0.001, 0.03, 400))  # no steady rate
    t[200] = t[150]
    with pytest.warns(TimestampWarning, match=r"dropped .* \(not retimed: .*\) \(policy='retime'"):
        out, rep = validate(imu_of(t))
    assert not rep.retimed and rep.retime_note and np.all(np.diff(out.t) > 0)


def test_retime_counts_slots_of_dropped_nonfinite_rows():
    t = kitti_jitter(n=600, dropout_at=500, dropout=0.0)
    imu = imu_of(t)
    imu.gyro[300, 0] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out, rep = validate(imu, nonfinite="drop")
    assert rep.retimed and len(out) == 599
    np.testing.assert_allclose(out.t[300] - out.t[299], 0.02, atol=1e-5)  # the NaN row kept its slot


def test_retime_function_on_raw_stamps():
    res = retime(kitti_jitter())
    assert res.t is not None and res.note == "" and res.breaks.tolist() == [2000]
    assert retime(np.arange(5.0)).t is None


def test_shared_drive_jitter_is_not_a_gap(shared_data):
    """Drive 0009: 'drop' threw away 54 samples (0.55 s of stamps ahead); retime keeps all, no gap."""
    path = shared_data / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        before = read_kitti_imu100(path, policy="drop")
        after = read_imu(path)
    rb, ra = before.meta["validation"], after.meta["validation"]
    assert rb.n_dropped == 54 and rb.n_gaps == 1
    assert ra.n_dropped == 0 and ra.n_gaps == 0 and ra.retimed
    assert ra.retime_shift_max == pytest.approx(0.54, abs=0.01) and ra.retime_shift_rms < 0.05
    with gzip.open(path, "rt") as f:
        raw = pd.read_csv(f)
    np.testing.assert_array_equal(after.gyro, raw[["wx", "wy", "wz"]].to_numpy())
    assert np.all(np.diff(after.t) > 0.0099) and np.all(np.diff(after.t) < 0.0101)
    assert (len(after) - 1) / after.t[-1] == pytest.approx(100.0, rel=1e-3)


def test_shared_drive_real_dropout_stays_a_gap(shared_data):
    """Drive 0029: a 1.6 s dropout (KITTI has real ones) is kept as a gap, named by its file line."""
    path = shared_data / "kitti_imu100" / "2011_09_26_drive_0029.csv.gz"
    with pytest.warns(GapWarning, match=r"1 gap\(s\).*longest 1\.6 s .*\(line 4186\)"), \
            pytest.warns(TimestampWarning, match=r"1 dropout\(s\) kept as gaps \(before lines \[4187\]\)"):
        imu = read_imu(path)
    rep = imu.meta["validation"]
    assert rep.n_dropped == 0 and rep.n_gaps == 1 and rep.gap_length[0] == pytest.approx(1.6, abs=0.01)
