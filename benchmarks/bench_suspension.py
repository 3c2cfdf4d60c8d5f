"""Latency of the SuspensionAwareFilter: streaming step, batch run, offline run (targets below).

Input: a synthetic drive (``imu_ground.evaluation.simulate``, nav-grade IMU) preintegrated into
10 Hz frames and tiled to ``--frames`` frames. Streaming: ``step(EgoFrame)`` per frame (median
over >= 5 repeats of the per-frame mean; p99 over every timed call); the
GravityVelocityFilter's ``step_sensor`` (the call the step makes) and ``run`` are timed in the
same run, and ``run`` once more with the gravity filter's result precomputed, so the share of the suspension layer (the residual
kernel and the plumbing around it) is visible. Batch: ``run``
over the whole drive (median of the repeats). The run checks that streaming equals batch.

The figures are those of the kernels compiled by numba (:mod:`imu_ground._jit`); the interpreted
bodies' figures (column ``python``, informative) are measured by this script in a child process
with ``NUMBA_DISABLE_JIT=1``.

Run: ``python benchmarks/bench_suspension.py [--frames N] [--stream-frames N] [--repeat R]``.
:func:`rows` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Dict, List

import numpy as np

from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import EgoMotion

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_filter import (  # noqa: E402
    P99_FACTOR,
    head_of,
    kernel_mode,
    python_figures,
    run_cli,
    run_fps,
    tiled_drive,
    time_steps,
)

__all__ = ["rows", "timings", "main"]

STEP_TARGET_US = 10.0
RUN_TARGET_FPS = 200_000.0


def _gravity_step_us(em: EgoMotion, repeat: int) -> float:
    """Median us per frame of the gravity filter's ``step_sensor``: the call SuspensionAwareFilter.step makes."""
    frames = [(fr.delta_R.ravel().tolist(), fr.delta_v.tolist(), float(fr.delta_t), bool(fr.stationary),
               bool(fr.valid), float("nan")) for fr in em.frames()]
    means = []
    for _ in range(repeat):
        step = GravityVelocityFilter().step_sensor
        t0 = time.perf_counter()
        for fr in frames:
            step(*fr)
        means.append((time.perf_counter() - t0) / len(frames))
    return float(np.median(means)) * 1e6


def _own_run_us(em: EgoMotion, repeat: int) -> float:
    """Median us per frame of ``run`` with the gravity filter's ``run`` replaced by its precomputed result:
    the suspension layer alone (frame check, load model, residual kernel, track assembly)."""
    gt = GravityVelocityFilter().run(em)
    times = []
    for _ in range(repeat):
        f = SuspensionAwareFilter()
        f.gravity_filter.run = lambda *args, **kwargs: gt
        t0 = time.perf_counter()
        f.run(em)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) / len(em) * 1e6


def timings(frames: int = 100_000, stream_frames: int = 20_000, repeat: int = 5,
            em: EgoMotion = None) -> Dict[str, float]:
    """The timed figures with the kernels in use: ``step`` (median, p99, CPU, us), the gravity filter's
    step (us), ``run`` and the gravity filter's ``run`` alone (frames/s), ``run`` without the gravity
    filter's share (us per frame), on ``em`` (default:
    :func:`~bench_filter.tiled_drive` of ``frames``)."""
    repeat = max(5, repeat)
    em = tiled_drive(frames) if em is None else em
    head = head_of(em, min(stream_frames, frames))
    med, p99, _, cpu = time_steps(SuspensionAwareFilter, list(head.frames()), repeat)
    us = 1e6
    return dict(step=med * us, step_p99=p99 * us, step_cpu=cpu * us, gravity_step=_gravity_step_us(head, repeat),
                run=run_fps(SuspensionAwareFilter, em, repeat), gravity_run=run_fps(GravityVelocityFilter, em, repeat),
                own_run=_own_run_us(em, repeat))


def rows(frames: int = 100_000, stream_frames: int = 20_000, repeat: int = 5) -> List[Dict]:
    """Benchmark rows: step, run (default and online gains), offline run, streaming == batch.

    Returns
    -------
    list of dict
        Keys ``benchmark``, ``target``, ``figure`` (the kernels in use), ``unit``, ``p99``, ``cpu``,
        ``kernel`` ("numba" or "Python"), ``python`` (the pure-Python kernels' figure, informative),
        ``passed`` (None: informative).
    """
    repeat = max(5, repeat)
    em = tiled_drive(frames)
    head = head_of(em, min(stream_frames, frames))
    t = timings(frames, stream_frames, repeat, em)
    med_on, p99_on, _, cpu_on = time_steps(lambda: SuspensionAwareFilter(online_gains=True), list(head.frames()),
                                           repeat)
    f = SuspensionAwareFilter()
    est = [f.step(fr) for fr in head.frames()]
    tb = SuspensionAwareFilter().run(head)
    diff = max(np.abs(np.array([e.normal for e in est]) - tb.normal).max(),
               np.abs(np.array([e.pitch for e in est]) - tb.pitch).max())
    py = python_figures(__file__, timings, frames, stream_frames, repeat)
    kernel, nan = kernel_mode(), float("nan")

    rows_ = [
        dict(benchmark="SuspensionAwareFilter.step(EgoFrame)", target=f"<= {STEP_TARGET_US:g} us, p99 <= "
             f"{P99_FACTOR:g}x median", figure=t["step"], unit="us", p99=t["step_p99"], cpu=t["step_cpu"],
             python=py["step"], passed=bool(t["step"] <= STEP_TARGET_US and t["step_p99"] <= P99_FACTOR * t["step"])),
        dict(benchmark="  of which GravityVelocityFilter.step_sensor", target="informative (other engineer's)",
             figure=t["gravity_step"], unit="us", p99=nan, python=py["gravity_step"], passed=None),
        dict(benchmark="SuspensionAwareFilter.step, online gains", target="informative", figure=med_on * 1e6,
             unit="us", p99=p99_on * 1e6, cpu=cpu_on * 1e6, python=nan, passed=None),
        dict(benchmark="SuspensionAwareFilter.run", target=f">= {RUN_TARGET_FPS:,.0f} frames/s", figure=t["run"],
             unit="frames/s", p99=nan, python=py["run"], passed=bool(t["run"] >= RUN_TARGET_FPS)),
        dict(benchmark="  of which GravityVelocityFilter.run", target="informative (other engineer's)",
             figure=t["gravity_run"], unit="frames/s", p99=nan, python=py["gravity_run"], passed=None),
        dict(benchmark="  run without the gravity filter's run", target="informative", figure=t["own_run"],
             unit="us/frame", p99=nan, python=py["own_run"], passed=None),
        dict(benchmark="SuspensionAwareFilter.run, online gains", target="informative",
             figure=run_fps(lambda: SuspensionAwareFilter(online_gains=True), em, repeat), unit="frames/s", p99=nan,
             python=nan, passed=None),
        dict(benchmark="SuspensionAwareFilter.run(smooth=True)", target="informative",
             figure=run_fps(SuspensionAwareFilter, head, repeat, smooth=True), unit="frames/s", p99=nan,
             python=nan, passed=None),
        dict(benchmark="SuspensionAwareFilter streaming == batch", target="<= 1e-12 (normal, rad)",
             figure=float(diff), unit="max abs diff", p99=nan, python=nan, passed=bool(diff <= 1e-12)),
    ]
    for r in rows_:
        r["kernel"] = kernel
    return rows_


def main(argv=None) -> None:
    run_cli(rows, __doc__, argv, timings)


if __name__ == "__main__":
    main()
