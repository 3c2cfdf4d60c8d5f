"""The live path's leftovers: what the front end hands on (snapshots, settings, slots), and a rejected sample.

(The live front end against the whole-log ``--causal`` run is in tests/test_streaming.py.)
"""
from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from imu_ground.imu.live.preint_stream import StreamingPreintegrator
from imu_ground.pipeline import streaming
from imu_ground.pipeline.streaming import StreamingEstimator, replay

EXAMPLE = Path(__file__).resolve().parent.parent / "datasets" / "fixtures" / "example_drive.csv"


def _log(n=300, seed=0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(0.01 * (1 + 0.2 * rng.uniform(-1, 1, n)))
    gyro = 0.8 * np.sin(t[:, None] * [1.3, 0.7, 2.1]) + rng.normal(0, 0.05, (n, 3))
    accel = np.cos(t[:, None] * [0.9, 1.7, 0.4]) + [0.3, -0.2, 9.8] + rng.normal(0, 0.2, (n, 3))
    return t, gyro, accel


def test_rejected_samples_leave_the_preintegrator_unchanged():
    t, gyro, accel = _log()
    sp = StreamingPreintegrator(rate=10.0, max_gap=0.1)
    ref = StreamingPreintegrator(rate=10.0, max_gap=0.1)
    for i in range(150):
        sp.push(t[i], gyro[i].tolist(), accel[i].tolist())
    before = (bytes(sp._b), sp.current._s)
    with pytest.raises(ValueError, match="strictly increasing"):
        sp.push(t[149], gyro[150].tolist(), accel[150].tolist())
    with pytest.raises(ValueError, match="gap"):
        sp.push(t[149] + 1.0, gyro[150].tolist(), accel[150].tolist())
    with pytest.raises(ValueError, match="3 values"):
        sp.push(t[150], [0.0, 1.0], accel[150].tolist())
    assert (bytes(sp._b), sp.current._s) == before
    rest, whole = [], []
    for i in range(300):
        whole += ref.push(t[i], gyro[i], accel[i])          # (numpy rows: the same frames)
        if i >= 150:
            rest += sp.push(t[i], gyro[i].tolist(), accel[i].tolist())
    tail = [f for f in whole if f.t_start >= rest[0].t_start]
    assert len(rest) == len(tail) > 5
    assert [(f._s, f.n_intervals, f.t_start, f.t_end, f.valid) for f in rest] == \
        [(f._s, f.n_intervals, f.t_start, f.t_end, f.valid) for f in tail]


def test_road_snapshot_is_python_floats(shared_data):
    """The road filter's snapshot hands the per-frame road formulas Python floats (numpy scalars made them
    several times slower): the first frame with a speed of a drive."""
    from imu_ground.datasets import detect_format, read_imu
    from imu_ground.pipeline.estimate import speed_samples
    path = shared_data / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fmt = detect_format(path)
        imu = read_imu(path, format=fmt)
        sp = speed_samples("auto", path, fmt, imu)[0]
    est = StreamingEstimator(extrinsic="kitti_imu")
    replay(est, imu.t[:300], imu.gyro[:300], imu.accel[:300], sp)
    gf = est.filter.road_filter.gravity_filter
    assert gf is not None
    g, R, p6 = gf.gravity_snapshot()
    assert {type(x) for x in (*g, *R, *p6)} == {float}


def test_causal_output_records_the_recorded_policy(cli, tmp_path):
    """--causal reads the stamps as recorded and the live clock applies the time-order policy: both in the
    output's settings."""
    from imu_ground.pipeline import estimate_log
    log = EXAMPLE
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meta = estimate_log(log, causal=True, policy="drop").meta
        default = estimate_log(log).meta
    assert meta["settings"]["policy"] == "recorded" and meta["settings"]["clock_policy"] == "drop"
    assert "clock_policy" not in default["settings"]
    out = tmp_path / "c.csv"
    code, _, err = cli("estimate", log, "--causal", "-o", out)
    assert code == 0, err
    head = [line for line in out.read_text().splitlines() if line.startswith("# settings:")][0]
    settings = json.loads(head.split(":", 1)[1])
    assert settings["policy"] == "recorded" and settings["clock_policy"] == "retime"


def test_frame_estimate_copies_every_slot_of_the_filters_estimate():
    """FrameEstimate.of copies GroundEstimate's slots one by one (no loop: it runs once a frame): every one."""
    from imu_ground.filters.estimator import GroundEstimate
    est = GroundEstimate.__new__(GroundEstimate)
    for i, name in enumerate(GroundEstimate.__slots__):
        setattr(est, name, f"value {i}" if name != "valid" else True)
    out = streaming.FrameEstimate.of(est, 1.0, 0.9, math.nan, ())
    assert [getattr(out, name) for name in GroundEstimate.__slots__] == \
        [getattr(est, name) for name in GroundEstimate.__slots__]


def _direct_windows(samples, k, W, tests):
    """Whether the trailing window of W blocks ending at k passes, straight from the samples (numpy, no sums)."""
    rows = []
    for j in range(k, k - W, -1):
        if j < 0 or not samples.get(j):
            return False
        rows += samples[j]
    g = np.array([r[0] for r in rows])
    a = np.array([r[1] for r in rows])
    return bool(np.linalg.norm(g.mean(0)) <= tests.gyro_norm_max and g.std(0).max() <= tests.gyro_std_max
                and a.std(0).max() <= tests.accel_std_max
                and abs(np.linalg.norm(a.mean(0)) - tests.gravity) <= tests.accel_norm_tol)


def test_standstill_windows_match_the_samples_and_the_ring_grows_past_a_jump():
    from imu_ground.imu.live.causal_standstill import StandstillBlocks
    rng = np.random.default_rng(2)
    bl = StandstillBlocks(10.0)                          # 1 s and 2 s windows: W = 10, Wb = 20 blocks
    r0 = bl.ring.shape[0]
    ks = list(range(40)) + list(range(40 + 3 * r0, 40 + 3 * r0 + 30))   # a jump onto the rows still held
    samples: dict = {}
    for k in ks:
        moving = 15 <= k < 18 or k == ks[-5]
        for _ in range(int(rng.integers(1, 4))):
            g = rng.normal(0, 0.05 if moving else 1e-3, 3) + 0.001
            a = rng.normal(0, 0.5 if moving else 5e-3, 3) + [0.0, 0.0, 9.81]
            bl.add(k, g.tolist(), a.tolist())
            samples.setdefault(k, []).append((g, a))
    assert bl.ring.shape[0] > r0                         # grown, nothing lost
    assert sorted(bl.blocks) == ks
    passed = set()
    for k in range(-2, ks[-1] + 2):
        for W in (1, 5, 10, 20):
            got = bl.windows(k, W, W)
            assert got == (_direct_windows(samples, k, W, bl.tests),) * 2, (k, W)
            passed |= {W} if got[0] else set()
    assert passed == {1, 5, 10, 20}                      # the tests pass somewhere and fail elsewhere (moving)
    copy = StandstillBlocks(10.0)
    copy.load_state_dict(json.loads(json.dumps(bl.state_dict())))
    assert all(copy.windows(k) == bl.windows(k) for k in ks) and copy.open_k == bl.open_k == ks[-1]
    bl.done(ks[-1])
    assert min(bl.blocks) == ks[-1] - 20 + 2


def test_last_sample_time_and_next_boundary():
    t, gyro, accel = _log()
    sp = StreamingPreintegrator(rate=10.0, t_origin=0.0, max_gap=0.1)
    assert sp.last_sample_time is None and sp.next_boundary == math.inf
    for i in range(40):
        sp.push(t[i], gyro[i].tolist(), accel[i].tolist())
        assert sp.last_sample_time == t[i]
        assert t[i] < sp.next_boundary <= t[i] + 0.1 + 1e-9 and sp.next_boundary * 10.0 == pytest.approx(
            round(sp.next_boundary * 10.0), abs=1e-9)
    every = StreamingPreintegrator(every=5)
    every.push(t[0], gyro[0].tolist(), accel[0].tolist())
    assert every.last_sample_time == t[0] and every.next_boundary == math.inf      # counted in samples
    ends = StreamingPreintegrator(frame_times=[t[3], t[10]])
    for i in range(12):
        ends.push(t[i], gyro[i].tolist(), accel[i].tolist())
        assert ends.next_boundary == (t[3] if i < 3 else t[10] if i < 10 else math.inf)


def test_a_gap_that_ends_many_frames_at_once_is_the_batch():
    """A flagged 3 s gap finishes 30 frames with one sample (more than the frames buffer's first rows)."""
    from imu_ground.imu.preintegration import preintegrate
    t, gyro, accel = _log()
    t = t.copy()
    t[150:] += 3.0
    kw = dict(rate=10.0, max_gap=0.1, on_gap="flag", bias_gyro=[0.01, 0.0, -0.02])
    sp = StreamingPreintegrator(**kw)
    frames = [f for i in range(t.size) for f in sp.push(t[i], gyro[i].tolist(), accel[i].tolist())]
    fd = preintegrate((t, gyro, accel), **kw)
    assert len(frames) == len(fd) > 40 and sum(not f.valid for f in frames) >= 30
    assert np.array_equal(fd.valid, [f.valid for f in frames])
    np.testing.assert_allclose(fd.delta_v, [f.delta_v for f in frames], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fd.delta_R, [f.delta_R for f in frames], rtol=0, atol=1e-14)
