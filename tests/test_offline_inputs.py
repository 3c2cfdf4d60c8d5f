"""Offline runs on inputs a user gives by mistake: gaps past the live limit, forced units that make
a log absurd, outputs over inputs or over files the tool did not write, a speed off the log's clock."""
import os
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
    t, live_t = table["t"].to_numpy(), pd.read_csv(causal, comment="#")["t"].to_numpy()
    assert np.array_equal(t[t < 4000], live_t[live_t < 4000])
    # after the jump the live clock first confirms the new clock on agreeing stamps (imu.live.sample_clock.CONFIRM) and
    # warms up again, so its new frame grid starts a few samples later: within one frame of the offline one's
    t_after, live_after = t[t > 4000], live_t[live_t > 4000]
    assert abs(len(t_after) - len(live_after)) <= 1 and 0 <= live_after[0] - t_after[0] < 0.1
    from imu_ground.datasets import read_imu
    from imu_ground.imu import imu_to_egomotion
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        em = imu_to_egomotion(read_imu(path))       # the library's front end too (calibrate, a filter's run)
    assert np.array_equal(em.t, table["t"].to_numpy())


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
    a, b = imu_to_egomotion(imu, rate=10.0, max_gap_frames=None), imu_to_egomotion(imu, rate=10.0)
    assert len(a) == len(b) and (~a.valid).sum() == 301 and np.array_equal(a.delta_R, b.delta_R)
    # with a limit under the gap, the frames start again after it: those of each half alone
    c = imu_to_egomotion(imu, rate=10.0, max_gap_frames=100)                 # 10 s
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


# ------------------------------------------------------------------------------------------ 11. outputs over inputs
def _lidar_args(shared: Path) -> list:
    d = shared / "kitti_raw" / "2011_09_26"
    drive = d / "2011_09_26_drive_0009_sync"
    return ["evaluate", "--lidar", str(drive / "oxts"), str(drive / "velodyne_points" / "data"),
            "--lidar-extrinsic", str(d)]


CASES = {  # name: (arguments with {dir}, the file given twice, the two flags the message names)
    "speed": (["estimate", str(EXAMPLE), "--speed", "{dir}/S.csv", "-o", "{dir}/S.csv"], "S.csv", ("--speed", "-o")),
    "extrinsic": (["estimate", str(EXAMPLE), "--extrinsic", "{dir}/out/my_car.txt", "--tum", "{dir}/out/my_car.txt"],
                  "out/my_car.txt", ("--extrinsic", "--tum")),
    "two outputs": (["estimate", str(EXAMPLE), "-o", "{dir}/a.csv", "--tum", "{dir}/./a.csv"], "a.csv",
                    ("-o", "--tum")),
    "preview": (["preview", str(EXAMPLE), "--images", "{dir}", "--times", "{dir}/T.png", "-o", "{dir}/T.png"],
                "T.png", ("--times", "-o")),
    "simulate": (["simulate", "-o", "{dir}/sim.csv", "--truth", "{dir}/sim.csv", "--duration", "1"], "sim.csv",
                 ("-o", "--truth")),
    "evaluate": (["evaluate", "--synthetic", "1", "--csv", "{dir}/r.csv", "--markdown", "{dir}/r.csv"], "r.csv",
                 ("--csv", "--markdown")),
    "stream": (["stream", "--replay", str(EXAMPLE), "--speed", "{dir}/S.csv", "--state", "{dir}/S.csv"], "S.csv",
               ("--speed", "--state")),
    "batch": (["batch", str(EXAMPLE), "-o", "{dir}/out", "--workers", "0", "--speed", "{dir}/out/summary.csv"],
              "out/summary.csv", ("--speed", "-o")),
}


@pytest.mark.parametrize("case", list(CASES))
def test_no_output_replaces_an_input_or_another_output(tmp_path, capsys, case):
    """Before: only the log was protected; each of these replaced the file (or lost one output), exit 0."""
    args, given, flags = CASES[case]
    (tmp_path / "out").mkdir()
    target = tmp_path / given
    target.write_text("t,speed\n0,5\n60,5\n" if given.endswith(".csv") else "keep\n")
    before = target.read_bytes()
    assert main([a.replace("{dir}", str(tmp_path)) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"given to both {flags[0]}" in err and f"and {flags[1]}" in err, err
    assert target.read_bytes() == before


@pytest.mark.parametrize("outputs, flags", [(["--csv", "{times}"], ("--times", "--csv")),
                                            (["--csv", "{dir}/X.png", "-o", "{dir}/X.png"], ("-o", "--csv"))])
def test_evaluate_lidar_writes_over_no_input_nor_its_other_output(shared_data, tmp_path, capsys, outputs, flags):
    times = tmp_path / "T.txt"
    times.write_text("keep\n")
    outputs = [o.replace("{times}", str(times)).replace("{dir}", str(tmp_path)) for o in outputs]
    assert main([*_lidar_args(shared_data), "--times", str(times), *outputs]) == 2
    err = capsys.readouterr().err
    assert f"given to both {flags[0]}" in err and f"and {flags[1]}" in err and times.read_text() == "keep\n"
    assert not (tmp_path / "X.png").exists()


# ------------------------------------------------------------------------------------------ 12. a user's files in -o
@pytest.mark.parametrize("name", ["summary.csv", "example_drive_ground.csv"])
@pytest.mark.parametrize("force", [False, True])
def test_batch_writes_over_no_file_in_its_folder_that_it_did_not_write(tmp_path, capsys, name, force):
    """Before: a user's summary.csv was replaced without a word; a user's example_drive_ground.csv made its log
    'skipped (output exists)' and was summarised as an estimate."""
    out = tmp_path / "out"
    out.mkdir()
    mine = out / name
    mine.write_text("my notes\n")
    args = ["batch", str(EXAMPLE), "-o", str(out), "--workers", "0", *(["--force"] if force else [])]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{mine}: exists and imu-ground did not write it" in err and "-o" in err
    assert mine.read_text() == "my notes\n" and sorted(p.name for p in out.iterdir()) == [name]
    mine.unlink()
    assert main(args) == 0                          # its own outputs: kept on a rerun, replaced with --force
    capsys.readouterr()
    assert main(args) == 0
    assert ("1 estimated" if force else "1 skipped") in capsys.readouterr().out.splitlines()[-1]


# ------------------------------------------------------------------------------------------ 13. a speed off the clock
@pytest.mark.parametrize("run", [["estimate", str(EXAMPLE)], ["estimate", str(EXAMPLE), "--causal"],
                                 ["stream", "--replay", str(EXAMPLE)]])
def test_a_speed_off_the_logs_clock_is_refused_by_every_run(tmp_path, capsys, run):
    """Before: refused by estimate, silently unused (IMU only, exit 0) by --causal and stream --replay."""
    speed = tmp_path / "speed.csv"
    speed.write_text("t,speed\n1000,5\n1060,5\n")                # the log spans 0 .. 60 s
    out = ["-o", str(tmp_path / "o.csv")] if run[0] == "estimate" else []
    assert main([*run, "--speed", str(speed), *out]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert len(err.splitlines()) == 1 and f"--speed {speed}" in err and "do not cover the log's" in err
    assert captured.out == "" and not (tmp_path / "o.csv").exists()


def test_the_same_file_under_another_name_is_the_same_file(tmp_path):
    """A hard link, a symbolic link and a spelling with '..' name the input as well as its own path does."""
    from imu_ground.errors import ImuGroundError
    from imu_ground.pipeline.output import check_run_paths
    speed = tmp_path / "S.csv"
    speed.write_text("t,speed\n")
    (tmp_path / "sub").mkdir()
    os.link(speed, tmp_path / "hard.csv")
    (tmp_path / "soft.csv").symlink_to(speed)
    for other in ("hard.csv", "soft.csv", "sub/../S.csv"):
        with pytest.raises(ImuGroundError, match="given to both --speed"):
            check_run_paths([("-o", tmp_path / other)], [("--speed", str(speed)), ("--extrinsic", "kitti_imu")])
        with pytest.raises(ImuGroundError, match="given to both -o and --tum"):
            check_run_paths([("-o", speed), ("--tum", tmp_path / other)])
    check_run_paths([("-o", tmp_path / "new.csv"), ("--tum", tmp_path / "new.tum")], [("--speed", "auto")])
