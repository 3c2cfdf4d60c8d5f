"""IMU log readers: real recordings (skipped without them) and tiny self-made fixtures."""
from __future__ import annotations

import gzip
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from imu_ground.datasets import (
    UnknownFormatError,
    detect_format,
    read_comma2k19,
    read_imu,
    read_kitti_imu100,
    read_kitti_oxts,
    read_nuscenes_imu,
    read_table,
)
from imu_ground.datasets.kitti_imu100 import COLUMNS
from imu_ground.datasets.kitti_oxts import OXTS_FIELDS
from imu_ground.datasets.validation import (
    STANDARD_GRAVITY,
    GapWarning,
    ImuValidationError,
    SensorWarning,
    ImuValidationWarning,
    MalformedFileError,
    TimestampWarning,
)

G = STANDARD_GRAVITY
DRIVE_0001 = Path("kitti_raw/2011_09_26/2011_09_26_drive_0001_sync")


# =========================================================================== real data
class TestKittiOxtsReal:
    def test_drive_0001(self, shared_data):
        imu = read_kitti_oxts(shared_data / DRIVE_0001)
        assert len(imu) == 108 and imu.frame == "FLU"
        assert 9.9 < imu.rate < 10.1
        assert imu.t[0] == 0.0
        # nanosecond timestamps: 13:02:26.074347616 - 13:02:25.964389445
        assert imu.t[1] == pytest.approx(0.109958171, abs=1e-12)
        assert imu.meta["t0_iso"] == "2011-09-26T13:02:25.964389445"
        assert imu.meta["t0_ns"] % 1_000_000_000 == 964389445
        # gyro = (wx, wy, wz), accel = (ax, ay, az): the body's axes; all 30 fields kept
        assert list(imu.extra.columns) == list(OXTS_FIELDS)  # dataformat.txt's 2nd "ay" fixed to "az"
        assert any("'ay' a second time" in n for n in imu.meta["notes"])
        np.testing.assert_array_equal(imu.gyro, imu.extra[["wx", "wy", "wz"]].to_numpy())
        np.testing.assert_array_equal(imu.accel, imu.extra[["ax", "ay", "az"]].to_numpy())
        # the body axes see gravity tilted by the INS roll (af, al, au are levelled: they do not)
        x = imu.extra
        tilt = 9.81 * np.sin(x["roll"].to_numpy()) * np.cos(x["pitch"].to_numpy())
        np.testing.assert_allclose(imu.accel[:, 1] - x["al"].to_numpy(), tilt, atol=0.05)
        assert imu.units["wf"] == "rad/s" and imu.units["au"] == "m/s^2" and imu.units["lat"] == "deg"
        assert imu.units["pos_accuracy"] == "m" and imu.units["navstat"] == "-"
        assert 9.5 < imu.accel[:, 2].mean() < 10.1
        assert imu.extra["lat"].iloc[0] == pytest.approx(49.015003823272)
        rep = imu.meta["validation"]
        assert rep.ok and rep.n_dropped == 0

    def test_oxts_folder_and_read_imu_agree(self, shared_data):
        a = read_kitti_oxts(shared_data / DRIVE_0001 / "oxts")
        b = read_imu(shared_data / DRIVE_0001)
        assert b.meta["format"] == "kitti_oxts" and b.meta["drive"] == DRIVE_0001.name
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.accel, b.accel)

    def test_drive_0005_missing_packets(self, shared_data):
        drive = shared_data / "kitti_raw/2011_09_26/2011_09_26_drive_0005_sync"
        with pytest.raises(FileNotFoundError, match=r"0000000001\.txt: no such file; 153 of 154"):
            read_kitti_oxts(drive)
        with pytest.warns(ImuValidationWarning, match="153 of 154"):
            imu = read_kitti_oxts(drive, allow_missing=True)
        assert len(imu) == 1 and imu.meta["missing_packets"].size == 153


class TestKittiImu100Real:
    @pytest.mark.filterwarnings("ignore::imu_ground.datasets.validation.GapWarning")
    def test_drive_0023(self, shared_data):
        path = shared_data / "kitti_imu100/2011_09_26_drive_0023.csv.gz"
        with pytest.warns(TimestampWarning, match=r"5 sample\(s\) out of order.*line 4015.*dropped 6 of 4973"):
            read_kitti_imu100(path, policy="drop")
        with pytest.warns(TimestampWarning, match=r"5 sample\(s\) out of order.*line 4015.*retimed on the "
                                                  r"sample index.*nothing dropped"):
            imu = read_kitti_imu100(path)
        assert imu.frame == "FLU" and len(imu) == 4973
        assert imu.meta["t0"] == pytest.approx(47878.763625)      # drives.csv
        assert imu.meta["expected_samples"] == 4973
        assert 99 < imu.rate < 101
        # gravity is +9.8 on z (specific force, up axis)
        assert imu.accel[:, 2].mean() == pytest.approx(9.8, abs=0.2)
        assert np.abs(imu.accel[:, :2].mean(axis=0)).max() < 1.0
        assert list(imu.extra.columns) == list(COLUMNS[7:])
        assert imu.units["pitch"] == "rad" and imu.units["vu"] == "m/s" and imu.units["px"] == "m"
        rep = imu.meta["validation"]
        assert rep.n_out_of_order == 5 and rep.n_duplicates == 1
        np.testing.assert_array_equal(rep.backstep_index, [4013])
        assert rep.backstep_size[0] == pytest.approx(-0.0499, abs=5e-4)
        assert rep.retimed and rep.retime_shift_max == pytest.approx(0.06, abs=1e-3)
        assert np.all(np.diff(imu.t) > 0)

    def test_strict_policy_refuses(self, shared_data):
        with pytest.raises(ImuValidationError, match="not strictly increasing"):
            read_kitti_imu100(shared_data / "kitti_imu100/2011_09_26_drive_0023.csv.gz", policy="strict")

    @pytest.mark.filterwarnings("ignore::imu_ground.datasets.validation.TimestampWarning")
    def test_long_gap_reported(self, shared_data):
        with pytest.warns(GapWarning, match=r"longest 1\.6 s at t=41\.84\d+ s \(line 4186\)"):
            imu = read_kitti_imu100(shared_data / "kitti_imu100/2011_09_26_drive_0029.csv.gz")
        rep = imu.meta["validation"]
        assert rep.gap_length.max() == pytest.approx(1.6, abs=1e-3)

    @pytest.mark.filterwarnings("ignore::imu_ground.datasets.validation.ImuValidationWarning")
    def test_all_drives(self, shared_data, kitti_index):
        folder = shared_data / "kitti_imu100"
        files = sorted(folder.glob("*.csv.gz"))
        assert [f.name for f in files] == sorted(f"{n}.csv.gz" for n in kitti_index["drive"])
        dropped = {}
        for f in files:
            imu = read_imu(f)
            rep = imu.meta["validation"]
            assert imu.meta["format"] == "kitti_imu100"
            assert rep.n_in == imu.meta["expected_samples"]
            assert rep.accel_median_norm == pytest.approx(G, abs=0.3)
            assert rep.gyro_max_norm < 1.0
            dropped[f.name] = rep.n_dropped
        assert sum(dropped.values()) == 0  # retimed (policy="drop" loses 2,900 samples, 603 on drive 0070)


def test_nuscenes_real(shared_data):
    imu = read_nuscenes_imu(shared_data / "nuscenes_can_bus" / "scene-0103_ms_imu.json")
    assert len(imu) == 1934 and imu.frame == "FLU"
    assert imu.rate == pytest.approx(100.0, abs=0.5)
    assert imu.meta["t0"] == pytest.approx(1533151603.550453)
    assert imu.meta["scene"] == "scene-0103"
    assert imu.extra["utime"].iloc[0] == 1533151603550453
    assert imu.accel[0] == pytest.approx([-0.5810940265655518, -0.07831503450870514, 9.865835189819336])
    assert imu.gyro[0] == pytest.approx([-0.021086912602186203, -0.012439718469977379, -0.02306700125336647])
    assert imu.accel[:, 2].mean() == pytest.approx(9.8, abs=0.3)
    assert imu.meta["validation"].ok
    # the folder works too
    assert len(read_imu(shared_data / "nuscenes_can_bus")) == 1934


def test_comma2k19_real(shared_data):
    imu = read_comma2k19(shared_data / "comma2k19_example")
    assert len(imu) == 6256 and imu.frame == "device"
    assert imu.rate == pytest.approx(104.4, abs=0.5)
    al = imu.meta["accel_alignment"]
    assert "interpolated onto the gyro times" in al["method"]
    assert al["identical_time_bases"] and al["max_offset_s"] == 0.0 and al["n_gyro_outside_accel"] == 0
    raw_t = np.load(shared_data / "comma2k19_example/processed_log/IMU/gyro/t")
    assert imu.meta["t0"] == raw_t[0]
    np.testing.assert_allclose(imu.t, raw_t - raw_t[0])
    assert imu.meta["validation"].accel_median_norm == pytest.approx(9.7, abs=0.3)
    assert read_imu(shared_data / "comma2k19_example" / "processed_log").meta["format"] == "comma2k19"


def test_detect_real_formats(shared_data):
    assert detect_format(shared_data / DRIVE_0001) == "kitti_oxts"
    assert detect_format(shared_data / DRIVE_0001 / "oxts") == "kitti_oxts"
    assert detect_format(shared_data / "kitti_imu100/2011_09_26_drive_0009.csv.gz") == "kitti_imu100"
    assert detect_format(shared_data / "nuscenes_can_bus/scene-0103_ms_imu.json") == "nuscenes"
    assert detect_format(shared_data / "comma2k19_example") == "comma2k19"
    with pytest.raises(UnknownFormatError, match=str(shared_data / "kitti_odometry")):
        detect_format(shared_data / "kitti_odometry")


# =========================================================================== generic table
def write_csv(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_table_units_converted(tmp_path):
    df = pd.DataFrame({"time_ms": [1000, 1010, 1020, 1030],
                       "gx": [90.0, 0.0, -45.0, 180.0], "gy": 0.0, "gz": 1.0,
                       "ax": [0.0, 0.5, 0.0, 0.0], "ay": 0.0, "az": [1.0, 1.0, 0.98, 1.02],
                       "speed": [3.0, 3.1, 3.2, 3.3]})
    path = tmp_path / "log.csv"
    df.to_csv(path, index=False)
    imu = read_table(path, time="time_ms", time_unit="ms", gyro=("gx", "gy", "gz"), gyro_unit="deg/s",
                     accel=("ax", "ay", "az"), accel_unit="g", extra_units={"speed": "m/s"})
    np.testing.assert_allclose(imu.t, [0.0, 0.01, 0.02, 0.03], atol=1e-15)
    assert imu.meta["t0"] == pytest.approx(1.0)
    assert imu.gyro[0, 0] == pytest.approx(math.pi / 2)
    assert imu.gyro[2, 0] == pytest.approx(-math.pi / 4)
    assert imu.gyro[0, 2] == pytest.approx(math.pi / 180)
    assert imu.accel[1, 0] == pytest.approx(0.5 * 9.80665)
    assert imu.accel[2, 2] == pytest.approx(0.98 * 9.80665)
    assert list(imu.extra.columns) == ["speed"] and imu.units == {"speed": "m/s"}
    assert imu.meta["source_units"] == {"time": "ms", "gyro": "deg/s", "accel": "g"}
    assert imu.source == str(path) and imu.meta["validation"].ok


def test_table_nanosecond_integers_keep_precision():
    start = 1_700_000_000_123_456_789
    df = pd.DataFrame({"t": start + np.arange(5, dtype=np.int64) * 10_000_001,
                       "wx": 0.0, "wy": 0.0, "wz": 0.0, "ax": 0.0, "ay": 0.0, "az": G})
    imu = read_table(df, time_unit="ns")
    np.testing.assert_array_equal(imu.t, (np.arange(5) * 10_000_001) * 1e-9)
    assert imu.meta["t0"] == pytest.approx(1_700_000_000.123456789)


def test_table_datetime_column():
    df = pd.DataFrame({"t": pd.date_range("2024-01-01", periods=4, freq="10ms"),
                       "wx": 0.0, "wy": 0.0, "wz": 0.0, "ax": 0.0, "ay": 0.0, "az": G})
    np.testing.assert_allclose(read_imu(df).t, [0, 0.01, 0.02, 0.03])


@pytest.mark.parametrize("kw, allowed", [
    ({"gyro_unit": "rpm"}, "'rad/s', 'deg/s'"),
    ({"accel_unit": "ft/s^2"}, "'m/s^2', 'm/s2', 'g'"),
    ({"time_unit": "min"}, "'s', 'ms', 'us', 'µs', 'ns'"),
])
def test_table_unknown_unit(kw, allowed, tmp_path):
    with pytest.raises(ValueError, match="unknown .* unit") as e:
        read_table(tmp_path / "not_read.csv", **kw)
    assert allowed in str(e.value)


def test_table_missing_column():
    df = pd.DataFrame({"t": [0.0, 0.1], "wx": 0, "wy": 0, "wz": 0, "ax": 0, "ay": 0})
    with pytest.raises(ValueError, match=r"column\(s\) \['az'\] not found"):
        read_table(df)


HEADER = "t,wx,wy,wz,ax,ay,az\n"
ROW = "{t},0.01,0.02,0.03,0.1,0.2,9.8\n"


def rows(n, dt=0.01):
    return "".join(ROW.format(t=round(i * dt, 6)) for i in range(n))


def test_table_short_line_names_file_and_line(tmp_path):
    p = write_csv(tmp_path / "bad.csv", HEADER + rows(3) + "0.03,0.01,0.02\n" + rows(2))
    with pytest.raises(MalformedFileError, match=r"bad\.csv, line 5: 3 fields, expected 7") as e:
        read_table(p)
    assert e.value.line == 5


def test_table_truncated_last_line(tmp_path):
    p = write_csv(tmp_path / "cut.csv", HEADER + rows(4) + "0.04,0.01,0.0")
    with pytest.raises(MalformedFileError, match=r"cut\.csv, line 6: .*truncated file"):
        read_table(p)


def test_table_non_number_names_line_and_column(tmp_path):
    p = write_csv(tmp_path / "nan.csv", HEADER + rows(2) + "0.02,0.01,abc,0.03,0.1,0.2,9.8\n")
    with pytest.raises(MalformedFileError, match=r"nan\.csv, line 4: column 'wy': 'abc' is not a number"):
        read_table(p)


def test_table_blank_lines_do_not_shift_line_numbers(tmp_path):
    p = write_csv(tmp_path / "blank.csv", HEADER + rows(2) + "\n" + "0.02,x,0.02,0.03,0.1,0.2,9.8\n")
    with pytest.raises(MalformedFileError, match=r"line 5: column 'wx'"):
        read_table(p)


def test_table_whitespace_lines_are_blank(tmp_path):
    p = write_csv(tmp_path / "ws.csv", HEADER + rows(2) + "   \n\t\n" + "0.02,x,0.02,0.03,0.1,0.2,9.8\n")
    with pytest.raises(MalformedFileError, match=r"line 6: column 'wx'"):
        read_table(p)
    p = write_csv(tmp_path / "ws2.csv", (HEADER + rows(20) + "  \n").replace("\n", "\r\n"))
    assert len(read_table(p)) == 20


def test_table_empty_and_header_only(tmp_path):
    with pytest.raises(MalformedFileError, match=r"empty\.csv: file is empty"):
        read_table(write_csv(tmp_path / "empty.csv", ""))
    with pytest.raises(MalformedFileError, match=r"head\.csv, line 1: header only"):
        read_table(write_csv(tmp_path / "head.csv", HEADER))


def test_table_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nope\.csv"):
        read_table(tmp_path / "nope.csv")


def test_table_truncated_gzip(tmp_path):
    data = gzip.compress((HEADER + rows(2000)).encode())
    p = tmp_path / "cut.csv.gz"
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(MalformedFileError, match=r"cut\.csv\.gz: truncated or corrupt gzip"):
        read_table(p)


def test_table_nan_value_reaches_validation(tmp_path):
    p = write_csv(tmp_path / "hole.csv", HEADER + rows(3) + "0.03,,0.02,0.03,0.1,0.2,9.8\n" + ROW.format(t=0.04))
    with pytest.raises(ImuValidationError, match=r"hole\.csv: 1 row\(s\) with NaN.*wx.*first bad line 5"):
        read_table(p)
    with pytest.warns(ImuValidationWarning, match="dropped 1 of 5"):
        imu = read_table(p, nonfinite="drop")
    assert len(imu) == 4


def test_validate_false_keeps_raw(tmp_path):
    p = write_csv(tmp_path / "raw.csv", HEADER + ROW.format(t=0.0) + ROW.format(t=0.02) + ROW.format(t=0.01))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        imu = read_table(p, validate=False)
    np.testing.assert_allclose(imu.t, [0, 0.02, 0.01])
    assert "validation" not in imu.meta
    with pytest.warns(TimestampWarning) as rec:
        assert len(read_imu(p)) == 2
    assert rec[0].filename == __file__  # warning points at the user's call


# =========================================================================== kitti_imu100 (synthetic)
def kitti100_text(n, t_values=None):
    t_values = np.arange(n) * 0.01 if t_values is None else t_values
    lines = [",".join(COLUMNS)]
    for t in t_values:
        lines.append(f"{t:.6f},0.01,0.0,-0.01,0.1,0.2,9.81,0.01,0.02,0.3,1,2,0,0,0,0")
    return "\n".join(lines) + "\n"


def test_kitti_imu100_synthetic_with_index(tmp_path):
    name = "2011_01_01_drive_0001"
    with gzip.open(tmp_path / f"{name}.csv.gz", "wt") as f:
        f.write(kitti100_text(50))
    (tmp_path / "drives.csv").write_text(f"drive,t0_seconds_of_day,samples\n{name},1000.5,50\n")
    imu = read_imu(tmp_path / f"{name}.csv.gz")
    assert imu.meta["format"] == "kitti_imu100" and imu.meta["t0"] == 1000.5
    assert len(imu) == 50 and imu.extra.shape == (50, 9)
    # the index disagrees: warned, not silent
    (tmp_path / "drives.csv").write_text(f"drive,t0_seconds_of_day,samples\n{name},1000.5,60\n")
    with pytest.warns(ImuValidationWarning, match="50 rows but .*lists 60"):
        read_kitti_imu100(tmp_path / f"{name}.csv.gz")


def test_kitti_imu100_drives_csv_choices(tmp_path):
    """None: the drives.csv beside the file if any; True: that one, required; False: ignored; a path: required."""
    name = "2011_01_01_drive_0002"
    path = tmp_path / f"{name}.csv"
    path.write_text(kitti100_text(20))
    assert read_kitti_imu100(path).meta["t0"] == 0.0                    # none beside: the file's own t
    with pytest.raises(FileNotFoundError, match=r"drives\.csv: no such file \(drives_csv=True\)"):
        read_kitti_imu100(path, drives_csv=True)
    with pytest.raises(FileNotFoundError, match=r"other\.csv: no such file$"):
        read_kitti_imu100(path, drives_csv=tmp_path / "other.csv")
    (tmp_path / "drives.csv").write_text(f"drive,t0_seconds_of_day,samples\n{name},7.5,20\n")
    assert read_kitti_imu100(path).meta["t0"] == 7.5
    assert read_kitti_imu100(path, drives_csv=True).meta["drives_csv"] == str(tmp_path / "drives.csv")
    assert "drives_csv" not in read_kitti_imu100(path, drives_csv=False).meta
    (tmp_path / "other.csv").write_text(f"drive,t0_seconds_of_day,samples\n{name},9.0,20\n")
    assert read_kitti_imu100(path, drives_csv=str(tmp_path / "other.csv")).meta["t0"] == 9.0


def test_kitti_imu100_wrong_header(tmp_path):
    p = write_csv(tmp_path / "x.csv", HEADER + rows(3))
    with pytest.raises(MalformedFileError, match=r"x\.csv, line 1: expected columns t,wx.*missing \['roll'"):
        read_kitti_imu100(p)


# =========================================================================== KITTI OXTS (synthetic)
PACKET = ("49.0 8.4 116.4 0.03 0.009 -2.6 -6.8 -11.2 13.1 -0.1 -0.03 -0.4 0.04 10.2 -0.3 -0.3 10.2 "
          "0.009 -0.023 -0.017 0.0089 -0.0225 -0.0188 0.027 0.0127 4 11 6 6 6")


def make_oxts(root: Path, n=5, dataformat=False) -> Path:
    oxts = root / "drive_sync" / "oxts"
    (oxts / "data").mkdir(parents=True)
    stamps = [f"2011-09-26 13:02:{25 + i // 10:02d}.{(i % 10) * 100_000_000 + 123:09d}" for i in range(n)]
    (oxts / "timestamps.txt").write_text("\n".join(stamps) + "\n")
    for i in range(n):
        (oxts / "data" / f"{i:010d}.txt").write_text(PACKET + "\n")
    if dataformat:
        (oxts / "dataformat.txt").write_text("\n".join(f"{f}: something ({'m' if i < 3 else 'x'})"
                                                       for i, f in enumerate(OXTS_FIELDS)))
    return oxts.parent


def test_oxts_synthetic_standard_fields(tmp_path):
    drive = make_oxts(tmp_path, n=5)
    imu = read_kitti_oxts(drive)
    assert len(imu) == 5 and list(imu.extra.columns) == list(OXTS_FIELDS)
    np.testing.assert_allclose(imu.t, np.arange(5) * 0.1, atol=1e-12)
    assert imu.gyro[0] == pytest.approx([0.009, -0.023, -0.017])          # wx wy wz (body), not wf wl wu
    assert imu.accel[0] == pytest.approx([-0.4, 0.04, 10.2])              # ax ay az (body), not af al au
    assert imu.meta["fields_source"].startswith("standard")
    assert imu.meta["t0_iso"] == "2011-09-26T13:02:25.000000123"


def test_oxts_dataformat_units(tmp_path):
    drive = make_oxts(tmp_path, n=3, dataformat=True)
    imu = read_kitti_oxts(drive / "oxts")
    assert imu.units["lat"] == "m" and imu.units["wf"] == "x"


def test_oxts_29_fields(tmp_path):
    drive = make_oxts(tmp_path)
    bad = drive / "oxts" / "data" / "0000000003.txt"
    bad.write_text(PACKET.rsplit(" ", 1)[0] + "\n")
    with pytest.raises(MalformedFileError, match=r"0000000003\.txt, line 1: 29 fields, expected 30"):
        read_kitti_oxts(drive)


def test_oxts_non_number(tmp_path):
    drive = make_oxts(tmp_path)
    (drive / "oxts" / "data" / "0000000002.txt").write_text(PACKET.replace("116.4", "1l6.4") + "\n")
    with pytest.raises(MalformedFileError, match=r"0000000002\.txt, line 1: field 3: '1l6\.4' is not a number"):
        read_kitti_oxts(drive)


def test_oxts_missing_packet_and_folders(tmp_path):
    drive = make_oxts(tmp_path)
    (drive / "oxts" / "data" / "0000000002.txt").unlink()
    with pytest.raises(FileNotFoundError, match=r"0000000002\.txt: no such file; 1 of 5"):
        read_kitti_oxts(drive)
    with pytest.raises(FileNotFoundError, match=r"nowhere: no such folder"):
        read_kitti_oxts(tmp_path / "nowhere")
    with pytest.raises(FileNotFoundError, match=r"oxts/timestamps\.txt: no such file"):
        read_kitti_oxts(tmp_path)


def test_oxts_more_packets_than_timestamps(tmp_path):
    drive = make_oxts(tmp_path)
    (drive / "oxts" / "data" / "0000000005.txt").write_text(PACKET + "\n")
    with pytest.raises(MalformedFileError, match=r"timestamps\.txt: 5 timestamps but packet file 0000000005\.txt"):
        read_kitti_oxts(drive)


def test_oxts_bad_timestamp_line(tmp_path):
    drive = make_oxts(tmp_path)
    ts = drive / "oxts" / "timestamps.txt"
    lines = ts.read_text().splitlines()
    lines[3] = "2011-09-26 13:02:xx"
    ts.write_text("\n".join(lines))
    with pytest.raises(MalformedFileError, match=r"timestamps\.txt, line 4: not a timestamp"):
        read_kitti_oxts(drive)


def test_oxts_backwards_timestamp_dropped(tmp_path):
    drive = make_oxts(tmp_path, n=6)
    ts = drive / "oxts" / "timestamps.txt"
    lines = ts.read_text().splitlines()
    lines[4] = lines[2]
    ts.write_text("\n".join(lines) + "\n")
    with pytest.warns(TimestampWarning, match=r"row 4.*dropped 1 of 6"):
        imu = read_kitti_oxts(drive)
    assert len(imu) == 5


# =========================================================================== nuScenes (synthetic)
def nus_msg(i, **over):
    m = {"linear_accel": [0.1, 0.0, 9.8], "q": [1.0, 0.0, 0.0, 0.0],
         "rotation_rate": [0.0, 0.01, 0.02], "utime": 1_533_151_603_000_000 + 10_000 * i}
    m.update(over)
    return m


def test_nuscenes_synthetic(tmp_path):
    p = tmp_path / "scene-1_ms_imu.json"
    p.write_text(json.dumps([nus_msg(i) for i in range(20)]))
    imu = read_imu(p)
    assert imu.meta["format"] == "nuscenes" and imu.meta["scene"] == "scene-1"
    np.testing.assert_allclose(imu.t, np.arange(20) * 0.01, atol=1e-12)
    assert imu.extra["qw"].iloc[0] == 1.0 and imu.units["utime"] == "us"


def test_nuscenes_malformed(tmp_path):
    p = tmp_path / "a_ms_imu.json"
    msgs = [nus_msg(i) for i in range(5)]
    msgs[3]["rotation_rate"] = [0.0, 0.1]
    p.write_text(json.dumps(msgs))
    with pytest.raises(MalformedFileError, match=r"a_ms_imu\.json: message 3: 'rotation_rate'.*not 3 numbers"):
        read_nuscenes_imu(p)
    msgs = [nus_msg(i) for i in range(5)]
    del msgs[2]["linear_accel"]
    p.write_text(json.dumps(msgs))
    with pytest.raises(MalformedFileError, match=r"message 2 has no 'linear_accel'"):
        read_nuscenes_imu(p)
    p.write_text(json.dumps(msgs, indent=1)[:200])
    with pytest.raises(MalformedFileError, match=r"a_ms_imu\.json, line \d+: not valid JSON"):
        read_nuscenes_imu(p)
    p.write_text("[]")
    with pytest.raises(MalformedFileError, match="no messages"):
        read_nuscenes_imu(p)


# =========================================================================== comma2k19 (synthetic)
def make_comma(root: Path, tg, ta, wg, va) -> Path:
    imu = root / "seg" / "processed_log" / "IMU"
    for name, t, v in (("gyro", tg, wg), ("accelerometer", ta, va)):
        (imu / name).mkdir(parents=True)
        with open(imu / name / "t", "wb") as f:
            np.save(f, np.asarray(t, dtype=float))
        with open(imu / name / "value", "wb") as f:
            np.save(f, np.asarray(v, dtype=float))
    return root / "seg"


def test_comma_accel_interpolated_onto_gyro(tmp_path):
    tg = 500.0 + np.arange(100) * 0.01
    ta = 500.0 - 0.003 + np.arange(102) * 0.01          # own time base, 3 ms earlier
    va = np.column_stack([ta - 500.0, -2 * (ta - 500.0), np.full(102, -9.81)])  # linear in time
    seg = make_comma(tmp_path, tg, ta, np.zeros((100, 3)), va)
    imu = read_imu(seg)
    assert imu.frame == "device" and len(imu) == 100 and imu.meta["t0"] == 500.0
    np.testing.assert_allclose(imu.t, tg - 500.0)
    np.testing.assert_allclose(imu.accel[:, 0], tg - 500.0, atol=1e-12)   # exact for linear data
    np.testing.assert_allclose(imu.accel[:, 1], -2 * (tg - 500.0), atol=1e-12)
    al = imu.meta["accel_alignment"]
    assert not al["identical_time_bases"] and al["max_offset_s"] == pytest.approx(0.003)


def test_comma_gyro_outside_accel_span_dropped_with_warning(tmp_path):
    tg = np.arange(100) * 0.01
    ta = 0.1 + np.arange(80) * 0.01
    seg = make_comma(tmp_path, tg, ta, np.zeros((100, 3)), np.tile([0, 0, 9.8], (80, 1)))
    with pytest.warns(ImuValidationWarning, match=r"gyro/t: 20 gyro sample\(s\) outside.*\[0\.100000, 0\.890000\]"):
        imu = read_comma2k19(seg / "processed_log")
    assert len(imu) == 80 and imu.meta["accel_alignment"]["n_gyro_outside_accel"] == 20
    assert imu.meta["t0"] == pytest.approx(0.1)


def test_comma_missing_and_bad_files(tmp_path):
    seg = make_comma(tmp_path, np.arange(5.0), np.arange(5.0), np.zeros((5, 3)), np.zeros((5, 3)))
    (seg / "processed_log/IMU/accelerometer/value").write_bytes(b"\x93NUMPY garbage")
    with pytest.raises(MalformedFileError, match=r"accelerometer/value: not a readable NumPy"):
        read_comma2k19(seg)
    (seg / "processed_log/IMU/accelerometer/value").unlink()
    with pytest.raises(FileNotFoundError, match=r"accelerometer/value: no such file"):
        read_comma2k19(seg)


# =========================================================================== read_imu
def test_read_imu_errors_name_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"ghost\.csv: no such file"):
        read_imu(tmp_path / "ghost.csv")
    p = tmp_path / "log.bin"
    p.write_bytes(b"\0")
    with pytest.raises(UnknownFormatError, match=r"log\.bin: cannot tell"):
        read_imu(p)
    (tmp_path / "empty_dir").mkdir()
    with pytest.raises(UnknownFormatError, match=r"empty_dir: cannot tell"):
        read_imu(tmp_path / "empty_dir")
    with pytest.raises(UnknownFormatError, match="unknown format 'sqlite'") as e:
        read_imu(p, format="sqlite")
    assert "--format" in e.value.cli_message()


def test_read_imu_generic_csv_with_kwargs(tmp_path):
    p = write_csv(tmp_path / "phone.csv", "ts,gx,gy,gz,x,y,z\n" +
                  "".join(f"{i * 5},1,2,3,0,0,1\n" for i in range(10)))
    assert detect_format(p) == "table"
    imu = read_imu(p, time="ts", time_unit="ms", gyro=("gx", "gy", "gz"), gyro_unit="deg/s",
                   accel=("x", "y", "z"), accel_unit="g", frame="device")
    assert imu.rate == pytest.approx(200.0)
    assert imu.gyro[0] == pytest.approx(np.deg2rad([1, 2, 3]))
    assert imu.accel[0, 2] == pytest.approx(G) and imu.frame == "device"
    # format="csv" is an alias; the time and gyro units are told from the data, one warning each
    with pytest.warns(UserWarning) as rec:
        imu2 = read_imu(p, format="csv", time="ts", gyro=("gx", "gy", "gz"), accel=("x", "y", "z"), accel_unit="g")
    texts = [str(w.message) for w in rec if w.category is not SensorWarning]   # (its accelerometer is constant)
    assert len(texts) == 2 and "time column 'ts' read as milliseconds" in texts[0] and "deg/s" in texts[1]
    np.testing.assert_allclose(imu2.gyro, imu.gyro, rtol=1e-15)


def test_reader_docstrings_carry_the_common_parameters():
    """The readers' shared validate/policy entries (skeleton.FINISH_PARAMETERS) stand in their docstrings."""
    import inspect

    from imu_ground.datasets.skeleton import FINISH_PARAMETERS
    for reader in (read_kitti_imu100, read_kitti_oxts, read_nuscenes_imu):
        doc = inspect.getdoc(reader)
        assert "{finish_parameters}" not in doc, reader.__name__
        assert FINISH_PARAMETERS in doc, reader.__name__
        assert doc.index(FINISH_PARAMETERS) < doc.index("Returns\n-------"), reader.__name__
