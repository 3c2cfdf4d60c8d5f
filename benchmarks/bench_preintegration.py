"""Speed of IMU preintegration: one hour of 100 Hz IMU into 10 Hz frames (batch), and
the streaming front-end's µs per sample.

Run: ``python benchmarks/bench_preintegration.py [--samples N] [--repeat R]``.
Targets (2-core machine): batch < 0.5 s for 360,000 samples, streaming < 10 µs a
sample. Both include the 9x9 covariance and the bias Jacobians. Wall-clock and
process CPU times are printed; on a shared machine the CPU time is the steadier one.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from imu_ground.imu.preintegration import PreintegratedImu, StreamingPreintegrator, preintegrate


def make_log(n: int, seed: int = 0):
    """n samples at 100 Hz with 1 % timing jitter, a car-like rate and specific force."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01 + rng.uniform(-1e-4, 1e-4, n)
    s = t[:, None]
    gyro = 0.2 * np.sin(s * [0.31, 0.17, 0.05]) + rng.normal(0, 0.01, (n, 3))
    accel = np.array([0.0, 0.0, 9.81]) + np.sin(s * [0.2, 0.7, 1.1]) + rng.normal(0, 0.1, (n, 3))
    return t, gyro, accel


def timed(fn, repeat: int):
    """Best wall and CPU time over `repeat` runs, and the last result."""
    wall = cpu = np.inf
    out = None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = min(wall, time.perf_counter() - w0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu, out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=360_000, help="batch log length (100 Hz)")
    ap.add_argument("--stream-samples", type=int, default=30_000)
    ap.add_argument("--repeat", type=int, default=5, help="best of this many runs")
    args = ap.parse_args(argv)
    kw = dict(gyro_noise_density=1e-3, accel_noise_density=1e-2,
              bias_gyro=[1e-3, -2e-3, 5e-4], bias_accel=[0.01, 0.02, -0.01])

    t, gyro, accel = make_log(args.samples)
    w0 = time.perf_counter()
    fd = preintegrate((t, gyro, accel), rate=10.0, **kw)           # first call (cold)
    cold = time.perf_counter() - w0
    wall, cpu, fd = timed(lambda: preintegrate((t, gyro, accel), rate=10.0, **kw), args.repeat)
    print(f"batch: {args.samples} samples ({args.samples / 360_000:.2f} h at 100 Hz) -> {len(fd)} "
          f"frames at 10 Hz: {wall:.3f} s wall, {cpu:.3f} s CPU (best of {args.repeat}; "
          f"first call {cold:.3f} s) = {args.samples / wall / 1e6:.2f} M samples/s  [target < 0.5 s]")

    m = args.stream_samples
    ts, gs, acs = t[:m].tolist(), gyro[:m].tolist(), accel[:m].tolist()

    def run_stream(uncertainty=True):
        sp = StreamingPreintegrator(rate=10.0, uncertainty=uncertainty, **kw)
        push = sp.push
        out = []
        for i in range(m):
            r = push(ts[i], gs[i], acs[i])
            if r:
                out += r
        return out

    wall, cpu, frames = timed(run_stream, max(3, args.repeat // 2 + 1))
    print(f"streaming front-end: {m} samples, {len(frames)} frames: {wall / m * 1e6:.2f} µs/sample "
          f"wall, {cpu / m * 1e6:.2f} µs/sample CPU (best of {max(3, args.repeat // 2 + 1)})  "
          f"[target < 10 µs]")
    wall, cpu, lean = timed(lambda: run_stream(False), max(3, args.repeat // 2 + 1))
    print(f"streaming, deltas only (uncertainty=False): {wall / m * 1e6:.2f} µs/sample wall, "
          f"{cpu / m * 1e6:.2f} µs/sample CPU")

    def run_value_type():
        pim = PreintegratedImu(**kw)
        integ = pim._integrate
        for i in range(m):
            g, a = gs[i], acs[i]
            integ(0.01, g[0], g[1], g[2], a[0], a[1], a[2])
        return pim

    wall, cpu, _ = timed(run_value_type, 3)
    print(f"value type alone (PreintegratedImu, one interval per call): {wall / m * 1e6:.2f} µs wall, "
          f"{cpu / m * 1e6:.2f} µs CPU")

    # the two paths agree on what was timed
    ref = preintegrate((t[:m], gyro[:m], accel[:m]), rate=10.0, **kw)
    dR = max(np.abs(f.delta_R - ref.delta_R[i]).max() for i, f in enumerate(frames))
    dC = max(np.abs(f.covariance - ref.covariance[i]).max() / np.abs(ref.covariance[i]).max()
             for i, f in enumerate(frames))
    dL = max(np.abs(f.delta_R - ref.delta_R[i]).max() for i, f in enumerate(lean))
    print(f"check: streaming vs batch over {len(frames)} frames: max |delta_R diff| {dR:.1e} "
          f"(deltas only: {dL:.1e}), max relative covariance diff {dC:.1e}")


if __name__ == "__main__":
    main()
