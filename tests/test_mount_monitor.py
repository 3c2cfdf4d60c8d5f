"""The mount monitor (one compiled body, ``update`` a frame or ``run`` over a batch): when it raises the alarm,
when it stays silent, and that batches continue a monitor's run (and its saved state) as frame-by-frame updates do.
"""
import json

import numpy as np
import pytest

from imu_ground.filters.mount_monitor import DRIFT_LIMIT, GATE, HOLD_OFF, WINDOW, MountMonitor
from imu_ground.units import DEG


def _stream(monitor: MountMonitor, t, gravity, usable) -> np.ndarray:
    """One ``update`` a frame."""
    has = np.isfinite(gravity).all(axis=1)
    return np.array([monitor.update(float(t[k]), tuple(gravity[k].tolist()) if has[k] else None,
                                    bool(usable[k])) is not None for k in range(len(t))], dtype=bool)


def _assert_same_state(a: MountMonitor, b: MountMonitor) -> None:
    assert json.dumps(a.state_dict()) == json.dumps(b.state_dict())
    assert a.active == b.active


def _sequence(rng: np.random.Generator, n: int, drift_rate: float, step_at: float | None, breaks: int,
              speeding: float = 0.0):
    """Frame times (about 10 Hz, jittered), a gravity that drifts (rad/s, faster by ``speeding`` rad/s^2,
    so that the gate's largest turn is its last) and turns by 1 deg at ``step_at`` (s), and ``breaks``
    runs of frames without gravity or not usable."""
    # jittered, or (speeding) on a grid of exact binary fractions, so that frames fall on the hold-off's,
    # the gate's and the window's ends exactly
    t = np.cumsum(rng.uniform(0.08, 0.12, n)) if speeding == 0.0 else 0.125 * np.arange(1, n + 1)
    axis = rng.normal(size=3)
    axis[2] = 0.0
    axis /= np.linalg.norm(axis)
    angle = drift_rate * t + 0.5 * speeding * t * t + rng.normal(0.0, 2e-4 if speeding == 0.0 else 1e-7, n)
    if step_at is not None:
        angle = angle + np.where(t >= step_at, 1.0 * DEG, 0.0)
    g = 9.81 * (np.cos(angle)[:, None] * np.array([0.0, 0.0, 1.0]) + np.sin(angle)[:, None] * axis)
    g *= rng.uniform(0.999, 1.001, (n, 1))
    usable = np.ones(n, dtype=bool)
    for _ in range(breaks):
        a = int(rng.integers(0, n))
        b = a + int(rng.integers(1, 30))
        if rng.random() < 0.5:
            g[a:b] = np.nan
        else:
            usable[a:b] = False
    return t, g, usable


CASES = [  # (drift rate rad/s, remount time s, breaks, drift speeding up rad/s^2)
    (0.0, 300.0, 0, 0.0), (0.0, None, 0, 0.0), (0.5 * DRIFT_LIMIT / WINDOW, 400.0, 3, 0.0),
    (3.0 * DRIFT_LIMIT / WINDOW, 300.0, 0, 0.0), (0.0, 200.0, 6, 0.0), (1e-6, 700.0, 12, 0.0), (0.0, 100.0, 0, 0.0),
    (0.0, None, 40, 0.0), (0.0, None, 8, 2e-7), (0.0, 500.0, 2, 3e-8),
]


@pytest.mark.parametrize("case", range(len(CASES)))
def test_alarm_after_a_remount_and_silence_while_the_gyro_drifts(case):
    drift_rate, step_at, breaks, speeding = CASES[case]
    t, g, usable = _sequence(np.random.default_rng(case), 9000, drift_rate, step_at, breaks, speeding)
    m = MountMonitor()
    alarm = m.run(t, g, usable)
    assert not alarm.any() or alarm[np.argmax(alarm):].all()            # latched
    if step_at is None:
        assert not alarm.any() and m.alarm is None
    if step_at is not None and drift_rate == 0.0 and breaks == 0 and step_at > HOLD_OFF + GATE + WINDOW:
        k = int(np.argmax(alarm))
        assert alarm.any() and step_at <= t[k] <= step_at + WINDOW
        assert m.alarm_t == t[k] and f"at t = {t[k]:.1f} s" in m.alarm and "turned 1.0 deg" in m.alarm
    if step_at is not None and step_at < HOLD_OFF + GATE:                  # a remount before it judges: no alarm
        assert not alarm.any()
    if drift_rate > DRIFT_LIMIT / WINDOW:
        assert not alarm.any() and m.state_dict()["drift"] > DRIFT_LIMIT   # the silenced monitor


@pytest.mark.parametrize("case", range(len(CASES)))
def test_batches_continue_a_monitors_run_as_the_stream_does(case):
    """Cut anywhere (in the hold-off, the gate, the judging, after the alarm): batch, stream or batch again."""
    drift_rate, step_at, breaks, speeding = CASES[case]
    rng = np.random.default_rng(100 + case)
    t, g, usable = _sequence(rng, 6000, drift_rate, step_at, breaks, speeding)
    whole = MountMonitor().run(t, g, usable)
    broken = np.flatnonzero(~usable | ~np.isfinite(g).all(axis=1))
    cuts = sorted(set(rng.integers(1, len(t) - 1, 20).tolist()) | {int(np.searchsorted(t, HOLD_OFF + GATE / 2))}
                  | set(broken[:3].tolist()) | set((broken[:3] + 1).tolist()) - {0, len(t)})
    a, b = MountMonitor(), MountMonitor()
    got, lo = [], 0
    for hi in [*cuts, len(t)]:
        part = slice(lo, hi)
        got.append(b.run(t[part], g[part], usable[part]))
        _stream(a, t[part], g[part], usable[part])
        _assert_same_state(b, a)
        c = MountMonitor()                          # a saved state resumes the batch too
        c.load_state_dict(json.loads(json.dumps(b.state_dict())))
        _assert_same_state(c, b)
        lo = hi
    np.testing.assert_array_equal(np.concatenate(got), whole)


def test_empty_and_all_broken_batches_keep_the_state():
    a, b = MountMonitor(), MountMonitor()
    t = np.arange(1.0, 200.0, 0.1)
    g = np.tile([0.0, 0.0, 9.81], (len(t), 1)) + np.random.default_rng(0).normal(0.0, 1e-3, (len(t), 3))
    u = np.ones(len(t), dtype=bool)
    u[-5:] = False                                  # a run through its gate, then a break: the drift is kept
    _stream(a, t, g, u)
    b.run(t, g, u)
    assert b.state_dict()["drift"] > 0.0
    for tt, gg, uu in ((t[:0], g[:0], u[:0]), (t + 300.0, g, ~u), (t + 600.0, g * np.nan, u)):
        np.testing.assert_array_equal(b.run(tt, gg, uu), _stream(a, tt, gg, uu))
        _assert_same_state(b, a)
