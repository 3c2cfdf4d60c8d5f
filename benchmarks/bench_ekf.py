"""Latency of ``InvariantEKF.predict`` + ``update`` against GTSAM's ``InvariantEKFRot3`` (target: no slower).

Both filters run the same left-invariant model on the same data in the same
process: predict with a body increment ``U`` and process noise ``Q``, then
correct with a measurement. Two measurements:

- ``rotation``: a full rotation ``Z = X Exp(v)``. GTSAM's update takes a vector
  innovation, so its loop computes ``Log(X^T Z)`` with ``gtsam.Rot3.Logmap``
  (``updateWithVector(0, I, Log(X^T Z), R)``); the "inputs given" row leaves that
  out (a lower bound for GTSAM: the innovation handed over precomputed).
- ``direction``: the world-frame up axis ``z = X e_z + v``; GTSAM gets
  ``prediction = e_z``, ``H = -[e_z]x``, ``z_body = X^T z`` and ``X^T R X``.

Each configuration runs ``--steps`` predict/update pairs per repeat, ours and
GTSAM's in alternation; the median is over ``--repeat`` (>= 5) repeats of the
per-step mean, the p99 over every individually timed step. GTSAM's update is
called with ``performReset=False``: its default transports the covariance
through the correction's Jacobian, which ours (like the paper's filter and
filterpy's) does not do; with it off the two agree to rounding. The run also checks that the two filters give
the same states and covariances. The figure is that of the kernels compiled by numba
(:mod:`imu_ground.filters.invariant_ekf_kernel`); the interpreted body's figure is printed too
(informative), measured by this script in a child process with ``NUMBA_DISABLE_JIT=1`` right after. Run: ``python benchmarks/bench_ekf.py``. :func:`rows` returns the table for
``benchmarks/make_results.py``.
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

from imu_ground import so3
from imu_ground._jit import DISABLE_JIT_ENV, JIT_ENABLED
from imu_ground.filters.invariant_ekf import InvariantEKF

__all__ = ["main", "rows"]

_Q = np.diag([1e-2, 2e-2, 5e-3])
_R = np.diag([1.0, 0.5, 2.0])


def _data(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    us = so3.exp(rng.normal(scale=0.05, size=(n, 3)))
    zs_rot = so3.exp(rng.normal(scale=0.3, size=(n, 3)))
    zs_dir = rng.normal(scale=0.1, size=(n, 3)) + [0.0, 0.0, 1.0]
    zs_dir /= np.linalg.norm(zs_dir, axis=1, keepdims=True)
    return us, zs_rot, zs_dir


def _time_pair(steps: list[Callable[[int], None]], n: int, repeat: int):
    """Per-step medians (s) and p99s (s) of several loops timed in alternation.

    Each repeat times every loop over ``n`` steps in turn (so that a busy
    machine slows them alike), then ``n`` single steps of each for the p99.
    """
    clock = time.perf_counter
    means = [[] for _ in steps]
    singles = [[] for _ in steps]
    for _ in range(repeat):
        for i, step in enumerate(steps):
            t0 = clock()
            for k in range(n):
                step(k)
            means[i].append((clock() - t0) / n)
        for i, step in enumerate(steps):
            one = np.empty(n)
            for k in range(n):
                t1 = clock()
                step(k)
                one[k] = clock() - t1
            singles[i].append(one)
    return [float(np.median(m)) for m in means], [float(np.percentile(np.concatenate(o), 99)) for o in singles]


def _ours(measure: str, us, zs):
    f = InvariantEKF(P=1.0, Q=_Q, R=_R)
    predict, update = f.predict, f.update

    def step(k):
        predict(us[k])
        update(zs[k])
    return f, step


def _gtsam(measure: str, us, zs, precomputed: bool = False):
    import gtsam
    g = gtsam.InvariantEKFRot3(gtsam.Rot3(), np.eye(3))
    Ug = [gtsam.Rot3(u) for u in us]
    zero, eye = np.zeros(3), np.eye(3)
    Q, R = _Q, _R
    predict, update, logmap = g.predict, g.updateWithVector, gtsam.Rot3.Logmap
    if measure == "rotation" and precomputed:
        xi = [so3.log_one(z) for z in zs]

        def step(k):
            predict(Ug[k], Q)
            update(zero, eye, xi[k], R, False)
    elif measure == "rotation":
        Zg = [gtsam.Rot3(z) for z in zs]

        def step(k):
            predict(Ug[k], Q)
            update(zero, eye, logmap(g.state().between(Zg[k])), R, False)
    else:
        ez = np.array([0.0, 0.0, 1.0])
        H = -so3.hat(ez)

        def step(k):
            predict(Ug[k], Q)
            X = g.state().matrix()
            update(ez, H, X.T @ zs[k], X.T @ R @ X, False)
    return g, step


def _agreement(measure: str, us, zs, n: int = 200) -> float:
    """Largest difference of state and covariance between ours and GTSAM after ``n`` steps."""
    f, s1 = _ours(measure, us, zs)
    g, s2 = _gtsam(measure, us, zs)
    worst = 0.0
    for k in range(n):
        s1(k)
        s2(k)
        worst = max(worst, np.abs(f.x - g.state().matrix()).max(), np.abs(f.P - g.covariance()).max())
    return float(worst)


def _ours_only(steps: int, repeat: int) -> dict[str, float]:
    """Median us per predict + update of the kernels in use, per measurement kind (no GTSAM)."""
    us, zs_rot, zs_dir = _data(steps)
    return {m: _time_pair([_ours(m, us, zs)[1]], steps, repeat)[0][0] * 1e6
            for m, zs in (("rotation", zs_rot), ("direction", zs_dir))}


def _python_figures(steps: int, repeat: int) -> dict[str, float]:
    """:func:`_ours_only` with the bodies interpreted, measured in a child process (``NUMBA_DISABLE_JIT=1``)."""
    if not JIT_ENABLED:
        return _ours_only(steps, repeat)
    env = dict(os.environ, **{DISABLE_JIT_ENV: "1"})
    out = subprocess.run([sys.executable, __file__, "--ours-json", "--steps", str(steps), "--repeat", str(repeat)],
                         env=env, capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def rows(steps: int = 20_000, repeat: int = 7) -> list[dict]:
    """Benchmark rows: one per measurement kind, ours against GTSAM in the same run.

    Returns
    -------
    list of dict
        Keys ``benchmark``, ``target``, ``figure`` (our median with the kernels in use), ``unit`` ("us"),
        ``p99`` (us), ``kernel`` ("numba" or "Python"), ``python`` (the interpreted body's median, us,
        informative), ``competitor`` (GTSAM median, us), ``competitor_p99``, ``agreement`` (max abs
        difference of X and P), ``passed``.
    """
    kernel = "numba" if JIT_ENABLED else "Python"
    us, zs_rot, zs_dir = _data(steps)
    try:
        import gtsam  # noqa: F401
        have_gtsam = True
    except ImportError:
        have_gtsam = False
    out = []
    for measure, zs in (("rotation", zs_rot), ("direction", zs_dir)):
        loops = [_ours(measure, us, zs)[1]]
        if have_gtsam:
            loops.append(_gtsam(measure, us, zs)[1])
            if measure == "rotation":
                loops.append(_gtsam(measure, us, zs, precomputed=True)[1])
        med, p99 = _time_pair(loops, steps, repeat)
        row = dict(benchmark=f"InvariantEKF.predict + update ({measure})",
                   target="<= GTSAM InvariantEKFRot3 (same run)", figure=med[0] * 1e6, unit="us", p99=p99[0] * 1e6,
                   kernel=kernel, python=float("nan"), competitor=float("nan"), competitor_p99=float("nan"),
                   agreement=float("nan"), passed=None)
        if have_gtsam:
            row.update(competitor=med[1] * 1e6, competitor_p99=p99[1] * 1e6,
                       agreement=_agreement(measure, us, zs), passed=bool(med[0] <= med[1]))
        out.append(row)
        if have_gtsam and measure == "rotation":
            out.append(dict(benchmark="InvariantEKF.predict + update (rotation), GTSAM given the innovation",
                            target="<= GTSAM with Log(X^T Z) precomputed (informative)", figure=med[0] * 1e6, unit="us",
                            p99=p99[0] * 1e6, kernel=kernel, python=float("nan"), competitor=med[2] * 1e6,
                            competitor_p99=p99[2] * 1e6, agreement=float("nan"), passed=bool(med[0] <= med[2])))
    py = _python_figures(steps, repeat)
    for r in out:
        r["python"] = py["rotation" if "(rotation)" in r["benchmark"] else "direction"]
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=7, help="median over this many repeats (>= 5)")
    ap.add_argument("--ours-json", action="store_true", help=argparse.SUPPRESS)   # child process of rows()
    args = ap.parse_args(argv)
    if args.ours_json:
        print(json.dumps(_ours_only(args.steps, max(5, args.repeat))))
        return
    res = rows(args.steps, max(5, args.repeat))
    print(f"{'benchmark':<70}{'ours us (p99)':>16}{'Python us':>10}{'GTSAM us (p99)':>17}{'max |diff|':>12}  result")
    for r in res:
        verdict = "n/a" if r["passed"] is None else ("PASS" if r["passed"] else "FAIL")
        print(f"{r['benchmark']:<70}{r['figure']:>7.2f} ({r['p99']:5.2f}){r['python']:>10.2f}{r['competitor']:>8.2f} "
              f"({r['competitor_p99']:5.2f}){r['agreement']:>12.1e}  {verdict}")
        print(f"    target: {r['target']}; ours = the {r['kernel']} kernels, "
              "Python = the pure-Python ones (informative)")


if __name__ == "__main__":
    main()
