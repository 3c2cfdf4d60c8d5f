"""Validation of IMU logs: every failure mode on small synthetic inputs."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pandas as pd
import pytest
from imu_ground.datasets.validation import (
    GapWarning,
    ImuValidationError,
    ImuValidationWarning,
    NonFiniteWarning,
    TimestampWarning,
    UnitsWarning,
    ValidationReport,
    check_timestamps,
    validate,
)

from imu_ground.imu.data import ImuData


def make_imu(t, gyro=None, accel=None, **kw) -> ImuData:
    t = np.asarray(t, dtype=float)
    n = t.size
    k = np.arange(n)        # a moving car: turns and brakes (a still or constant log gets a SensorWarning)
    if gyro is None:
        gyro = np.tile([0.001, -0.002, 0.01], (n, 1)) + np.outer(0.2 * np.sin(k / 7.0), [0, 0, 1])
    if accel is None:
        accel = np.tile([0.1, -0.2, 9.81], (n, 1)) + np.outer(np.sin(k / 5.0), [1, 0, 0])
    extra = pd.DataFrame({"k": np.arange(n)})
    return ImuData(t, gyro, accel, extra=extra, units={"k": "-"}, source=kw.pop("source", "log.csv"), **kw)


def regular(n=100, dt=0.01):
    return np.arange(n) * dt


def test_clean_log_passes_without_warnings():
    imu = make_imu(regular())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, rep = validate(imu)
    assert rep.ok and rep.n_in == rep.n_out == 100
    assert out.meta["validation"] is rep
    assert rep.median_step == pytest.approx(0.01)
    assert rep.gap_threshold == pytest.approx(0.05)
    rest = np.linalg.norm(imu.gyro, axis=1) < 0.05          # the at-rest samples' median, by definition
    assert rep.accel_median_norm == pytest.approx(np.median(np.linalg.norm(imu.accel[rest], axis=1)), rel=1e-12)
    assert "no issues" in rep.summary()
    assert out is not imu and imu.meta == {}  # input untouched


def test_empty_log_raises():
    imu = ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), source="empty.csv")
    with pytest.raises(ImuValidationError, match=r"empty\.csv: no samples"):
        validate(imu)


def test_out_of_order_dropped_and_reported():
    t = regular(20)
    t[10:13] = [0.05, 0.06, 0.07]  # steps back by 0.04 s at index 10
    imu = make_imu(t)
    with pytest.warns(TimestampWarning) as rec:
        out, rep = validate(imu, policy="drop")
    msg = str(rec[0].message)
    assert "log.csv" in msg and "3 sample(s) out of order" in msg
    assert "row 10" in msg and "t=0.050000" in msg and "step -0.040000" in msg
    assert "dropped 3 of 20" in msg
    assert rep.n_out_of_order == 3 and rep.n_duplicates == 0 and rep.n_dropped == 3
    np.testing.assert_array_equal(rep.out_of_order_index, [10, 11, 12])
    np.testing.assert_array_equal(rep.backstep_index, [10])
    assert rep.backstep_size[0] == pytest.approx(-0.04)
    assert np.all(np.diff(out.t) > 0) and len(out) == 17
    # rows of extra follow the kept samples
    np.testing.assert_array_equal(out.extra["k"].to_numpy(), np.delete(np.arange(20), [10, 11, 12]))


def test_duplicates_dropped_and_counted():
    t = np.array([0.0, 0.01, 0.02, 0.02, 0.03, 0.04, 0.04, 0.04, 0.05])
    with pytest.warns(TimestampWarning, match=r"3 duplicate timestamp\(s\) \(first at row 3, t=0\.020000 s\)"):
        out, rep = validate(make_imu(t), policy="drop")
    np.testing.assert_array_equal(rep.duplicate_index, [3, 6, 7])
    assert rep.n_out_of_order == 0
    np.testing.assert_array_equal(out.extra["k"], [0, 1, 2, 4, 5, 8])


def test_strict_policy_raises_naming_where():
    t = regular(20)
    t[5] = 0.02
    with pytest.raises(ImuValidationError, match=r"log\.csv: timestamps not strictly increasing.*row 5.*t=0\.020000"):
        validate(make_imu(t), policy="strict")


def test_sort_policy_keeps_late_samples():
    # a block sent twice, as in the KITTI extract logs: 0..5, then 3..9 again
    t = np.r_[np.arange(6), np.arange(3, 10)] * 0.01
    with pytest.warns(TimestampWarning, match="sorted by time and dropped 3 repeated"):
        out, rep = validate(make_imu(t), policy="sort")
    np.testing.assert_allclose(out.t, np.arange(10) * 0.01)
    assert rep.reordered and rep.n_dropped == 3
    np.testing.assert_array_equal(rep.duplicate_index, [6, 7, 8])  # repeats keep the first
    # "drop" keeps only later samples: the same input loses 3 as well here
    with pytest.warns(TimestampWarning):
        out2, _ = validate(make_imu(t), policy="drop")
    assert len(out2) == 10


def test_bad_policy_names_choices():
    with pytest.raises(ValueError, match=r"policy='ignore'.*\['retime', 'drop', 'sort', 'strict', 'recorded'\]"):
        validate(make_imu(regular()), policy="ignore")
    with pytest.raises(ValueError, match="nonfinite"):
        validate(make_imu(regular()), nonfinite="keep")


def test_gaps_listed_and_warned():
    t = regular(100)
    t[40:] += 1.0     # 1 s hole after index 39
    t[70:] += 0.2     # 0.2 s hole after index 69
    with pytest.warns(GapWarning) as rec:
        out, rep = validate(make_imu(t))
    msg = str(rec[0].message)
    assert "2 gap(s) longer than 0.05 s = 5 x median step 0.01 s" in msg
    assert "longest 1.01 s at t=0.390000 s (row 39)" in msg
    assert rep.n_gaps == 2 and len(out) == 100
    np.testing.assert_allclose(rep.gap_start, [0.39, 1.69])
    np.testing.assert_allclose(rep.gap_length, [1.01, 0.21])
    assert rep.gaps[0].index == 39 and rep.gaps[0].out_index == 39
    # threshold configurable
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, rep2 = validate(make_imu(t), gap_threshold=0.5, gaps="ignore")
    assert rep2.n_gaps == 1 and rep2.gap_threshold == 0.5
    with pytest.raises(ImuValidationError, match="1 gap"):
        validate(make_imu(t), gap_threshold=0.5, gaps="raise")
    with pytest.raises(ImuValidationError, match="gap"):
        validate(make_imu(t), policy="strict")


def test_gap_indices_refer_to_output_after_drop():
    t = np.r_[0.0, 0.01, 0.02, 0.015, 0.03, 0.5, 0.51]  # index 3 out of order, gap after 0.03
    with pytest.warns(ImuValidationWarning):
        out, rep = validate(make_imu(t), policy="drop")
    g = rep.gaps[0]
    assert (g.index, g.out_index) == (4, 3)
    assert out.t[g.out_index] == g.t_start == 0.03


def test_nonfinite_raise_names_column_and_rows():
    gyro = np.tile([0.0, 0.0, 0.01], (50, 1))
    gyro[[3, 7], 1] = np.nan
    with pytest.raises(ImuValidationError) as e:
        validate(make_imu(regular(50), gyro=gyro))
    msg = str(e.value)
    assert "log.csv" in msg and "2 row(s) with NaN/inf" in msg
    assert "wy (2 value(s), first rows [3, 7])" in msg and "first bad row 3 (t=0.030000 s)" in msg
    assert e.value.option == "nonfinite" and "--nonfinite drop" in e.value.cli_message()
    assert "nonfinite='drop'" in msg


def test_nonfinite_drop_warns():
    t = regular(50)
    t[10] = np.inf
    accel = np.tile([0, 0, 9.8], (50, 1))
    accel[20, 2] = np.nan
    with pytest.warns(NonFiniteWarning, match=r"columns t \(1 value.*az \(1 value.*dropped 2 of 50"):
        out, rep = validate(make_imu(t, accel=accel), nonfinite="drop")
    assert len(out) == 48 and rep.nonfinite_columns == {"t": 1, "az": 1}
    np.testing.assert_array_equal(rep.nonfinite_index, [10, 20])
    np.testing.assert_array_equal(rep.dropped_index, [10, 20])


def test_gyro_in_degrees_suspected():
    n = 300
    gyro = np.zeros((n, 3))
    gyro[100:200, 2] = 30.0  # 30 "rad/s" for a second: really 30 deg/s
    with pytest.warns(UnitsWarning, match=r"above 10 rad/s for 1 s from row 100 \(t=1\.000000 s\).*deg/s"):
        _, rep = validate(make_imu(regular(n), gyro=gyro))
    assert rep.gyro_sustained == pytest.approx(1.0)
    assert rep.gyro_max_norm == 30.0
    # a single spike is not sustained
    gyro2 = np.zeros((n, 3))
    gyro2[50, 0] = 40.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        validate(make_imu(regular(n), gyro=gyro2))
    with pytest.raises(ImuValidationError, match="deg/s"):
        validate(make_imu(regular(n), gyro=gyro), units="raise")


@pytest.mark.parametrize("accel, expect", [
    ([0.0, 0.0, 1.0], "units of g"),
    ([0.1, 0.05, 0.0], "gravity seems to be missing"),
    ([0.0, 0.0, 1000.0], "units of mg"),
    ([0.0, 0.0, 9806.65], "mm/s"),
    ([0.0, 0.0, 15.0], "check the accelerometer units"),
])
def test_accel_magnitude_suspected(accel, expect):
    imu = make_imu(regular(), accel=np.tile(accel, (100, 1)))
    with pytest.warns(UnitsWarning, match=expect) as rec:
        _, rep = validate(imu)
    assert "median specific-force magnitude at rest" in str(rec[0].message)
    assert not rep.ok and rep.accel_norm_at_rest


def test_units_strict_and_ignore():
    imu = make_imu(regular(), accel=np.tile([0, 0, 1.0], (100, 1)))
    with pytest.raises(ImuValidationError, match="units of g"):
        validate(imu, policy="strict")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, rep = validate(imu, units="ignore")
    assert rep.issues  # still recorded


def test_warn_false_records_only():
    t = regular(20)
    t[5] = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, rep = validate(make_imu(t), policy="drop", warn=False)
    assert rep.n_dropped == 1 and len(rep.issues) == 1


def test_check_timestamps_on_raw_array():
    t = np.array([0.0, 0.1, 0.2, 0.15, 0.3, 0.3, 2.0])
    with pytest.warns(ImuValidationWarning) as rec:
        keep, _, rep = check_timestamps(t, "drop", source="ts.txt")
    np.testing.assert_array_equal(keep, [0, 1, 2, 4, 6])
    assert rep.n_out_of_order == 1 and rep.n_duplicates == 1 and rep.n_gaps == 1
    assert {type(w.message) for w in rec} == {TimestampWarning, GapWarning}
    assert all("ts.txt" in str(w.message) for w in rec)
    with pytest.raises(ImuValidationError, match=r"ts\.txt.*row 3"):
        check_timestamps(t, policy="strict", source="ts.txt")


def test_report_is_json_friendly():
    t = regular(30)
    t[7] = 0.0
    t[20:] += 1.0
    with pytest.warns(ImuValidationWarning):
        _, rep = validate(make_imu(t), policy="drop")
    d = rep.to_dict()
    json.dumps(d)
    assert d["n_dropped"] == 1 and d["n_gaps"] == 1 and d["ok"] is False
    assert isinstance(rep, ValidationReport)


def test_warning_points_at_caller():
    t = regular(20)
    t[5] = 0.0
    with pytest.warns(TimestampWarning) as rec:
        validate(make_imu(t))
    assert rec[0].filename == __file__


def test_recorded_policy_keeps_file_order_and_stamps_and_still_checks_the_rest():
    """policy='recorded' (the live front end's read): back-steps and repeats kept as written, listed in the
    report without a warning; a newest-first log and NaN rows are still refused."""
    t = np.arange(200) * 0.01
    t[50] -= 0.05
    t[120] = t[119]
    rng = np.random.default_rng(3)
    gyro, accel = rng.normal(0, 0.1, (200, 3)), [0.0, 0.0, 9.81] + rng.normal(0, 0.3, (200, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, report = validate(ImuData(t, gyro, accel), policy="recorded")
    assert np.array_equal(out.t, t) and report.n_out == 200
    assert report.backstep_index.tolist() == [50] and 120 in report.duplicate_index
    assert any("kept as recorded" in x for x in report.issues)
    with pytest.raises(ImuValidationError, match="reverse"):
        validate(ImuData(t[::-1].copy(), gyro, accel), policy="recorded")
    gyro[7, 1] = np.nan
    with pytest.raises(ImuValidationError, match="nonfinite|NaN|non-finite"):
        validate(ImuData(t, gyro, accel), policy="recorded")
