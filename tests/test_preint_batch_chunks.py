"""Batch preintegration (imu/preint_frames.py): the frames a timestamp gap flags."""
import numpy as np
import pytest

from imu_ground.imu.preint_batch import preintegrate

def _log(n: int = 3000, seed: int = 5):
    """100 Hz with jittered stamps and one 0.4 s dropout; gyro rad/s, specific force m/s^2."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01 + rng.uniform(-2e-3, 2e-3, n)
    t[1500:] += 0.4
    gyro = rng.normal(0, 0.2, (n, 3))
    accel = rng.normal(0, 1.0, (n, 3)) + [0, 0, 9.81]
    return t, gyro, accel


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
