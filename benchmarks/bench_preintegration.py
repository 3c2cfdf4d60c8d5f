"""Speed of IMU preintegration against GTSAM in the same run (targets: :data:`_TARGETS`).

- streaming: ``StreamingPreintegrator.push`` in µs per sample, 100 Hz samples into
  10 Hz frames: deltas only (``uncertainty=False``), with the 9x9 covariance and
  the bias Jacobians, and with the frame read-out (``delta_R``, ``delta_v``,
  ``covariance``, ``bias_jacobian`` of every emitted frame); GTSAM's
  ``PreintegratedImuMeasurements.integrateMeasurement`` called from Python per
  sample (it always propagates covariance and Jacobians);
- batch: ``preintegrate`` of one hour at 100 Hz into 10 Hz frames, with
  covariance and bias Jacobians, against GTSAM's per-sample loop over the same
  hour (``resetIntegration`` at each frame).

Figures are medians over ``--repeat`` (>= 5) runs of wall-clock time; the CPU
time is printed too (steadier on a shared machine). The run checks that the
streaming frames equal the batch ones. The streaming figures are those of the kernels in
use (compiled by numba, :mod:`imu_ground._jit`); the interpreted kernels' figures are
printed too (informative), measured by this script in a child process with
``NUMBA_DISABLE_JIT=1`` right after. Run: ``python benchmarks/bench_preintegration.py``.
:func:`rows` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable

import numpy as np

from imu_ground._jit import DISABLE_JIT_ENV, JIT_ENABLED
from imu_ground.imu.preintegration import (
    PreintegrationParams,
    StreamingPreintegrator,
    preintegrate,
)

__all__ = ["main", "make_log", "rows"]

_PARAMS = PreintegrationParams(gyro_noise_density=1e-3, accel_noise_density=1e-2,
                               bias_gyro=(1e-3, -2e-3, 5e-4), bias_accel=(0.01, 0.02, -0.01))
_TARGETS = {"deltas": 2.0, "covariance": 4.0}     # µs per sample: a 100 Hz log preintegrates far faster than real time
_BATCH_TARGET = 0.5                               # s for one hour at 100 Hz


def make_log(n: int, seed: int = 0):
    """n samples at 100 Hz with 1 % timing jitter, a car-like rate and specific force."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01 + rng.uniform(-1e-4, 1e-4, n)
    s = t[:, None]
    gyro = 0.2 * np.sin(s * [0.31, 0.17, 0.05]) + rng.normal(0, 0.01, (n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + np.sin(s * [0.2, 0.7, 1.1]) + rng.normal(0, 0.1, (n, 3))
    return t, gyro, accel


def _median_times(fns: dict[str, Callable[[], object]], repeat: int) -> dict[str, tuple[float, float, object]]:
    """Median wall and CPU seconds of each function over ``repeat`` rounds, and its last result.

    The functions run in turn within each round, so that a machine shared with
    other work slows them alike and their ratios stay fair.
    """
    times: dict[str, tuple[list, list]] = {k: ([], []) for k in fns}
    last: dict[str, object] = {}
    for _ in range(repeat):
        for k, fn in fns.items():
            w0, c0 = time.perf_counter(), time.process_time()
            last[k] = fn()
            times[k][0].append(time.perf_counter() - w0)
            times[k][1].append(time.process_time() - c0)
    return {k: (float(np.median(w)), float(np.median(c)), last[k]) for k, (w, c) in times.items()}


def _stream(ts, gs, acs, uncertainty: bool, readout: bool) -> Callable[[], list]:
    def run() -> list:
        sp = StreamingPreintegrator(rate=10.0, params=_PARAMS, uncertainty=uncertainty)
        push = sp.push
        out = []
        for i in range(len(ts)):
            r = push(ts[i], gs[i], acs[i])
            if r:
                if readout:
                    for f in r:
                        _ = (f.delta_R, f.delta_v, f.covariance, f.bias_jacobian)
                out += r
        return out
    return run


def _gtsam_pim(params: PreintegrationParams, manifold: bool = False):
    """GTSAM's preintegration with our noise and bias (its default build, or the manifold one)."""
    import gtsam
    p = gtsam.PreintegrationParams.MakeSharedU(params.gravity)
    p.setGyroscopeCovariance(params.gyro_noise_density ** 2 * np.eye(3))
    p.setAccelerometerCovariance(params.accel_noise_density ** 2 * np.eye(3))
    p.setIntegrationCovariance(np.zeros((3, 3)))
    bias = gtsam.imuBias.ConstantBias(np.array(params.bias_accel), np.array(params.bias_gyro))
    cls = gtsam.PreintegratedImuMeasurementsManifold if manifold else gtsam.PreintegratedImuMeasurements
    return cls(p, bias)


def _gtsam_loop(t, gyro, accel, frame_every: int = 10) -> Callable[[], object]:
    pim = _gtsam_pim(_PARAMS)
    dts = np.diff(t).tolist()
    gs, acs = list(gyro[:-1]), list(accel[:-1])     # numpy rows: what GTSAM's binding takes
    integrate, reset = pim.integrateMeasurement, pim.resetIntegration

    def run():
        for i in range(len(dts)):
            integrate(acs[i], gs[i], dts[i])
            if i % frame_every == frame_every - 1:
                reset()
        return pim
    return run


def _gtsam_agreement(t, gyro, accel, frame_every: int = 10) -> tuple[float, float]:
    """Largest |delta_R| difference and relative covariance difference of our zero-order-hold
    frames from GTSAM's manifold preintegration of the same samples."""
    par = PreintegrationParams.coerce(_PARAMS, hold="left")
    fd = preintegrate((t, gyro, accel), frame_times=t[::frame_every], params=par)
    pim = _gtsam_pim(par, manifold=True)
    order = np.r_[0:3, 6:9, 3:6]        # ours [rot, vel, pos] -> GTSAM [rot, pos, vel], end body frame
    dR = dC = 0.0
    for i in range(len(fd)):
        pim.resetIntegration()
        for k in range(i * frame_every, (i + 1) * frame_every):
            pim.integrateMeasurement(accel[k], gyro[k], t[k + 1] - t[k])
        D = np.kron(np.eye(3), fd.delta_R[i].T)
        D[0:3, 0:3] = np.eye(3)
        C = D @ fd.covariance[i][np.ix_(order, order)] @ D.T
        dR = max(dR, float(np.abs(fd.delta_R[i] - pim.deltaRij().matrix()).max()))
        dC = max(dC, float(np.abs(C - pim.preintMeasCov()).max() / np.abs(C).max()))
    return dR, dC


_CASES = (("deltas only (uncertainty=False)", False, False, _TARGETS["deltas"]),
          ("with covariance and bias Jacobians", True, False, _TARGETS["covariance"]),
          ("with covariance, Jacobians and frame read-out", True, True, None))


def _stream_only(samples: int, repeat: int) -> dict[str, float]:
    """Median wall µs per sample of each streaming case with the kernels in use (no GTSAM, no checks)."""
    t, gyro, accel = make_log(samples)
    ts, gs, acs = t.tolist(), gyro.tolist(), accel.tolist()
    res = _median_times({name: _stream(ts, gs, acs, unc, readout) for name, unc, readout, _ in _CASES}, repeat)
    return {name: res[name][0] / samples * 1e6 for name, *_ in _CASES}


def _python_figures(samples: int, repeat: int) -> dict[str, float]:
    """:func:`_stream_only` with the bodies interpreted, in a child process (``NUMBA_DISABLE_JIT=1``)."""
    env = dict(os.environ, **{DISABLE_JIT_ENV: "1"})
    out = subprocess.run([sys.executable, __file__, "--stream-json", "--stream-samples", str(samples),
                          "--repeat", str(repeat)], env=env, capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def _row(benchmark: str, target: str, figure: float, cpu: float, unit: str, limit: float | None,
         competitor: tuple[float, float] = (float("nan"), float("nan")), agreement: float = float("nan")) -> dict:
    return {"benchmark": benchmark, "target": target, "figure": figure, "cpu": cpu, "unit": unit,
            "kernel": "numba" if JIT_ENABLED else "Python", "python": float("nan"), "competitor": competitor[0],
            "competitor_cpu": competitor[1], "agreement": agreement,
            "passed": None if limit is None else bool(figure <= limit)}


def rows(samples: int = 360_000, stream_samples: int = 20_000, repeat: int = 5) -> list[dict]:
    """Benchmark rows: each operation with its target, the figure and GTSAM's in the same run.

    Returns
    -------
    list of dict
        Keys ``benchmark``, ``target``, ``figure`` (median wall time), ``cpu``
        (median CPU time), ``unit`` ("us/sample" or "s"), ``competitor`` and
        ``competitor_cpu`` (GTSAM, same unit; nan without gtsam), ``agreement`` (max abs difference of the
        streaming frames' ``delta_R`` from the batch ones), ``passed`` (None if
        there is no target).
    """
    try:
        import gtsam  # noqa: F401
        have_gtsam = True
    except ImportError:
        have_gtsam = False
    repeat = max(5, repeat)
    t, gyro, accel = make_log(samples)
    m = min(stream_samples, samples)
    ts, gs, acs = t[:m].tolist(), gyro[:m].tolist(), accel[:m].tolist()
    ref = preintegrate((t[:m], gyro[:m], accel[:m]), rate=10.0, params=_PARAMS)
    fns = {name: _stream(ts, gs, acs, unc, readout) for name, unc, readout, _ in _CASES}
    if have_gtsam:
        fns["gtsam"] = _gtsam_loop(t[:m + 1], gyro[:m + 1], accel[:m + 1])
    res = _median_times(fns, repeat)
    nan2 = (float("nan"), float("nan"))
    g_us = (res["gtsam"][0] / m * 1e6, res["gtsam"][1] / m * 1e6) if have_gtsam else nan2
    py = _python_figures(m, repeat) if JIT_ENABLED else {n: res[n][0] / m * 1e6 for n, *_ in _CASES}
    out = []
    for name, _, _, limit in _CASES:
        wall, cpu, frames = res[name]
        agree = max(float(np.abs(f.delta_R - ref.delta_R[i]).max()) for i, f in enumerate(frames))
        target = f"<= {limit:g} us/sample" if limit else "(informative)"
        out.append(_row(f"StreamingPreintegrator.push, {name}", target, wall / m * 1e6, cpu / m * 1e6,
                        "us/sample", limit, g_us, agree))
        out[-1]["python"] = py[name]
    batch = {"ours": lambda: preintegrate((t, gyro, accel), rate=10.0, params=_PARAMS)}
    if have_gtsam:
        batch["gtsam"] = _gtsam_loop(t, gyro, accel)
    res = _median_times(batch, repeat)
    wall, cpu, fd = res["ours"]
    g_batch = res["gtsam"][:2] if have_gtsam else nan2
    out.append(_row(f"preintegrate, {samples / 360_000:g} h at 100 Hz into {len(fd)} frames, with covariance",
                    f"< {_BATCH_TARGET:g} s", wall, cpu, "s", _BATCH_TARGET, g_batch))
    if have_gtsam:
        n = min(samples, 2001)
        dR, dC = _gtsam_agreement(t[:n], gyro[:n], accel[:n])
        out.append(_row("agreement with GTSAM manifold preintegration (hold='left', 10-sample frames)",
                        "max relative covariance difference <= 1e-12", dC, float("nan"), "relative", 1e-12,
                        nan2, dR))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=360_000, help="batch log length (100 Hz)")
    ap.add_argument("--stream-samples", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=5, help="median over this many runs (>= 5)")
    ap.add_argument("--stream-json", action="store_true", help=argparse.SUPPRESS)   # child process of rows()
    args = ap.parse_args(argv)
    if args.stream_json:
        print(json.dumps(_stream_only(args.stream_samples, max(5, args.repeat))))
        return
    res = rows(args.samples, args.stream_samples, args.repeat)
    print(f"{'benchmark':<84}{'ours (CPU)':>18}{'Python':>8}{'GTSAM (CPU)':>18}  result")
    for r in res:
        verdict = "n/a" if r["passed"] is None else ("PASS" if r["passed"] else "FAIL")
        print(f"{r['benchmark']:<84}{r['figure']:>8.3g} ({r['cpu']:6.3g}){r['python']:>8.3g}{r['competitor']:>10.3g} "
              f"({r['competitor_cpu']:5.3g})  {verdict}  [{r['unit']}]")
        what = "GTSAM" if r["unit"] == "relative" else "batch"
        extra = (f"; max |delta_R diff| from {what} {r['agreement']:.1e}" if r["agreement"] == r["agreement"]
                 else "")
        kern = (f"; ours = the {r['kernel']} kernels, Python = the pure-Python ones (informative)"
                if r["python"] == r["python"] else "")
        print(f"    target: {r['target']}{extra}{kern}")


if __name__ == "__main__":
    main()
