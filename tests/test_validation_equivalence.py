"""The validation's fast paths against straightforward references, bit for bit.

The references below are the plain whole-array forms of each step (the
running maximum of the stamps, the padded window median, the retime fit as it
was written before it ran block by block, einsum norms, ``np.median``); the
inputs are jittered stamps with bumps, dropouts, duplicates and backsteps.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from imu_ground.datasets.order_stats import _running_median, median
from imu_ground.datasets.retime import _Clock, _seq_sum, retime
from imu_ground.datasets.timestamps import _ooo_dup, check_timestamps
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


def ref_retime(t, index=None, window_s=2.0, min_inliers=0.95):
    """The retime fit on whole arrays: (t or None, rate, breaks, note)."""
    t = np.asarray(t, dtype=float)
    k = np.arange(t.size, dtype=float) if index is None else np.asarray(index, dtype=float)
    none = np.zeros(0, dtype=np.int64)
    nan = float("nan")
    if t.size < 10:
        return None, nan, none, "fewer than 10 samples"
    steps = np.diff(t) if index is None else np.diff(t) / np.maximum(np.diff(k), 1.0)
    sub = steps[:: max(1, steps.size // 200_000)]
    pos = sub[sub > 0]
    if pos.size < sub.size // 2:
        return None, nan, none, "most time steps are not positive"
    dt = float(np.median(pos))
    w = int(min(max(21, round(window_s / dt) | 1), (t.size // 2) | 1))
    off = (t - t[0]) * (1.0 / dt) - k
    events = np.flatnonzero(np.abs(np.diff(off)) > 0.5)
    level, near = ref_running_median(off, w, events)
    j = near[near < t.size - 1]
    jump = level[j + 1] - level[j]
    if np.any(jump < -1.0):
        return None, 1.0 / dt, none, ("more samples than the stamps' time span in a stretch "
                                      "(the sample count disagrees with a steady rate)")
    breaks = j[jump > 1.0] + 1
    seg = np.zeros(t.size, dtype=np.int64)
    seg[breaks] = 1
    seg = np.cumsum(seg)
    inl = np.abs(off - level) < 0.5
    n_seg = int(seg[-1]) + 1
    cnt = np.bincount(seg[inl], minlength=n_seg)
    fit = inl & (cnt[seg] >= 2)
    if fit.sum() < t.size // 2:
        return None, 1.0 / dt, none, (f"only {inl.mean():.0%} of the stamps lie within half a "
                                      f"sample of a steady {1 / dt:.6g} Hz clock")
    sf = seg[fit]
    cf = np.bincount(sf, minlength=n_seg)
    km = np.bincount(sf, k[fit], n_seg) / np.maximum(cf, 1)
    tm = np.bincount(sf, t[fit], n_seg) / np.maximum(cf, 1)
    dk = k[fit] - (km[0] if n_seg == 1 else km[sf])
    dtt = t[fit] - (tm[0] if n_seg == 1 else tm[sf])
    slope = float(np.dot(dk, dtt) / np.dot(dk, dk))
    if not (slope > 0 and 1.0 <= 1.0 / slope <= 1e5):
        return None, 1.0 / dt, none, "no steady positive rate"
    icpt = tm - slope * km
    for s in np.flatnonzero(cf == 0):
        icpt[s] = float(np.median(t[seg == s] - slope * k[seg == s]))
    out = slope * k + (icpt[0] if n_seg == 1 else icpt[seg])
    agree = float(np.mean(np.abs((out - t[0]) * (1.0 / dt) - k - level) < 1.0))
    if agree < min_inliers:
        return None, 1.0 / slope, none, (f"the stamps follow the sample clock within a sample "
                                         f"over only {agree:.0%} of the log")
    if np.any(np.diff(out) <= 0):
        return None, 1.0 / slope, none, "stretches between dropouts overlap"
    return out, 1.0 / slope, breaks, ""


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


def test_sequential_sum_is_bincounts():
    rng = np.random.default_rng(1)
    for n in (1, 7, 40_000, 100_003):
        x = rng.uniform(-1e4, 1e5, n)
        want = np.bincount(np.zeros(n, dtype=np.int64), x, 1)[0]
        got = _seq_sum(x.copy())
        assert got == want
        acc = 0.0
        for v in x[:2000].tolist():                                   # and a plain loop, left to right
            acc += v
        assert _seq_sum(x[:2000].copy()) == acc


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
    steps = np.diff(t)
    back, ooo, dup = ref_order(t)
    zero = np.flatnonzero(steps == 0) + 1
    for finite in (True, False):
        got_ooo, got_dup = _ooo_dup(t, steps, back, zero, finite)
        assert np.array_equal(got_ooo, ooo) and np.array_equal(got_dup, dup)
    keep, _, rep = check_timestamps(t, "drop", warn=False)
    assert np.array_equal(rep.backstep_index, back) and np.array_equal(rep.out_of_order_index, ooo)
    assert np.array_equal(rep.duplicate_index, dup)
    assert np.array_equal(keep, np.setdiff1d(np.arange(n), np.union1d(ooo, dup)))


def test_order_checks_with_non_finite_stamps():
    t = np.array([0.0, 0.01, np.nan, 0.03, 0.02, 0.02, np.inf, 0.05, 0.05])
    steps = np.diff(t)
    back, ooo, dup = ref_order(t)
    with np.errstate(invalid="ignore"):
        got = _ooo_dup(t, steps, back, np.flatnonzero(steps == 0) + 1, False)
    assert np.array_equal(got[0], ooo) and np.array_equal(got[1], dup)


# --------------------------------------------------------------------------- retime
@pytest.mark.parametrize("seed", range(4))
def test_offset_events_from_raw_steps(seed):
    """Events found from the raw steps (the shortcut) are those of the offset's own steps, near 0.5 and 1.5 too."""
    rng = np.random.default_rng(seed)
    n, dt = 200_000, 0.01
    steps = np.full(n - 1, dt) + rng.normal(0, 1e-5, n - 1)
    odd = rng.integers(0, n - 1, 3000)
    steps[odd] = dt * rng.choice([0.5, 1.5, -1.0, 3.0], odd.size) + rng.normal(0, 1e-9, odd.size) * rng.choice(
        [0.0, 1.0, 1e3], odd.size)                                 # at, about and near either side of a half sample
    t = np.concatenate([[1.6e9 * (seed % 2)], steps]).cumsum()
    raw = t[1:] - t[:-1]
    clock = _Clock(t, None, dt)
    assert clock.shortcuts()
    want = np.flatnonzero(np.abs(np.diff((t - t[0]) * (1.0 / dt) - np.arange(n))) > 0.5)
    assert np.array_equal(clock.events(raw), want)
    assert np.array_equal(clock.events(None), want)
    assert want.size > 1000


def assert_retime_equal(t, index=None, **kw):
    want_t, want_rate, want_breaks, want_note = ref_retime(t, index, **kw)
    got = retime(t, index, **kw)
    assert got.note == want_note
    assert same_float(float(got.rate), float(want_rate))
    assert np.array_equal(got.breaks, want_breaks)
    assert (got.t is None) == (want_t is None)
    if want_t is not None:
        assert np.array_equal(got.t, want_t)
    return got


@pytest.mark.parametrize("seed", range(10))
def test_retime_matches_the_whole_array_fit(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.choice([500, 5000, 70_000]))
    t = jittered(rng, n, jitter=float(rng.choice([2e-5, 1e-3])), bumps=int(rng.integers(0, 40)),
                 dropouts=int(rng.integers(0, 4)), dups=int(rng.integers(0, 5)), backsteps=int(rng.integers(0, 3)))
    assert_retime_equal(t)
    assert_retime_equal(t, window_s=0.5)
    index = np.arange(n) + (np.arange(n) >= n // 2)                   # a row left out half way
    assert_retime_equal(t, index)


def test_retime_notes_match():
    rng = np.random.default_rng(3)
    notes = set()
    cases = [np.arange(8) * 0.01,                                     # too short
             np.sort(rng.uniform(0, 10, 2000)),                       # no steady rate
             -np.arange(2000) * 0.01,                                 # steps not positive
             np.arange(2000) * 2.0,                                   # 0.5 Hz: no plausible rate
             np.r_[np.arange(1000) * 0.01, np.arange(1000) * 0.01 + 3.0]]  # a stretch back in time
    t = jittered(rng, 3000, jitter=0.004)                             # stamps too loose to follow
    cases.append(t)
    for t in cases:
        notes.add(assert_retime_equal(t).note.split(" ")[0])
    assert len(notes) >= 4


@pytest.mark.parametrize("seed", range(2))
def test_check_timestamps_retimes_as_the_whole_array_fit(seed):
    """check_timestamps hands retime the raw steps (its shortcuts); the result is the plain fit's."""
    rng = np.random.default_rng(10 + seed)
    n = 100_000
    t = jittered(rng, n, bumps=200, dropouts=2, dups=5, backsteps=5)
    keep, t_out, rep = check_timestamps(t, "retime", warn=False)
    want_t, want_rate, want_breaks, _ = ref_retime(t)
    assert rep.retimed and np.array_equal(t_out, want_t) and np.array_equal(keep, np.arange(n))
    assert rep.retime_rate == want_rate and np.array_equal(rep.retime_dropout_index, want_breaks)
    shift = want_t - t
    assert rep.retime_shift_max == float(np.abs(shift).max())
    assert rep.retime_shift_rms == float(np.sqrt(np.mean(shift ** 2)))
    dk = np.diff(want_t)
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
