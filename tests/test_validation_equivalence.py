"""The validation's fast paths against straightforward references, bit for bit.

The references below are the plain whole-array forms of each step (the
running maximum of the stamps, the padded window median, einsum norms,
``np.median``); the inputs are jittered stamps with bumps, dropouts,
duplicates and backsteps.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from imu_ground.datasets.order_stats import _running_median, median
from imu_ground.datasets.retime import retime
from imu_ground.datasets.timestamps import check_timestamps
from imu_ground.datasets.validation import _RowStats, _sqrt_below, validate

from imu_ground.imu.data import ImuData


# --------------------------------------------------------------------------- references
def ref_order(t):
    """Backsteps, out-of-order and duplicate positions from the running maximum of the stamps."""
    steps = np.diff(t)
    prev_max = np.maximum.accumulate(t)[:-1]
    return (np.flatnonzero(steps < 0) + 1, np.flatnonzero(t[1:] < prev_max) + 1,
            np.flatnonzero(t[1:] == prev_max) + 1)


def ref_running_median(x, w, events):
    """Medians of the edge-padded windows centred within ``w // 2 + 1`` of an event (else ``x``)."""
    h = w // 2
    mark = np.zeros(x.size + 1, dtype=np.int64)
    for e in np.asarray(events).tolist():
        mark[max(e - h - 1, 0)] += 1
        mark[min(e + h + 2, x.size)] -= 1
    near = np.flatnonzero(np.cumsum(mark)[:-1] > 0)
    out = x.copy()
    win = np.lib.stride_tricks.sliding_window_view(np.pad(x, h, mode="edge"), w)
    for i in range(0, near.size, 2048):
        out[near[i:i + 2048]] = np.median(win[near[i:i + 2048]], axis=1)
    return out, near


def jittered(rng, n, dt=0.01, jitter=2e-5, bumps=8, dropouts=1, dups=3, backsteps=3):
    """Steady samples whose stamps jitter, jump ahead and back (bumps), drop out, repeat and step back."""
    t = np.arange(n) * dt + rng.normal(0, jitter, n)
    for s in rng.integers(0, n - 40, bumps):                        # KITTI-like: ahead, then back
        t[s:s + int(rng.integers(2, 30))] -= dt * float(rng.choice([5.0, 3.0, -2.5]))
    for s in rng.integers(1, n, dropouts):
        t[s:] += dt * float(rng.choice([1.7, 3.0, 40.0]))
    for i in rng.integers(1, n, dups):
        t[i] = t[i - 1]
    for i in rng.integers(1, n, backsteps):
        t[i] = t[i - 1] - dt * float(rng.uniform(0.1, 3))
    return t


def same_float(a, b):
    return type(a) is type(b) and (a == b or (np.isnan(a) and np.isnan(b)))


# --------------------------------------------------------------------------- order statistics
@pytest.mark.parametrize("seed", range(6))
def test_median_is_numpys_median(seed):
    rng = np.random.default_rng(seed)
    for n in (3, 65_535, 65_536, 200_001, 300_000):
        for x in (rng.normal(size=n), rng.integers(0, 5, n).astype(float), np.full(n, 0.01),
                  np.sort(rng.exponential(size=n)), np.repeat(rng.normal(size=4), -(-n // 4))[:n]):
            assert same_float(median(x), float(np.median(x)))
            ax = np.abs(x)
            assert same_float(median(ax, sqrt=True), float(np.median(np.sqrt(ax))))
    x = rng.normal(size=100_000)
    x[77] = np.nan
    assert np.isnan(median(x))


@pytest.mark.parametrize("seed", range(4))
def test_running_median_matches_window_by_window(seed):
    rng = np.random.default_rng(seed)
    for w in (3, 5, 21, 201):
        n = int(rng.integers(w, 3000))
        x = rng.normal(size=n).round(int(rng.integers(0, 3)))        # ties too
        events = np.unique(rng.integers(0, n - 1, int(rng.integers(1, 30))))
        level, near = _running_median(x, w, events)
        want, want_near = ref_running_median(x, w, events)
        assert np.array_equal(near, want_near)
        assert np.array_equal(level, want)
    x = rng.normal(size=500)
    x[250] = np.nan                                                   # np.median's NaN, window by window
    level, _ = _running_median(x, 21, np.array([245]))
    assert np.array_equal(level, ref_running_median(x, 21, [245])[0], equal_nan=True)


# --------------------------------------------------------------------------- time order
@pytest.mark.parametrize("seed", range(8))
def test_order_checks_match_the_running_maximum(seed):
    rng = np.random.default_rng(seed)
    n = 20_000
    t = jittered(rng, n, bumps=int(rng.integers(0, 60)), dups=20, backsteps=20)
    if seed % 2:
        t[-3:] = t[-4] - 1.0                                          # never caught up again
    if seed % 3 == 0:
        t[rng.integers(1, n, 40)] = t[0] - 5.0                        # far back: long stretches
    back, ooo, dup = ref_order(t)
    keep, _, rep = check_timestamps(t, "drop", warn=False)
    assert np.array_equal(rep.backstep_index, back) and np.array_equal(rep.out_of_order_index, ooo)
    assert np.array_equal(rep.duplicate_index, dup)
    assert np.array_equal(keep, np.setdiff1d(np.arange(n), np.union1d(ooo, dup)))


def test_order_checks_with_non_finite_stamps():
    t = np.array([0.0, 0.01, np.nan, 0.03, 0.02, 0.02, np.inf, 0.05, 0.05])
    back, ooo, dup = ref_order(t)
    with np.errstate(invalid="ignore"):
        _, _, rep = check_timestamps(t, "drop", warn=False)
    assert np.array_equal(rep.out_of_order_index, ooo) and np.array_equal(rep.duplicate_index, dup)


# --------------------------------------------------------------------------- retime
def test_retime_notes():
    rng = np.random.default_rng(3)
    cases = [np.arange(8) * 0.01,                                     # too short
             np.sort(rng.uniform(0, 10, 2000)),                       # no steady rate
             -np.arange(2000) * 0.01,                                 # steps not positive
             np.arange(2000) * 2.0,                                   # 0.5 Hz: no plausible rate
             np.r_[np.arange(1000) * 0.01, np.arange(1000) * 0.01 + 3.0],  # a stretch back in time
             jittered(rng, 3000, jitter=0.004)]                       # stamps too loose to follow
    notes = set()
    for t in cases:
        got = retime(t)
        assert got.t is None and got.breaks.size == 0
        notes.add(got.note.split(" ")[0])
    assert len(notes) >= 4


@pytest.mark.parametrize("seed", range(2))
def test_check_timestamps_retimes_as_retime(seed):
    """check_timestamps' report holds the retime fit, its shift from the stamps and the gaps of its steps."""
    rng = np.random.default_rng(10 + seed)
    n = 100_000
    t = jittered(rng, n, bumps=200, dropouts=2, dups=5, backsteps=5)
    keep, t_out, rep = check_timestamps(t, "retime", warn=False)
    want = retime(t)
    assert want.t is not None and float(np.median(np.abs(want.t - t))) < 1e-4
    assert rep.retimed and np.array_equal(t_out, want.t) and np.array_equal(keep, np.arange(n))
    assert rep.retime_rate == want.rate and np.array_equal(rep.retime_dropout_index, want.breaks)
    shift = want.t - t
    assert rep.retime_shift_max == float(np.abs(shift).max())
    assert rep.retime_shift_rms == float(np.sqrt(np.mean(shift ** 2)))
    dk = np.diff(want.t)
    assert rep.median_step == float(np.median(dk))
    assert np.array_equal(rep.gap_out_index, np.flatnonzero(dk > 5.0 * float(np.median(dk))))


# --------------------------------------------------------------------------- units
def test_rest_bound_is_exact():
    rng = np.random.default_rng(2)
    for limit in (0.05, 1e-3, 0.1, 7.0, 1e5):
        s = _sqrt_below(limit)
        x = limit * limit * (1 + rng.normal(0, 1e-15, 20_000))      # right at the boundary
        x = np.concatenate([x, np.nextafter(s, [-np.inf, np.inf]), [s]])
        assert np.array_equal(np.sqrt(x) < limit, x < s)
    assert _sqrt_below(0.0) is None and _sqrt_below(np.inf) is None and _sqrt_below(np.nan) is None


@pytest.mark.parametrize("seed", range(3))
def test_row_stats_and_units_match_the_norms(seed):
    rng = np.random.default_rng(seed)
    n = 90_000
    g = rng.normal(0, 0.04, (n, 3))
    a = rng.normal(0, 0.3, (n, 3)) + [0.0, 0.0, 9.81]
    gn, an = np.sqrt(np.einsum("ij,ij->i", g, g)), np.sqrt(np.einsum("ij,ij->i", a, a))
    st = _RowStats(g, a, _sqrt_below(0.05))
    assert float(np.sqrt(st.top)) == float(gn.max())
    assert np.array_equal(np.sqrt(st.rest_accel), an[gn < 0.05])
    t = jittered(rng, n, bumps=30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, rep = validate(ImuData(t, g, a, source="x.csv"))
    assert rep.gyro_max_norm == float(gn.max())
    assert rep.accel_median_norm == float(np.median(an[gn < 0.05]))
    assert rep.accel_norm_at_rest
