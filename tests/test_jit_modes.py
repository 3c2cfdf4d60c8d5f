"""The loops written once and compiled by numba (:mod:`imu_ground._jit`) give the same numbers interpreted.

Each case of :data:`CASES` is a function of this module returning a dict of arrays. The test
runs every case here (compiled, the normal run) and once more in one child process with
``NUMBA_DISABLE_JIT=1`` (every :func:`~imu_ground._jit.njit` body then runs as plain Python), and
checks the two equal to 1e-12 relative to ``max(1, |value|)``, NaN in the same places. To add a
subset: write a small function (a few hundred frames: the interpreted run is slow) and add its
name to :data:`CASES`.
"""
from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from imu_ground import _jit, so3

RTOL = 1e-12


def _frames(n: int = 300, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = so3.exp(rng.normal(scale=[0.004, 0.004, 0.03], size=(n, 3)))
    d[7] = so3.exp_one(np.array([2.9, 0.1, 0.2]))              # an off-trace Shepperd branch
    d[11] = np.diag([1.0, -1.0, -1.0])                          # a half turn without twist
    return np.ascontiguousarray(d)


def residual_kernel() -> dict:
    """The residual kernel's batch (with tilt, extrinsic, cumulative rotation) and its checked steps."""
    from imu_ground.filters import residual
    from imu_ground.filters.residual import ResidualKernel
    d = _frames()
    rng = np.random.default_rng(1)
    q, tilt = rng.uniform(1e-6, 1e-3, len(d)), rng.normal(scale=0.01, size=(2, len(d)))
    k = ResidualKernel(0.7, 0.9, 0.05, 0.002, Rgs=so3.exp_one(np.array([0.02, -0.03, 1.2])), cumulative=True)
    run = k.run(d, q, 1e-4, tilt[0], tilt[1], angles=True)
    s = ResidualKernel(0.7, 0.9, 0.05, 0.002, up=True)
    steps = np.array([residual.step(s.buf, d[i], float(q[i]), 1e-4, None, None, None, 0.1) for i in range(len(d))])
    return {"run": run, "buf": k.buf, "steps": steps, "up buf": s.buf}


def frame_checks() -> dict:
    """The batch frame check on good and bad frames."""
    from imu_ground.filters.frame_checks import frame_statuses
    d = _frames(60)
    d[3] *= 1.001
    d[5, 0, 0] = np.nan
    dv = np.zeros((len(d), 3))
    dv[8, 1] = np.inf
    dt = np.full(len(d), 0.1)
    dt[9] = 0.0
    return {"status": frame_statuses(d, dv, dt).astype(float)}


def ground_filter() -> dict:
    """GroundNormalFilter's stream and batch on a short drive."""
    from imu_ground.filters.ground import GroundNormalFilter
    d = _frames(200, seed=2)
    f = GroundNormalFilter()
    steps = np.array([[e.pitch, e.roll, e.pitch_std] for e in (f.step(x) for x in d)])
    tr = GroundNormalFilter().run(d)
    return {"steps": steps, "pitch": tr.pitch, "roll": tr.roll, "P": tr.P}


def suspension_filter() -> dict:
    """SuspensionAwareFilter's batch (with a speed: road, drive statistics, monitor) and steps; the road and the
    mount monitor (through an alarm) alone."""
    from imu_ground.evaluation.simulate import simulate
    from imu_ground.filters.suspension import SuspensionAwareFilter
    from imu_ground.imu.egomotion import imu_to_egomotion
    em = imu_to_egomotion(simulate(20.0, seed=3, imu="mems").imu)
    from imu_ground.filters.mount_monitor import MountMonitor
    from imu_ground.filters.road import road_angles, road_std
    tr = SuspensionAwareFilter().run(em)
    f = SuspensionAwareFilter()
    steps = np.array([[e.pitch, e.roll] for e in (f.step(em.frame_at(k)) for k in range(40))])
    speed = np.full(len(em), 8.0)
    speed[50:60] = np.nan
    ts = SuspensionAwareFilter().run(em, speed=speed)              # the road, the drive statistics, the monitor
    t = np.arange(1, 2001) * 0.1                                    # the mount monitor through an alarm
    g = so3.exp(np.column_stack([np.zeros(len(t)), np.where(t > 150.0, 0.02, 0.0), np.zeros(len(t))])) @ [0, 0, 9.8]
    g[1800:1810] = np.nan
    m = MountMonitor()
    alarm = m.run(t, g, np.ones(len(t), dtype=bool))
    d = _frames(50, seed=6)
    road = np.array([*road_angles(d, g[:50], d[::-1]), *road_std(g[:50, 0] * 1e-3, g[:50, 1] * 1e-3,
                                                             np.tile(np.eye(3) * 1e-4, (50, 1, 1)), g[:50], d)])
    assert alarm.any() and np.isfinite(ts.road_grade).any()
    return {"pitch": tr.pitch, "roll": tr.roll, "steps": steps, "speed_std": np.array([ts.pitch_std, ts.roll_std]),
            "road": np.array([ts.road_grade, ts.road_bank, ts.road_grade_std, ts.road_bank_std]),
            "status": ts.status, "alarm": alarm, "monitor": np.array([m.alarm_t, *m.reference]), "road_fn": road}


def imu_bodies() -> dict:
    """The IMU side and the live front step: standstill windows and intervals, the batch preintegration's deltas,
    the interval kernel with its covariance and bias Jacobians, the streaming preintegrator's frames, the sample
    clock and the live estimator's frames over the example drive."""
    import warnings
    from imu_ground.imu import ImuData, preint_kernel
    from imu_ground.imu.preint_batch import preintegrate
    from imu_ground.imu.live.preint_stream import StreamingPreintegrator
    from imu_ground.imu.live.sample_clock import SampleClock
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
    out: dict = {}
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
        log = read_imu(Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv")
    live = StreamingEstimator(extrinsic="kitti_imu")
    fr = replay(live, log.t, log.gyro, log.accel)
    out["live"] = np.array([(f.t, f.pitch, f.roll, f.pitch_std, f.valid, f.status_code) for f in fr])
    assert out["intervals"].shape[0] >= 2 and out["live"].shape[0] > 100     # something to compare
    return out


#: The cases run both ways (names of functions of this module returning a dict of arrays).
def invariant_ekf() -> dict:
    """InvariantEKF, left and right error: every increment and measurement kind, a skipped and a singular update."""
    from imu_ground.filters.invariant_ekf import InvariantEKF
    d = _frames(40, seed=4)
    rng = np.random.default_rng(5)
    out = {}
    for error in ("left", "right"):
        f = InvariantEKF(x=so3.exp_one(np.array([0.3, -0.2, 1.0])), P=0.4, Q=np.diag([1e-2, 2e-2, 5e-3]),
                         R=np.array([[1.0, 0.1, 0.0], [0.1, 0.5, 0.05], [0.0, 0.05, 2.0]]), error=error)
        states = []
        for k in range(len(d)):
            f.predict(d[k] if k % 3 else (None if k % 2 else so3.log(d[k])), Q=None if k % 4 else 1e-3)
            z = so3.exp_one(rng.normal(scale=0.3, size=3))
            f.update(None if k % 7 == 6 else (z if k % 2 else np.ascontiguousarray(z[:, 2])),
                     R=None if k % 5 else 0.3)
            states.append(f.kernel_state())
        g = InvariantEKF(P=0.0, Q=0.0, R=0.0, error=error)
        g.predict(d[1])
        for z in (d[2], np.array([0.0, 0.6, 0.8])):
            try:
                g.update(z)
            except np.linalg.LinAlgError:
                states.append(g.kernel_state())
        assert len(states) == len(d) + 2, "a singular update did not raise"
        out[error] = np.array(states)
    return out


CASES = ["residual_kernel", "frame_checks", "ground_filter", "suspension_filter", "imu_bodies", "invariant_ekf"]

_CHILD = """
import importlib.util, sys
import numpy as np
spec = importlib.util.spec_from_file_location("jit_cases", sys.argv[1])
mod = importlib.util.module_from_spec(spec)
spec.loader.exec_module(mod)
from imu_ground import _jit
assert not _jit.JIT_ENABLED, "NUMBA_DISABLE_JIT=1 did not switch the compiled bodies off"
out = {}
for name in sys.argv[3:]:
    for key, value in getattr(mod, name)().items():
        out[name + "/" + key] = np.asarray(value, dtype=float)
np.savez(sys.argv[2], **out)
"""


@pytest.fixture(scope="module")
def interpreted(tmp_path_factory) -> dict:
    """Every case's arrays computed in a child process with the bodies interpreted."""
    path = tmp_path_factory.mktemp("jit") / "interpreted.npz"
    env = dict(os.environ, **{_jit.DISABLE_JIT_ENV: "1"})
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(Path(__file__).resolve()), str(path), *CASES],
                          env=env, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def test_numba_compiles_the_bodies_in_the_normal_run():
    if importlib.util.find_spec("numba") is None or os.environ.get(_jit.DISABLE_JIT_ENV, "") not in ("", "0"):
        pytest.skip("numba is not installed or switched off: the bodies run interpreted")
    assert _jit.JIT_ENABLED
    from imu_ground.filters import residual
    assert hasattr(residual.frame, "signatures")            # a numba dispatcher, not the plain function


@pytest.mark.parametrize("name", CASES)
def test_interpreted_equals_compiled(name, interpreted):
    compiled = getattr(sys.modules[__name__], name)()
    assert compiled
    for key, value in compiled.items():
        a, b = np.asarray(value, dtype=float), interpreted[f"{name}/{key}"]
        assert a.shape == b.shape, key
        assert (np.isnan(a) == np.isnan(b)).all(), key
        ok = ~np.isnan(b)
        err = np.abs(a[ok] - b[ok]) / np.maximum(1.0, np.abs(b[ok]))
        assert err.max(initial=0.0) <= RTOL, f"{name}/{key}: compiled and interpreted differ by {err.max():.3g}"
