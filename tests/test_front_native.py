"""The compiled live front end (imu/_front_native.c) against its Python twin, and the live path's leftovers.

``StreamingEstimator.push_imu`` runs one C call a sample in the steady state (the sample clock's
retiming, the standstill block sums, the compiled preintegration step) and the standstill windows in
C; the Python path (``push_imu`` with ``streaming._FRONT`` and ``causal_standstill._FRONT`` set to
None) is the reference. They must agree bit for bit: the C is the Python formula term for term
(compiled without FMA contraction), and every case it does not take it leaves to the Python path.
Skipped when the extension is not built (or IMU_GROUND_PURE_PYTHON=1).
"""
from __future__ import annotations

import json
import math
import warnings
from array import array
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from imu_ground._native import FRONT
from imu_ground.imu import causal_standstill
from imu_ground.imu.causal_standstill import StandstillBlocks
from imu_ground.imu.sample_clock import SampleClock
from imu_ground.pipeline import streaming
from imu_ground.pipeline.streaming import StreamingEstimator, replay

EXAMPLE = Path(__file__).resolve().parent.parent / "datasets" / "fixtures" / "example_drive.csv"
native = pytest.mark.skipif(FRONT is None or streaming._FRONT is None,
                            reason="C kernels not built or IMU_GROUND_PURE_PYTHON set")


def _frames_key(frames):
    return [(f.t, f.t_start, f.pitch, f.roll, f.pitch_std, f.roll_std, f.road_grade, f.road_bank, f.valid,
             f.status_code, f.status_reason, f.speed) for f in frames]


def _same(a, b):
    """Equal lists of frame keys, NaN equal to NaN."""
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert all(u == v or (isinstance(u, float) and math.isnan(u) and math.isnan(v)) for u, v in zip(x, y, strict=True)), (x, y)


def _python_front(monkeypatch):
    monkeypatch.setattr(streaming, "_FRONT", None)
    monkeypatch.setattr(causal_standstill, "_FRONT", None)


def _run(t, g, a, speed=None, **kw):
    est = StreamingEstimator(extrinsic="kitti_imu", **kw)
    frames = replay(est, t, g, a, speed)
    return _frames_key(frames), est


# --------------------------------------------------------------------------- the whole front end
@native
def test_compiled_front_equals_python_on_the_timed_drive(shared_data, kitti_index, monkeypatch):
    """The benchmark's drive (jittered KITTI stamps retimed by the clock) and the first of drives.csv, with
    their speed: every frame and the final state bit-identical, and the compiled path taken."""
    from imu_ground.datasets import detect_format, read_imu
    from imu_ground.pipeline.estimate import speed_samples
    names = list(dict.fromkeys(["2011_09_30_drive_0027", kitti_index["drive"].iloc[0]]))
    for name in names:
        path = shared_data / "kitti_imu100" / f"{name}.csv.gz"
        if not path.is_file():
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fmt = detect_format(path)
            imu = read_imu(path, format=fmt, policy="recorded")
            sp = speed_samples("auto", path, fmt, imu)[0]
        calls = []
        real = streaming._front_push
        monkeypatch.setattr(streaming, "_front_push", lambda *x: calls.append(1) or real(*x))  # noqa: B023 (called within this iteration)
        fast, est_c = _run(imu.t, imu.gyro, imu.accel, sp)
        monkeypatch.undo()
        assert len(calls) >= 0.9 * len(imu.t)
        _python_front(monkeypatch)
        slow, est_p = _run(imu.t, imu.gyro, imu.accel, sp)
        monkeypatch.undo()
        _same(fast, slow)
        assert json.dumps(est_c.state_dict()) == json.dumps(est_p.state_dict())


def _messy_stream(seed: int, n: int = 2500):
    """100 Hz samples with jitter, back-steps, repeats, a dropout, a long gap, a clock set back, NaN and
    integers / numpy rows among the floats; a speed at 10 Hz with a hole."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01 + rng.normal(0, 0.002, n)
    t[300:] += 0.35                                      # ahead: retimed, then a dropout after the hold
    t[900:] += 3.0                                       # a gap
    t[1400] = t[1399]                                    # a repeated stamp
    t[1500] = t[1497] - 0.005                            # a back-step
    t[2000:] -= 30.0                                     # the clock set back: a restart
    still = (np.arange(n) // 400) % 2 == 0
    g = np.where(still[:, None], 2e-3 + rng.normal(0, 3e-4, (n, 3)), rng.normal(0, 0.05, (n, 3)))
    a = np.array([0.1, -0.2, 9.80665]) + np.where(still[:, None], rng.normal(0, 0.005, (n, 3)),
                                                     rng.normal(0, 0.4, (n, 3)))
    g[700, 1] = np.nan
    a[1100, 2] = np.inf
    ts = np.arange(0.0, t.max(), 0.1)
    v = 8.0 + np.sin(ts / 5.0)
    v[40:45] = np.nan
    return t, g, a, (ts, v)


@native
@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("policy", ["retime", "drop"])
def test_compiled_front_equals_python_on_messy_streams(seed, policy, monkeypatch):
    t, g, a, sp = _messy_stream(seed)
    fast, est_c = _run(t, g, a, sp, policy=policy)
    _python_front(monkeypatch)
    slow, est_p = _run(t, g, a, sp, policy=policy)
    _same(fast, slow)
    assert len(fast) > 100
    assert json.dumps(est_c.state_dict()) == json.dumps(est_p.state_dict())


@native
def test_compiled_front_equals_python_over_a_clock_set_forward(monkeypatch):
    """A stamp 5,000 s ahead (a clock set forward, more than MAX_GAP_FRAMES frames): the compiled step hands the
    dropout to Python, which restarts the front end; both paths give the same frames, and no gap frames."""
    t, g, a, _ = _messy_stream(3)
    t = t.copy()
    t[2300:] += 5000.0
    fast, est_c = _run(t, g, a)
    _python_front(monkeypatch)
    slow, est_p = _run(t, g, a)
    _same(fast, slow)
    assert json.dumps(est_c.state_dict()) == json.dumps(est_p.state_dict())
    assert 200 < len(fast) < 400                          # 5,000 s of gap frames would be 50,000 more
    assert sum("the clock jumped forward by 5000." in k[10] for k in fast) == 1


@native
def test_compiled_front_takes_odd_argument_types_through_python(monkeypatch):
    """Integers, numpy rows and numpy scalars go to the Python path (its checks), with the same frames."""
    t, g, a, _ = _messy_stream(5)
    mixed = []
    for i in range(len(t)):
        gi, ai = g[i], a[i].tolist()
        if i % 3 == 0:
            gi = gi.tolist()
        elif i % 3 == 1:
            ai = tuple(int(x) if x == x and abs(x) < 1e9 and x == int(x) else x for x in ai)
        mixed.append((np.float64(t[i]) if i % 5 == 0 else float(t[i]), gi, ai))

    def feed():
        est = StreamingEstimator(extrinsic="kitti_imu")
        out = []
        for ti, gi, ai in mixed:
            out += est.push_imu(ti, gi, ai)
        return _frames_key(out + est.flush())
    fast = feed()
    _python_front(monkeypatch)
    _same(fast, feed())


@native
def test_resume_between_compiled_and_python_front(monkeypatch):
    """A state saved with the compiled front end resumes in the Python one (and back) bit-identically."""
    t, g, a, sp = _messy_stream(7)
    whole, _ = _run(t, g, a, sp)
    for cut, (first, second) in ((437, (True, False)), (1711, (False, True))):
        if not first:
            _python_front(monkeypatch)
        est = StreamingEstimator(extrinsic="kitti_imu")
        out = replay_part(est, t[:cut], g[:cut], a[:cut], sp, upto=t[:cut].max())
        state = json.loads(json.dumps(est.state_dict()))
        monkeypatch.undo()
        if not second:
            _python_front(monkeypatch)
        est2 = StreamingEstimator(extrinsic="kitti_imu")
        est2.load_state_dict(state)
        out += replay_part(est2, t[cut:], g[cut:], a[cut:], sp, after=t[:cut].max(), final=True)
        monkeypatch.undo()
        _same(_frames_key(out), whole)


def replay_part(est, t, g, a, sp, upto=math.inf, after=-math.inf, final=False):
    """:func:`replay`'s order for a piece of a stream: speed samples in (after, stamp] before each IMU sample."""
    ts, vs = sp[0].tolist(), sp[1].tolist()
    j = int(np.searchsorted(sp[0], after, side="right"))
    top, out = after, []
    for ti, gi, ai in zip(t.tolist(), g.tolist(), a.tolist(), strict=True):
        top = max(top, ti)
        while j < len(ts) and ts[j] <= top:
            est.push_speed(ts[j], vs[j])
            j += 1
        out += est.push_imu(ti, gi, ai)
    if final:
        while j < len(ts):
            est.push_speed(ts[j], vs[j])
            j += 1
        out += est.flush()
    return out


# --------------------------------------------------------------------------- the pieces
@native
def test_compiled_windows_equal_python():
    rng = np.random.default_rng(11)
    for trial in range(300):
        blocks = StandstillBlocks(10.0)
        n_blocks = int(rng.integers(0, 40))
        quiet = rng.random() < 0.6
        for k in range(n_blocks):
            if rng.random() < 0.05:
                continue                                   # a missing block (a gap)
            for _ in range(int(rng.integers(0, 12))):
                s = 2e-3 if quiet else 0.05
                blocks.add(k, (rng.normal(0, s, 3) + 1e-3).tolist(),
                           (np.array([0, 0, 9.80665]) + rng.normal(0, 4 * s, 3)).tolist())
            if rng.random() < 0.03:
                blocks.open_block(k)                       # an empty block
        for k in range(-2, n_blocks + 2):
            for W, Wb in ((10, 20), (10, 0), (0, 20), (1, 1), (3, 7), (0, 0)):
                assert blocks.windows(k, W, Wb) == blocks.windows_python(k, W, Wb), (trial, k, W, Wb)
    assert FRONT is not None


def test_sample_clock_buffer_round_trip():
    """to_buffer / from_buffer carry every value the compiled push reads and writes."""
    rng = np.random.default_rng(2)
    c = SampleClock("retime")
    for x in np.arange(40) * 0.01 + rng.normal(0, 0.003, 40):
        c.push(float(x))
    b = array("d", bytes(8 * 17))
    c.to_buffer(b)
    d = SampleClock("retime")
    d.from_buffer(b)
    d._steps = list(c._steps)
    assert json.dumps(d.state_dict()) == json.dumps(c.state_dict())
    e = SampleClock("drop")
    e.to_buffer(b)
    assert b[10] == 1.0 and b[6] == e.hold and b[7] == e.gap_factor


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


@native
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), jitter=st.floats(0.0, 0.008), p_back=st.floats(0.0, 0.2),
       p_nan=st.floats(0.0, 0.05), gap=st.floats(0.0, 2.0), policy=st.sampled_from(["retime", "drop"]),
       speed_step=st.sampled_from([1, 5, 10]))
def test_compiled_front_equals_python_on_random_streams(seed, jitter, p_back, p_nan, gap, policy, speed_step):
    rng = np.random.default_rng(seed)
    n = 600
    t = np.arange(n) * 0.01 + rng.normal(0, jitter + 1e-12, n)
    back = rng.random(n) < p_back
    t[back] -= rng.uniform(0, 0.05, back.sum())
    t[n // 2:] += gap
    g = rng.normal(0, 0.02, (n, 3)) + 1e-3
    a = np.array([0.0, 0.0, 9.80665]) + rng.normal(0, 0.05, (n, 3))
    g[rng.random(n) < p_nan, 0] = np.nan
    ts = np.arange(0.0, t.max(), 0.01 * speed_step)
    sp = (ts, 5.0 + np.sin(ts))
    results = []
    for front in (streaming._FRONT, None):
        saved = streaming._FRONT, causal_standstill._FRONT
        streaming._FRONT, causal_standstill._FRONT = front, (front and saved[1])
        try:
            results.append(_run(t, g, a, sp, policy=policy)[0])
        finally:
            streaming._FRONT, causal_standstill._FRONT = saved
    _same(*results)
