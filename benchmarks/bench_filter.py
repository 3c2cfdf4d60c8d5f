"""Speed of GroundNormalFilter on 10^5 frames: streaming µs/frame and batch frames/s.

Run: ``python benchmarks/bench_filter.py [--frames N]``. Targets (2-core machine):
streaming at most 30 µs a frame, batch at least 10^5 frames a second.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from imu_ground import so3
from imu_ground.filters.ground import GroundNormalFilter


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    d = so3.exp(rng.normal(scale=[0.003, 0.003, 0.02], size=(args.frames, 3)))
    rows = []
    for meas in ("rotation", "up"):
        best_stream = best_batch = np.inf
        for _ in range(args.repeat):
            f = GroundNormalFilter(measurement=meas)
            step = f.step
            t0 = time.perf_counter()
            for x in d:
                step(x)
            best_stream = min(best_stream, time.perf_counter() - t0)
            f = GroundNormalFilter(measurement=meas)
            t0 = time.perf_counter()
            f.run(d)
            best_batch = min(best_batch, time.perf_counter() - t0)
        rows.append((meas, best_stream / args.frames * 1e6, args.frames / best_batch))
    f = GroundNormalFilter()
    t0 = time.perf_counter()
    f.run(d[:20_000], smooth=True)
    smooth_fps = 20_000 / (time.perf_counter() - t0)
    print(f"GroundNormalFilter, {args.frames} frames (best of {args.repeat})")
    print(f"{'measurement':<12}{'streaming µs/frame':>20}{'batch frames/s':>18}")
    for meas, us, fps in rows:
        print(f"{meas:<12}{us:>20.1f}{fps:>18,.0f}")
    print(f"offline (filter + RTS smoother): {smooth_fps:,.0f} frames/s")


if __name__ == "__main__":
    main()
