"""Latency of the gravity/velocity filter: ``GravityVelocityFilter.step``, ``step_body``, ``run``.

Input: a synthetic drive (``imu_ground.evaluation.simulate``, nav-grade IMU,
standstills included) preintegrated into 10 Hz frames and tiled to ``--frames``
frames, sensor frame of a tilted mount with a lever arm (the suspension filter's
configuration). Timed with the kernel (``gravity_kernel``, compiled by numba):

- ``step``: the public streaming call (3x3 and 3-vector arrays, frame check);
- ``step_body``: the plain-float fast path as ``SuspensionAwareFilter.step`` calls
  it (``step_body(*to_body_flat(d9, dv), ...)``), and ``step_sensor`` (the same in one call);
- ``run``: the whole drive (median of the repeats).

Streaming figures are the median over >= 5 repeats of the per-frame mean; p99
over every timed call. The run checks that streaming equals batch and prints the
largest difference. The suspension filter's
batch rate, which the gravity run bounds, is printed for information.

Run: ``python benchmarks/bench_gravity.py [--frames N] [--stream-frames N] [--repeat R]``.
:func:`rows` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import argparse
import os
import time
from typing import Callable, Dict, List

import numpy as np

from imu_ground import so3
from imu_ground._jit import DISABLE_JIT_ENV
from imu_ground.evaluation.simulate import simulate
from imu_ground.filters import gravity_kernel
from imu_ground.filters.extrinsics import Extrinsic
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion

__all__ = ["rows", "main"]

#: Targets, the gravity filter's share of the suspension filter's: the suspension step's budget is 10 us in
#: all, its run >= 200,000 frames/s (5 us/frame), of which the gravity filter may take about 2 us (step_body)
#: and 1 us/frame (run).
STEP_TARGET_US = 4.0
STEP_BODY_TARGET_US = 2.0
RUN_TARGET_US = 1.0
P99_FACTOR = 3.0
KERNELS = {"compiled": gravity_kernel}


def _frames(n: int) -> EgoMotion:
    em = imu_to_egomotion(simulate(600.0, seed=3, imu="nav").imu)
    reps = -(-n // len(em))
    tile = lambda a: np.concatenate([a] * reps)[:n]  # noqa: E731
    return EgoMotion(np.arange(1, n + 1) * 0.1, tile(em.delta_R), tile(em.delta_v), tile(em.delta_t),
                     tile(em.stationary), tile(em.valid))


def _filter(kernel=None) -> GravityVelocityFilter:
    ext = Extrinsic(so3.rotz(0.1) @ so3.roty(0.03) @ so3.rotx(-0.02), [0.4, 0.1, 1.1])
    f = GravityVelocityFilter(extrinsic=ext, lever_arm=ext.translation)
    if kernel is not None:
        f.kernel = kernel
        f.reset()
    return f


def _callers(em: EgoMotion, n: int) -> Dict[str, Callable]:
    """Per entry point: ``make(filter) -> call(k)`` processing frame k."""
    dR, dv = list(em.delta_R[:n]), list(em.delta_v[:n])
    d9, dv3 = em.delta_R[:n].reshape(n, 9).tolist(), em.delta_v[:n].tolist()
    dt, st, va = em.delta_t[:n].tolist(), em.stationary[:n].tolist(), em.valid[:n].tolist()

    def step(f):
        s = f.step
        return lambda k: s(dR[k], dv[k], dt[k], st[k], va[k])

    def step_body(f):
        sb, tb = f.step_body, f.to_body_flat
        return lambda k: sb(*tb(d9[k], dv3[k]), dt[k], st[k], va[k], None)

    def step_sensor(f):
        ss = f.step_sensor
        return lambda k: ss(d9[k], dv3[k], dt[k], st[k], va[k], None)
    return {"step": step, "step_body": step_body, "step_sensor": step_sensor}


def _time_stream(make: Callable, kernel, n: int, repeat: int):
    """Median per-frame mean (s), the p99 of single calls (s), median per-frame CPU time (s)."""
    clock, cpu = time.perf_counter, time.process_time
    means, singles, cpus = [], [], []
    for _ in range(repeat):
        call = make(_filter(kernel))
        t0, c0 = clock(), cpu()
        for k in range(n):
            call(k)
        means.append((clock() - t0) / n)
        cpus.append((cpu() - c0) / n)
        call = make(_filter(kernel))
        one = np.empty(n)
        for k in range(n):
            t1 = clock()
            call(k)
            one[k] = clock() - t1
        singles.append(one)
    return float(np.median(means)), float(np.percentile(np.concatenate(singles), 99)), float(np.median(cpus))


def _time_run(em: EgoMotion, kernel, repeat: int):
    """Median per-frame wall and CPU time of ``run`` (s)."""
    runs, cpus = [], []
    for _ in range(repeat):
        f = _filter(kernel)
        t0, c0 = time.perf_counter(), time.process_time()
        f.run(em)
        runs.append((time.perf_counter() - t0) / len(em))
        cpus.append((time.process_time() - c0) / len(em))
    return float(np.median(runs)), float(np.median(cpus))


def _differences(em: EgoMotion, n: int, kernel) -> Dict[str, float]:
    """Largest |streaming - batch| with ``kernel``, and |kernel - pure Python| over the batch."""
    head = EgoMotion(em.t[:n], em.delta_R[:n], em.delta_v[:n], em.delta_t[:n], em.stationary[:n], em.valid[:n])
    f = _filter(kernel)
    est = [f.step(head.delta_R[k], head.delta_v[k], head.delta_t[k], head.stationary[k], head.valid[k])
           for k in range(n)]
    tb, tp = _filter(kernel).run(head), _filter(gravity_kernel).run(head)
    names = ("velocity", "gravity", "acceleration")
    return {"stream": max(float(np.abs(np.array([getattr(e, m) for e in est]) - getattr(tb, m)).max()) for m in names),
            "kernels": max(float(np.abs(getattr(tb, m) - getattr(tp, m)).max()) for m in names + ("P",))}


def _row(name, target, figure, unit, p99=float("nan"), passed=None, cpu=float("nan")) -> Dict:
    return dict(benchmark=name, target=target, figure=figure, unit=unit, p99=p99, cpu=cpu, passed=passed)


def rows(frames: int = 100_000, stream_frames: int = 20_000, repeat: int = 5) -> List[Dict]:
    """Benchmark rows: step, step_body, step_sensor and run per kernel, streaming == batch, C == Python,
    the suspension run for information.

    Returns
    -------
    list of dict
        Keys ``benchmark``, ``target``, ``figure``, ``unit``, ``p99`` (where
        timed per call), ``cpu`` (the process's CPU time per call or frame, less
        sensitive to a shared machine), ``passed`` (None: informative; every pure-Python row is).
    """
    em = _frames(frames)
    n = min(stream_frames, frames)
    callers = _callers(em, n)
    targets = {"step": STEP_TARGET_US, "step_body": STEP_BODY_TARGET_US, "step_sensor": STEP_BODY_TARGET_US}
    out = []
    for label, kernel in KERNELS.items():
        if kernel is None:                  # a failure unless switched off on purpose
            off = os.environ.get(DISABLE_JIT_ENV, "") not in ("", "0")
            out.append(_row(f"GravityVelocityFilter ({label} kernel)", f"built ({DISABLE_JIT_ENV} set)" if off
                            else "built", float("nan"), "", passed=None if off else False))
            continue
        timed = label == "compiled"
        for name, make in callers.items():
            mean, p99, cpu = (v * 1e6 for v in _time_stream(make, kernel, n, repeat))
            target = f"<= {targets[name]:g} us, p99 <= {P99_FACTOR:g}x median" if timed else "informative"
            out.append(_row(f"GravityVelocityFilter.{name} ({label})", target, mean, "us", p99,
                            bool(mean <= targets[name] and p99 <= P99_FACTOR * mean) if timed else None, cpu))
        run_us, run_cpu = (v * 1e6 for v in _time_run(em, kernel, repeat))
        out.append(_row(f"GravityVelocityFilter.run ({label})",
                        f"<= {RUN_TARGET_US:g} us/frame" if timed else "informative", run_us, "us/frame",
                        passed=bool(run_us <= RUN_TARGET_US) if timed else None, cpu=run_cpu))
    diff = _differences(em, min(n, 5000), gravity_kernel)
    out.append(_row("GravityVelocityFilter streaming == batch", "<= 1e-12 (m/s, m/s^2)", diff["stream"],
                    "max abs diff", passed=bool(diff["stream"] <= 1e-12)))
    try:
        from imu_ground.filters.suspension import SuspensionAwareFilter
    except ImportError:
        return out
    sus = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        SuspensionAwareFilter().run(em)
        sus.append(frames / (time.perf_counter() - t0))
    out.append(_row("SuspensionAwareFilter.run (informative: filters engineer's)", ">= 200,000 frames/s",
                    float(np.median(sus)), "frames/s"))
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--stream-frames", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=5, help="median over this many repeats (>= 5)")
    args = ap.parse_args(argv)
    res = rows(args.frames, args.stream_frames, max(5, args.repeat))
    print(f"{'benchmark':<62}{'figure':>14}  {'unit':<14}{'p99':>8}{'cpu':>8}  result")
    for r in res:
        verdict = "info" if r["passed"] is None else ("PASS" if r["passed"] else "FAIL")
        fig = f"{r['figure']:.3g}" if r["figure"] < 1e-3 else f"{r['figure']:,.2f}"
        print(f"{r['benchmark']:<62}{fig:>14}  {r['unit']:<14}{r['p99']:>8.2f}{r['cpu']:>8.2f}  {verdict}")
        print(f"    target: {r['target']}")


if __name__ == "__main__":
    main()
