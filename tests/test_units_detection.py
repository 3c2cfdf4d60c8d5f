"""Units and time scales told from the data, the option each error names, pose files handed to the IMU readers, formats."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.datasets import (
    FORMATS,
    READER_OPTIONS,
    ImuInputError,
    PoseFileError,
    detect_format,
    detect_pose_format,
    read_imu,
    read_poses,
)
from imu_ground.datasets.validation import ImuValidationError, UnitsWarning
from imu_ground.units import GRAVITY

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(scope="module")
def example() -> pd.DataFrame:
    """The shipped example drive (t s, gyro rad/s, accel m/s^2)."""
    return pd.read_csv(EXAMPLE)


@pytest.fixture(scope="module")
def reference(example):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return read_imu(EXAMPLE)


def write(df: pd.DataFrame, path: Path) -> Path:
    df.to_csv(path, index=False, float_format="%.17g")
    return path


def test_gyro_in_degrees_converted_with_one_warning(tmp_path, example, reference):
    df = example.copy()
    df[["wx", "wy", "wz"]] = np.degrees(df[["wx", "wy", "wz"]])
    p = write(df, tmp_path / "deg.csv")
    with pytest.warns(UnitsWarning, match=r"deg\.csv: gyro read as deg/s.*gyro_unit='deg/s'") as rec:
        imu = read_imu(p)
    assert len(rec) == 1
    np.testing.assert_allclose(imu.gyro, reference.gyro, rtol=1e-12, atol=1e-15)
    assert imu.meta["detected_units"]["gyro"] == "deg/s"
    assert "--gyro-unit deg/s" in rec[0].message.cli_message()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # saying so silences it
        read_imu(p, gyro_unit="deg/s")


def test_time_in_milliseconds_converted(tmp_path, example, reference):
    df = example.copy()
    df["t"] = np.round(df["t"] * 1000.0, 6)
    with pytest.warns(UnitsWarning, match=r"time column 't' read as milliseconds.*100 Hz") as rec:
        imu = read_imu(write(df, tmp_path / "ms.csv"))
    assert len(rec) == 1 and len(imu) == len(reference)
    np.testing.assert_allclose(imu.t, reference.t, atol=1e-9)
    assert imu.rate == pytest.approx(100.0)


def test_epoch_nanoseconds_converted_exactly(tmp_path, example, reference):
    df = example.copy()
    start = 1_700_000_000_123_456_789
    df["t"] = start + np.round(df["t"].to_numpy() * 1e9).astype(np.int64)
    with pytest.warns(UnitsWarning, match=r"read as nanoseconds from the data: epoch-sized values"):
        imu = read_imu(write(df, tmp_path / "ns.csv"))
    np.testing.assert_allclose(imu.t, reference.t, atol=1e-9)
    assert imu.meta["t0"] == pytest.approx(1_700_000_000.123456789)


def test_accel_in_g_converted(tmp_path, example, reference):
    df = example.copy()
    df[["ax", "ay", "az"]] = df[["ax", "ay", "az"]] / GRAVITY
    with pytest.warns(UnitsWarning, match=r"accelerometer read as units of g") as rec:
        imu = read_imu(write(df, tmp_path / "g.csv"))
    assert len(rec) == 1  # no second warning from the validation's magnitude check
    np.testing.assert_allclose(imu.accel, reference.accel, rtol=1e-12)


def test_ambiguous_gyro_names_the_option(tmp_path, example):
    df = example.copy()
    w = df[["wx", "wy", "wz"]].to_numpy()
    q99 = np.percentile(np.linalg.norm(w, axis=1), 99)
    df[["wx", "wy", "wz"]] = w * (1.5 / q99)  # between a car in rad/s and one in deg/s
    p = write(df, tmp_path / "fast.csv")
    with pytest.raises(ImuInputError, match=r"fast\.csv: cannot tell the gyro unit.*gyro_unit='deg/s'") as e:
        read_imu(p)
    assert e.value.option == "gyro_unit" and "--gyro-unit deg/s" in e.value.cli_message()
    assert len(read_imu(p, gyro_unit="rad/s")) == len(df)


@pytest.mark.parametrize("step, match", [
    (1.0, r"median step 1 fits s or ms"),
    (1e-6, r"gives no IMU rate of 1-2000 Hz"),
])
def test_ambiguous_or_implausible_time_names_the_option(tmp_path, example, step, match):
    df = example.copy()
    df["t"] = np.arange(len(df)) * step
    with pytest.raises(ImuInputError, match=match) as e:
        read_imu(write(df, tmp_path / "t.csv"))
    assert e.value.option == "time_unit" and "time_unit=..." in str(e.value)
    assert "--time-unit" in e.value.cli_message()


def test_explicit_wrong_time_unit_is_refused(tmp_path, example):
    """A unit given that makes the log absurd (0.1 Hz: a frame grid of 10 s steps) is refused naming the option
    (it was a warning, then 600,000 frames)."""
    df = example.copy()
    df["t"] = np.round(df["t"] * 1000.0, 6)
    with pytest.raises(ImuInputError, match=r"time_unit s makes .* 0.1 Hz, no IMU's rate.*milliseconds") as e:
        read_imu(write(df, tmp_path / "ms.csv"), time_unit="s")
    assert e.value.option == "time_unit" and "--time-unit ms" in e.value.cli_message()


def test_every_suggested_option_is_a_reader_option(tmp_path, example):
    """Each error's option exists as a read_imu keyword and a CLI flag, and the message names it."""
    df = example.copy()
    df.loc[5, "wy"] = np.nan
    errors = []
    for kw in ({}, {"policy": "strict"}):
        try:
            read_imu(write(df, tmp_path / "nan.csv"), **kw)
        except ImuInputError as e:
            errors.append(e)
    (tmp_path / "x.bin").write_bytes(b"\0")
    try:
        read_imu(tmp_path / "x.bin")
    except ImuInputError as e:
        errors.append(e)
    assert {e.option for e in errors} == {"nonfinite", "format"}
    for e in errors:
        opt = READER_OPTIONS[e.option]
        assert opt.flag in e.cli_message() and e.option in str(e)


def test_nan_rows_named_by_file_line_after_blank_lines(tmp_path, example):
    text = EXAMPLE.read_text().splitlines()
    text.insert(3, "")  # a blank line before the bad one shifts the file lines, not the rows
    fields = text[10].split(",")
    fields[2] = ""
    text[10] = ",".join(fields)
    p = tmp_path / "hole.csv"
    p.write_text("\n".join(text) + "\n")
    with pytest.raises(ImuValidationError, match=r"hole\.csv: 1 row\(s\) with NaN.*first bad line 11 "):
        read_imu(p)


def test_option_that_does_not_apply_is_named(tmp_path):
    with pytest.raises(ImuInputError, match=r"option topic='/imu' does not apply to table logs") as e:
        read_imu(EXAMPLE, topic="/imu")
    assert "--topic /imu" in e.value.cli_message()
    assert len(read_imu(EXAMPLE, topic=None, allow_missing=False)) > 0  # "not set" is fine


# --------------------------------------------------------------------------- formats
def test_parquet_table_reads_like_csv(tmp_path, example, reference):
    pytest.importorskip("pyarrow")
    p = tmp_path / "log.parquet"
    example.to_parquet(p)
    assert detect_format(p) == "parquet"
    imu = read_imu(p)
    np.testing.assert_array_equal(imu.t, reference.t)
    np.testing.assert_array_equal(imu.gyro, reference.gyro)
    assert imu.meta["format"] == "parquet" and imu.meta["validation"].ok


def test_rosbag_probe_without_importing_the_reader(tmp_path):
    (tmp_path / "log.bag").write_bytes(b"#ROSBAG V2.0\n")
    (tmp_path / "log.mcap").write_bytes(b"\x89MCAP0\r\n")
    (tmp_path / "ros2").mkdir()
    (tmp_path / "ros2" / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    assert {detect_format(tmp_path / n) for n in ("log.bag", "log.mcap", "ros2")} == {"rosbag"}
    assert FORMATS["rosbag"].options == frozenset({"topic"})


def kitti_pose_lines(n=4, index=False):
    rng = np.random.default_rng(1)
    out = []
    for i in range(n):
        c, s = np.cos(0.1 * i), np.sin(0.1 * i)
        m = np.array([[c, 0, s, rng.normal()], [0, 1, 0, 0.0], [-s, 0, c, i * 1.0]])
        out.append((f"{i + 1} " if index else "") + " ".join(f"{v:.9e}" for v in m.ravel()))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("name, text, kind", [
    ("00.txt", kitti_pose_lines(), "kitti"),
    ("orb.txt", kitti_pose_lines(index=True), "kitti"),
    ("traj.txt", "# t x y z qx qy qz qw\n0.0 0 0 0 0 0 0 1\n0.1 1 0 0 0 0 0.0499792 0.9987503\n", "tum"),
])
def test_pose_files_are_named_as_such(tmp_path, name, text, kind):
    p = tmp_path / name
    p.write_text(text)
    assert detect_pose_format(p) == kind
    assert len(read_poses(p)) >= 2
    with pytest.raises(PoseFileError, match=r"a pose file .*not an IMU log; `imu-ground estimate` accepts it"):
        read_imu(p)
    with pytest.raises(PoseFileError):
        detect_format(p)


def test_tables_are_not_pose_files(tmp_path):
    assert detect_pose_format(EXAMPLE) is None
    p = tmp_path / "eight.txt"
    p.write_text("1 2 3 4 5 6 7 8\n2 3 4 5 6 7 8 9\n")  # 8 numbers, not a unit quaternion
    assert detect_pose_format(p) is None


def test_pose_file_real(shared_data):
    assert detect_pose_format(shared_data / "kitti_odometry" / "poses" / "00.txt") == "kitti"
    assert detect_pose_format(shared_data / "kitti_odometry" / "orbslam2_mono" / "00.txt") == "kitti"
    assert detect_pose_format(shared_data / "kitti_odometry" / "times" / "00.txt") is None
    with pytest.raises(PoseFileError, match="KITTI odometry poses"):
        read_imu(shared_data / "kitti_odometry" / "poses" / "00.txt")


def test_nuscenes_folder_with_several_scenes_names_the_scene_option(tmp_path):
    for name in ("scene-0001", "scene-0002"):
        (tmp_path / f"{name}_ms_imu.json").write_text("[]")
    with pytest.raises(ImuInputError, match=r"2 \*_ms_imu\.json files.*scene='scene-0001'") as e:
        read_imu(tmp_path)
    assert "--scene scene-0001" in e.value.cli_message() and "scene" in READER_OPTIONS
