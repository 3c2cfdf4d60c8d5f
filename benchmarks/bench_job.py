"""The whole ``imu-ground estimate`` job on a 10 h log against ``pandas.read_csv`` of the same file, with its stages.

Run: ``python benchmarks/bench_job.py [--hours 10] [--repeat 3] [--tmp DIR] [--before PYTHON]``.

The log (issue 30): shared kitti_imu100 drive ``2011_10_03_drive_0042`` tiled to ``hours``
(its stamps continued, jitter included) by :func:`bench_readers.make_log`, written with gzip
level 1 (``.csv.gz``) and as plain CSV, in a temporary folder (never the repository). Cases:
the gzip log to a CSV output, the plain log to a CSV output, the gzip log to a Parquet output;
the log's INS speed is used (``--speed auto``, the default).

Each figure is a whole fresh process (wall clock from start to exit, with its CPU time; peak
RSS from the kernel), the median of ``--repeat`` rounds; in each round every case's
``imu-ground estimate`` and ``python -c "import pandas; pandas.read_csv(LOG)"`` (the competitor)
run one after the other, so both meet the same load of the shared machine (the 1-minute load
average is printed). With ``--before PYTHON`` (or ``IMU_GROUND_BENCH_BEFORE``), an interpreter
whose ``imu_ground`` is another checkout (the code before a change), that version runs in the
same rounds too.

Targets (issue 30): ``imu-ground estimate`` <= 1.5x ``pandas.read_csv`` of the same file in wall
time, and peak RSS <= 1.5x pandas', for each case.

The stages (one fresh process per case and version, informative): read (``read_imu``),
standstill masks and gyro bias, preintegration, the frame speeds, the filter proper, then its
outputs (1-sigma, road grade and bank, mount monitor, status), the table, the writer; wall and
CPU seconds of each, and the peak RSS after each top-level stage. Stages are timed by wrapping
the package's own functions by name, so the same probe times an older checkout. A row per case
sets the job's CPU time (the timed runs' median) beside the room the target leaves on this
machine's cores (1.5x pandas' wall time, times the cores), and the work after the read beside the
allowed wall time alone.
:func:`rows` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bytecode import compile_package
from bench_readers import SHARED, make_log

__all__ = ["CASES", "DRIVE", "LIMIT", "main", "rows"]

REPO = Path(__file__).resolve().parents[1]
#: The shared drive tiled into the long log (issue 30's construction).
DRIVE = SHARED / "kitti_imu100" / "2011_10_03_drive_0042.csv.gz"
#: Largest ratio to pandas.read_csv of the same file, wall time and peak RSS.
LIMIT = 1.5
#: (name, gzip-compressed log, output suffix).
CASES = (("gzip log -> CSV", True, ".csv"), ("plain CSV log -> CSV", False, ".csv"),
         ("gzip log -> Parquet", True, ".parquet"))

_PANDAS = "import sys, pandas as pd; pd.read_csv(sys.argv[1])"

#: The stage probe: wraps the package's functions by name (in every module that holds them), runs estimate_to_files.
_STAGES = r"""
import importlib, json, resource, sys, time, warnings
warnings.simplefilter("ignore")
log, out = sys.argv[1], sys.argv[2]
t_start = time.perf_counter()
import imu_ground.pipeline.estimate as est
for name in ("imu_ground.filters.confidence", "imu_ground.filters.suspension", "imu_ground.filters.road",
             "imu_ground.filters.mount_monitor", "imu_ground.filters.status", "imu_ground.imu.standstill"):
    try:
        importlib.import_module(name)
    except ImportError:                 # (a module of another version)
        pass
stages, order = {}, []

def timer(fn, label):
    def timed(*a, **k):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            return fn(*a, **k)
        finally:
            s = stages.setdefault(label, [0.0, 0.0, 0.0])
            s[0] += time.perf_counter() - t0
            s[1] += time.process_time() - c0
            s[2] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return timed

def wrap(name, label):
    # a function: every module that holds it; "Class.method": the class of the package that has it
    if label not in order:
        order.append(label)
    mods = [m for k, m in list(sys.modules.items()) if k.startswith("imu_ground") and m is not None]
    if "." in name:
        cls_name, meth = name.split(".")
        for m in mods:
            cls = getattr(m, cls_name, None)
            if isinstance(cls, type) and meth in vars(cls) and cls.__module__ == m.__name__:
                setattr(cls, meth, timer(vars(cls)[meth], label))
        return
    for fn in {id(getattr(m, name)): getattr(m, name) for m in mods if callable(getattr(m, name, None))}.values():
        timed = timer(fn, label)
        for m in mods:
            if getattr(m, name, None) is fn:
                setattr(m, name, timed)

wrap("read_imu", "read")
wrap("imu_to_egomotion", "ego-motion (standstill + preintegration)")
wrap("estimate_gyro_bias", "  standstill: gyro bias")
wrap("detect_standstill", "  standstill: frame flags")
wrap("preintegrate", "  preintegration")
wrap("_frame_speeds", "frame speeds")
wrap("_run_method", "filter (with its outputs)")
wrap("suspension_confidence", "  outputs: 1-sigma, road, monitor, status")              # (before the rooms merge)
wrap("SuspensionAwareFilter._track_confidence", "  outputs: 1-sigma, road, monitor, status")
wrap("RoadFilter.run", "    road grade and bank")
wrap("RoadFilter.gravity_pass", "    road: its gravity pass (a second thread on long batches, overlapped)")
wrap("monitor_track", "    mount monitor")                                           # (a function, then a method)
wrap("MountMonitor.run", "    mount monitor")
wrap("track_statuses", "    status")
wrap("SigmaModel.statuses", "    status")
wrap("track_reasons", "    status")
wrap("result_table", "table")
wrap("write_outputs", "write")
t0 = time.perf_counter()
est.estimate_to_files(log, [out])
total = time.perf_counter() - t0
print(json.dumps({"stages": stages, "order": order, "total": total, "imports": t0 - t_start,
                  "rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _process(cmd: list[str], cwd: Path) -> tuple[float, float, float]:
    """(wall s, CPU s, peak RSS MiB) of one whole process; raises on a failure."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=cwd)
    _, status, usage = os.wait4(p.pid, 0)
    dt = time.perf_counter() - t0
    err = p.stderr.read().decode() if p.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(cmd[:4])} failed: {err.strip()[-400:]}")
    return dt, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def _load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def _source(python: str) -> Path:
    """The checkout whose ``imu_ground`` this interpreter imports (the working folder of its runs).

    Asked from the file system's root: from a checkout's folder ``python -c`` would import that
    checkout's package (the folder comes first on ``sys.path``), whatever the interpreter installs.
    """
    out = subprocess.run([python, "-c", "import imu_ground, pathlib; print(pathlib.Path(imu_ground.__file__)"
                                        ".resolve().parents[1])"], capture_output=True, text=True, check=True,
                         cwd=Path(REPO.anchor))
    return Path(out.stdout.strip())


def _stages(python: str, log: Path, out: Path) -> dict:
    proc = subprocess.run([python, "-c", _STAGES, str(log), str(out)], capture_output=True, text=True,
                          cwd=_source(python))
    if proc.returncode != 0:
        return {"error": proc.stderr.strip()[-300:]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _stage_text(st: dict) -> str:
    if "error" in st:
        return f"failed: {st['error']}"
    parts = [f"imports {st['imports']:.2f} s"]
    for name in [k for k in st["order"] if k in st["stages"]]:
        wall, cpu, rss = st["stages"][name]
        parts.append(f"{name.strip()} {wall:.2f} s (CPU {cpu:.2f}" + (f", peak {rss:,.0f} MiB)" if not
                                                                      name.startswith(" ") else ")"))
    return "; ".join(parts) + f"; whole job {st['total']:.2f} s, peak {st['rss']:,.0f} MiB"


def measure(hours: float, folder: Path, repeat: int, versions: dict[str, str]) -> dict:
    """Every case's runs (each version's estimate and pandas, interleaved) and stages."""
    logs = {True: make_log(hours, folder, DRIVE, gzip_level=1), False: make_log(hours, folder, DRIVE)}
    runs: dict[tuple[str, str], list[tuple[float, float, float]]] = {}
    loads = [_load()]
    for _ in range(repeat):
        for case, gz, suffix in CASES:
            log = logs[gz]
            for version, python in versions.items():
                cmd = [python, "-m", "imu_ground", "estimate", str(log), "-o", str(folder / f"out_{version}{suffix}"),
                       "--no-progress"]
                runs.setdefault((case, version), []).append(_process(cmd, _source(python)))
                runs.setdefault((case, "pandas"), []).append(_process([versions["after"], "-c", _PANDAS, str(log)],
                                                                      REPO))
        loads.append(_load())
    stages = {(case, v): _stages(py, logs[gz], folder / f"stages_{v}{suffix}")
              for case, gz, suffix in CASES for v, py in versions.items()}
    loads.append(_load())
    return {"logs": {k: (p.name, p.stat().st_size / 1e6) for k, p in logs.items()}, "runs": runs,
            "stages": stages, "load": loads}


def _median(rr: list[tuple[float, float, float]], i: int) -> float:
    return statistics.median(r[i] for r in rr)


def rows(hours: float | tuple[float, ...] = 10.0, repeat: int = 3, folder: Path | None = None,
         before: str | None = None) -> list[dict[str, object]]:
    """The benchmark as table rows: ``benchmark``, ``target``, ``figure``, ``passed`` (None: informative).

    ``hours``: the log's length (of a sequence, the longest: make_results' ``--quick`` passes one);
    ``before``: see the module docstring.
    """
    hours = float(max(hours)) if isinstance(hours, (tuple, list)) else float(hours)
    before = before or os.environ.get("IMU_GROUND_BENCH_BEFORE") or None
    versions = {"after": sys.executable, **({"before": before} if before else {})}
    tmp = tempfile.TemporaryDirectory(prefix="imu_ground_job_") if folder is None else None
    where = Path(tmp.name) if tmp else Path(folder)  # type: ignore[arg-type]
    compile_package()
    try:
        m = measure(hours, where, repeat, versions)
    finally:
        if tmp:
            tmp.cleanup()
    load = f"load {min(m['load']):.1f}-{max(m['load']):.1f}"
    out: list[dict[str, object]] = []
    for case, gz, _ in CASES:
        name, mb = m["logs"][gz]
        pd_runs = m["runs"][(case, "pandas")]
        pt, pc, pm = (_median(pd_runs, i) for i in range(3))
        for version in sorted(versions, reverse=True):          # before, then after
            rr = m["runs"][(case, version)]
            et, ec, em = (_median(rr, i) for i in range(3))
            rt, rm = et / pt, em / pm
            walls = ", ".join(f"{r[0]:.1f}" for r in rr)
            theirs = ", ".join(f"{r[0]:.1f}" for r in pd_runs)
            label = "" if len(versions) == 1 else f" ({version})"
            out.append({"benchmark": f"imu-ground estimate, {hours:g} h, {case}{label} ({mb:.0f} MB log)",
                        "target": f"<= {LIMIT:g}x pandas.read_csv of the same file, wall and peak RSS",
                        "figure": f"{et:.2f} s (CPU {ec:.2f}), {em:,.0f} MiB; pandas.read_csv {pt:.2f} s "
                                  f"(CPU {pc:.2f}), {pm:,.0f} MiB; ratio {rt:.2f} wall (CPU {ec / pc:.2f}), "
                                  f"{rm:.2f} RSS; runs {walls} s, pandas {theirs} s; {load}",
                        "passed": bool(rt <= LIMIT and rm <= LIMIT)})
    ncpu = os.cpu_count() or 1
    for case, _, _ in CASES:                            # the room the target leaves, against the job's work
        pt = _median(m["runs"][(case, "pandas")], 0)
        ec = _median(m["runs"][(case, "after")], 1)
        st = m["stages"][(case, "after")]
        read = st["stages"]["read"][1] if "stages" in st and "read" in st["stages"] else float("nan")
        allowed = LIMIT * pt
        out.append({"benchmark": f"imu-ground estimate, {hours:g} h, {case}: its work against the target's room",
                    "target": "informative", "passed": None,
                    "figure": f"the target allows {LIMIT:g} x {pt:.2f} = {allowed:.2f} s wall, {ncpu * allowed:.2f} "
                              f"CPU s on this machine's {ncpu} cores; the job used {ec:.2f} CPU s "
                              f"({ec / (ncpu * allowed):.2f}x that room); the read alone {read:.2f} CPU s, the rest "
                              f"(ego-motion, filters and outputs, table, writer) {ec - read:.2f} CPU s: "
                              f"{(ec - read) / allowed:.2f}x the allowed wall time"})
    for case, _, _ in CASES:
        for version in sorted(versions, reverse=True):
            label = "" if len(versions) == 1 else f" ({version})"
            out.append({"benchmark": f"imu-ground estimate, {hours:g} h, {case}{label}, by stage (one process)",
                        "target": "informative", "figure": _stage_text(m["stages"][(case, version)]),
                        "passed": None})
    return out


def main(argv: list[str] | None = None) -> None:
    """Print target, figure and pass/fail for each row."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3, help="median of this many rounds of fresh processes")
    ap.add_argument("--tmp", type=Path, help="folder for the generated logs (kept); default a temporary one")
    ap.add_argument("--before", help="interpreter of another checkout, timed in the same rounds")
    args = ap.parse_args(argv)
    if not DRIVE.is_file():
        sys.exit(f"{DRIVE}: shared drive not found (set IMU_GROUND_SHARED_DATA)")
    for r in rows(args.hours, args.repeat, args.tmp, args.before):
        verdict = {True: "PASS", False: "FAIL", None: "info"}[r["passed"]]
        print(f"{verdict}  {r['benchmark']}: target {r['target']}: {r['figure']}")


if __name__ == "__main__":
    main()
