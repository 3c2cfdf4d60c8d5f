"""``evaluate --lidar DRIVE_DIR ...``: KITTI raw sync folders, the --log form, the JSON, the fits, the path region."""
import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sklearn")

from imu_ground.datasets.options import OptionError  # noqa: E402
from imu_ground.evaluation import lidar as L  # noqa: E402
from imu_ground.evaluation import lidar_kitti as K  # noqa: E402
from imu_ground.filters import Extrinsic  # noqa: E402

DAY = ("kitti_raw", "2011_09_26")
NAME_0009 = "2011_09_26_drive_0009"


def _drives(shared: Path) -> list[Path]:
    """The shared LiDAR drives that can be compared (2 scans or more), found from the folders."""
    return [d for d in K.find_lidar_drives(shared / "kitti_raw")
            if len(list((d / "velodyne_points" / "data").glob("*.bin"))) >= 2]


# ----------------------------------------------------------------------------- the reader
def test_reader_on_every_shared_lidar_folder(shared_data):
    drives = _drives(shared_data)
    assert len(drives) >= 3
    sources = set()
    for folder in drives:
        d = K.read_kitti_lidar_drive(folder)
        assert d.name == folder.name[:-5] and d.calibration == folder.parent
        assert len(d.files) == len(list((folder / "velodyne_points" / "data").glob("*.bin")))
        assert np.all(np.diff(d.stamps_ns) > 0)
        has_velo = (folder / "velodyne_points" / "timestamps.txt").is_file()
        sources.add(has_velo)
        assert ("Velodyne" in d.times_source) == has_velo and ("OXTS" in d.times_source) != has_velo
        # where both exist, the Velodyne's times are within 0.05 s of the same frames' OXTS stamps
        gap = (d.stamps_ns - d.oxts_ns[d.frames]) * 1e-9
        assert np.abs(gap).max() < 0.05
        if not has_velo:
            assert np.array_equal(d.stamps_ns, d.oxts_ns[d.frames])
    assert sources == {True, False}, "the shared folders have drives with and without Velodyne timestamps"


def test_scan_times_on_the_100hz_csv_clock(shared_data):
    """drive 0009's scans on the CSV's clock (drives.csv t0_seconds_of_day): the older estimate is 0.016-0.029 s
    earlier (../shared/data/README.md)."""
    d = K.read_kitti_lidar_drive(shared_data.joinpath(*DAY, f"{NAME_0009}_sync"))
    csv = shared_data / "kitti_imu100" / f"{NAME_0009}.csv.gz"
    t = K.scan_times_on_log(d, K.log_clock(csv))
    older = L.read_scan_times(d.folder / "frames_estimated_times.txt", len(d.files))
    assert np.all((t - older > 0.010) & (t - older < 0.035))
    on_oxts = K.scan_times_on_log(d, ("epoch_ns", int(d.oxts_ns[0])))
    assert on_oxts[0] == 0.0 and abs(on_oxts[1] - 0.11) < 0.01           # exact integer ns: no rounding below 0


def test_a_log_without_a_known_clock_is_refused(tmp_path):
    log = tmp_path / "some.csv"
    log.write_text("t,wx\n0,0\n")
    with pytest.raises(OptionError, match="t0_seconds_of_day") as e:
        K.log_clock(log)
    assert "give --log a kitti_imu100 CSV" in e.value.cli_message()


# ----------------------------------------------------------------------------- the driven path
def test_path_region_follows_a_turn_and_leaves_the_kerb_out():
    # a track turning left on a 20 m radius from the LiDAR's origin; points 1 m off it are in, the straight box's far
    # end (on the kerb beyond the turn) is out
    a = np.linspace(0, math.pi / 2, 200)
    xy = np.column_stack([20 * np.sin(a), 20 * (1 - np.cos(a))])
    r = L.PathRegion(xy)
    on = np.array([[20 * math.sin(0.8), 20 * (1 - math.cos(0.8)) + 1.0, -1.7]])
    kerb = np.array([[28.0, -3.0, -1.7], [1.0, 0.0, -1.7]])                 # beyond the turn; closer than 3 m
    assert r.mask(on).tolist() == [True]
    assert r.mask(kerb).tolist() == [False, False]
    assert L.ROAD_REGION.mask(kerb[:1]).tolist() == [True]
    assert "driven path" in str(r)


def test_path_region_from_a_track_in_the_lidar_frame():
    # the body drives along the world's y axis (heading 90 deg), the LiDAR 0.8 m ahead of the body: the future track
    # lies along the LiDAR's x axis, and a standstill continues straight ahead
    t = np.arange(0.0, 5.0, 0.1)
    pos = np.column_stack([np.zeros_like(t), 10.0 * t, np.zeros_like(t)])
    rot = np.repeat(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])[None], len(t), axis=0)    # world <- body
    r = L.path_region(1.0, t, pos, rot, Extrinsic(np.eye(3), np.array([-0.8, 0.0, -0.8])))
    ahead = r.xy[(r.along >= 3) & (r.along <= 32)]
    assert np.abs(ahead[:, 1]).max() < 1e-9 and ahead[0, 0] == pytest.approx(3.0, abs=0.3)
    still = L.path_region(1.0, t, np.zeros_like(pos), rot, Extrinsic(np.eye(3), np.array([-0.8, 0.0, -0.8])))
    assert still.xy[:, 0].max() > 32 and np.abs(still.xy[:, 1]).max() < 1e-9


def test_patchwork_and_ransac_agree_on_a_real_scan(shared_data):
    pytest.importorskip("pypatchworkpp")
    files = L.scan_files(shared_data.joinpath(*DAY, "2011_09_26_drive_0048_sync", "velodyne_points", "data"))
    for f in files[:3]:
        pts = L.read_scan(f)
        n_r, d_r = L.fit_ground_plane(pts)
        n_p, d_p, count = L.fit_ground_plane(pts, ground="patchwork", return_inliers=True)
        assert count > 2000 and abs(d_p - d_r) < 0.03
        assert math.degrees(math.acos(min(1.0, float(n_r @ n_p)))) < 0.05


# ----------------------------------------------------------------------------- the command
def _json(cli, tmp_path, *args) -> tuple[dict, str]:
    out = tmp_path / "lidar.json"
    code, stdout, err = cli("evaluate", "--lidar", *args, "--json", out)
    assert code == 0, err
    return json.loads(out.read_text()), stdout


METHOD_KEYS = {"scans", "pitch_spread_deg", "pitch_spread_lo95", "pitch_spread_hi95", "roll_spread_deg",
               "roll_spread_lo95", "roll_spread_hi95", "angle_mean_deg", "angle_centred_deg", "pitch_offset_deg",
               "roll_offset_deg", "p_best_pitch", "p_best_roll"}


def test_log_form_on_0009_the_same_scans_on_the_csv_clock(shared_data, cli, tmp_path):
    sync = shared_data.joinpath(*DAY, f"{NAME_0009}_sync")
    csv = shared_data / "kitti_imu100" / f"{NAME_0009}.csv.gz"
    common = ["--methods", "paper,naive", "--lidar-fit", "ransac", "--lidar-scans", "12"]
    folder, _ = _json(cli, tmp_path, sync, *common)
    log, out = _json(cli, tmp_path, sync, "--log", csv, *common)
    a, b = folder["drives"][0], log["drives"][0]
    assert a["drive"] == b["drive"] == NAME_0009 and a["scans"] == b["scans"] == 12
    assert Path(a["input"]) == sync and Path(b["input"]) == csv and csv.name in out
    assert set(b["methods"]) == {"default", "paper", "naive"}
    # the same scans and planes: the static extrinsic's spreads are the same on both inputs, the estimates' are not
    for key in ("pitch_spread_deg", "roll_spread_deg"):
        assert a["methods"]["naive"][key] == pytest.approx(b["methods"]["naive"][key], abs=1e-9)
    assert a["methods"]["default"]["pitch_spread_deg"] != pytest.approx(b["methods"]["default"]["pitch_spread_deg"],
                                                                         abs=1e-6)
    assert a["methods"]["paper"]["pitch_spread_deg"] < a["methods"]["naive"]["pitch_spread_deg"]


def test_json_schema_pooled_and_the_ranking_per_fit(shared_data, cli, tmp_path):
    drives = [shared_data.joinpath(*DAY, f"2011_09_26_drive_{n}_sync") for n in ("0048", "0052")]
    report, out = _json(cli, tmp_path, *drives, "--methods", "paper,naive", "--lidar-fit", "all", "--lidar-scans", "8")
    assert {"drives", "pooled", "fits", "ranking", "fit", "region", "default"} <= set(report)
    expect = {"ransac box", "ransac path"} | ({"patchwork box", "patchwork path"} if L.patchwork_available() else set())
    assert set(report["fits"]) == expect and report["fit"] == "ransac box"
    assert [d["drive"] for d in report["drives"]] == [f.name[:-5] for f in drives]
    for fit in report["fits"].values():
        for d in fit["drives"]:
            assert d["scans"] <= 8 and d["scans_total"] > 8 and any("--lidar-scans" in x for x in d["left_out"])
            assert d["fit_noise_pitch_deg"] > 0 and d["times"]
            for name, m in d["methods"].items():
                assert set(m) == METHOD_KEYS and m["pitch_spread_lo95"] <= m["pitch_spread_hi95"], name
        # pooled: each drive's offset removed, one degree of freedom a drive
        for name, m in fit["pooled"]["methods"].items():
            parts = [(d["methods"][name]["scans"], d["methods"][name]["pitch_spread_deg"]) for d in fit["drives"]]
            n = sum(k for k, _ in parts)
            pooled = math.sqrt(sum((k - 1) * s * s for k, s in parts) / (n - len(parts)))
            assert m["pitch_spread_deg"] == pytest.approx(pooled, rel=1e-9) and m["scans"] == n
    for key in [f.name[:-5] for f in drives] + ["pooled"]:
        for what in ("pitch", "roll"):
            r = report["ranking"][key][what]
            assert set(r["order"]) == expect and isinstance(r["holds"], bool)
            assert all(sorted(o) == ["default", "naive", "paper"] for o in r["order"].values())
    assert "ranking across the fits" in out and "pooled over 2 drives" in out


def test_plot_legend_below_the_curves(shared_data, cli, tmp_path):
    sync = shared_data.joinpath(*DAY, "2011_09_26_drive_0048_sync")
    png = tmp_path / "lidar.png"
    code, _, err = cli("evaluate", "--lidar", sync, "--lidar-fit", "ransac", "--lidar-scans", "6", "-o", png)
    assert code == 0, err and png.stat().st_size > 10_000
    import pandas as pd
    rng = np.random.default_rng(0)
    frames = pd.concat([pd.DataFrame({"t": np.arange(10.0), "method": m, "lidar_pitch_deg": rng.normal(size=10),
                                      "lidar_roll_deg": rng.normal(size=10), "pitch_deg": rng.normal(size=10),
                                      "roll_deg": rng.normal(size=10), "d_pitch_deg": rng.normal(size=10),
                                      "d_roll_deg": rng.normal(size=10)}) for m in ("default", "paper", "naive", "x")])
    fig = L.lidar_figure(frames)
    fig.canvas.draw()
    legend = (fig.legends or [ax.get_legend() for ax in fig.axes if ax.get_legend()])[0]
    box = legend.get_window_extent()
    for ax in fig.axes:
        assert not box.overlaps(ax.get_window_extent()), "the legend covers an axes"


def test_drive_form_bad_inputs_exit_2_naming_the_flag(shared_data, cli, tmp_path):
    day = shared_data.joinpath(*DAY)
    sync = day / "2011_09_26_drive_0048_sync"
    csv = shared_data / "kitti_imu100" / f"{NAME_0009}.csv.gz"
    no_calib = tmp_path / "2011_09_26_drive_0048_sync"
    no_calib.mkdir()
    for sub in ("oxts", "velodyne_points"):
        (no_calib / sub).symlink_to(sync / sub)
    clockless = tmp_path / f"{NAME_0009}.csv.gz"
    clockless.symlink_to(csv)
    one_scan = [d for d in K.find_lidar_drives(shared_data / "kitti_raw")
                if len(list((d / "velodyne_points" / "data").glob("*.bin"))) < 2]
    no_velo = next(d for d in day.iterdir() if (d / "oxts").is_dir() and not (d / "velodyne_points").is_dir())
    cases = {
        "no velodyne_points/ folder": ([no_velo], "--lidar"),
        "is none of the --lidar DRIVE_DIRs": ([sync, "--log", csv], "--log"),
        "no such file": ([sync, "--log", tmp_path / "none.csv"], "--log"),
        "--times goes with --lidar LOG SCANS": ([sync, "--times", tmp_path / "t.txt"], "--times"),
        "a DRIVE_DIR given twice": ([sync, sync], "--lidar"),
        "give four numbers": ([sync, "--lidar-region", "path", "3"], "--lidar-region"),
        "at least 2 scans": ([sync, "--lidar-scans", "1"], "--lidar-scans"),
        "a speed >= 0": ([sync, "--lidar-min-speed", "-1"], "--lidar-min-speed"),
        "is a folder": ([sync, "--json", tmp_path], "--json"),
        "no calib_imu_to_velo.txt": ([no_calib], "--lidar-extrinsic"),
        "start on the scans' clock is unknown": ([day / f"{NAME_0009}_sync", "--log", clockless], "--log"),
        "goes with --lidar DRIVE_DIR": ([csv, sync / "velodyne_points" / "data", "--lidar-region", "path"],
                                        "--lidar-region path"),
    }
    if one_scan:
        cases["compares 2 or more a drive"] = ([one_scan[0]], "--lidar")
    for expect, (args, flag) in cases.items():
        code, _, err = cli("evaluate", "--lidar", *args, "--lidar-fit", "ransac", "--methods", "naive")
        assert code == 2, (expect, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and expect in lines[0] and flag in lines[0], (expect, err)
    code, _, err = cli("evaluate", "--synthetic", "1", "--json", tmp_path / "x.json")
    assert code == 2 and "--json goes with --lidar" in err
