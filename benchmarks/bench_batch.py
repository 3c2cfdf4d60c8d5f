"""Fleet throughput of ``imu-ground batch`` (Dask) against a plain loop of ``estimate`` in one process.

The benchmark: ``n`` synthetic drives of ``minutes`` minutes each, written by
``imu-ground simulate`` into a temporary folder; then

- ``loop``: one process estimating them one after the other (what a shell loop of
  ``imu-ground estimate`` does, without paying the interpreter start each time);
- ``batch, 1 worker`` and ``batch, 2 workers``: :func:`imu_ground.pipeline.run_batch`
  on Dask's local process scheduler (worker start-up included).

Each run is timed in its own fresh process, as a user runs one command for a fleet:
the imports count, the interpreter start does not.

Every run writes the same files (checked: the batch outputs equal the loop's byte for
byte). Printed: logs/s, hours of driving estimated per second, and the speed-up over
the loop; target: 2 workers >= 1.7x the loop. An informative row starts two plain loops
together, each over every other log (fresh processes, no Dask): the speed-up two processes
get on this machine's two cores at all, the ceiling of the 2-worker figure. Run::

    python benchmarks/bench_batch.py                 # 200 logs of 10 minutes
    python benchmarks/bench_batch.py --n 40          # fewer logs

:func:`rows` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import argparse
import multiprocessing
import subprocess
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["TARGET_SPEEDUP", "rows", "write_logs"]

#: Target: two workers at least this many times the single-process loop (on 2 cores).
TARGET_SPEEDUP = 1.7


def _simulate(args: tuple[str, float, int]) -> None:
    from imu_ground.cli import main
    path, seconds, seed = args
    if main(["simulate", "-o", path, "--duration", str(seconds), "--seed", str(seed), "--imu", "mems"]) != 0:
        raise RuntimeError(f"simulate failed for {path}")


def write_logs(folder: Path, n: int, minutes: float, processes: int = 2) -> list[Path]:
    """``n`` synthetic logs of ``minutes`` minutes (seeds 0..n-1) written by ``imu-ground simulate``."""
    paths = [folder / f"drive{i:04d}.csv" for i in range(n)]
    jobs = [(str(p), 60.0 * minutes, i) for i, p in enumerate(paths)]
    with multiprocessing.get_context("spawn").Pool(processes) as pool:
        pool.map(_simulate, jobs, chunksize=1)
    return paths


def _loop(logs: list[Path], out: Path) -> None:
    import warnings

    from imu_ground.pipeline.estimate import estimate_to_files
    from imu_ground.pipeline.output import default_output_name
    out.mkdir()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for log in logs:
            estimate_to_files(log, [out / default_output_name(log)])


def _batch(logs: list[Path], out: Path, workers: int) -> None:
    from imu_ground.pipeline import run_batch
    table = run_batch([str(p) for p in logs], out, workers=workers)
    failed = table[table["status"] != "ok"]
    if len(failed):
        raise RuntimeError(f"batch: {len(failed)} logs failed, first: {failed.iloc[0]['error']}")


def _logs_in(folder: Path) -> list[Path]:
    """The logs :func:`write_logs` wrote into ``folder`` (not their truth files)."""
    return sorted(folder.glob("drive[0-9][0-9][0-9][0-9].csv"))


def _child(folder: str, out: str, workers: str) -> None:
    """In a fresh process: the loop (``workers`` "loop"), the loop over every other log (``"half0"``, ``"half1"``)
    or the batch over the logs of ``folder``; prints seconds."""
    logs = _logs_in(Path(folder))
    t0 = time.perf_counter()
    if workers == "loop":
        _loop(logs, Path(out))
    elif workers.startswith("half"):
        _loop(logs[int(workers[4:])::2], Path(out))
    else:
        _batch(logs, Path(out), int(workers))
    print(time.perf_counter() - t0)


def _timed_in_fresh_process(folder: Path, out: Path, workers: int | None) -> float:
    """Seconds of one run in its own fresh process (as a user runs one command a fleet): the imports are
    counted, the interpreter start is not."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).resolve().parent)!r}); "
            f"from bench_batch import _child; _child(*sys.argv[1:])")
    done = subprocess.run([sys.executable, "-c", code, str(folder), str(out), "loop" if workers is None else str(workers)],
                          check=True, capture_output=True, text=True)
    return float(done.stdout.split()[-1])


def _two_loops_side_by_side(folder: Path, out: Path) -> float:
    """Seconds until both of two fresh processes, started together, have each looped over every other log (no
    Dask, no pool): what two processes on this machine's cores can do, the ceiling of the 2-worker speed-up."""
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).resolve().parent)!r}); "
            f"from bench_batch import _child; _child(*sys.argv[1:])")
    procs = [subprocess.Popen([sys.executable, "-c", code, str(folder), str(out / f"half{k}"), f"half{k}"],
                              stdout=subprocess.PIPE, text=True) for k in (0, 1)]
    times = []
    for p in procs:
        stdout, _ = p.communicate()
        if p.returncode != 0:
            raise RuntimeError("a side-by-side loop failed")
        times.append(float(stdout.split()[-1]))
    return max(times)


def rows(n: int = 200, minutes: float = 10.0, workers: tuple[int, ...] = (1, 2)) -> list[dict]:
    """Throughput of the loop and of ``batch`` with each number of workers.

    Parameters
    ----------
    n : int
        Number of logs.
    minutes : float
        Length of each log, minutes (100 Hz MEMS IMU).
    workers : tuple of int
        Worker counts of the local cluster.

    Returns
    -------
    list of dict
        ``run``, ``logs``, ``seconds``, ``logs_per_s``, ``driving_h_per_s``,
        ``speedup_vs_loop``, and ``target``/``pass`` on the 2-worker row.
    """
    with tempfile.TemporaryDirectory(prefix="imu_ground_bench_batch_") as tmp:
        tmp = Path(tmp)
        (tmp / "logs").mkdir()
        write_logs(tmp / "logs", n, minutes)
        hours = n * minutes / 60.0
        results = []
        runs = [("loop (estimate, one process)", None)]
        runs += [(f"batch, {w} worker{'s' if w > 1 else ''}", w) for w in workers]
        for i, (name, w) in enumerate(runs):
            out = tmp / f"out{i}"
            results.append((name, _timed_in_fresh_process(tmp / "logs", out, w), out))
        side = tmp / "side"
        side.mkdir()
        results.append(("two loops side by side, every other log each (no Dask: the machine's ceiling)",
                        _two_loops_side_by_side(tmp / "logs", side), side))
        base = results[0][1]
        reference = {p.name: p.read_bytes() for p in results[0][2].glob("*_ground.csv")}
        table = []
        for name, sec, out in results:
            made = {p.name: p for p in out.rglob("*_ground.csv")}
            same = made.keys() == reference.keys() and all(made[k].read_bytes() == v for k, v in reference.items())
            row = {"run": name, "logs": n, "seconds": sec, "logs_per_s": n / sec, "driving_h_per_s": hours / sec,
                   "speedup_vs_loop": base / sec, "outputs_identical": same}
            if name.startswith("batch, 2 "):
                row["target"] = f">= {TARGET_SPEEDUP}x"
                row["pass"] = base / sec >= TARGET_SPEEDUP
            table.append(row)
        return table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="number of logs (default 200)")
    ap.add_argument("--minutes", type=float, default=10.0, help="minutes per log (default 10)")
    a = ap.parse_args()
    table = rows(a.n, a.minutes)
    print(f"{'run':32s} {'s':>8s} {'logs/s':>8s} {'h/s':>8s} {'x loop':>7s}  same  target")
    for r in table:
        tgt = f"{r.get('target', '')} {'PASS' if r.get('pass') else 'FAIL' if 'pass' in r else ''}"
        print(f"{r['run']:32s} {r['seconds']:8.1f} {r['logs_per_s']:8.3f} {r['driving_h_per_s']:8.3f} "
              f"{r['speedup_vs_loop']:7.2f}  {'yes' if r['outputs_identical'] else 'NO':4s}  {tgt}")


if __name__ == "__main__":
    main()
