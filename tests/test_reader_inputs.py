"""Inputs users really produce, read as they mean them or refused with one line naming the file and the flag.

KITTI-format CSV files in other units, logs newest first, logs too short for a
frame, sensors that do not work, unknown keywords, KITTI pose files without
times or in camera axes, and tables whose columns have other names.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from imu_ground.cli import main
from imu_ground.datasets import ImuInputError, read_imu, read_poses
from imu_ground.datasets.kitti_imu100 import COLUMNS
from imu_ground.datasets.poses import moves_along_z
from imu_ground.datasets.validation import ImuValidationError, SensorWarning, UnitsWarning
from imu_ground.units import GRAVITY

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


def run(capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(scope="module")
def example() -> pd.DataFrame:
    return pd.read_csv(EXAMPLE)


def kitti_csv(df: pd.DataFrame, path: Path) -> Path:
    """``df`` (t, wx..az) in the kitti_imu100 layout: the 9 INS columns added as zeros."""
    out = df[list(COLUMNS[:7])].copy()
    for c in COLUMNS[7:]:
        out[c] = 0.0
    out.to_csv(path, index=False, float_format="%.17g")
    return path


@pytest.fixture(scope="module")
def kitti_reference(example, tmp_path_factory):
    """The example in the kitti_imu100 layout, in KITTI's own units (s, rad/s, m/s^2)."""
    p = kitti_csv(example, tmp_path_factory.mktemp("ref") / "ref.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return read_imu(p)


# ------------------------------------------------------------------------------------------ KITTI CSV units
def test_kitti_csv_in_degrees_and_g_is_converted_with_one_line_each(example, kitti_reference, tmp_path, capsys):
    df = example.copy()
    df[["wx", "wy", "wz"]] = np.degrees(df[["wx", "wy", "wz"]])
    df[["ax", "ay", "az"]] = df[["ax", "ay", "az"]] / GRAVITY
    p = kitti_csv(df, tmp_path / "deg_g.csv")
    with pytest.warns(UnitsWarning) as rec:
        imu = read_imu(p)
    assert imu.meta["format"] == "kitti_imu100"
    texts = [str(w.message) for w in rec]
    assert len(texts) == 2 and "gyro read as deg/s" in texts[0] and "units of g" in texts[1]
    np.testing.assert_allclose(imu.gyro, kitti_reference.gyro, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(imu.accel, kitti_reference.accel, rtol=1e-12)
    code, _, err = run(capsys, "estimate", p, "-o", tmp_path / "o.csv", "--no-progress")
    assert code == 0, err
    assert "--gyro-unit deg/s" in err and "--accel-unit g" in err
    assert "gyro_unit" not in err and "accel_unit" not in err          # CLI flags, never Python keywords


@pytest.mark.parametrize("unit, scale, start", [("ms", 1e3, 0), ("ns", 1e9, 1_317_000_000_000_000_000)])
def test_kitti_csv_times_in_ms_or_epoch_ns_are_converted(unit, scale, start, example, kitti_reference, tmp_path,
                                                         capsys):
    df = example.copy()
    df["t"] = start + np.round(df["t"].to_numpy() * scale).astype(np.int64)
    p = kitti_csv(df, tmp_path / f"t_{unit}.csv")
    with pytest.warns(UnitsWarning, match="time column 't' read as " + {"ms": "milli", "ns": "nano"}[unit]):
        imu = read_imu(p)
    np.testing.assert_allclose(imu.t, kitti_reference.t, atol=1e-9)
    assert imu.rate == pytest.approx(100.0)
    code, out, err = run(capsys, "estimate", p, "-o", tmp_path / "o.csv", "--no-progress")
    assert code == 0, err                                  # (epoch ns read as s once asked for 3.40 TiB)
    assert f"{len(pd.read_csv(tmp_path / 'o.csv', comment='#'))} frames at 10 Hz" in out


def test_kitti_csv_unit_flags_are_accepted(example, kitti_reference, tmp_path, capsys):
    df = example.copy()
    df["t"] = df["t"] * 1e3
    df[["wx", "wy", "wz"]] = np.degrees(df[["wx", "wy", "wz"]])
    df[["ax", "ay", "az"]] = df[["ax", "ay", "az"]] / GRAVITY
    p = kitti_csv(df, tmp_path / "all.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UnitsWarning)           # saying the units silences the detection
        imu = read_imu(p, time_unit="ms", gyro_unit="deg/s", accel_unit="g")
    np.testing.assert_allclose(imu.gyro, kitti_reference.gyro, rtol=1e-12, atol=1e-15)
    code, _, err = run(capsys, "estimate", p, "-o", tmp_path / "o.csv", "--no-progress", "--time-unit", "ms",
                       "--gyro-unit", "deg/s", "--accel-unit", "g")
    assert code == 0, err
    assert "read as" not in err
    with pytest.raises(ImuInputError, match=r"unknown gyro unit 'rpm'"):
        read_imu(p, gyro_unit="rpm")


# ------------------------------------------------------------------------------------------ order and length
def test_newest_first_log_says_reverse_order_and_names_policy_sort(example, tmp_path, capsys):
    p = tmp_path / "reversed.csv"
    example.iloc[::-1].to_csv(p, index=False, float_format="%.17g")
    with pytest.raises(ImuValidationError, match=r"reversed\.csv: the samples are in reverse order .*policy='sort'"):
        read_imu(p)
    code, _, err = run(capsys, "estimate", p, "-o", tmp_path / "o.csv")
    assert code == 2
    line = error_line(err)
    assert "reversed.csv" in line and "reverse order" in line and "--policy sort" in line
    imu = read_imu(p, policy="sort")
    assert len(imu) == len(example) and np.all(np.diff(imu.t) > 0)


@pytest.mark.parametrize("rows", [1, 2, 3, 4, 5])
def test_one_to_five_row_csv_names_the_file(rows, example, tmp_path, capsys):
    p = tmp_path / f"short{rows}.csv"
    example.iloc[:rows].to_csv(p, index=False)
    code, _, err = run(capsys, "estimate", p, "-o", tmp_path / "o.csv")
    assert code == 2
    assert str(p) in error_line(err)


# ------------------------------------------------------------------------------------------ sensors
def _moving(n: int = 3000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    t = np.arange(n) * 0.01
    gyro = rng.normal(0, 0.01, (n, 3)) + np.outer(0.3 * np.sin(t / 3.0), [0, 0, 1])
    accel = rng.normal(0, 0.05, (n, 3)) + np.outer(1.5 * np.sin(t / 2.0), [1, 0, 0]) + [0, 0, GRAVITY]
    return t, gyro, accel


def _write(path: Path, t, gyro, accel) -> Path:
    pd.DataFrame({"t": t, "wx": gyro[:, 0], "wy": gyro[:, 1], "wz": gyro[:, 2],
                  "ax": accel[:, 0], "ay": accel[:, 1], "az": accel[:, 2]}).to_csv(path, index=False)
    return path


@pytest.mark.parametrize("case, expected", [
    ("dead gyro", "gyro reads exactly 0 on all 3000 samples"),
    ("stuck accelerometer", "accelerometer reads the same value"),
    ("never moves", "vehicle never moves"),
])
def test_sensors_that_do_not_work_get_one_warning_each(case, expected, tmp_path):
    t, gyro, accel = _moving()
    if case == "dead gyro":
        gyro[:] = 0.0
    elif case == "stuck accelerometer":
        accel[:] = [0.3, -0.1, 9.79]
    else:                                      # parked, engine running: sensor noise only
        gyro = gyro * 0.0 + np.random.default_rng(6).normal(0, 0.003, gyro.shape)
        accel = np.random.default_rng(7).normal(0, 0.03, accel.shape) + [0.2, 0.1, 9.8]
    p = _write(tmp_path / "log.csv", t, gyro, accel)
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        read_imu(p)
    sensor = [str(w.message) for w in rec if issubclass(w.category, SensorWarning)]
    assert len(sensor) == 1 and expected in sensor[0] and sensor[0].startswith(str(p))


def test_a_moving_log_gets_no_sensor_warning(tmp_path):
    p = _write(tmp_path / "log.csv", *_moving())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_imu(p)


# ------------------------------------------------------------------------------------------ keywords
def test_unknown_keyword_names_read_imu(tmp_path, example):
    with pytest.raises(TypeError, match=r"read_imu\(\) got an unexpected keyword argument 'bogus_kw'") as e:
        read_imu(EXAMPLE, bogus_kw=1)
    assert "validate()" not in str(e.value)
    p = kitti_csv(example, tmp_path / "k.csv")
    with pytest.raises(TypeError, match=r"read_imu\(\) .*'bogus_kw' for kitti_imu100 logs"):
        read_imu(p, bogus_kw=1)


# ------------------------------------------------------------------------------------------ KITTI pose files
def _trajectory(n: int, forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A gently turning path whose steps go along ``forward`` in the sensor frame: rotations, positions."""
    rot = Rotation.from_rotvec(np.outer(np.linspace(0, 0.5, n), [0, 1, 0] if forward[2] else [0, 0, 1]))
    R = rot.as_matrix()
    p = np.zeros((n, 3))
    for k in range(1, n):
        p[k] = p[k - 1] + R[k - 1] @ forward
    return R, p


def _write_kitti(path: Path, R: np.ndarray, p: np.ndarray) -> Path:
    np.savetxt(path, np.concatenate([R, p[:, :, None]], axis=2).reshape(len(R), 12), fmt="%.12e")
    return path


def test_camera_poses_are_told_from_body_poses():
    R, p = _trajectory(60, np.array([0.0, 0.0, 1.0]))     # camera: z forward
    from imu_ground.datasets.poses import PoseSequence
    assert moves_along_z(PoseSequence(R, p, None, np.arange(60)))
    R, p = _trajectory(60, np.array([1.0, 0.0, 0.0]))     # vehicle body: x forward
    assert not moves_along_z(PoseSequence(R, p, None, np.arange(60)))


def test_kitti_camera_poses_without_extrinsic_are_refused_naming_it(tmp_path, capsys):
    kitti = _write_kitti(tmp_path / "00.txt", *_trajectory(60, np.array([0.0, 0.0, 1.0])))
    code, _, err = run(capsys, "estimate", kitti, "-o", tmp_path / "o.csv")
    assert code == 2
    line = error_line(err)
    assert "00.txt" in line and "camera" in line and "--extrinsic kitti_cam0" in line
    assert not (tmp_path / "o.csv").exists()
    code, _, err = run(capsys, "estimate", kitti, "-o", tmp_path / "o.csv", "--extrinsic", "kitti_cam0")
    assert code == 0, err


def test_kitti_pose_times_file_sets_the_clock(tmp_path, capsys):
    R, p = _trajectory(60, np.array([0.0, 0.0, 1.0]))
    kitti = _write_kitti(tmp_path / "00.txt", R, p)
    times = np.cumsum(np.full(60, 0.1037)) - 0.1037
    np.savetxt(tmp_path / "times.txt", times, fmt="%.6e")
    poses = read_poses(kitti, times=tmp_path / "times.txt")
    np.testing.assert_allclose(poses.t, times, rtol=1e-6)
    assert "times.txt" in poses.clock
    code, out, err = run(capsys, "estimate", kitti, "--extrinsic", "kitti_cam0", "--times", tmp_path / "times.txt",
                         "-o", tmp_path / "o.csv")
    assert code == 0, err
    assert "no times" not in err
    df = pd.read_csv(tmp_path / "o.csv", comment="#")
    np.testing.assert_allclose(df["t"], times[1:], rtol=1e-6)
    header = [ln for ln in (tmp_path / "o.csv").read_text().splitlines() if ln.startswith("# clock:")]
    assert len(header) == 1 and "times.txt" in header[0]
    assert "times.txt" in out.splitlines()[0]                          # the summary line names the clock
    # without it: a warning naming --times, frames on index / rate, the clock named as such
    code, out, err = run(capsys, "estimate", kitti, "--extrinsic", "kitti_cam0", "-o", tmp_path / "o2.csv")
    assert code == 0 and "--times" in err and "no times" in out.splitlines()[0]
    # a times file that does not fit the poses: one line naming it
    np.savetxt(tmp_path / "short.txt", times[:10])
    code, _, err = run(capsys, "estimate", kitti, "--extrinsic", "kitti_cam0", "--times", tmp_path / "short.txt",
                       "-o", tmp_path / "o3.csv")
    assert code == 2 and "short.txt" in error_line(err)



def test_a_kitti_times_file_of_another_length_is_refused_naming_both_files(tmp_path, capsys):
    """A longer times file (another sequence's) was accepted: its first lines timed the poses (exit 0)."""
    R, p = _trajectory(60, np.array([0.0, 0.0, 1.0]))
    kitti = _write_kitti(tmp_path / "00.txt", R, p)
    times = np.arange(100) * 0.1037
    np.savetxt(tmp_path / "other.txt", times, fmt="%.6e")
    with pytest.raises(ImuInputError, match="60 poses but 100 times") as got:
        read_poses(kitti, times=tmp_path / "other.txt")
    assert got.value.option == "times"
    code, _, err = run(capsys, "estimate", kitti, "--extrinsic", "kitti_cam0", "--times", tmp_path / "other.txt",
                       "-o", tmp_path / "o.csv")
    line = error_line(err)
    assert code == 2 and str(kitti) in line and str(tmp_path / "other.txt") in line and "--times" in line
    assert not (tmp_path / "o.csv").exists()
    # a file with a frame index may skip frames (ORB-SLAM2's): only its frames need times
    indexed = tmp_path / "orb.txt"
    rows = np.loadtxt(kitti)[5:]
    np.savetxt(indexed, np.column_stack([np.arange(6, 61), rows]), fmt=["%d"] + ["%.12e"] * 12)
    np.testing.assert_allclose(read_poses(indexed, times=tmp_path / "other.txt").t, times[5:60], rtol=1e-6)


def test_real_kitti_poses_take_only_their_own_sequences_times(shared_data):
    """No false alarm on the benchmark's files; every other sequence's times of another length refused."""
    odo = shared_data / "kitti_odometry"
    names = sorted(f.name for f in (odo / "poses").glob("*.txt") if (odo / "times" / f.name).is_file())
    lines = {n: sum(1 for ln in (odo / "times" / n).read_text().splitlines() if ln.strip()) for n in names}
    for n in names:
        assert len(read_poses(odo / "poses" / n, times=odo / "times" / n).t) == lines[n]
    n = min(names, key=lines.get)                 # the shortest: the others are longer times files
    for other in names:
        if lines[other] != lines[n]:
            with pytest.raises(ImuInputError, match="times"):
                read_poses(odo / "poses" / n, times=odo / "times" / other)

def test_real_kitti_times_file(shared_data):
    odo = shared_data / "kitti_odometry"
    poses = read_poses(odo / "poses" / "00.txt", times=odo / "times" / "00.txt")
    steps = np.diff(poses.t)
    assert steps.mean() == pytest.approx(0.1037, abs=5e-4)                # 9.65 Hz, not 10 Hz
    assert moves_along_z(poses)
    orb = read_poses(odo / "orbslam2_mono" / "00.txt", times=odo / "times" / "00.txt")
    np.testing.assert_array_equal(orb.t, poses.t[orb.index - 1])          # its frames count from 1


# ------------------------------------------------------------------------------------------ column names
def test_columns_option_maps_other_names(example, tmp_path, capsys):
    ref = read_imu(EXAMPLE)
    named = example.set_axis(["timestamp", "gyro_x", "gyro_y", "gyro_z", "acc_x", "acc_y", "acc_z"], axis=1)
    p = tmp_path / "named.csv"
    named.to_csv(p, index=False, float_format="%.17g")
    with pytest.raises(ImuInputError, match=r"named\.csv: column\(s\) .* not found.*columns=") as e:
        read_imu(p)
    assert "--columns t=NAME" in e.value.cli_message()
    spec = "t=timestamp,wx=gyro_x,wy=gyro_y,wz=gyro_z,ax=acc_x,ay=acc_y,az=acc_z"
    imu = read_imu(p, columns=spec)
    np.testing.assert_array_equal(imu.gyro, ref.gyro)
    np.testing.assert_array_equal(imu.t, ref.t)
    assert list(imu.extra.columns) == []
    code, _, err = run(capsys, "estimate", p, "--columns", spec, "-o", tmp_path / "o.csv")
    assert code == 0, err
    code, _, err = run(capsys, "estimate", p, "--columns", "t=timestamp,speed=v", "-o", tmp_path / "o2.csv")
    assert code == 2 and "--columns" in error_line(err) and "speed" in error_line(err)


def test_upper_case_names_are_read(example, tmp_path):
    ref = read_imu(EXAMPLE)
    p = tmp_path / "upper.csv"
    example.set_axis([c.upper() for c in example.columns], axis=1).to_csv(p, index=False, float_format="%.17g")
    imu = read_imu(p)
    np.testing.assert_array_equal(imu.accel, ref.accel)
    assert list(imu.extra.columns) == []


# ------------------------------------------------------------------------------------------ one option error
def test_one_option_error_for_the_readers_and_the_pipeline():
    from imu_ground.datasets.options import OptionError
    from imu_ground.pipeline import OptionError as PipelineOptionError
    assert PipelineOptionError is OptionError and issubclass(ImuInputError, OptionError)
    e = OptionError("{opt} must be positive, got -1", "rate")
    assert str(e) == "rate must be positive, got -1" and e.cli_message() == "--rate must be positive, got -1"
    e = ImuInputError("x.csv: pass {hint}", option="gyro_unit", value="deg/s")
    assert str(e) == "x.csv: pass gyro_unit='deg/s'" and e.cli_message() == "x.csv: pass --gyro-unit deg/s"
    e = OptionError("{opt} kitti_cam0 is needed", "extrinsic")
    assert e.cli_message() == "--extrinsic kitti_cam0 is needed"
