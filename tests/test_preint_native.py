"""The C preintegration kernel and streaming fast path (imu/_preint_native.c) against their Python twins.

Held to the twin rule (:func:`imu_ground._native.assert_twins_equal`): the C kernel is the
Python one term for term, compiled without FMA contraction. Skipped when the extension is not built
(or IMU_GROUND_PURE_PYTHON=1).
"""
from __future__ import annotations

import gc
import math
import sys
import tracemalloc

import numpy as np
import pytest

from imu_ground._native import assert_twins_equal
from imu_ground.imu import preint_kernel, preint_stream
from imu_ground.imu.preint_kernel import (
    DELTAS_IDENTITY,
    UNCERTAINTY_ZERO,
    integrate_interval_python,
)
from imu_ground.imu.preint_stream import StreamingPreintegrator, _PythonKernel

NATIVE = preint_kernel.NATIVE
pytestmark = pytest.mark.skipif(NATIVE is None, reason="C kernels not built or IMU_GROUND_PURE_PYTHON set")

NOISE = (1e-4, 1e-2)


def _intervals(rng, n):
    """Rotation increments over the kernel's branches: zero, tiny (series), small, large (up to ~pi)."""
    scales = (0.0, 1e-9, 1e-5, 1e-3, 0.05, 1.0, 3.0)
    for i in range(n):
        phi = rng.normal(size=3) * scales[i % len(scales)]
        if i % 11 == 0:
            phi = np.array([np.pi - 1e-7, 0.0, 0.0]) * (-1) ** i
        yield float(rng.uniform(1e-4, 0.05)), phi.tolist(), (rng.normal(size=3) * 3.0).tolist()


@pytest.mark.parametrize("with_u", [True, False])
@pytest.mark.parametrize("noise", [NOISE, (0.0, 0.0), (1e-4, 0.0)])
def test_kernel_equals_python_over_every_branch(with_u, noise):
    rng = np.random.default_rng(3)
    s_py = s_c = DELTAS_IDENTITY
    u_py = u_c = UNCERTAINTY_ZERO if with_u else None
    for dt, phi, f in _intervals(rng, 700):
        s_py, u_py = integrate_interval_python(s_py, u_py, dt, *phi, *f, noise)
        s_c, u_c = NATIVE.integrate_interval(s_c, u_c, dt, *phi, *f, noise)
        assert_twins_equal(s_c, s_py, "deltas")
        assert_twins_equal(u_c, u_py, "uncertainty")
    assert type(s_c) is tuple and len(s_c) == 11
    assert (u_c is None) == (not with_u) and (u_c is None or len(u_c) == 90)
    assert preint_kernel.integrate_interval is NATIVE.integrate_interval


def test_kernel_rejects_bad_arguments_by_name():
    with pytest.raises(ValueError, match="deltas s must have 11 values"):
        NATIVE.integrate_interval((0.0,) * 10, None, 0.01, 0, 0, 0, 0, 0, 0, NOISE)
    with pytest.raises(ValueError, match="uncertainty u must have 90"):
        NATIVE.integrate_interval(DELTAS_IDENTITY, (0.0,) * 89, 0.01, 0, 0, 0, 0, 0, 0, NOISE)
    with pytest.raises(TypeError):
        NATIVE.integrate_interval(DELTAS_IDENTITY, None, "x", 0, 0, 0, 0, 0, 0, NOISE)
    with pytest.raises(TypeError, match="10 arguments"):
        NATIVE.integrate_interval(DELTAS_IDENTITY, None)
    with pytest.raises(ValueError, match="132 doubles"):
        NATIVE.push(bytearray(16), None, 0.0, [0.0] * 3, [0.0] * 3)


if NATIVE is not None:
    class _Pure(_PythonKernel, StreamingPreintegrator):
        """The pure-Python front-end (its fast path first in the MRO), for a same-process comparison."""


def _frames(cls, t, gyro, accel, as_arrays=False, **kw):
    sp = cls(**kw)
    out = []
    for i in range(len(t)):
        g, a = (gyro[i], accel[i]) if as_arrays else (gyro[i].tolist(), accel[i].tolist())
        out += sp.push(float(t[i]), g, a)
    return out, sp


def _log(n=1500, seed=0, gaps=()):
    rng = np.random.default_rng(seed)
    dt = 0.01 * (1 + 0.2 * rng.uniform(-1, 1, n))
    for k in gaps:
        dt[k] = 0.5                               # a timestamp gap
    t = np.cumsum(dt)
    gyro = 0.8 * np.sin(t[:, None] * [1.3, 0.7, 2.1]) + rng.normal(0, 0.05, (n, 3))
    gyro[200:260] = 0.0                           # zero rates
    gyro[400:420] = [0.0, 0.0, 25.0]              # fast spin: large angles per interval
    accel = np.cos(t[:, None] * [0.9, 1.7, 0.4]) + [0.3, -0.2, 9.8] + rng.normal(0, 0.2, (n, 3))
    return t, gyro, accel


def _assert_frames_equal(a, b):
    assert len(a) == len(b) > 0
    for fa, fb in zip(a, b, strict=True):
        assert_twins_equal(fa._s, fb._s, "deltas")
        assert_twins_equal(fa._u, fb._u, "uncertainty")
        assert (fa.n_intervals, fa.t_start, fa.t_end, fa.valid) == (fb.n_intervals, fb.t_start, fb.t_end, fb.valid)


@pytest.mark.parametrize("frames", [dict(rate=10.0), dict(rate=7.0, t_origin=0.0123), dict(rate=230.0),
                                    dict(every=9), dict(frame_times="knots"), dict(frame_times="between")])
@pytest.mark.parametrize("hold", ["midpoint", "left"])
@pytest.mark.parametrize("uncertainty", [True, False])
def test_streaming_fast_path_equals_python(monkeypatch, frames, hold, uncertainty):
    monkeypatch.setattr(preint_stream, "integrate_interval", integrate_interval_python)
    t, gyro, accel = _log(gaps=(700, 1100))
    if "frame_times" in frames:                   # on sample times, or strictly between samples
        ft = t[5:-5:37] if frames["frame_times"] == "knots" else (t[5:-5:37] + t[6:-4:37]) / 2
        frames = dict(frame_times=ft)
    kw = dict(frames, hold=hold, uncertainty=uncertainty, on_gap="flag", max_gap=0.1,
              bias_gyro=(1e-3, -2e-3, 5e-4), bias_accel=(0.01, 0.02, -0.01),
              gyro_noise_density=1e-3, accel_noise_density=1e-2)
    ref, sp_ref = _frames(_Pure, t, gyro, accel, **kw)
    got, sp = _frames(StreamingPreintegrator, t, gyro, accel, **kw)
    _assert_frames_equal(got, ref)
    assert not all(f.valid for f in got)          # the gaps were crossed
    cur, cur_ref = sp.current, sp_ref.current
    assert_twins_equal(cur._s, cur_ref._s, "current deltas")
    assert cur.n_intervals == cur_ref.n_intervals
    got_arrays, _ = _frames(StreamingPreintegrator, t, gyro, accel, as_arrays=True, **kw)
    _assert_frames_equal(got_arrays, ref)


@pytest.mark.shared
def test_streaming_on_kitti_oxts_bit_identical(shared_data, monkeypatch):
    """Three real KITTI OXTS drives (100 Hz, with their gaps flagged), 10 Hz frames, with covariance."""
    import warnings

    from imu_ground.datasets import read_kitti_imu100
    monkeypatch.setattr(preint_stream, "integrate_interval", integrate_interval_python)
    files = sorted((shared_data / "kitti_imu100").glob("*.csv.gz"))[:3]
    assert files
    for path in files:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            imu = read_kitti_imu100(path)
        kw = dict(rate=10.0, on_gap="flag", max_gap=0.05, gyro_noise_density=1e-3, accel_noise_density=1e-2)
        ref, _ = _frames(_Pure, imu.t, imu.gyro, imu.accel, **kw)
        got, _ = _frames(StreamingPreintegrator, imu.t, imu.gyro, imu.accel, **kw)
        _assert_frames_equal(got, ref)


def test_rejected_samples_leave_the_state_unchanged():
    t, gyro, accel = _log(300)
    sp = StreamingPreintegrator(rate=10.0, max_gap=0.1)
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
    rest, _ = [], None
    for i in range(150, 300):
        rest += sp.push(t[i], gyro[i].tolist(), accel[i].tolist())
    ref, _ = _frames(StreamingPreintegrator, t[:300], gyro[:300], accel[:300], rate=10.0, max_gap=0.1)
    _assert_frames_equal(rest, [f for f in ref if f.t_start >= rest[0].t_start])


def test_no_leaks_over_many_calls():
    """1e5 kernel calls and pushes (frames finished in C and in Python) allocate nothing that stays;
    the inputs' refcounts are unchanged."""
    s, u, noise = DELTAS_IDENTITY, UNCERTAINTY_ZERO, NOISE
    g, a = [0.1, -0.2, 0.3], [0.0, 0.0, 9.8]
    sps = [StreamingPreintegrator(every=50), StreamingPreintegrator(rate=10.0),
           StreamingPreintegrator(frame_times=np.arange(0.0003, 1001.0, 0.1), uncertainty=False)]
    refs = [sys.getrefcount(o) for o in (s, u, noise, g, a)]
    frames = 0

    def run(k0, k1):
        nonlocal frames
        for k in range(k0, k1):
            NATIVE.integrate_interval(s, u, 0.01, 1e-3, 2e-3, 3e-3, 0.1, 0.2, 9.8, noise)
            for sp in sps:
                frames += len(sp.push(k * 0.01 + 0.0003, g, a))
    run(0, 2000)                                        # warm-up: free lists and caches
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    run(2000, 100_000)
    gc.collect()
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    assert grown < 64 * 1024, grown
    assert [sys.getrefcount(o) for o in (s, u, noise, g, a)] == refs
    assert frames > 20_000 and all(math.isfinite(sp.current.delta_t) for sp in sps)
