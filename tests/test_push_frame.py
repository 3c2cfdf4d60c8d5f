"""The live estimator's frame-completing step: the standstill windows in one pass
(:meth:`~imu_ground.imu.live.causal_standstill.StandstillBlocks.frame_windows`), the speed's mean over a frame and
the notes' usual empty case."""
import math

import numpy as np

from imu_ground.imu.live.causal_standstill import StandstillBlocks
from imu_ground.imu.live.sample_clock import SampleClock
from imu_ground.imu.live.speed_buffer import SpeedBuffer


def test_frame_windows_are_the_three_windows():
    rng = np.random.default_rng(5)
    bl = StandstillBlocks(10.0)
    seen = set()
    for k in range(60):
        still = 15 <= k < 45
        for _ in range(10):
            g = rng.normal(0, 0.001 if still else 0.2, 3)
            a = rng.normal(0, 0.01 if still else 1.0, 3) + [0, 0, 9.81]
            bl.add(k, g, a)
        for bias in (True, False):
            got = bl.frame_windows(k, bias)
            want = (*bl.windows(k, bl.W, bl.Wb if bias else 0), bl.windows(k, 1, 0)[0])
            assert got == want, (k, bias)
            seen.add(got)
        bl.done(k)
    assert {(True, True, True), (False, False, False)} <= seen


def _mean_by_intervals(ts, vs, t_start, t_end):
    """The trapezoid mean of the samples over (t_start, t_end], interval by interval (the reference)."""
    a, b = max(t_start, ts[0]), min(t_end, ts[-1])
    total = 0.0
    for t0, t1, v0, v1 in zip(ts, ts[1:], vs, vs[1:], strict=False):
        lo, hi = max(a, t0), min(b, t1)
        if hi > lo:
            slope = (v1 - v0) / (t1 - t0)
            total += (hi - lo) * (v0 + 0.5 * slope * ((lo - t0) + (hi - t0)))
    return total / (t_end - t_start)


def test_speed_mean_over_a_frame():
    rng = np.random.default_rng(2)
    sp = SpeedBuffer()
    ts = np.cumsum(rng.uniform(0.005, 0.03, 80)).tolist()
    vs = rng.uniform(0, 20, 80).tolist()
    for t, v in zip(ts, vs, strict=True):
        sp.push(t, v)
    for t_start, t_end in ((ts[3], ts[10]), (ts[3] + 0.001, ts[10] - 0.002), (ts[0], ts[-1]), (ts[5], ts[5] + 1e-4)):
        assert sp.mean(t_start, t_end) == _mean_by_intervals(ts, vs, t_start, t_end)
    assert math.isnan(sp.mean(ts[0] - 1.0, ts[4])) and math.isnan(sp.mean(ts[4], ts[-1] + 1.0))
    assert sp.take_notes() == []
    sp.push(ts[-1], 1.0)                                 # a repeated time: said once
    assert sp.take_notes() == ["1 repeated-time speed sample(s) ignored"] and sp.take_notes() == []


def test_clock_notes_empty_then_said_once():
    c = SampleClock()
    for i in range(40):
        c.push(i * 0.01)
    c.take_notes()
    assert c.take_notes() == []
    c.push(0.2)                                          # a step back: retimed
    notes = c.take_notes()
    assert notes and c.take_notes() == []


def test_finished_motion_is_finished_frames():
    from imu_ground.imu.preintegration import StreamingPreintegrator
    rng = np.random.default_rng(7)
    pre = StreamingPreintegrator(rate=10.0, t_origin=0.0, max_gap=0.1, on_gap="flag", uncertainty=False)
    seen = 0
    for i in range(1, 300):
        t = i * 0.01 + (0.3 if i > 150 else 0.0)         # a gap: a frame not valid
        frames = pre.push(t, rng.normal(0, 0.1, 3), rng.normal(0, 1, 3) + [0, 0, 9.8])
        motion = pre.finished_motion(len(frames))
        for f, (dR, dv, dt, ts, te, valid) in zip(frames, motion, strict=True):
            assert (dR == f.delta_R).all() and (dv == f.delta_v).all() and dt == f.delta_t
            assert (ts, te, valid) == (f.t_start, f.t_end, f.valid) and type(valid) is bool
            seen += 1
    assert seen > 25


def test_finished_motion_is_what_push_gives_and_push_counted_counts_it():
    """``push_counted`` + ``finished_motion`` (the live path) against ``push``'s measurements, sample by sample,
    through a gap (a frame of several pieces) and the frames buffer growing."""
    from imu_ground.imu.preintegration import StreamingPreintegrator
    rng = np.random.default_rng(8)
    t = np.cumsum(rng.uniform(0.008, 0.012, 900))
    t[400:] += 2.0                                     # a gap: 20 frames finish at one sample (16 rows held)
    g, a = rng.normal(0, 0.1, (900, 3)), rng.normal(0, 1.0, (900, 3)) + [0, 0, 9.81]
    one, two = (StreamingPreintegrator(rate=10.0, t_origin=float(t[0]), on_gap="flag") for _ in range(2))
    frames, most = 0, 0
    for i in range(900):
        want = one.push(t[i], g[i], a[i])
        n = two.push_counted(t[i], g[i], a[i])
        assert n == len(want)
        for f, (dR, dv, dt, t0, t1, valid) in zip(want, two.finished_motion(n), strict=True):
            assert np.array_equal(dR, f.delta_R) and np.array_equal(dv, f.delta_v)
            assert (dt, t0, t1, valid) == (f.delta_t, f.t_start, f.t_end, f.valid)
        frames, most = frames + n, max(most, n)
    assert frames > 80 and most > 16
