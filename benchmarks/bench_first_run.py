"""What a new install costs before its first answer: the cold first run (numba compiling), and a fresh process's
import plus its first live estimate.

Rows (each a fresh child process, wall clock from start to exit, median of ``--repeat`` runs):

- cold first run: the README's main command, ``imu-ground estimate datasets/fixtures/example_drive.csv``, with
  an empty numba cache (``NUMBA_CACHE_DIR`` set to a new folder), so every compiled body the job uses is compiled
  (target: at most 30 s, once per install);
- the same command again on that filled cache (informative);
- the first live estimate below on that cache, which compiles the live path's own bodies (target: 30 s);
- ``import imu_ground``, a :class:`~imu_ground.StreamingEstimator` and samples pushed until its first frame
  estimate, on a cache filled by both (target: at most 1.0 s);
- beside it, the floors it cannot go under: ``import numpy``, and numba's own (``import numba`` and the first call
  of one trivial cached ``njit`` function), both informative.

Run ``python benchmarks/bench_first_run.py [--repeat R]``; :func:`rows` returns the table for
``benchmarks/make_results.py``. Bytecode is compiled first (:func:`_bytecode.compile_package`), as after an install.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _bytecode import compile_package  # noqa: E402

__all__ = ["COLD_TARGET_S", "FIRST_ESTIMATE_TARGET_S", "rows", "main"]

#: The cold first run (compilation included) may take this long, s, once per install.
COLD_TARGET_S = 30.0
#: A fresh process's import plus its first live estimate, s.
FIRST_ESTIMATE_TARGET_S = 1.0

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"

#: A fresh process: import, a live estimator, pushes until its first estimate (a level, still IMU at 100 Hz).
FIRST_ESTIMATE_CODE = (
    "import imu_ground\n"
    "est = imu_ground.StreamingEstimator()\n"
    "i, out = 0, []\n"
    "while not out:\n"
    "    out = est.push_imu(i * 0.01, (0.0, 0.0, 0.0), (0.0, 0.0, 9.81))\n"
    "    i += 1\n"
)
#: numba's floor: its import and the first call of one trivial cached compiled function.
NUMBA_FLOOR_CODE = (
    "import numba\n"
    "@numba.njit(cache=True)\n"
    "def one(x):\n"
    "    return x + 1.0\n"
    "one(1.0)\n"
)


def _seconds(argv: List[str], env: Optional[Dict[str, str]] = None, cwd: Optional[Path] = None) -> float:
    """Wall seconds of one child process (raises if it fails)."""
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, capture_output=True, env=env, cwd=cwd)
    return time.perf_counter() - t0


def _estimate_argv(out: Path) -> List[str]:
    """The README's main command on the shipped example, through this Python."""
    return [sys.executable, "-m", "imu_ground", "estimate", str(EXAMPLE), "-o", str(out)]


def rows(repeat: int = 3) -> List[Dict]:
    """The table: one row per measurement, ``figure`` in s, ``target``, ``passed`` (None: informative)."""
    compile_package()
    cold, warm, cold_live, first, floor_numba, floor_numpy = [], [], [], [], [], []
    load = []
    for _ in range(repeat):
        with tempfile.TemporaryDirectory() as tmp:
            env = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "numba"))
            cold.append(_seconds(_estimate_argv(Path(tmp) / "cold.csv"), env, REPO))
            warm.append(_seconds(_estimate_argv(Path(tmp) / "warm.csv"), env, REPO))
            cold_live.append(_seconds([sys.executable, "-c", FIRST_ESTIMATE_CODE], env))   # (its own bodies)
            first.append(_seconds([sys.executable, "-c", FIRST_ESTIMATE_CODE], env))
            floor = Path(tmp) / "numba_floor.py"                               # (a file: numba caches by file)
            floor.write_text(NUMBA_FLOOR_CODE)
            _seconds([sys.executable, str(floor)], env)                         # (fills its cache)
            floor_numba.append(_seconds([sys.executable, str(floor)], env))
            floor_numpy.append(_seconds([sys.executable, "-c", "import numpy"], env))
            load.append(os.getloadavg()[0])
    med = statistics.median
    loads = f"{min(load):.2f}-{max(load):.2f}"
    return [
        dict(benchmark="cold first run: imu-ground estimate on the example, empty numba cache",
             target=f"<= {COLD_TARGET_S:g} s once per install", figure=round(med(cold), 2), unit="s",
             worst=round(max(cold), 2), load=loads, passed=med(cold) <= COLD_TARGET_S),
        dict(benchmark="  the same command again, cache filled", target="informative", figure=round(med(warm), 2),
             unit="s", worst=round(max(warm), 2), load=loads, passed=None),
        dict(benchmark="cold first live estimate: the live bodies compiled (after the job above)",
             target=f"<= {COLD_TARGET_S:g} s once per install", figure=round(med(cold_live), 2), unit="s",
             worst=round(max(cold_live), 2), load=loads, passed=med(cold_live) <= COLD_TARGET_S),
        dict(benchmark="fresh process: import imu_ground + StreamingEstimator + first live estimate",
             target=f"<= {FIRST_ESTIMATE_TARGET_S:g} s", figure=round(med(first), 3), unit="s",
             worst=round(max(first), 3), load=loads, passed=med(first) <= FIRST_ESTIMATE_TARGET_S),
        dict(benchmark="  floor: import numba + first call of one cached njit function", target="informative",
             figure=round(med(floor_numba), 3), unit="s", worst=round(max(floor_numba), 3), load=loads, passed=None),
        dict(benchmark="  floor: import numpy", target="informative", figure=round(med(floor_numpy), 3), unit="s",
             worst=round(max(floor_numpy), 3), load=loads, passed=None),
    ]


def main(argv: Optional[List[str]] = None) -> None:
    """Print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="median of this many rounds of fresh processes")
    args = ap.parse_args(argv)
    for r in rows(args.repeat):
        verdict = "info" if r["passed"] is None else ("PASS" if r["passed"] else "FAIL")
        print(f"{r['benchmark']:<80}{r['figure']:>9} {r['unit']}  worst {r['worst']}  load {r['load']}  "
              f"{verdict}  ({r['target']})")


if __name__ == "__main__":
    main()
