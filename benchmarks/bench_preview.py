"""Peak memory (and time) of ``imu-ground preview`` by bird's-eye grid: the bound is 1 GB for any grid ``--bev`` accepts.

Each row runs ``python -m imu_ground preview`` in a fresh child process and reads the
child's peak resident set size (``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss``, taken
in a wrapper process of its own, so that one row's child never counts in another's).
The rows: the default grid (5 cm), about the finest 40 x 14 m grid ``BevGrid`` accepts (3.4 mm,
48 M pixels; before the views were drawn at a bounded size, the one that took the most), a 3-frame
GIF at 5 mm, and the largest grid drawn at full size (1200 x 1200 pixels), as a 20-frame GIF.

Run ``python benchmarks/bench_preview.py`` for the table; :func:`rows` returns it for
``benchmarks/make_results.py``.
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["TARGET_MB", "rows"]

#: Peak resident memory a preview may take, MB, whatever the grid.
TARGET_MB = 1024.0

#: (what, extra preview arguments, output suffix)
CASES = (
    ("default grid 5 45 -7 7 0.05, png", [], ".png"),
    ("--bev 5 45 -7 7 0.0034 (48 M pixels), png", ["--bev", "5", "45", "-7", "7", "0.0034"], ".png"),
    ("--bev 5 45 -7 7 0.005, gif of 3 frames", ["--bev", "5", "45", "-7", "7", "0.005", "--frames", "3"], ".gif"),
    ("--bev 0 60 -30 30 0.05 (1200 x 1200), gif of 20 frames", ["--bev", "0", "60", "-30", "30", "0.05"], ".gif"),
)

_WRAPPER = ("import resource, subprocess, sys\n"
            "done = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
            "sys.stderr.write(done.stderr)\n"
            "print(done.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n")


def _peak(args: list[str]) -> tuple[int, float, float]:
    """(exit status, peak resident MB, seconds) of ``python -m imu_ground ARGS`` in a fresh process."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _WRAPPER, sys.executable, "-m", "imu_ground", *args],
                          capture_output=True, text=True, check=True)
    code, kb = done.stdout.split()
    return int(code), int(kb) / 1024.0, time.perf_counter() - t0


def rows(cases: tuple = CASES) -> list[dict]:
    """One row per case: peak resident memory (MB), seconds, the target and whether it passes."""
    table = []
    with tempfile.TemporaryDirectory() as tmp:
        for what, extra, suffix in cases:
            code, mb, sec = _peak(["preview", "-o", str(Path(tmp) / f"p{suffix}"), *extra])
            table.append({"preview": what, "exit": code, "peak_MB": round(mb, 1), "seconds": round(sec, 1),
                          "target": f"<= {TARGET_MB:.0f} MB", "pass": code == 0 and mb <= TARGET_MB})
    return table


def main() -> None:
    print(f"{'preview':58s} {'exit':>4s} {'peak MB':>8s} {'s':>7s}  target")
    for r in rows():
        print(f"{r['preview']:58s} {r['exit']:4d} {r['peak_MB']:8.1f} {r['seconds']:7.1f}  {r['target']} "
              f"{'pass' if r['pass'] else 'FAIL'}")


if __name__ == "__main__":
    main()
