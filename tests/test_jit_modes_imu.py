"""The IMU side's compiled bodies run interpreted too (``NUMBA_DISABLE_JIT=1``) and give the same results.

Each loop body of ``imu_ground/imu`` and of the live front step is one Python function that
:mod:`imu_ground._jit` compiles with numba; with numba's own switch set it runs as plain Python.
A small set of outputs (standstill windows and intervals, the batch preintegration's deltas, the
interval kernel with its covariance and bias Jacobians, the streaming preintegrator's frames, the
sample clock and the live estimator's frames) is computed in two child processes, one in each
mode, and compared: equal to 1e-12 relative to ``max(1, |value|)`` (compiled and interpreted round
alike but for the last bit of library functions such as ``sin``), integers and flags exactly.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_ground._jit import DISABLE_JIT_ENV

REPO = Path(__file__).resolve().parent.parent

_OUTPUTS = r'''
import sys, warnings
import numpy as np
from imu_ground import _jit
from imu_ground.imu import ImuData, preint_kernel
from imu_ground.imu.preint_batch import preintegrate
from imu_ground.imu.preint_stream import StreamingPreintegrator
from imu_ground.imu.sample_clock import SampleClock
from imu_ground.imu.standstill import WindowSums, estimate_gyro_bias
from imu_ground.datasets import read_imu
from imu_ground.pipeline.streaming import StreamingEstimator, replay

rng = np.random.default_rng(5)
n = 3000
t = 10.0 + np.cumsum(0.01 * (1 + 0.1 * rng.uniform(-1, 1, n)))
t[1500:] += 0.4                                              # a gap
gyro = rng.normal(0, 1e-3, (n, 3)) + [0.002, -0.001, 0.003]
accel = rng.normal(0, 5e-3, (n, 3)) + [0.1, -0.2, 9.8]
gyro[800:1900] += 0.4 * np.sin(t[800:1900, None] * [1.3, 0.7, 2.1])
accel[800:1900] += rng.normal(0, 0.5, (1100, 3))
out = {"jit": np.array([_jit.JIT_ENABLED])}
imu = ImuData(t, gyro, accel)
est = estimate_gyro_bias(imu, window=1.0)
out.update(bias=est.bias, intervals=est.intervals, c1=WindowSums(imu).c1)
for hold in ("midpoint", "left"):
    fd = preintegrate(imu, rate=10.0, hold=hold, on_gap="flag", max_gap=0.1, uncertainty=False)
    out.update({f"batch_{hold}_R": fd.delta_R, f"batch_{hold}_v": fd.delta_v, f"batch_{hold}_p": fd.delta_p,
                f"batch_{hold}_valid": fd.valid})
s, u = preint_kernel.DELTAS_IDENTITY, preint_kernel.UNCERTAINTY_ZERO
for i in range(200):
    phi = rng.normal(size=3) * (0.0, 1e-9, 1e-3, 0.5, 3.0)[i % 5]
    s, u = preint_kernel.integrate_interval(s, u, 0.01, *phi, *rng.normal(size=3), (1e-4, 1e-2))
out.update(kernel_s=np.array(s), kernel_u=np.array(u))
for unc in (False, True):
    sp = StreamingPreintegrator(rate=7.0, max_gap=0.1, on_gap="flag", uncertainty=unc, bias_gyro=[0.01, 0.0, -0.01])
    frames = [f for i in range(n) for f in sp.push(t[i], gyro[i].tolist(), accel[i].tolist())]
    out[f"stream_{unc}_s"] = np.array([f._s for f in frames])
    out[f"stream_{unc}_n"] = np.array([(f.n_intervals, f.valid, f.t_end) for f in frames])
    if unc:
        out["stream_u"] = np.array([f._u for f in frames])
clock = SampleClock("retime")
tj = t + rng.normal(0, 0.003, n)
tj[2000:2005] -= 0.05                                         # stamps stepping back
out["clock"] = np.array([clock.push(x) for x in tj.tolist()])
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    log = read_imu(sys.argv[2])
live = StreamingEstimator(extrinsic="kitti_imu")
fr = replay(live, log.t, log.gyro, log.accel)
out["live"] = np.array([(f.t, f.pitch, f.roll, f.pitch_std, f.valid, f.status_code) for f in fr])
np.savez(sys.argv[1], **out)
'''


def _run(tmp_path: Path, interpreted: bool) -> dict:
    script = tmp_path / "outputs.py"
    script.write_text(_OUTPUTS)
    dest = tmp_path / f"{'interpreted' if interpreted else 'compiled'}.npz"
    env = {k: v for k, v in os.environ.items() if k != DISABLE_JIT_ENV}
    if interpreted:
        env[DISABLE_JIT_ENV] = "1"
    subprocess.run([sys.executable, str(script), str(dest), str(REPO / "datasets" / "fixtures" / "example_drive.csv")],
                   env=env, cwd=REPO, check=True, capture_output=True, text=True)
    with np.load(dest) as z:
        return {k: z[k] for k in z.files}


def test_the_imu_bodies_give_the_same_results_compiled_and_interpreted(tmp_path):
    pytest.importorskip("numba")
    compiled, interpreted = _run(tmp_path, False), _run(tmp_path, True)
    assert compiled.pop("jit")[0] and not interpreted.pop("jit")[0]          # each child ran in its mode
    assert sorted(compiled) == sorted(interpreted)
    assert compiled["intervals"].shape[0] >= 2 and compiled["live"].shape[0] > 100       # something to compare
    for k, a in compiled.items():
        b = interpreted[k]
        assert a.shape == b.shape, k
        if a.dtype.kind != "f":
            assert np.array_equal(a, b), k
            continue
        same = (a == b) | (np.isnan(a) & np.isnan(b))
        err = np.where(same, 0.0, np.abs(a - b) / np.maximum(1.0, np.abs(b)))
        assert np.all(np.isfinite(err)) and err.max(initial=0.0) <= 1e-12, (k, float(np.nanmax(err)))
