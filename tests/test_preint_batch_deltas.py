"""The batch preintegration's deltas (imu/preint_frames.py): the streaming step over the log.

With or without ``uncertainty`` the deltas are the same on synthetic logs over every branch (small
and large rotations, both holds, boundaries between samples, long frames, gaps, biases), and they
are the streaming preintegrator's frames.
"""
from __future__ import annotations

import numpy as np
import pytest

from imu_ground.imu import preint_frames as pb
from imu_ground.imu.live.preint_stream import StreamingPreintegrator

FIELDS = ("t_start", "t_end", "delta_t", "delta_R", "delta_v", "delta_p", "valid", "n_intervals")


def _log(seed: int, n: int = 4000, rate: float = 100.0, scale: float = 1.0):
    """(t, gyro, accel): jittered stamps with two gaps, rates from zero (series branch) to several rad/s."""
    rng = np.random.default_rng(seed)
    dt = np.full(n - 1, 1.0 / rate) * rng.uniform(0.7, 1.3, n - 1)
    dt[[n // 4, n // 2]] = [0.35, 1.2]
    t = 50.0 + np.concatenate([[0.0], np.cumsum(dt)])
    gyro = rng.normal(0.0, 0.3, (n, 3)) * scale
    gyro[: n // 5] = 0.0                                # zero rotation: the series branch exactly
    gyro[n // 5: n // 4] *= 1e-6                        # tiny rotations
    gyro[-200:] *= 20.0                                 # fast spins
    accel = rng.normal(0.0, 1.0, (n, 3)) + np.array([0.2, -0.1, 9.81])
    return t, gyro, accel


def _both(*args, **kw):
    """The deltas-only frames and the frames with uncertainty."""
    return pb.preintegrate(*args, uncertainty=False, **kw), pb.preintegrate(*args, uncertainty=True, **kw)


def _assert_same(c, p):
    for f in FIELDS:
        a, b = np.asarray(getattr(c, f)), np.asarray(getattr(p, f))
        assert a.shape == b.shape and a.dtype == b.dtype, f
        if a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=f)
        else:
            assert np.array_equal(a, b), f
    assert c.covariance is None and p.covariance is not None


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("hold", ["midpoint", "left"])
@pytest.mark.parametrize("frames", ["rate10", "rate3.7", "every7", "explicit"])
def test_the_deltas_do_not_depend_on_the_uncertainty(seed, hold, frames):
    t, gyro, accel = _log(seed)
    kw = dict(hold=hold, on_gap="flag", max_gap=0.1, bias_gyro=[0.01, -0.02, 0.005], bias_accel=[0.1, 0.0, -0.05])
    if frames.startswith("rate"):
        kw["rate"] = float(frames[4:])
    elif frames == "every7":
        kw["every"] = 7
    else:                                               # uneven frames, one of them long (several blocks)
        rng = np.random.default_rng(seed + 10)
        inner = np.sort(rng.uniform(t[0], t[-1], 60))
        inner = inner[(inner > t[0] + 5.0) | (inner < t[0] + 0.5)]
        kw["frame_times"] = np.concatenate([[t[0]], inner, [t[-1]]])
        kw["frame_times"] = kw["frame_times"][np.concatenate([[True], np.diff(kw["frame_times"]) > 0.05])]
    c, p = _both((t, gyro, accel), **kw)
    _assert_same(c, p)
    assert not c.valid.all() and c.valid.any()          # the gaps flagged, the rest kept


@pytest.mark.parametrize("hold", ["midpoint", "left"])
def test_the_batch_deltas_are_the_streaming_frames(hold):
    """Frames on samples (every N): the batch runs the streaming step over the same samples, so the two agree
    to the bit but for the rotation matrix's normalisation (numpy's norm against math.sqrt)."""
    t, gyro, accel = _log(3, n=2000)
    kw = dict(hold=hold, on_gap="flag", max_gap=0.1, bias_gyro=[0.01, -0.02, 0.005], bias_accel=[0.1, 0.0, -0.05])
    fd = pb.preintegrate((t, gyro, accel), every=9, uncertainty=False, **kw)
    sp = StreamingPreintegrator(every=9, uncertainty=False, **kw)
    frames = [f for i in range(t.size) for f in sp.push(t[i], gyro[i].tolist(), accel[i].tolist())]
    n = fd.delta_t.size
    assert n > 200 and len(frames) >= n
    frames = frames[:n]
    assert np.array_equal(fd.delta_v, [f.delta_v for f in frames])
    assert np.array_equal(fd.delta_p, [f.delta_p for f in frames])
    assert np.array_equal(fd.delta_t, [f.delta_t for f in frames])
    assert np.array_equal(fd.valid, [f.valid for f in frames])
    np.testing.assert_allclose(fd.delta_R, [f.delta_R for f in frames], rtol=0, atol=4e-16)
