"""Batch preintegration (imu/preint_batch.py) gathered chunk by chunk: the chunk size changes no delta."""
import numpy as np
import pytest

from imu_ground.imu import preint_batch
from imu_ground.imu.preint_batch import preintegrate

#: Per-block scans and cumulative sums: bit-identical whatever the chunk.
EXACT = ("delta_t", "delta_R", "delta_v", "delta_p", "valid", "n_intervals")
#: Sums over a block's intervals, whose rounding may follow the chunk's width.
SUMS = ("covariance", "d_R_d_bg", "d_v_d_bg", "d_p_d_bg", "d_v_d_ba", "d_p_d_ba")


def _log(n: int = 3000, seed: int = 5):
    """100 Hz with jittered stamps and one 0.4 s dropout; gyro rad/s, specific force m/s^2."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01 + rng.uniform(-2e-3, 2e-3, n)
    t[1500:] += 0.4
    gyro = rng.normal(0, 0.2, (n, 3))
    accel = rng.normal(0, 1.0, (n, 3)) + [0, 0, 9.81]
    return t, gyro, accel


@pytest.mark.parametrize("options", [{"rate": 7.3, "uncertainty": True},
                                     {"rate": 10.0, "uncertainty": False, "hold": "left"},
                                     {"every": 9, "uncertainty": True, "bias_accel": [0.1, -0.2, 0.05]}])
def test_chunk_size_changes_nothing(options, monkeypatch):
    imu = _log()
    kw = {"on_gap": "flag", "max_gap": 0.1, "bias_gyro": [0.01, -0.02, 0.003], **options}
    whole = preintegrate(imu, **kw)
    monkeypatch.setattr(preint_batch, "_CHUNK", 40)
    small = preintegrate(imu, **kw)
    assert not whole.valid.all()                               # the dropout's frame is flagged
    for f in EXACT:
        assert np.array_equal(getattr(whole, f), getattr(small, f)), f
    for f in SUMS:
        a, b = getattr(whole, f), getattr(small, f)
        assert (a is None) == (b is None) == (not options["uncertainty"]), f
        if a is not None:
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15 * np.abs(a).max(), err_msg=f)


def test_the_dropout_flags_exactly_the_frames_it_falls_in():
    t, gyro, accel = _log()
    fd = preintegrate((t, gyro, accel), rate=10.0, on_gap="flag", max_gap=0.1, uncertainty=False)
    gap_start, gap_end = t[1499], t[1500]
    crosses = (fd.t_start < gap_end) & (fd.t_end > gap_start)
    assert crosses.sum() >= 1
    assert np.array_equal(~fd.valid, crosses)


def _valid_by_knot_intervals(t, T, snap_tol, max_gap):
    """Reference for the gap rule: each knot interval's sample interval, one by one (no shared code)."""
    bounds = []
    for x in T:
        j = int(np.argmin(np.abs(t - x)))
        if abs(t[j] - x) <= snap_tol:
            bounds.append(("sample", j))
        else:
            bounds.append(("insert", x))
    pos = []
    kt_all = sorted([(x, 1, i) for i, x in enumerate(t)] + [(x, 0, -1) for kind, x in bounds if kind == "insert"])
    sample_of_knot = []
    last = -1
    for _x, is_s, i in kt_all:
        if is_s:
            last = i
        sample_of_knot.append(last)
    times = [x for x, _, _ in kt_all]
    for kind, v in bounds:
        pos.append(times.index(t[v]) if kind == "sample" else times.index(v))
    valid = []
    for f in range(len(T) - 1):
        valid.append(not any(t[sample_of_knot[j] + 1] - t[sample_of_knot[j]] > max_gap
                             for j in range(pos[f], pos[f + 1])))
    return np.array(valid)


@pytest.mark.parametrize("seed", range(6))
def test_frames_across_gaps_are_flagged_as_knot_by_knot(seed):
    rng = np.random.default_rng(seed)
    n = 600
    dt = np.full(n - 1, 0.01) * rng.uniform(0.8, 1.2, n - 1)
    dt[rng.choice(n - 1, 8, replace=False)] = rng.uniform(0.12, 0.6, 8)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    gyro, accel = rng.normal(0, 0.1, (n, 3)), rng.normal(0, 1, (n, 3)) + [0, 0, 9.8]
    for T in (np.linspace(t[0], t[-1], 37), np.concatenate([t[::9], [t[-1]]]) if (n - 1) % 9 else t[::9],
              np.sort(np.concatenate([[t[0], t[-1]], rng.choice(t[1:-1], 30, replace=False)]))):
        T = np.unique(T)
        fd = preintegrate((t, gyro, accel), T, max_gap=0.1, on_gap="flag", uncertainty=False)
        ref = _valid_by_knot_intervals(t, T, 1e-9, 0.1)
        assert np.array_equal(fd.valid, ref) and not ref.all()
        with pytest.raises(ValueError, match="gap"):
            preintegrate((t, gyro, accel), T, max_gap=0.1, on_gap="raise", uncertainty=False)
