"""The live estimator: StreamingEstimator against ``estimate --causal``, warm start, bad data, misuse, the clock.

The equality tests feed every shared drive (``drives.csv``, its raw CSV rows in file order), a ROS 1
bag, a ROS 2 sqlite3 bag, an MCAP file and the KITTI OXTS folder sample by sample through
:class:`~imu_ground.pipeline.streaming.StreamingEstimator` in Python and compare with
``estimate_log(..., causal=True)`` (:func:`~imu_ground.pipeline.streaming.causal_track`, the log as read);
with the compiled kernels that takes about 10 s for all drives (the pure-Python kernels: a few
times longer).
"""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imu_ground.datasets.options import OptionError
from imu_ground.pipeline.streaming import MAX_FRAME_RATE, StreamingEstimator, causal_track, replay
from imu_ground.imu.live.sample_clock import RESTART, SampleClock

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "datasets" / "fixtures" / "example_drive.csv"
TOL_DEG = 1e-9


def _read(path, **kw):
    from imu_ground.datasets import detect_format, read_imu
    from imu_ground.pipeline.estimate import speed_samples
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fmt = detect_format(path)
        imu = read_imu(path, format=fmt)
        sp = speed_samples(kw.pop("speed", "auto"), path, fmt, imu)[0]
    return imu, sp


def _assert_same(frames, track):
    """Streamed frames against an offline track: same frames, times, statuses; angles to 1e-9 deg."""
    assert len(frames) == len(track) > 0
    t = np.array([f.t for f in frames])
    np.testing.assert_allclose(t, track.t, rtol=0, atol=1e-9)
    for name in ("pitch", "roll"):
        a = np.degrees([getattr(f, name) for f in frames])
        assert np.max(np.abs(a - np.degrees(getattr(track, name)))) <= TOL_DEG, name
    assert [f.status_code for f in frames] == track.status.tolist()
    assert [f.status_reason for f in frames] == list(track.status_reason)
    assert [f.valid for f in frames] == track.valid.tolist()


def _offline(path, **kw):
    from imu_ground.pipeline import estimate_log
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return estimate_log(path, causal=True, **kw)


# --------------------------------------------------------------------------- one engine, both ways
def _raw_kitti(path):
    """The rows of a KITTI CSV as the file has them (pandas, file order; jitter, back-steps, repeats and
    dropouts kept): stamps (s), gyro, accel, and the INS speed hypot(ve, vn) (m/s) at its distinct stamps."""
    import pandas as pd
    raw = pd.read_csv(path)
    t = raw["t"].to_numpy(float)
    v = np.hypot(raw["ve"], raw["vn"]).to_numpy(float)
    order = np.argsort(t, kind="stable")
    first = np.r_[True, np.diff(t[order]) > 0]
    return t, raw[["wx", "wy", "wz"]].to_numpy(float), raw[["ax", "ay", "az"]].to_numpy(float), \
        (t[order][first], v[order][first])


def test_equal_to_offline_on_every_shared_drive(shared_data, kitti_index):
    """Every drive of drives.csv: its raw CSV rows (back-steps of about -0.05 s, repeats, dropouts) and INS
    speed streamed equal --causal, which hands the sample clock the stamps as recorded (not retimed over
    the whole file first)."""
    stepped_back = 0
    for name in kitti_index["drive"]:
        path = shared_data / "kitti_imu100" / f"{name}.csv.gz"
        res = _offline(path, extrinsic="kitti_imu")
        t, gyro, accel, sp = _raw_kitti(path)
        stepped_back += bool((np.diff(t) <= 0).any())
        frames = replay(StreamingEstimator(extrinsic="kitti_imu"), t, gyro, accel, sp)
        _assert_same(frames, res.track)
    assert stepped_back                         # the raw stamps do step back: the test can tell


def test_causal_refuses_whole_log_policies_and_recorded_is_live_only(shared_data):
    """--policy drop is the live clock's; sort and strict need the whole log; 'recorded' alone is refused."""
    from imu_ground.datasets.options import OptionError
    from imu_ground.pipeline import estimate_log
    path = shared_data / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
    res = _offline(path, extrinsic="kitti_imu", policy="drop")
    t, gyro, accel, sp = _raw_kitti(path)
    _assert_same(replay(StreamingEstimator(extrinsic="kitti_imu", policy="drop"), t, gyro, accel, sp), res.track)
    for policy in ("sort", "strict"):
        with pytest.raises(OptionError, match="whole log"):
            _offline(path, extrinsic="kitti_imu", policy=policy)
    with pytest.raises(OptionError, match="live front end"):
        estimate_log(path, extrinsic="kitti_imu", policy="recorded")


def test_stream_replay_equals_causal_on_a_drive(cli, shared_data):
    from imu_ground.filters.status import status_names
    path = shared_data / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
    code, out, err = cli("stream", "--replay", path, "--extrinsic", "kitti_imu")
    assert code == 0, err
    got = _csv_rows(out)
    track = _offline(path, extrinsic="kitti_imu").track
    assert len(got) == len(track) > 0
    np.testing.assert_allclose(got["t"], track.t, rtol=0, atol=1e-9)
    for name in ("pitch", "roll"):
        np.testing.assert_allclose(got[f"{name}_deg"], np.degrees(getattr(track, name)), rtol=0, atol=TOL_DEG)
    assert got["status"].tolist() == list(status_names(track.status))


@pytest.mark.parametrize("which", ["nuscenes", "comma2k19"])
def test_equal_to_offline_other_formats(shared_data, which):
    path, ext = {"nuscenes": (shared_data / "nuscenes_can_bus" / "scene-0103_ms_imu.json", None),
                 "comma2k19": (shared_data / "comma2k19_example", np.diag([1.0, -1.0, -1.0]))}[which]
    res = _offline(path, extrinsic=ext)
    imu, sp = _read(path)
    assert sp is not None                       # both have a speed of their own
    frames = replay(StreamingEstimator(extrinsic=ext), imu.t, imu.gyro, imu.accel, sp)
    _assert_same(frames, res.track)


@pytest.mark.parametrize("kind", ["sqlite3", "mcap"])
def test_equal_to_offline_ros2_bag_and_mcap_on_recorded_stamps(tmp_path, kind):
    """A ROS 2 sqlite3 bag and an MCAP file whose header stamps step back and repeat (the messages in
    record order): --causal equals the stream fed the stamps as written, in message order."""
    pytest.importorskip("rosbags")
    imu, _ = _read(EXAMPLE)
    raw = imu.t.copy()
    raw[20::37] -= 0.05                                   # back-steps, as KITTI's
    raw[31::53] = raw[30::53][:raw[31::53].size]          # repeated stamps
    t0 = 1_700_000_000_123_456_789
    hdr = t0 + np.round(raw * 1e9).astype(np.int64)
    rec = t0 + np.round(imu.t * 1e9).astype(np.int64)
    path = _write_bag(tmp_path / f"drive_{kind}", imu, hdr, rec, storage=kind)
    res = _offline(path)
    t = (hdr - hdr[0]) / 1e9
    assert (np.diff(t) < 0).any() and (np.diff(t) == 0).any()
    _assert_same(replay(StreamingEstimator(), t, imu.gyro, imu.accel), res.track)


def test_equal_to_offline_kitti_oxts_folder(shared_data):
    """The KITTI OXTS native folder (10 Hz packets, timestamps.txt): --causal equals the stream fed its
    packets (wx wy wz, ax ay az: body axes) at the stamps of timestamps.txt, and their INS speed hypot(ve, vn)."""
    import pandas as pd
    from imu_ground.datasets.kitti_oxts import OXTS_FIELDS
    folder = shared_data / "kitti_raw" / "2011_09_26" / "2011_09_26_drive_0001_sync" / "oxts"
    res = _offline(folder)
    ns = pd.to_datetime(pd.read_csv(folder / "timestamps.txt", header=None)[0]).to_numpy("datetime64[ns]")
    ns = ns.astype(np.int64)
    packets = np.array([np.loadtxt(f) for f in sorted((folder / "data").glob("*.txt"))])
    col = {n: packets[:, i] for i, n in enumerate(OXTS_FIELDS)}
    t = (ns - ns[0]) * 1e-9
    gyro = np.column_stack([col[n] for n in ("wx", "wy", "wz")])
    accel = np.column_stack([col[n] for n in ("ax", "ay", "az")])
    assert "hypot(ve, vn)" in res.meta["speed"]
    frames = replay(StreamingEstimator(), t, gyro, accel, (t, np.hypot(col["ve"], col["vn"])))
    _assert_same(frames, res.track)


def test_equal_to_offline_csv_and_filter_methods():
    imu, _ = _read(EXAMPLE)
    for method in ("auto", "filter", "paper"):
        res = _offline(EXAMPLE, method=method)
        frames = replay(StreamingEstimator(method), imu.t, imu.gyro, imu.accel)
        _assert_same(frames, res.track)


def _write_bag(path, imu, header_ns, record_ns, storage="mcap", twist=False):
    """A ROS log at ``path`` (.bag: ROS 1; else a ROS 2 bag of ``storage``) with the samples of ``imu`` on
    /imu/data at header stamps ``header_ns`` in the order of ``record_ns``; ``twist``: a TwistStamped speed
    every 5th sample. Returns the file to read (the .mcap storage file itself for an MCAP bag)."""
    from imu_ground.pipeline.ros_output import RosWriter
    vec = "geometry_msgs/msg/Vector3"
    with RosWriter(path, storage=storage) as w:
        hi = w.add_topic("/imu/data", "sensor_msgs/msg/Imu")
        hs = w.add_topic("/vehicle/twist", "geometry_msgs/msg/TwistStamped") if twist else None
        for k, (ns, rec) in enumerate(zip(header_ns.tolist(), record_ns.tolist(), strict=True)):
            g, a = imu.gyro[k], imu.accel[k]
            w.write(hi, rec, w.message(
                "sensor_msgs/msg/Imu", header=w.header(ns, "imu_link", k),
                orientation=w.message("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.r_[-1.0, np.zeros(8)],
                angular_velocity=w.message(vec, x=g[0], y=g[1], z=g[2]), angular_velocity_covariance=np.zeros(9),
                linear_acceleration=w.message(vec, x=a[0], y=a[1], z=a[2]),
                linear_acceleration_covariance=np.zeros(9)))
            if twist and k % 5 == 0:
                tw = w.message("geometry_msgs/msg/Twist", linear=w.message(vec, x=10.0 + 0.01 * k, y=0.0, z=0.0),
                               angular=w.message(vec, x=0.0, y=0.0, z=0.0))
                w.write(hs, rec, w.message("geometry_msgs/msg/TwistStamped", header=w.header(ns, "base", k),
                                           twist=tw))
    mcap = sorted(Path(path).glob("*.mcap")) if Path(path).is_dir() else []
    return mcap[0] if mcap else Path(path)


def test_equal_to_offline_bag(tmp_path):
    """A ROS 1 bag with IMU and a TwistStamped speed written at test time: --causal equals the stream."""
    pytest.importorskip("rosbags")
    imu, _ = _read(EXAMPLE)
    ns = 1_700_000_000_000_000_000 + np.round(imu.t * 1e9).astype(np.int64)
    path = _write_bag(tmp_path / "drive.bag", imu, ns, ns, twist=True)
    res = _offline(path)
    assert "twist" in res.meta["speed"] or "odometry" in res.meta["speed"]
    bag_imu, sp = _read(path)
    frames = replay(StreamingEstimator(), bag_imu.t, bag_imu.gyro, bag_imu.accel, sp)
    _assert_same(frames, res.track)
    assert np.isfinite([f.speed for f in frames[5:]]).all()


def test_causal_close_to_default_on_drive(shared_data):
    """Not equal (the default sees the whole log), but close: the issue's live loop stayed within 0.01 deg."""
    from imu_ground.pipeline import estimate_log
    path = shared_data / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = estimate_log(path, extrinsic="kitti_imu").track
    c = _offline(path, extrinsic="kitti_imu").track
    assert len(c) == len(d)
    assert np.max(np.abs(np.degrees(c.pitch - d.pitch))) < 0.05
    assert np.max(np.abs(np.degrees(c.roll - d.roll))) < 0.05


@pytest.mark.parametrize("name", ["2011_09_30_drive_0034", "2011_09_30_drive_0027"])
def test_causal_standstill_finds_the_stops_from_their_start(shared_data, kitti_index, name):
    """Issue 38, case 7: the causal detector found far fewer standstill frames than the offline one (51 against
    132 on a drive kept aside; here 12 of 41 and 40 of 50): a trailing window of 1 s flags a stop only after its
    first second. The quiet frames leading into a passing window are now flagged too (held until it passes, at
    most 0.9 s): nearly every frame the offline detector flags, none it does not; live and --causal alike."""
    if name not in set(kitti_index["drive"]):
        pytest.skip(f"{name} not in drives.csv")
    from imu_ground.pipeline import estimate_log
    path = shared_data / "kitti_imu100" / f"{name}.csv.gz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = estimate_log(path, extrinsic="kitti_imu").egomotion.stationary
    c = _offline(path, extrinsic="kitti_imu").egomotion.stationary
    n = min(len(d), len(c))
    d, c = np.asarray(d[:n], bool), np.asarray(c[:n], bool)
    assert d.sum() >= 20
    assert (c & d).sum() >= 0.9 * d.sum() and not (c & ~d).any()


# --------------------------------------------------------------------------- warm start
def _kitti_or_example():
    path = ROOT.parent / "shared" / "data" / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
    return (path, "kitti_imu") if path.is_file() else (EXAMPLE, None)


def _stream_with_cut(imu, sp, ext, cut):
    """Frames of the log streamed, stopped after sample ``cut``, saved to JSON and resumed in a new object."""
    est = StreamingEstimator(extrinsic=ext)
    t, g, a = imu.t.tolist(), imu.gyro.tolist(), imu.accel.tolist()
    ts, vs = ([], []) if sp is None else (sp[0].tolist(), sp[1].tolist())
    out, j, size = [], 0, 0
    for i in range(len(t)):
        while j < len(ts) and ts[j] <= t[i]:
            est.push_speed(ts[j], vs[j])
            j += 1
        out += est.push_imu(t[i], g[i], a[i])
        if i == cut:
            text = json.dumps(est.state_dict())
            size = len(text)
            est = StreamingEstimator(extrinsic=ext)
            est.load_state_dict(json.loads(text))
    while j < len(ts):
        est.push_speed(ts[j], vs[j])
        j += 1
    return out + est.flush(), size


def test_resume_at_random_samples_is_bit_identical():
    path, ext = _kitti_or_example()
    imu, sp = _read(path)
    whole = replay(StreamingEstimator(extrinsic=ext), imu.t, imu.gyro, imu.accel, sp)
    rng = np.random.default_rng(29)
    cuts = [3, 9, 10, *rng.integers(11, len(imu.t) - 1, 5).tolist()]   # in the warm-up, at its end, anywhere
    for cut in cuts:
        frames, size = _stream_with_cut(imu, sp, ext, cut)
        assert size < 16 * 1024, (cut, size)
        assert len(frames) == len(whole)
        for x, y in zip(frames, whole, strict=True):
            fields = ("t", "pitch", "roll", "pitch_std", "roll_std", "road_grade", "road_bank", "speed")
            assert np.array_equal([getattr(x, n) for n in fields], [getattr(y, n) for n in fields], equal_nan=True)
            assert (x.status, x.status_reason, x.valid) == (y.status, y.status_reason, y.valid)
            assert x.normal.tolist() == y.normal.tolist()


def test_state_of_other_settings_refused():
    est = StreamingEstimator(rate=10.0)
    est.push_imu(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
    other = StreamingEstimator(rate=20.0)
    with pytest.raises(ValueError, match="state.*rate"):
        other.load_state_dict(est.state_dict())
    with pytest.raises(ValueError, match="state"):
        other.load_state_dict({"kind": "something else"})


# --------------------------------------------------------------------------- data never raise
def _finite_when_valid(frames):
    for f in frames:
        if f.valid:
            assert np.isfinite([f.pitch, f.roll, *f.normal]).all()
        assert isinstance(f.status_reason, str)


@st.composite
def _streams(draw):
    n = draw(st.integers(30, 400))
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    steps = np.full(n, 0.01) + rng.normal(0, draw(st.sampled_from([0.0, 1e-4, 2e-3])), n)
    for _ in range(draw(st.integers(0, 3))):                      # gaps up to 10 s
        steps[rng.integers(1, n)] = draw(st.sampled_from([0.3, 1.7, 10.0]))
    for _ in range(draw(st.integers(0, 3))):                      # back-steps and repeats
        steps[rng.integers(1, n)] = draw(st.sampled_from([0.0, -0.05]))
    t = 100.0 + np.cumsum(steps)
    gyro = rng.normal(0, 0.05, (n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.5, (n, 3))
    for _ in range(draw(st.integers(0, 3))):                      # NaN and inf samples
        gyro[rng.integers(0, n), rng.integers(0, 3)] = draw(st.sampled_from([np.nan, np.inf]))
    if draw(st.booleans()):
        t[rng.integers(0, n)] = np.nan
    speed_kind = draw(st.sampled_from(["never", "on_time", "late", "shuffled", "nan"]))
    return t, gyro, accel, speed_kind, seed


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_streams())
def test_random_streams_never_raise(stream):
    t, gyro, accel, speed_kind, seed = stream
    rng = np.random.default_rng(seed)
    est = StreamingEstimator()
    frames = []
    ts = np.nan_to_num(t, nan=100.0)
    sp = [(x, 8.0 + rng.normal()) for x in ts[::5]]
    if speed_kind == "shuffled":
        rng.shuffle(sp)
    if speed_kind == "nan":
        sp = [(x, np.nan if k % 3 else v) for k, (x, v) in enumerate(sp)]
    lag = 0.4 if speed_kind == "late" else 0.0
    j = 0
    for i in range(len(t)):
        while speed_kind != "never" and j < len(sp) and (speed_kind == "shuffled" or sp[j][0] + lag <= ts[i]):
            est.push_speed(*sp[j])
            j += 1
        frames += est.push_imu(t[i], gyro[i], accel[i])
    frames += est.flush()
    _finite_when_valid(frames)
    times = [f.t for f in frames]
    assert all(b > a for a, b in zip(times, times[1:], strict=False))          # in time order (no restart: no jump back)


def test_bad_data_each_said():
    est = StreamingEstimator()
    out = []
    for k in range(300):
        t = 0.01 * k + (10.0 if k >= 200 else 0.0)                # a 10 s gap
        g = (math.nan, 0.0, 0.0) if k == 50 else (0.0, 0.0, 0.0)
        if k == 80:
            t = 0.79                                                 # a repeated stamp (retimed)
        est.push_speed(t, math.nan if k == 120 else 5.0)
        if k == 130:
            est.push_speed(math.nan, 5.0)                            # a speed without a time: ignored, said
        out += est.push_imu(t, g, (0.0, 0.0, 9.81))
    reasons = " | ".join(f.status_reason for f in out)
    assert "1 non-finite IMU sample(s) skipped" in reasons
    assert "retimed on the sample clock" in reasons
    assert "no speed over this frame: IMU only" in reasons         # the NaN speed is a hole
    assert "1 non-finite-time speed sample(s) ignored" in reasons
    assert any(f.status == "gap" for f in out)
    # the clock set back by a minute: a restart, said
    out = est.push_imu(-60.0, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
    for k in range(1, 150):                                        # (the new run's first frames: a stop's start)
        out += est.push_imu(-60.0 + 0.01 * k, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
    assert any("clock stepped back by" in f.status_reason and "restarted" in f.status_reason for f in out)


def test_a_clock_set_forward_restarts_rather_than_filling_the_gap():
    """A stamp more than MAX_GAP_FRAMES frames ahead (a clock set forward by time sync) restarts the front end,
    said in the next frame; it made a gap frame for every 0.1 s of the jump (a day: 864,000 frames from one push,
    minutes and gigabytes). A gap below the limit is still integrated through. The whole-log twin gives the
    same frames."""
    from imu_ground.pipeline.streaming import MAX_GAP_FRAMES
    half, over = 0.5 * MAX_GAP_FRAMES / 10.0, 1.5 * MAX_GAP_FRAMES / 10.0           # s, at 10 Hz frames
    t = np.r_[np.arange(2000) * 0.01, 20.0 + half + np.arange(500) * 0.01, 25.0 + half + over + np.arange(500) * 0.01]
    g, a = np.zeros((t.size, 3)), np.tile([0.0, 0.0, 9.81], (t.size, 1))
    est = StreamingEstimator()
    frames = replay(est, t, g, a)
    reasons = [f.status_reason for f in frames]
    assert sum("jumped forward by" in r and "restarted" in r for r in reasons) == 1
    assert any("gap in the log" in r for r in reasons)                       # the half-limit gap: a gap
    assert MAX_GAP_FRAMES / 2 < len(frames) < MAX_GAP_FRAMES / 2 + 400
    track, _ = StreamingEstimator().run(t, g, a)
    assert len(track) == len(frames) and track.status_reason.tolist() == reasons


def test_stamps_no_unit_explains_are_skipped_and_said():
    """Stamps no time unit makes an IMU's (stepping by 1e12: 0.001 Hz even in ns): no frame, one note with the
    count, no memory blown up (it raised MemoryError in the preintegrator); once the stamps are seconds the
    stream goes on, and the first frame says what was skipped. The whole-log twin gives the same."""
    t = np.r_[5e13 + np.arange(3000) * 1e12, 100.0 + np.arange(300) * 0.01]
    g, a = np.zeros((t.size, 3)), np.tile([0.0, 0.0, 9.81], (t.size, 1))
    est = StreamingEstimator()
    assert replay(est, t[:3000], g[:3000], a[:3000]) == []
    frames = replay(est, t[3000:], g[3000:], a[3000:])
    assert 20 < len(frames) < 31
    assert "IMU stamps step by 1e+12 s" in frames[0].status_reason
    assert "not in seconds" in frames[0].status_reason and "IMU samples skipped: 3000" in frames[0].status_reason
    assert all("IMU stamps" not in f.status_reason for f in frames[1:])
    track, _ = StreamingEstimator().run(t, g, a)
    assert track.status_reason.tolist() == [f.status_reason for f in frames]
    first = StreamingEstimator()                            # saved halfway through the skipping, resumed
    replay(first, t[:1500], g[:1500], a[:1500])
    resumed = StreamingEstimator()
    resumed.load_state_dict(json.loads(json.dumps(first.state_dict())))
    again = replay(resumed, t[1500:], g[1500:], a[1500:])
    fields = ("t", "pitch", "roll", "pitch_std", "roll_std", "status", "status_reason", "valid")
    assert [[getattr(f, n) for n in fields] for f in again] == [[getattr(f, n) for n in fields] for f in frames]


FIELDS = ("t", "t_start", "pitch", "roll", "pitch_std", "roll_std", "road_grade", "road_bank", "speed", "valid",
          "status")


def _keys(frames, fields=FIELDS):
    return [tuple(getattr(f, n) for n in fields) for f in frames]


def _drive_rows(n=6000, seed=3):
    """100 Hz samples of a drive (the example log's, repeated), stamps in seconds from an epoch-sized start, and
    a 10 Hz speed."""
    from imu_ground.datasets import read_imu
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imu = read_imu(EXAMPLE)
    reps = -(-n // len(imu.t))
    g, a = np.tile(imu.gyro, (reps, 1))[:n], np.tile(imu.accel, (reps, 1))[:n]
    rng = np.random.default_rng(seed)
    t = 1.7e9 + np.arange(n) * 0.01 + rng.normal(0, 1e-4, n)
    ts = 1.7e9 + np.arange(0.0, n * 0.01, 0.1)
    return t, g, a, (ts, 8.0 + np.sin(ts / 7.0))


def _gaps_in_output(frames):
    t = [f.t for f in frames]
    return max(b - a for a, b in zip(t, t[1:], strict=False))


@pytest.mark.parametrize("bad", [1.7e18, 3600.0, 5e4], ids=["ns", "hour-ahead", "half-day-ahead"])
def test_a_lone_bad_stamp_is_a_bad_sample_not_a_new_clock(bad):
    """Issue 38, case 1: one sample stamped in nanoseconds, or one an hour or more ahead, silenced the stream for
    the rest of the drive (the clock restarted at it, and every later stamp was before it). Now the sample is
    dropped, the next frame says so, the frames go on every 0.1 s (never a step back), and the twin agrees."""
    t, g, a, sp = _drive_rows(3000)
    t = t.copy()
    t[1500] = bad if bad > 1e10 else t[1500] + bad
    frames = replay(StreamingEstimator(), t, g, a, sp)
    clean = replay(StreamingEstimator(), np.delete(t, 1500), np.delete(g, 1500, 0), np.delete(a, 1500, 0), sp)
    assert len(frames) == len(clean) >= 290
    assert _gaps_in_output(frames) < 0.1 + 1e-6
    said = [f for f in frames if "stamp far off the clock" in f.status_reason]
    assert len(said) == 1 and abs(said[0].t - t[1499]) < 0.11
    assert "a bad stamp, not a new clock" in said[0].status_reason
    track, _ = StreamingEstimator().run(t, g, a, sp)
    assert track.status_reason.tolist() == [f.status_reason for f in frames]
    np.testing.assert_allclose(track.roll, [f.roll for f in frames], rtol=0, atol=1e-12)   # (to rounding)


def test_a_real_clock_change_restarts_and_estimates_resume_within_2_s():
    """Several agreeing stamps an hour and a half ahead are a new clock: a restart, said, and frames again within
    2 s of stream time; a clock set back likewise."""
    t, g, a, _ = _drive_rows(4000)
    t = t.copy()
    t[1500:] += 5400.0
    t[3000:] -= 9000.0
    frames = replay(StreamingEstimator(), t, g, a)
    reasons = [f.status_reason for f in frames]
    assert sum("jumped forward by 5400." in r and "restarted" in r for r in reasons) == 1
    assert sum("stepped back by 8999.9" in r and "restarted" in r for r in reasons) == 1
    assert not any("a bad stamp" in r for r in reasons)
    assert sum("2 IMU sample(s) dropped while the change of the clock was confirmed" in r for r in reasons) == 2
    for word, i in (("jumped forward", 1500), ("stepped back", 3000)):     # the first frame of the new clock
        first = next(f for f in frames if word in f.status_reason)
        assert 0 < first.t - t[i] < 2.0
    assert len(frames) > 370


def test_one_sample_10_s_ahead_makes_no_gap_frames_and_time_never_steps_back():
    """Issue 38, case 3: one sample 10 s ahead made 101 gap frames, then a restart with time stepping back
    (39.9 -> 39.1 s). Now: a bad sample, said; no gap frame; the output's time only moves forward."""
    t, g, a, sp = _drive_rows(4000)
    t = t.copy()
    t[3000] += 10.0
    frames = replay(StreamingEstimator(), t, g, a, sp)
    times = [f.t for f in frames]
    assert all(y > x for x, y in zip(times, times[1:], strict=False))
    assert not any(f.status == "gap" for f in frames)
    assert 395 <= len(frames) <= 401
    assert sum(bool(re.search(r"the last (9\.99\d*|10) s ahead\), a bad stamp", f.status_reason)) for f in frames) == 1


@pytest.mark.parametrize("unit, scale", [("ns", 1e9), ("us", 1e6), ("ms", 1e3)])
def test_a_stream_stamped_in_ns_us_or_ms_gives_the_frames_of_seconds(unit, scale):
    """Issue 38, case 2: a whole stream stamped in ns or ms gave 0 frames, silently. The unit is told from the
    data at the warm-up (as the readers do), said in the first frame, and the frames are the seconds run's: the
    IMU stamps and the speed's given in that unit."""
    t, g, a, sp = _drive_rows(2000)
    t_s = (t * scale) / scale                           # the stamps the unit's run turns into seconds
    sec = replay(StreamingEstimator(), (t * scale) * (1 / scale), g, a, (sp[0] * scale * (1 / scale), sp[1]))
    est = StreamingEstimator()
    got = replay(est, t * scale, g, a, (sp[0] * scale, sp[1]))
    assert len(got) == len(sec) > 150 and t_s.size
    assert _keys(got) == _keys(sec)
    names = {"ns": "nanoseconds", "us": "microseconds", "ms": "milliseconds"}
    assert f"IMU stamps read as {names[unit]} from the data" in got[0].status_reason
    assert [f.status_reason for f in got[1:]] == [f.status_reason for f in sec[1:]]
    track, _ = StreamingEstimator().run(t * scale, g, a, (sp[0] * scale, sp[1]))
    assert track.status_reason.tolist() == [f.status_reason for f in got]
    resumed = StreamingEstimator()                      # the unit is in the saved state
    est = StreamingEstimator()                          # (not replay: its flush ends the stream)
    head = [f for i in range(700) for f in est.push_imu(t[i] * scale, g[i], a[i])]
    resumed.load_state_dict(json.loads(json.dumps(est.state_dict())))
    tail = replay(resumed, t[700:] * scale, g[700:], a[700:])
    whole = replay(StreamingEstimator(), t * scale, g, a)
    assert _keys(head + tail) == _keys(whole)


def test_speed_that_never_comes_back_runs_imu_only_and_says_so():
    est = StreamingEstimator(speed_wait=0.25)
    out = []
    for k in range(200):
        t = 0.01 * k
        if k < 50:
            est.push_speed(t, 5.0)
        got = est.push_imu(t, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
        for f in got:                                 # a frame waits at most speed_wait of IMU time (the first
            assert t <= f.t + max(0.25, 0.9) + 0.011   # frames of a stop: held until its window passes, 0.9 s)
        out += got
    assert any(f.status_reason.endswith("no speed over this frame: IMU only") for f in out)
    assert math.isfinite(out[2].speed) and math.isnan(out[-1].speed)


def test_misuse_is_one_line_naming_the_argument():
    est = StreamingEstimator()
    with pytest.raises(ValueError, match="gyro") as e:
        est.push_imu(0.0, np.eye(3), (0.0, 0.0, 9.81))
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="^t ") as e:
        est.push_imu("0.1", (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))
    with pytest.raises(ValueError, match="accel"):
        est.push_imu(0.0, (0.0, 0.0, 0.0), (0.0, 9.81))
    with pytest.raises(ValueError, match="speed"):
        est.push_speed(0.0, "fast")
    with pytest.raises(ValueError, match="method"):
        StreamingEstimator("suspension-offline")


# --------------------------------------------------------------------------- the clock
def _clock(raw):
    c = SampleClock()
    out = [c.push(x) for x in raw]
    return c, np.array([o[1] for o in out]), [o[0] for o in out]


def test_clock_retimes_kitti_jitter_without_a_gap():
    """The OXTS extract's pattern: stamps jump 0.55 s ahead, then step back 50 ms every 6 samples."""
    k = np.arange(600)
    true = 0.01 * k
    raw = true.copy()
    ahead = np.zeros(600)
    ahead[300:] = 0.55
    for j in range(9):
        ahead[306 + 6 * j:] -= 0.05
    raw = raw + ahead + 0.0                                   # ends 0.10 s ahead: a dropout of 10 samples
    c, out, codes = _clock(raw)
    assert np.all(np.diff(out) > 0)
    assert c.dropouts == 1                                    # the lasting 0.1 s, after hold = 1 s
    np.testing.assert_allclose(out[:300], true[:300], atol=1e-9)
    assert np.max(np.abs(np.diff(out[300:395]) - 0.01)) < 1e-3   # no gap inside the jitter
    np.testing.assert_allclose(out[-50:], raw[-50:], atol=2e-3)


def test_clock_long_dropout_confirmed_and_restart():
    """A stamp 1.6 s ahead is a bad one until CONFIRM agreeing stamps make it a dropout (the first ones dropped, then
    the clock on the stamps); a lone stamp 5 s back is dropped, CONFIRM of them restart the clock."""
    from imu_ground.imu.live.sample_clock import CONFIRM, DROP
    raw = np.r_[np.arange(100) * 0.01, 0.99 + 1.6 + np.arange(50) * 0.01]
    c, out, codes = _clock(raw)
    assert c.dropouts == 1 and codes[100:100 + CONFIRM - 1] == [DROP] * (CONFIRM - 1)
    assert abs(out[100 + CONFIRM - 1] - raw[100 + CONFIRM - 1]) < 1e-12 and c.confirming == CONFIRM - 1
    assert c.bad == 0
    assert c.push(raw[-1] - 5.0)[0] == DROP and c.bad == 1            # a lone stamp back: a bad one
    assert c.push(raw[-1] + 0.01)[0] == 0 and c.restarts == 0
    for k in range(CONFIRM):
        code, t = c.push(raw[-1] - 5.0 + 0.01 * k)
    assert code == RESTART and t == raw[-1] - 5.0 + 0.01 * (CONFIRM - 1) and c.restarts == 1


def test_clock_state_round_trip():
    rng = np.random.default_rng(1)
    raw = np.cumsum(0.01 + rng.normal(0, 2e-3, 300))
    a = SampleClock()
    for x in raw[:150]:
        a.push(x)
    b = SampleClock()
    b.load_state_dict(json.loads(json.dumps(a.state_dict())))
    assert [a.push(x) for x in raw[150:]] == [b.push(x) for x in raw[150:]]


# --------------------------------------------------------------------------- small fixes of the issue
def test_step_takes_a_preintegrated_frame():
    from imu_ground import StreamingPreintegrator, SuspensionAwareFilter
    from imu_ground.imu.egomotion import EgoFrame
    p = StreamingPreintegrator(rate=10.0, uncertainty=False)
    frames = []
    for i in range(40):
        frames += p.push(0.01 * i, (0.01, 0.002, 0.0), (0.1, 0.0, 9.81))
    a, b = SuspensionAwareFilter(), SuspensionAwareFilter()
    for f in frames:
        x, y = a.step(f), b.step(EgoFrame(f.delta_R, f.delta_v, f.delta_t, False, f.valid, f.t_end))
        assert (x.pitch, x.roll) == (y.pitch, y.roll)


# --------------------------------------------------------------------------- command line
def _csv_rows(text):
    import io

    import pandas as pd
    return pd.read_csv(io.StringIO(text))


def test_stream_stdin_equals_estimate_causal(cli, monkeypatch, tmp_path):
    import io
    monkeypatch.setattr(sys, "stdin", io.StringIO(EXAMPLE.read_text()))
    state = tmp_path / "state.json"
    code, out, err = cli("stream", "--state", state)
    assert code == 0, err
    got = _csv_rows(out)
    res = _offline(EXAMPLE)
    assert len(got) == len(res.track)
    np.testing.assert_allclose(got["pitch_deg"], np.degrees(res.track.pitch), rtol=0, atol=1e-9)
    assert json.loads(state.read_text())["kind"] == "imu_ground.StreamingEstimator"
    # --json, resumed from the state: the stream's clock jumps back (the same log again), said, no error
    monkeypatch.setattr(sys, "stdin", io.StringIO(EXAMPLE.read_text()))
    code, out, err = cli("stream", "--json", "--state", state)
    assert code == 0, err
    lines = [json.loads(x) for x in out.splitlines()]
    assert "restarted" in lines[0]["status_reason"] and set(lines[0]) >= {"t", "pitch_deg", "status"}


def test_stream_from_stdin_refuses_a_frame_rate_it_cannot_run(cli, monkeypatch):
    """``stream --rate 1e9`` on standard input (IMU rate unknown up front) ran forever: refused now."""
    import io
    monkeypatch.setattr(sys, "stdin", io.StringIO(EXAMPLE.read_text()))
    code, out, err = cli("stream", "--rate", "1e9")
    assert code == 2 and out == ""
    assert "--rate 1e+09 Hz is above the live path's highest frame rate of 1000 Hz" in err
    assert len(err.strip().splitlines()) == 1
    with pytest.raises(OptionError, match="highest frame rate"):
        StreamingEstimator(rate=MAX_FRAME_RATE * 1.01)
    StreamingEstimator(rate=MAX_FRAME_RATE)


def test_stream_refuses_a_state_file_it_did_not_write(cli, tmp_path):
    state = tmp_path / "notes.txt"
    state.write_text("my notes\n")
    code, out, err = cli("stream", "--replay", EXAMPLE, "--state", state)
    assert code == 2 and "--state" in err and err.count("\n") == 1
    assert state.read_text() == "my notes\n"


def test_stream_replay_quiet_under_head(tmp_path):
    exe = Path(sys.executable).with_name("imu-ground")
    r = subprocess.run(f"'{exe}' stream --replay '{EXAMPLE}' --state '{tmp_path / 's.json'}' | head -2",
                       shell=True, capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0 and r.stderr == "" and len(r.stdout.splitlines()) == 2
    assert (tmp_path / "s.json").is_file()                 # the state is written when the reader goes away


def test_estimate_causal_cli(cli, tmp_path):
    out = tmp_path / "c.csv"
    code, _, err = cli("estimate", EXAMPLE, "--causal", "-o", out)
    assert code == 0, err
    assert "causal" in out.read_text().split("\nt,")[0]
    code, _, err = cli("estimate", EXAMPLE, "--causal", "--method", "suspension-offline", "-o", out)
    assert code == 2 and "--method" in err


def test_speed_buffer_equals_frame_speed():
    from imu_ground.datasets.speed import frame_speed
    from imu_ground.imu.live.speed_buffer import SpeedBuffer
    rng = np.random.default_rng(4)
    ts = np.cumsum(rng.uniform(0.01, 0.2, 300))
    v = 10 + np.cumsum(rng.normal(0, 0.3, 300))
    te = np.arange(1.0, ts[-1] + 1.0, 0.1)
    want = frame_speed(ts, v, te, np.full(te.size, 0.1))
    buf = SpeedBuffer()
    for x, y in zip(ts, v, strict=True):
        buf.push(float(x), float(y))
    got = []
    for e in te:
        got.append(buf.mean(e - 0.1, e))
        buf.done(e)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert np.isnan(got[-1]) and np.isfinite(got[5])


def test_stream_writes_its_state_on_sigterm(tmp_path):
    import signal
    import time as _time
    exe = Path(sys.executable).with_name("imu-ground")
    state = tmp_path / "s.json"
    p = subprocess.Popen([str(exe), "stream", "--state", str(state)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    lines = EXAMPLE.read_text().splitlines()[:400]
    p.stdin.write("\n".join(lines) + "\n")
    p.stdin.flush()
    first = p.stdout.readline()                      # the header line: samples are being processed
    assert first.startswith("t,normal_x")
    _time.sleep(0.3)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 143 and "terminated" in err
    assert json.loads(state.read_text())["kind"] == "imu_ground.StreamingEstimator"


def test_stream_realtime_paces_the_replay(cli, tmp_path):
    import time as _time
    log = tmp_path / "short.csv"
    log.write_text("\n".join(EXAMPLE.read_text().splitlines()[:61]) + "\n")    # 0.6 s at 100 Hz
    t0 = _time.monotonic()
    code, out, err = cli("stream", "--replay", log, "--realtime")
    assert code == 0, err
    assert _time.monotonic() - t0 >= 0.55 and len(out.splitlines()) == 1 + 5


def test_camera_plane_live_equals_causal_estimate(cli, tmp_path):
    imu, _ = _read(EXAMPLE)
    res = _offline(EXAMPLE, camera="kitti_cam2")
    frames = replay(StreamingEstimator(camera="kitti_cam2"), imu.t, imu.gyro, imu.accel)
    got = np.array([f.plane for f in frames])
    np.testing.assert_allclose(got, res.meta["plane"].coefficients, rtol=0, atol=1e-12)
    log = tmp_path / "short.csv"
    log.write_text("\n".join(EXAMPLE.read_text().splitlines()[:101]) + "\n")
    code, out, err = cli("stream", "--replay", log, "--camera", "kitti_cam2")
    assert code == 0, err
    header = out.splitlines()[0].split(",")
    assert header[header.index("valid") - 4:header.index("valid")] == ["plane_a", "plane_b", "plane_c", "plane_d"]


def test_causal_track_of_a_log_with_nan_and_a_restart_equals_the_stream():
    """The logs the vectorised form does not cover (non-finite samples, a clock set back) are streamed."""
    rng = np.random.default_rng(7)
    t = np.r_[np.arange(600) * 0.01, 2.0 + np.arange(400) * 0.01]        # set back by 4 s after 6 s
    gyro = rng.normal(0, 0.02, (1000, 3))
    accel = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.2, (1000, 3))
    gyro[300, 1] = np.nan
    track, _ = causal_track(t, gyro, accel)
    frames = replay(StreamingEstimator(), t, gyro, accel)
    _assert_same(frames, track)
    assert any("restarted" in r for r in track.status_reason)
    assert any("non-finite IMU sample" in r for r in track.status_reason)


def test_speed_holes_live_as_offline():
    """NaN speeds are holes (datasets.speed.frame_speed): the frames they reach run IMU only, live as offline."""
    imu, _ = _read(EXAMPLE)
    ts = imu.t[::5].copy()
    v = 10.0 + 0.01 * np.arange(ts.size)
    v[200:230] = np.nan
    track, _ = causal_track(imu.t, imu.gyro, imu.accel, speed=(ts, v))
    frames = replay(StreamingEstimator(), imu.t, imu.gyro, imu.accel, (ts, v))
    _assert_same(frames, track)
    got = np.array([f.speed for f in frames])
    from imu_ground.datasets.speed import frame_speed
    want = frame_speed(ts, v, track.t, np.full(len(track), 0.1))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert np.isnan(got).sum() >= 6 and np.isfinite(got[5:95]).all() and np.isnan(got[102:112]).all()


# --------------------------------------------------------------------------- stream: what estimate reads (issue 38)
def _example_text(time_scale=1.0, bom=False, speed_column=False):
    """The example log as CSV text: stamps in another unit from an epoch-sized start, a BOM, a speed column (the
    example's truth)."""
    import pandas as pd
    df = pd.read_csv(EXAMPLE)
    if speed_column:
        truth = pd.read_csv(EXAMPLE.with_name("example_drive_truth.csv"))
        df["speed"] = np.interp(df["t"], truth["t"], truth["speed"])
    if time_scale != 1.0:
        df["t"] = np.round(1.7e9 * time_scale + df["t"] * time_scale).astype(np.int64)
    return ("\ufeff" if bom else "") + df.to_csv(index=False)


def test_stream_stdin_reads_a_bom_and_epoch_ns_stamps(cli, monkeypatch):
    """Issue 38, cases 2 and 8: a UTF-8 byte-order mark on standard input was exit 2 (estimate reads it); epoch-ns
    stamps gave exit 0 and no line, nothing on stderr. Now both give the frames, the ns ones those of the same
    stamps in seconds, the unit said in the first frame."""
    import io
    monkeypatch.setattr(sys, "stdin", io.StringIO(_example_text(bom=True)))
    code, out, err = cli("stream")
    assert code == 0, err
    plain = _csv_rows(out)
    assert len(plain) > 50
    monkeypatch.setattr(sys, "stdin", io.StringIO(_example_text(time_scale=1e9)))
    code, out, err = cli("stream")
    assert code == 0, err
    ns = _csv_rows(out)
    assert abs(len(ns) - len(plain)) <= 1                 # (the last frame's end: ns stamps rounded to float64)
    assert "read as nanoseconds" in ns["status_reason"].iloc[0]
    n = min(len(ns), len(plain))
    np.testing.assert_allclose(ns["t"][:n] - 1.7e9, plain["t"][:n], rtol=0, atol=1e-5)
    np.testing.assert_allclose(ns["roll_deg"][:n], plain["roll_deg"][:n], rtol=0, atol=1e-3)


def test_stream_stdin_speed_file_is_used_and_a_missing_one_refused(cli, monkeypatch, tmp_path):
    """Issue 38, case 8: --speed FILE with standard input was ignored without a word (a missing file too). Now the
    file's speed is merged by time (the frames those of the speed as a column) and a missing file is exit 2
    naming --speed."""
    import io

    import pandas as pd
    text = _example_text(speed_column=True)
    monkeypatch.setattr(sys, "stdin", io.StringIO(text))
    code, out, err = cli("stream")
    assert code == 0, err
    with_column = _csv_rows(out)
    assert np.isfinite(with_column["road_grade_deg"]).sum() > 100     # (the speed is used)
    speed = tmp_path / "speed.csv"
    pd.read_csv(io.StringIO(text))[["t", "speed"]].to_csv(speed, index=False)
    monkeypatch.setattr(sys, "stdin", io.StringIO(_example_text(speed_column=False)))
    code, out, err = cli("stream", "--speed", speed)
    assert code == 0, err
    from_file = _csv_rows(out)
    assert len(from_file) == len(with_column)
    np.testing.assert_allclose(from_file["roll_deg"], with_column["roll_deg"], rtol=0, atol=1e-6)
    monkeypatch.setattr(sys, "stdin", io.StringIO(_example_text(speed_column=False)))
    code, out, err = cli("stream", "--speed", tmp_path / "missing.csv")
    assert code == 2 and "--speed" in err and len(err.strip().splitlines()) == 1


def test_stream_stdin_names_damaged_lines(cli, monkeypatch):
    """Issue 38, case 8: garbage lines were only counted as "non-finite IMU samples"; now each is said on stderr with
    its line number (and still skipped)."""
    import io
    lines = _example_text().splitlines()
    lines[5] = "garbage," + lines[5].split(",", 1)[1]
    lines[40] = lines[40].replace(",", ",x", 1)
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n".join(lines) + "\n"))
    code, out, err = cli("stream")
    assert code == 0, err
    assert "<stdin>: warning: line 6: column t is 'garbage', not a number: sample skipped" in err
    assert "line 41: column wx" in err
    assert "non-finite IMU sample(s) skipped" in out


def test_stream_replay_with_state_resumes_where_it_left_off(cli, tmp_path):
    """Issue 38, case 8: `--replay LOG --state` fed the log from 0 again (the clock stepped back: a restart). The
    state file now says how far the replay got; the next run on the same log resumes there, and the two runs'
    lines are the one run's."""
    import signal
    state = tmp_path / "state.json"
    code, out, err = cli("stream", "--replay", EXAMPLE)
    assert code == 0, err
    whole = _csv_rows(out)
    proc = subprocess.Popen([sys.executable, "-m", "imu_ground", "stream", "--replay", str(EXAMPLE), "--realtime",
                             "--state", str(state)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT)
    head = [proc.stdout.readline() for _ in range(14)]    # the header and 13 frames (after the first stop's
    # start, held and written at once): samples are being fed, paced
    assert head[0].startswith("t,normal_x")
    proc.send_signal(signal.SIGTERM)
    rest, first_err = proc.communicate(timeout=60)
    first_out = "".join(head) + rest
    first = _csv_rows(first_out) if first_out.strip() else None
    assert json.loads(state.read_text())["stream_replay"]["samples"] > 0, first_err
    code, out, err = cli("stream", "--replay", EXAMPLE, "--state", state)
    assert code == 0, err
    second = _csv_rows(out)
    n1 = 0 if first is None else len(first)
    assert n1 + len(second) == len(whole)
    assert not any("restarted" in r for r in second["status_reason"])
    np.testing.assert_allclose(second["t"], whole["t"].iloc[n1:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(second["roll_deg"], whole["roll_deg"].iloc[n1:], rtol=0, atol=1e-9)


def test_stream_holds_a_signal_until_the_sample_is_written():
    """A SIGTERM or Ctrl-C while a sample is pushed and its frames written is raised once they are written and
    counted (a saved state and the frames written agree: the resumed run above neither repeats nor loses a frame;
    before, a signal between the push and the write lost that sample's frames); outside that, at once."""
    import os
    import signal

    from imu_ground.cli import Terminated
    from imu_ground.cli.stream import _WholeSamples
    for sig, error in ((signal.SIGTERM, Terminated), (signal.SIGINT, KeyboardInterrupt)):
        with _WholeSamples() as whole:
            whole.busy = True
            os.kill(os.getpid(), sig)                      # delivered here, in the main thread: held
            written = True
            with pytest.raises(error):
                whole.done()
            assert written and whole.pending is None
            with pytest.raises(error):                     # not busy (waiting for a line): raised at once
                os.kill(os.getpid(), sig)
    assert signal.getsignal(signal.SIGTERM) != whole._on_signal       # the handlers before come back


@pytest.mark.parametrize("late", [0.16, 0.4])
def test_a_late_speed_is_waited_for_as_long_as_its_latency_needs(late):
    """Issue 38, case 5: a 10 Hz speed 0.16 s late or more made every frame run IMU only (roll 0.16-0.18 deg off)
    with status ok and the reason "too slow ... below 3 m/s" at 8-14 m/s. Now the frames wait as long as the
    measured latency needs (said once): they get the speed, and equal the frames of the speed on time."""
    t, g, a, sp = _drive_rows(4000)
    ts, vs = sp

    def run(lag):
        est, out, j = StreamingEstimator(), [], 0
        for i in range(len(t)):
            while j < len(ts) and ts[j] + lag <= t[i]:
                est.push_speed(ts[j], vs[j])
                j += 1
            out += est.push_imu(t[i], g[i], a[i])
        while j < len(ts):
            est.push_speed(ts[j], vs[j])
            j += 1
        return out + est.flush()
    on_time, late_run = run(0.0), run(late)
    assert len(late_run) == len(on_time)
    assert np.isfinite([f.speed for f in late_run[20:-1]]).all()    # (the last frame is past the last speed)
    fields = ("t", "speed", "status")               # (the first two frames, before a latency is measured, differ)
    assert _keys(late_run[20:], fields) == _keys(on_time[20:], fields)
    for name in ("pitch", "roll"):
        diff = np.degrees([getattr(x, name) - getattr(y, name) for x, y in zip(late_run[20:], on_time[20:], strict=False)])
        assert np.abs(diff).max() < 0.05                # (the road filter starts a frame later: its first speed)
    said = [f.status_reason for f in late_run if "after their stamps: frames wait up to" in f.status_reason]
    assert 1 <= len(said) <= 3
    assert not any("too slow" in f.status_reason for f in late_run[20:] if f.speed > 3.0)


def test_a_speed_later_than_the_longest_wait_says_so():
    """A speed 3 s late: frames wait MAX_SPEED_WAIT at most (the stream is never held longer), then run IMU only
    and the reason says how late the speed comes and how long they waited."""
    from imu_ground.pipeline.streaming import MAX_SPEED_WAIT
    t, g, a, (ts, vs) = _drive_rows(3000)
    est, out, j = StreamingEstimator(), [], 0
    for i in range(len(t)):
        while j < len(ts) and ts[j] + 3.0 <= t[i]:
            est.push_speed(ts[j], vs[j])
            j += 1
        got = est.push_imu(t[i], g[i], a[i])
        assert all(t[i] - f.t <= MAX_SPEED_WAIT + 0.02 for f in got)
        out += got
    reasons = [f.status_reason for f in out[100:]]
    assert all(f"waited {MAX_SPEED_WAIT:.2f} s; speed samples arrive up to 3." in r for r in reasons)


# --------------------------------------------------------------------------- the live object never goes silent
@st.composite
def _glitchy_streams(draw):
    """100 Hz streams (stamps in s, ms, us or ns) with lone bad stamps (ns among them, an hour, 10 s ahead, far
    back), real gaps, NaN samples and a 10 Hz speed on time, late or absent."""
    n = draw(st.integers(300, 1500))
    seed = draw(st.integers(0, 2 ** 32 - 1))
    rng = np.random.default_rng(seed)
    steps = np.full(n, 0.01) + rng.normal(0, draw(st.sampled_from([0.0, 1e-4, 2e-3])), n)
    for _ in range(draw(st.integers(0, 2))):                      # real gaps, each with samples after it to
        # confirm the clock across it (CONFIRM agreeing stamps; 2 stamps 10 s ahead at the end are bad samples)
        steps[rng.integers(20, n - 10)] = draw(st.sampled_from([0.3, 1.7, 10.0]))
    true = 1.7e9 + np.cumsum(steps)                               # the stream's time, s
    unit = draw(st.sampled_from([1.0, 1e3, 1e6, 1e9]))
    t = true * unit
    bad = {}
    for _ in range(draw(st.integers(0, 4))):                      # lone bad stamps
        i = int(rng.integers(1, n))
        kind = draw(st.sampled_from(["ns", "hour", "10s", "back", "nan"]))
        bad[i] = kind
        t[i] = {"ns": 1.7e18, "hour": t[i] + 3600.0 * unit, "10s": t[i] + 10.0 * unit,
                "back": t[i] - 500.0 * unit, "nan": np.nan}[kind]
    gyro = rng.normal(0, 0.05, (n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.5, (n, 3))
    for _ in range(draw(st.integers(0, 3))):                      # NaN and inf samples
        gyro[rng.integers(0, n), rng.integers(0, 3)] = draw(st.sampled_from([np.nan, np.inf]))
    lag = draw(st.sampled_from([None, 0.0, 0.2, 0.5]))
    return true, t, gyro, accel, unit, lag, seed


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(_glitchy_streams())
def test_the_live_object_never_goes_silent(stream):
    """Issue 38, "Done when": fed streams with glitches (lone bad stamps, stamps in another unit, gaps, late speed,
    NaN), the live object never raises, is never silent for more than 2 s of stream time, gives its frames in time
    order, never NaN with valid."""
    true, t, gyro, accel, unit, lag, seed = stream
    rng = np.random.default_rng(seed)
    est = StreamingEstimator()
    ts = true[::10]
    sp = ts + 0.0, 8.0 + rng.normal(0, 0.3, ts.size)
    frames, j, last_emit, silent = [], 0, 0, 0
    for i in range(len(t)):
        while lag is not None and j < ts.size and sp[0][j] + lag <= true[i]:
            est.push_speed(sp[0][j] * unit, sp[1][j])
            j += 1
        got = est.push_imu(t[i], gyro[i], accel[i])
        if got:
            last_emit = i
        silent = max(silent, i - last_emit)
        frames += got
    frames += est.flush()
    assert silent * 0.01 <= 2.0                                   # samples since the last frame, at 100 Hz
    _finite_when_valid(frames)
    times = [f.t for f in frames]
    assert all(b > a for a, b in zip(times, times[1:], strict=False))
    assert len(frames) >= 0.9 * (true[-1] - true[0]) * 10 - 25, (unit, lag, np.flatnonzero(np.diff(true) > 0.1),
                                                                 np.diff(true)[np.diff(true) > 0.1],
                                                                 np.flatnonzero(~np.isclose(t, true * unit)),
                                                                 [f.status_reason[-60:] for f in frames[-3:]])


def test_a_speed_in_kmh_is_told_from_the_data_and_the_frames_are_the_m_s_run(shared_data, kitti_index):
    """Issue 38, case 4: a speed in km/h was taken for m/s (roll off by up to 2.6 deg, status ok) while the offline
    reader detects km/h. Now the live object tells it from the data as offline does (the speed's changes against
    the accelerometer over 20 s of driving), says so, converts, and runs the filter again from its first speed:
    from then on the frames are those of the speed in m/s; the whole-log twin gives the same. The m/s run is
    told m/s (no note)."""
    name = kitti_index["drive"].iloc[0]
    t, gyro, accel, (ts, v) = _raw_kitti(shared_data / "kitti_imu100" / f"{name}.csv.gz")
    ms = replay(StreamingEstimator(extrinsic="kitti_imu"), t, gyro, accel, (ts, v))
    kmh = replay(StreamingEstimator(extrinsic="kitti_imu"), t, gyro, accel, (ts, v * 3.6))
    said = [i for i, f in enumerate(kmh) if "speed read as km/h from the data" in f.status_reason]
    assert len(said) == 1 and not any("km/h" in f.status_reason for f in ms)
    k = said[0]
    assert "filter run again" in kmh[k].status_reason
    assert k < len(kmh) - 50
    for name_ in ("pitch", "roll"):
        diff = np.degrees([getattr(x, name_) - getattr(y, name_) for x, y in zip(kmh[k:], ms[k:], strict=False)])
        assert np.abs(diff).max() < 1e-9, name_
    np.testing.assert_allclose([f.speed for f in kmh[k:]], [f.speed for f in ms[k:]], rtol=1e-12, atol=0)
    track, _ = StreamingEstimator(extrinsic="kitti_imu").run(t, gyro, accel, (ts, v * 3.6))
    assert track.status_reason.tolist() == [f.status_reason for f in kmh]


def test_an_hour_ahead_stamp_in_the_warm_up_is_a_bad_sample():
    """A far-ahead stamp as the last of the warm-up's samples (found by the property above): it completed the
    warm-up, the front end integrated an hour of gap frames up to it, then restarted an hour back (output time
    stepped back). Now it is dropped as a bad sample and said; the frames go on in order, none a gap."""
    n = 400
    t = 1.7e9 + 0.01 * np.arange(1, n + 1)
    t[9] += 3600.0
    est = StreamingEstimator()
    frames = []
    for i in range(n):
        frames += est.push_imu(t[i], [0.0, 0.0, 0.0], [0.0, 0.0, 9.81])
    frames += est.flush()
    times = np.array([f.t for f in frames])
    assert len(frames) < 50 and np.all(np.diff(times) > 0) and times[-1] < 1.7e9 + 5
    assert not any(f.status == "gap" for f in frames)
    assert any("dropped" in f.status_reason for f in frames[:3])
