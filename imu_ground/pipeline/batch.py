"""Many logs: :func:`run_batch` estimates every log on Dask, one output file per log and a summary table.

Each log is one task (:func:`process_log`): read, estimate, write its output atomically (the file
``imu-ground estimate LOG -o OUT`` writes, byte for byte), return one summary row, never the data; a
worker holds one log at a time. A failing log becomes a row with its error; the others go on. An output
that exists is complete, so a rerun skips it (resume).

Logs, patterns and the output folder may be fsspec URLs (:mod:`imu_ground.datasets.storage`). An output
folder at a URL has no lock and no rename: each output is uploaded whole, then the log's record
(:func:`record_path`), which a rerun needs to skip the log (``docs/storage.md``).
"""
from __future__ import annotations

import contextlib
import glob
import json
import multiprocessing
import os
import re
import socket
import sys
import threading
import time
import warnings
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from imu_ground.datasets import storage
from imu_ground.errors import ImuGroundError, require_extra, warn_user
from imu_ground.pipeline.estimate import OptionError, check_options, estimate_to_files, requested_options
from imu_ground.pipeline.input_checks import process_running
from imu_ground.pipeline.output import (OUTPUT_SUFFIXES, atomic_path, check_output_path, check_run_paths,
                                        default_output_name, read_output_settings, summarize_table)

__all__ = ["LOCK_NAME", "WORKERS_PER_CORE", "SUMMARY_COLUMNS", "check_existing_outputs", "expand_logs", "is_own_output",
           "output_folder_lock", "output_names", "process_log", "run_batch", "unique_logs"]

#: Columns of the summary table, in order.
SUMMARY_COLUMNS = ("log", "status", "format", "method", "frames", "valid_share", "pitch_mean_deg", "pitch_std_deg",
                   "pitch_min_deg", "pitch_max_deg", "roll_mean_deg", "roll_std_deg", "roll_min_deg", "roll_max_deg",
                   "warnings", "error", "output")
_GLOB_CHARS = set("*?[")
#: Folder (key prefix) of the records of a batch whose output folder is a URL (:func:`record_path`).
RECORD_FOLDER = ".imu-ground-batch"
#: Lock file in a batch's output folder while a run writes there (:func:`output_folder_lock`).
LOCK_NAME = ".imu-ground-batch.lock"
#: At most this many local worker processes a CPU core (``--workers`` above it is capped, with a warning).
WORKERS_PER_CORE = 4


def expand_logs(patterns: Iterable[str | Path]) -> list[tuple[str, str | None]]:
    """Logs named by paths and glob patterns (local or URLs), in order, each once: ``(log, error or None)``; a
    pattern that matches nothing gives ``(pattern, "no file matches ...")``, a plain path is kept as given."""
    out: dict[str, str | None] = {}
    for pat in patterns:
        pat = str(pat)
        url = storage.is_url(pat) or storage.local_name(pat) != pat
        if _GLOB_CHARS & set(pat) and not (storage.exists(pat) if url else Path(pat).exists()):
            matches = storage.glob(pat) if url else sorted(glob.glob(pat, recursive=True))
            if not matches:
                out.setdefault(pat, f"{pat}: no file matches this pattern")
            for m in matches:
                out.setdefault(m, None)
        else:
            out.setdefault(pat, None)
    return list(out.items())


def output_names(logs: Sequence[str], suffix: str = ".csv") -> list[str]:
    """Output file name of each log (``<name>_ground<suffix>``, a bare name), made unique with the parent folders'
    names, then a number (``_2``, ``_3``...)."""
    base = [default_output_name(log, suffix) for log in logs]
    names = list(base)
    for depth in range(1, 8):
        counts = Counter(names)
        clash = [i for i, n in enumerate(names) if counts[n] > 1]
        if not clash:
            break
        for i in clash:
            if storage.is_url(logs[i]):
                parents = list(storage.url_parts(logs[i]))[-depth:]
            else:
                folder = Path(os.path.abspath(storage.local_name(logs[i]))).parent
                parents = list(folder.parts[1:] if folder.anchor else folder.parts)[-depth:]   # never the root
            names[i] = "_".join([*parents, base[i]])
    seen: dict[str, int] = {}
    for i, n in enumerate(names):
        seen[n] = seen.get(n, 0) + 1
        if seen[n] > 1:
            stem, dot, ext = n.partition(".")
            names[i] = f"{stem}_{seen[n]}{dot}{ext}"
    return names


def unique_logs(found: Sequence[tuple[str, str | None]]) -> tuple[list[tuple[str, str | None]], dict[str, str]]:
    """Drop the logs that name a file already listed (``a/x.csv`` and ``a/../a/x.csv``, symbolic links).

    Returns
    -------
    kept : list of (log, error or None)
        :func:`expand_logs`' entries, each file once (the first spelling).
    duplicates : dict
        Dropped spelling -> the kept spelling of the same file.
    """
    first: dict[str, str] = {}
    kept: list[tuple[str, str | None]] = []
    dup: dict[str, str] = {}
    for log, err in found:
        key = log if err is not None or storage.is_url(log) else os.path.realpath(storage.local_name(log))
        if key in first:
            dup[log] = first[key]
            continue
        first[key] = log
        kept.append((log, err))
    return kept, dup


def is_own_output(path: str | Path, out_dir: str | Path | None = None) -> bool:
    """Whether ``path`` is a file this tool wrote, not a log: an output recording its settings, a summary (starting
    with :data:`SUMMARY_COLUMNS`), or a ROS output named ``*_ground.bag`` / ``*_ground.mcap`` inside ``out_dir``."""
    url = storage.local_name(path)
    remote = storage.is_url(url)
    p = Path(storage.url_name(url) if remote else url)
    if not remote and not p.is_file():
        return False
    if read_output_settings(url if remote else p) is not None:
        return True
    if p.suffix.lower() == ".csv":
        try:
            with storage.open_file(url if remote else p, "r", errors="replace") as fh:
                if fh.readline().rstrip("\r\n") == ",".join(SUMMARY_COLUMNS):
                    return True
        except (OSError, ValueError):
            return False
    if out_dir is None or not p.name.endswith(("_ground.bag", "_ground.mcap")):
        return False
    if remote:
        return str(url).rsplit("/", 1)[0] == str(storage.local_name(out_dir)).rstrip("/")
    return p.parent.resolve() == Path(out_dir).resolve()


def _recorded_format_method(out: Path) -> dict[str, Any]:
    """The format and method an existing output records (what a skipped log's summary row shows)."""
    info: dict[str, Any] = {}
    if out.suffix == ".csv":
        with open(out, encoding="utf-8") as fh:
            m = re.search(r"estimate: format (\S+), method (\S+)", fh.readline())
        if m:
            info = {"format": m.group(1), "method": m.group(2)}
    elif out.suffix == ".parquet":
        import pyarrow.parquet as pq
        raw = (pq.read_schema(out).metadata or {}).get(b"imu_ground")
        meta = json.loads(raw) if raw else {}
        info = {k: meta.get(k) for k in ("format", "method")}
    if not info.get("method"):
        info["method"] = (read_output_settings(out) or {}).get("method")
    return {k: v for k, v in info.items() if v}


def _skipped_row(out: Path) -> dict[str, Any]:
    row: dict[str, Any] = {"status": "skipped (output exists)"}
    try:
        if out.suffix in (".csv", ".parquet"):
            import pandas as pd
            row.update(summarize_table(pd.read_csv(out, comment="#") if out.suffix == ".csv" else pd.read_parquet(out)))
        row.update(_recorded_format_method(out))
    except Exception as e:                                   # noqa: BLE001 - the row reports it
        row["warnings"] = f"{out}: could not summarise the existing output ({e})"
    return row


def process_log(log: str, out: str | Path, options: dict, cli: bool = False, force: bool = False,
                extra: Sequence[tuple[str | Path, str]] = ()) -> dict[str, Any]:
    """One task: estimate ``log`` into ``out`` unless its outputs exist; one summary row, never an exception.

    Parameters
    ----------
    log : str
    out : str or Path
    options : dict
        :func:`~imu_ground.pipeline.estimate_log` keywords.
    cli : bool
        Errors with the options spelled as command-line flags.
    force : bool
        Estimate even when the outputs exist.
    extra : sequence of (path, kind)
        Further outputs of the same table (e.g. ``(".../x_ground.tum", ".tum")``).
    """
    out = _as_path(out)
    row: dict[str, Any] = {"log": log, "output": str(out)}
    paths = [out, *(_as_path(p) for p, _ in extra)]
    record = record_path(out) if isinstance(out, str) else None
    if not force and all(storage.exists(p) for p in paths) and (record is None or storage.exists(record)):
        row.update(_skipped_row(Path(out)) if record is None else _recorded_row(record))
        return row
    try:
        for p in paths:
            check_output_path(p, [log])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res, table = estimate_to_files(log, paths, [None, *(k for _, k in extra)], **options)
        done = {**row, "status": "ok", "format": res.meta.get("format"), "method": res.meta.get("method"),
                **summarize_table(table)}
        if record is not None:          # after every output: the record says they are all complete
            storage.write_bytes(record, json.dumps({"outputs": [str(p) for p in paths], "row": done}).encode())
    except Exception as e:                                   # noqa: BLE001 - a failing log never stops the others
        message = " ".join(str(e.cli_message() if cli and hasattr(e, "cli_message") else e).split())
        if not isinstance(e, (ImuGroundError, OSError)):              # not bad input: a bug, said so
            message = f"bug: unexpected {type(e).__name__}: {message} (please report it)"
        row.update(status="failed", error=message or type(e).__name__)
        return row
    row.update(done, warnings=" | ".join(res.meta.get("warnings", [])))
    return row


def _as_path(path: str | Path) -> str | Path:
    """A local path as a Path, a URL as it is (``file://`` URLs are local paths)."""
    path = storage.local_name(path)
    return path if storage.is_url(path) else Path(path)


def record_path(out: str) -> str:
    """The record of a batch output at a URL, ``OUTDIR/.imu-ground-batch/<output name>.json``, written after all the
    log's outputs: they are complete; it holds the log's summary row."""
    return str(storage.join(out.rsplit("/", 1)[0], f"{RECORD_FOLDER}/{storage.url_name(out)}.json"))


def _recorded_row(record: str) -> dict[str, Any]:
    """The summary row of a skipped log whose outputs are at URLs, from its record."""
    row: dict[str, Any] = {"status": "skipped (output exists)"}
    try:
        with storage.open_file(record, "rb") as fh:
            done = json.load(fh)["row"]
        row.update({k: done.get(k) for k in SUMMARY_COLUMNS if k not in ("log", "status", "error", "output",
                                                                           "warnings")})
    except Exception as e:                                   # noqa: BLE001 - the row reports it
        row["warnings"] = f"{record}: could not read the record of the existing output ({e})"
    return row


def _settings_change(recorded: dict | None, wanted: dict) -> str | None:
    """What differs between an output's recorded options and this run's (None: nothing, or not recorded)."""
    if recorded is None:
        return None                                  # a ROS bag / MCAP: no record read back; kept as before
    have = recorded.get("options")
    if not isinstance(have, dict):
        return "written without a record of its options (an earlier version)"
    diff = [f"{k} {have.get(k)!s} -> {wanted.get(k)!s}" for k in sorted(set(have) | set(wanted))
            if have.get(k) != wanted.get(k)]
    return ", ".join(diff) or None


def check_existing_outputs(paths: Iterable[str | Path], options: dict) -> None:
    """Refuse to keep outputs that were written with other options than ``options`` (``force`` replaces them).

    Raises
    ------
    OptionError
        Naming the first such output, what changed and ``force`` (``--force``).
    """
    wanted = requested_options(**{k: v for k, v in options.items() if k != "progress"})
    changed = []
    for p in paths:
        p = _as_path(p)
        if storage.exists(p):
            what = _settings_change(read_output_settings(p), wanted)
            if what:
                changed.append((p, what))
    if changed:
        p, what = changed[0]
        more = f" ({len(changed) - 1} more outputs likewise)" if len(changed) > 1 else ""
        raise OptionError(f"{p}: exists and was written with other settings ({what}){more}; a rerun would keep "
                          "it: pass {opt} to estimate again and replace it, or choose another output folder",
                          "force", "--force")


@contextlib.contextmanager
def output_folder_lock(out_dir: str | Path, option: str = "-o") -> Iterator[Path]:
    """Hold the batch lock of an output folder (:data:`LOCK_NAME`) for the block; a second run is refused.

    The lock file records the holder (process id, host, start time, command) and is a kernel lock
    (``flock``; without it, the recorded process id decides). One left by a process that no longer runs
    is taken over with a warning.

    Raises
    ------
    OptionError
        Another run holds the lock: naming it and ``option``.
    """
    path = Path(out_dir) / LOCK_NAME
    try:
        import fcntl
    except ImportError:                                 # not a POSIX system: the recorded process id decides
        fcntl = None  # type: ignore[assignment]  # (mypy takes the module as always there)
    for _ in range(10):
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            if fcntl is not None:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            holder = _lock_holder(fd)
            if fcntl is None and holder and holder.get("host") == socket.gethostname() and \
                    process_running(int(holder.get("pid", -1))):
                raise BlockingIOError
            if os.path.samestat(os.fstat(fd), os.stat(path)):
                break                                   # not a file removed by its holder meanwhile
        except BlockingIOError:
            holder = _lock_holder(fd)
            os.close(fd)
            raise OptionError(f"{out_dir}: another imu-ground batch is writing to this folder ({_describe(holder)}); "
                              "wait for it to finish or give {opt} another folder", "outdir", flag=option) from None
        except FileNotFoundError:
            pass
        os.close(fd)
    else:
        raise OptionError(f"{path}: could not take the batch lock; give {{opt}} another folder", "outdir", flag=option)
    if holder:
        warn_user(f"{out_dir}: an earlier batch that wrote here ({_describe(holder)}) no longer runs; its lock "
                      "is taken over (its outputs are complete or absent: writes are atomic)", UserWarning)
    me = {"pid": os.getpid(), "host": socket.gethostname(),
          "started": time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime()), "command": " ".join(sys.argv)}
    os.ftruncate(fd, 0)
    os.pwrite(fd, (json.dumps(me) + "\n").encode(), 0)
    try:
        yield path
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        os.close(fd)


def _lock_holder(fd: int) -> dict:
    try:
        data = os.pread(fd, 65536, 0)
        holder = json.loads(data) if data.strip() else {}
    except (OSError, ValueError):
        return {"pid": "?"}
    return holder if isinstance(holder, dict) else {"pid": "?"}


def _describe(holder: dict) -> str:
    return (f"pid {holder.get('pid', '?')}" + (f" on {holder['host']}" if holder.get("host") else "")
            + (f", started {holder['started']}" if holder.get("started") else "")
            + (f": {holder['command']}" if holder.get("command") else ""))


def run_batch(logs: Iterable[str | Path], outdir: str | Path, *, workers: int | None = None,
              scheduler: str | None = None, suffix: str = ".csv", progress: bool = False, cli: bool = False,
              summary: str | None = "summary.csv", force: bool = False, tum: bool = False, **options: Any):
    """Estimate every log into ``outdir`` on Dask; returns the summary table.

    Parameters
    ----------
    logs : iterable of str or Path
        Log paths and glob patterns (``"logs/**/*.csv.gz"``).
    outdir : str or Path
        Output folder (created); one ``<log name>_ground<suffix>`` per log.
    workers : int, optional
        Worker processes of Dask's local process pool (default: CPU count); 0: one log after the other in
        this process, without Dask.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``) to use instead.
    suffix : str
        Output type, one of :data:`~imu_ground.pipeline.output.OUTPUT_SUFFIXES`.
    progress, cli : bool
        Progress bar counting logs; error messages naming command-line flags.
    summary : str, optional
        File name of the summary CSV in ``outdir`` (None: not written).
    force : bool
        Estimate every log again. Without it an existing output recording the same options is kept (resume),
        and one written with other options raises :class:`~imu_ground.pipeline.estimate.OptionError` first.
    tum : bool
        Also write each log's dynamic extrinsic as TUM poses, ``<log name>_ground.tum``.
    **options
        :func:`~imu_ground.pipeline.estimate_log` keywords.

    Returns
    -------
    pandas.DataFrame
        :data:`SUMMARY_COLUMNS`, one row per log in input order, then one row (status ``"duplicate"``) per
        path that named a file already listed.
    """
    if suffix not in OUTPUT_SUFFIXES:
        raise ImuGroundError(f"unknown output type {suffix!r}; choose from {', '.join(OUTPUT_SUFFIXES)}")
    check_options(**{k: v for k, v in options.items() if k not in ("extrinsic", "progress", "speed")})
    found = [str(p) for p in ([logs] if isinstance(logs, (str, Path)) else logs)]
    out_dir = storage.local_name(str(outdir))
    in_memory = [p for p in [out_dir, *found] if storage.is_url(p) and p.lower().startswith("memory://")]
    if in_memory and (workers != 0 or scheduler):
        raise OptionError(f"{in_memory[0]}: memory:// is the memory of this process, which worker processes do "
                          "not share: pass {opt}=0 (one log after the other in this process)", "workers")
    if storage.is_url(out_dir):         # object storage: no folder, no lock (docs/storage.md)
        fs, key = storage.filesystem(out_dir)
        if fs.isfile(key):
            raise ImuGroundError(f"{out_dir}: is a file; give -o an output folder")
        storage.check_bucket(out_dir, "-o" if cli else "outdir")
        return _run_batch_locked(found, out_dir.rstrip("/"), workers, scheduler, suffix, progress, cli, summary,
                                 force, tum, options)
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ImuGroundError(f"{out_dir}: is a file; give -o an output folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    with output_folder_lock(out_dir, "-o" if cli else "outdir"):
        return _run_batch_locked(found, out_dir, workers, scheduler, suffix, progress, cli, summary, force, tum,
                                 options)


def _run_batch_locked(logs, out_dir: Path | str, workers, scheduler, suffix, progress, cli, summary, force, tum, options):
    """:func:`run_batch` once the output folder is locked (a local folder) or checked (a URL)."""
    import pandas as pd
    from tqdm.auto import tqdm

    found = expand_logs(logs)
    own = [log for log, err in found if err is None and is_own_output(log, out_dir)]
    if own:
        more = f" and {len(own) - 1} more" if len(own) > 1 else ""
        warn_user(f"{own[0]}{more}: written by imu-ground (outputs or a summary), not logs: skipped", UserWarning)
        found = [(log, err) for log, err in found if log not in set(own)]
    found, duplicates = unique_logs(found)
    names = output_names([log for log, _ in found], suffix)
    extra_kind = ".tum" if tum and suffix != ".tum" else None
    rows: list[dict | None] = [None] * len(found)
    jobs = []
    for i, ((log, err), name) in enumerate(zip(found, names, strict=True)):
        if err is not None:
            rows[i] = {"log": log, "status": "failed", "error": err}
        else:
            out = storage.join(out_dir, name)
            extra = [(str(storage.with_suffix(out, extra_kind)), extra_kind)] if extra_kind else []
            jobs.append((i, log, str(out), extra))
    planned = [p for _, _, out, extra in jobs for p in [out, *(e for e, _ in extra)]]     # local paths or URLs
    _check_batch_paths(out_dir, planned + ([str(storage.join(out_dir, summary))] if summary else []), options, cli)
    if not force:
        check_existing_outputs(planned, options)
    local = bool(jobs) and workers != 0 and not scheduler
    # the local worker processes start before the progress bar (whose monitor thread would make forking unsafe)
    with _local_pool(workers, len(jobs), cli) if local else contextlib.nullcontext() as pool:
        bar = tqdm(total=len(found), desc="logs", unit="log", disable=not progress)
        bar.update(len(found) - len(jobs))
        if pool is not None:
            _run_local(jobs, rows, options, cli, force, pool, bar)
        elif scheduler:
            _run_on_dask(jobs, rows, options, cli, force, scheduler, bar)
        else:
            for i, log, out_name, extra in jobs:
                rows[i] = process_log(log, out_name, options, cli, force, extra)
                bar.update()
        bar.close()
    rows += [{"log": log, "status": "duplicate", "error": f"{log}: the same file as {kept}, estimated once"}
             for log, kept in duplicates.items()]
    table = pd.DataFrame(rows).reindex(columns=list(SUMMARY_COLUMNS))
    if summary:
        with atomic_path(storage.join(out_dir, summary)) as tmp:
            table.to_csv(tmp, index=False, float_format="%.6g")
    return table


def _check_batch_paths(out_dir: str | Path, planned: Sequence[str | Path], options: dict, cli: bool) -> None:
    """Before any work: no output is an input the user named, and none would replace a file in the output folder that
    this tool did not write (:class:`OptionError` naming the file and ``-o``)."""
    flag = (lambda name: "--" + name.replace("_", "-")) if cli else (lambda name: name)
    check_run_paths([("-o" if cli else "outdir", p) for p in planned],
                    [(flag(k), options.get(k)) for k in ("speed", "extrinsic", "times")
                     if isinstance(options.get(k), (str, Path))])
    foreign = [p for p in planned if storage.exists(p) and not is_own_output(p, out_dir)]
    if foreign:
        names = ", ".join(str(p).replace("\\", "/").rsplit("/", 1)[-1] for p in foreign[1:4])
        more = f" (and {len(foreign) - 1} more: {names})" if len(foreign) > 1 else ""
        raise OptionError(f"{foreign[0]}: exists and imu-ground did not write it (it holds no record of an "
                          f"imu-ground run){more}; the batch would replace it: move it away or give {{opt}} another "
                          "output folder; nothing was changed", "outdir", flag="-o" if cli else None)


def _start_method() -> str:
    """``"fork"`` where the platform has it and this process runs no other Python thread (safe only then), else
    ``"spawn"``."""
    if "fork" in multiprocessing.get_all_start_methods() and threading.active_count() == 1:
        return "fork"
    return "spawn"


@contextlib.contextmanager
def _local_pool(workers: int | None, n_logs: int, cli: bool = False) -> Iterator[ProcessPoolExecutor]:
    """``workers`` (default: CPU count) worker processes, started now; at most one a log and
    :data:`WORKERS_PER_CORE` a CPU core (warned)."""
    require_extra("dask.multiprocessing", "fleet", "imu-ground batch")      # checked before any worker starts
    cores = os.cpu_count() or 1
    n = min(int(workers) if workers else cores, max(1, n_logs))
    if n > WORKERS_PER_CORE * cores:
        limit = WORKERS_PER_CORE * cores
        warnings.warn(f"{'--workers' if cli else 'workers'} {n} capped to {limit} ({WORKERS_PER_CORE} a CPU core "
                      f"of {cores}: each worker holds a whole log in memory)", stacklevel=3)
        n = limit
    with ProcessPoolExecutor(n, mp_context=multiprocessing.get_context(_start_method())) as pool:
        pool.submit(int).result()       # a forking pool starts all its workers at the first task
        yield pool


def _run_local(jobs, rows, options, cli, force, pool: ProcessPoolExecutor, bar) -> None:
    """The logs on Dask's local process scheduler over ``pool``, one task a log at a time (the scheduler passed as a
    function, so Dask does not look for a ``dask.distributed`` client)."""
    import dask
    from dask.callbacks import Callback
    from dask.multiprocessing import get as process_scheduler

    class _Progress(Callback):
        def _posttask(self, key, result, dsk, state, worker_id):
            bar.update()

    tasks = [dask.delayed(process_log, pure=False)(log, out, options, cli, force, extra)
             for _, log, out, extra in jobs]
    with _Progress():
        results = dask.compute(*tasks, scheduler=process_scheduler, pool=pool, chunksize=1)
    for (i, *_), row in zip(jobs, results, strict=True):
        rows[i] = row


def _run_on_dask(jobs, rows, options, cli, force, scheduler, bar) -> None:
    """The logs on a running dask.distributed cluster; a worker that dies fails its log only."""
    distributed = require_extra("dask.distributed", "fleet", "imu-ground batch --scheduler")
    client = distributed.Client(scheduler, timeout="10s")
    from dask.distributed import as_completed
    try:
        futures = {client.submit(process_log, log, out, options, cli, force, extra, pure=False): (i, log)
                   for i, log, out, extra in jobs}
        for fut in as_completed(futures):
            i, log = futures[fut]
            try:
                rows[i] = fut.result()
            except Exception as e:                           # noqa: BLE001 - e.g. a worker killed by memory
                rows[i] = {"log": log, "status": "failed", "error": f"{log}: worker failed: {e}"}
            bar.update()
    finally:
        client.close()
