"""Speed of the SuspensionAwareFilter: streaming µs/frame and batch frames/s.

Input: a synthetic drive (``imu_ground.evaluation.simulate``, nav-grade IMU) preintegrated
into 10 Hz frames and tiled to ``--frames`` frames (the filter does not care
that the drive repeats). Run: ``python benchmarks/bench_suspension.py
[--frames N] [--repeat R]``.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion
from imu_ground.evaluation.simulate import simulate
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.suspension import SuspensionAwareFilter


def _frames(n: int) -> EgoMotion:
    em = imu_to_egomotion(simulate(600.0, seed=3, imu="nav").imu)
    reps = -(-n // len(em))
    tile = lambda a: np.concatenate([a] * reps)[:n]
    return EgoMotion(np.arange(1, n + 1) * 0.1, tile(em.delta_R), tile(em.delta_v), tile(em.delta_t),
                     tile(em.stationary), tile(em.valid))


def _stream(f, em: EgoMotion) -> float:
    step = f.step
    t0 = time.perf_counter()
    for k in range(len(em)):
        step(em.delta_R[k], em.delta_v[k], em.delta_t[k], em.stationary[k], em.valid[k])
    return time.perf_counter() - t0


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=50_000)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs")
    args = ap.parse_args(argv)
    em = _frames(args.frames)
    n_stream = min(len(em), 20_000)
    em_s = EgoMotion(em.t[:n_stream], em.delta_R[:n_stream], em.delta_v[:n_stream], em.delta_t[:n_stream],
                     em.stationary[:n_stream], em.valid[:n_stream])
    rows = []
    configs = [("default (fixed gains)", {}), ("online gains", dict(online_gains=True))]
    for label, kw in configs:
        best_stream = best_batch = best_off = np.inf
        for _ in range(args.repeat):
            best_stream = min(best_stream, _stream(SuspensionAwareFilter(**kw), em_s))
            f = SuspensionAwareFilter(**kw)
            t0 = time.perf_counter()
            f.run(em)
            best_batch = min(best_batch, time.perf_counter() - t0)
        t0 = time.perf_counter()
        SuspensionAwareFilter(**kw).run(em_s, smooth=True)
        best_off = time.perf_counter() - t0
        rows.append((label, best_stream / n_stream * 1e6, len(em) / best_batch, n_stream / best_off))
    t0 = time.perf_counter()
    GravityVelocityFilter().run(em)
    gv_fps = len(em) / (time.perf_counter() - t0)
    print(f"SuspensionAwareFilter: batch on {len(em)} frames, streaming on {n_stream} (best of {args.repeat})")
    print(f"{'configuration':<24}{'streaming µs/frame':>20}{'batch frames/s':>16}{'offline frames/s':>18}")
    for label, us, fps, off in rows:
        print(f"{label:<24}{us:>20.1f}{fps:>16,.0f}{off:>18,.0f}")
    print(f"GravityVelocityFilter alone (batch): {gv_fps:,.0f} frames/s")


if __name__ == "__main__":
    main()
