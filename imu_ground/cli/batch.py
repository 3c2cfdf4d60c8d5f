"""``imu-ground batch LOG_OR_GLOB... -o OUTDIR``: estimate many logs on Dask, one output per log and a summary."""
from __future__ import annotations

import math

import argparse

from imu_ground.cli._common import (add_logs_command, add_progress_flag, add_reader_flags, nonnegative_int,
                                    progress_enabled, say)
from imu_ground.cli.estimate import add_method_flags, method_kwargs
from imu_ground.pipeline.batch import run_batch

__all__ = ["register", "run"]


def register(sub) -> None:
    """Add the ``batch`` sub-command."""
    b = add_logs_command(
        sub, "batch", help="many logs -> one output each and a summary table (Dask)",
        description="Estimate every log (paths or quoted glob patterns) on Dask: a local pool of --workers processes, "
                    "or a running cluster (--scheduler). Each output is the file 'imu-ground estimate' writes; a rerun "
                    "skips logs whose output exists with the same settings (--force replaces them); one file named "
                    "twice is estimated once; a failing log is reported in the summary and never stops the others. "
                    "One run at a time writes to a local OUTDIR (a second one exits 2 naming the running one; a lock "
                    "left by a killed run is taken over; an OUTDIR URL, s3://..., has no lock: each output is "
                    "uploaded whole, then its record, see docs/storage.md); files this tool wrote that the patterns "
                    "match (outputs, summary.csv) are skipped, not read as logs.",
        logs_metavar="LOG_OR_GLOB",
        logs_help="IMU logs or pose files, or glob patterns in quotes (e.g. 'logs/**/*.csv.gz'); URLs too (file://, "
                  "s3://bucket/logs/*.csv.gz with s3fs)",
        output_metavar="OUTDIR",
        output_help="output folder (created) or URL (s3://bucket/out): <log name>_ground.<type> per log and summary.csv")
    b.add_argument("--type", default="csv", choices=("csv", "parquet", "tum", "mcap", "bag"),
                   help="output file type of every log (default csv)")
    b.add_argument("--workers", type=nonnegative_int, metavar="N",
                   help="worker processes of the local Dask cluster (default: CPU count; never more than the "
                        "logs, nor than 4 a CPU core; 0: no Dask, one log after the other in this process)")
    b.add_argument("--scheduler", metavar="ADDRESS",
                   help="address of a running Dask scheduler (e.g. tcp://10.0.0.5:8786) instead of a local cluster")
    b.add_argument("--tum", action="store_true",
                   help="also write each log's dynamic extrinsic (ground <- sensor) of the valid frames as TUM "
                        "poses, <log name>_ground.tum")
    b.add_argument("--speed", default="auto", metavar="auto|none|FILE|COLUMN",
                   help="measured vehicle speed for the suspension methods, as for 'imu-ground estimate' "
                        "(auto by default: each log's own where its format has one; none: IMU only)")
    b.add_argument("--force", action="store_true",
                   help="estimate every log again and replace its outputs (by default a rerun keeps the outputs "
                        "that exist and were written with the same settings, and refuses those written with "
                        "other settings)")
    add_method_flags(b)
    add_reader_flags(b, poses=True)
    add_progress_flag(b)
    b.set_defaults(func=run)


def _fmt(x) -> str:
    if isinstance(x, float):
        return "" if math.isnan(x) else f"{x:+.3f}"
    return "" if x is None else str(x)


def run(a: argparse.Namespace) -> int:
    """Run the batch, print one line per log and the totals; exit 1 when a log failed."""
    table = run_batch(a.logs, a.output, workers=a.workers, scheduler=a.scheduler, suffix="." + a.type,
                      progress=progress_enabled(a), cli=True, force=a.force, tum=a.tum, speed=a.speed,
                      **method_kwargs(a))
    for _, r in table.iterrows():
        if r["status"] == "failed":
            say(f"FAILED  {r['log']}: {r['error']}")
        elif r["status"] == "duplicate":
            say(f"duplicate {r['error']}")
        else:
            share = "" if r["valid_share"] != r["valid_share"] else f"{100 * r['valid_share']:.1f}% valid"
            frames = "" if r["frames"] != r["frames"] else f"{int(r['frames'])} frames"
            fmt = _fmt(r["format"]) or "(format not recorded)"
            say(f"{r['status'][:7]:7s} {r['log']}: {fmt} {frames} {share}, pitch "
                f"{_fmt(r['pitch_mean_deg'])} +- {_fmt(r['pitch_std_deg'])} deg, roll {_fmt(r['roll_mean_deg'])} "
                f"+- {_fmt(r['roll_std_deg'])} deg" + (f"; warnings: {r['warnings']}" if _fmt(r["warnings"]) else ""))
    failed = int((table["status"] == "failed").sum())
    done = int((table["status"] == "ok").sum())
    dups = int((table["status"] == "duplicate").sum())
    say(f"{len(table) - dups} logs: {done} estimated, {len(table) - dups - done - failed} skipped (output exists), "
        f"{failed} failed" + (f", {dups} named twice" if dups else "") + f"; wrote {a.output}/summary.csv")
    return 1 if failed else 0
