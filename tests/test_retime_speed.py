"""Retiming's running median (datasets/order_stats.py) against its definition, windows at the ends included."""
import numpy as np
import pytest
from imu_ground.datasets.order_stats import _running_median
from imu_ground.datasets.timestamps import retime


@pytest.mark.parametrize("seed", range(12))
def test_running_median_is_the_padded_window_median_near_events(seed):
    rng = np.random.default_rng(seed)
    n, w = int(rng.integers(30, 800)), int(rng.integers(1, 40)) * 2 + 1
    h = w // 2
    x = rng.normal(size=n).round(1)
    events = np.unique(np.concatenate([[0, n - 2], rng.integers(0, n - 1, int(rng.integers(0, 12)))]))
    level, near = _running_median(x, w, events)
    want_near = np.array([p for p in range(n) if any(e - h - 1 <= p < e + h + 2 for e in events)])
    assert np.array_equal(near, want_near)
    padded = np.pad(x, h, mode="edge")
    for p in range(n):
        assert level[p] == (np.median(padded[p:p + w]) if p in set(want_near) else x[p])


def test_one_stretch_and_several_give_the_same_clock_where_they_agree():
    rng = np.random.default_rng(3)
    t = np.arange(5000) * 0.01 + rng.uniform(-1e-4, 1e-4, 5000)
    t[700:705] -= 0.05                                          # jitter: one bump
    one = retime(t)
    t2 = t.copy()
    t2[3000:] += 1.7                                            # a real dropout: a second stretch
    two = retime(t2)
    assert one.t is not None and two.t is not None
    assert one.breaks.size == 0 and np.array_equal(two.breaks, [3000])
    assert np.all(np.diff(one.t) > 0) and np.allclose(np.diff(one.t), 1 / one.rate)
    assert np.allclose(two.t[:3000], one.t[:3000], atol=1e-3)
