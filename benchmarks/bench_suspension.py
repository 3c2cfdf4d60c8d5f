"""Latency of the SuspensionAwareFilter (issue 12): streaming step, batch run, offline run.

Input: a synthetic drive (``imu_ground.evaluation.simulate``, nav-grade IMU) preintegrated into
10 Hz frames and tiled to ``--frames`` frames. Streaming: ``step(EgoFrame)`` per frame (median
over >= 5 repeats of the per-frame mean; p99 over every timed call); the
GravityVelocityFilter's own step is timed in the same run, so the share of the suspension
layer is visible. Batch: ``run`` over the whole drive (median of the repeats). The run checks
that streaming equals batch.

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
from bench_filter import P99_FACTOR, run_cli, tiled_drive, time_steps  # noqa: E402

__all__ = ["rows", "main"]

STEP_TARGET_US = 10.0
RUN_TARGET_FPS = 200_000.0


def _gravity_step_us(em: EgoMotion, repeat: int) -> float:
    frames = [(fr.delta_R, fr.delta_v, fr.delta_t, fr.stationary, fr.valid) for fr in em.frames()]
    means = []
    for _ in range(repeat):
        step = GravityVelocityFilter().step
        t0 = time.perf_counter()
        for fr in frames:
            step(*fr)
        means.append((time.perf_counter() - t0) / len(frames))
    return float(np.median(means)) * 1e6


def _run_fps(em: EgoMotion, repeat: int, smooth: bool = False, **kw) -> float:
    fps = []
    for _ in range(repeat):
        f = SuspensionAwareFilter(**kw)
        t0 = time.perf_counter()
        f.run(em, smooth=smooth)
        fps.append(len(em) / (time.perf_counter() - t0))
    return float(np.median(fps))


def rows(frames: int = 100_000, stream_frames: int = 20_000, repeat: int = 5) -> List[Dict]:
    """Benchmark rows: step, run (default and online gains), offline run, streaming == batch.

    Returns
    -------
    list of dict
        Keys ``benchmark``, ``target``, ``figure``, ``unit``, ``p99``, ``passed`` (None: informative).
    """
    repeat = max(5, repeat)
    em = tiled_drive(frames)
    n = min(stream_frames, frames)
    head = EgoMotion(em.t[:n], em.delta_R[:n], em.delta_v[:n], em.delta_t[:n], em.stationary[:n], em.valid[:n])
    med, p99, est, cpu = time_steps(SuspensionAwareFilter, list(head.frames()), repeat)
    med_on, p99_on, _, cpu_on = time_steps(lambda: SuspensionAwareFilter(online_gains=True), list(head.frames()),
                                           repeat)
    gv = _gravity_step_us(head, repeat)
    tb = SuspensionAwareFilter().run(head)
    diff = max(np.abs(np.array([e.normal for e in est]) - tb.normal).max(),
               np.abs(np.array([e.pitch for e in est]) - tb.pitch).max())
    fps = _run_fps(em, repeat)
    us = 1e6
    nan = float("nan")
    return [
        dict(benchmark="SuspensionAwareFilter.step(EgoFrame)", target=f"<= {STEP_TARGET_US:g} us, p99 <= "
             f"{P99_FACTOR:g}x median", figure=med * us, unit="us", p99=p99 * us, cpu=cpu * us,
             passed=bool(med * us <= STEP_TARGET_US and p99 <= P99_FACTOR * med)),
        dict(benchmark="  of which GravityVelocityFilter.step", target="informative (other engineer's)", figure=gv,
             unit="us", p99=nan, passed=None),
        dict(benchmark="SuspensionAwareFilter.step, online gains", target="informative", figure=med_on * us,
             unit="us", p99=p99_on * us, cpu=cpu_on * us, passed=None),
        dict(benchmark="SuspensionAwareFilter.run", target=f">= {RUN_TARGET_FPS:,.0f} frames/s", figure=fps,
             unit="frames/s", p99=nan, passed=bool(fps >= RUN_TARGET_FPS)),
        dict(benchmark="SuspensionAwareFilter.run, online gains", target="informative",
             figure=_run_fps(em, repeat, online_gains=True), unit="frames/s", p99=nan, passed=None),
        dict(benchmark="SuspensionAwareFilter.run(smooth=True)", target="informative",
             figure=_run_fps(head, repeat, smooth=True), unit="frames/s", p99=nan, passed=None),
        dict(benchmark="SuspensionAwareFilter streaming == batch", target="<= 1e-12 (normal, rad)",
             figure=float(diff), unit="max abs diff", p99=nan, passed=bool(diff <= 1e-12)),
    ]


def main(argv=None) -> None:
    run_cli(rows, __doc__, argv)


if __name__ == "__main__":
    main()
