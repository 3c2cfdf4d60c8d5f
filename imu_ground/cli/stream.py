"""``imu-ground stream``: samples in (stdin CSV lines, or a log replayed), one line per frame out, as it completes.

The command-line form of :class:`imu_ground.pipeline.streaming.StreamingEstimator`. Standard input: a header naming
``t,wx,wy,wz,ax,ay,az`` (any order and case; optionally ``speed``, m/s, or ``--speed COLUMN`` / ``--speed FILE``)
then one sample a line (a line that does not parse: said with its number, skipped); units s, rad/s, m/s^2 or
``--time-unit``, ``--gyro-unit``, ``--accel-unit``. ``--replay LOG`` feeds a log with its stamps as recorded
(:func:`~imu_ground.pipeline.live_replay.replay`, as ``estimate --causal``); ``--realtime`` paces it on the log's
clock. Each frame is written (and flushed) as soon as it is complete: a CSV line (header first) or ``--json`` lines.
``--state FILE`` resumes from a saved state and writes it at the end, on SIGTERM and on Ctrl-C (atomically; a file
that is not a saved state is refused, never replaced); with ``--replay`` it also holds how far into the log it got,
and a run on the same log resumes there.
"""
from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
import time
from pathlib import Path

from imu_ground.cli._common import add_reader_flags, input_paths, reader_options
from imu_ground.filters.methods import default_method, live_methods

__all__ = ["register", "run"]

_SAMPLE_COLUMNS = ("t", "wx", "wy", "wz", "ax", "ay", "az")


def register(sub) -> None:
    """Add the ``stream`` sub-command."""
    p = sub.add_parser("stream", help="samples in (stdin CSV or --replay LOG), one estimate line per frame out",
                       description="Live estimation: IMU samples (and a speed) from standard input as CSV lines, "
                                   "or a log replayed sample by sample; one output line per frame as soon as it "
                                   "is complete (the numbers of 'imu-ground estimate --causal').")
    p.add_argument("--replay", metavar="LOG", help="feed this log (any format estimate reads) sample by sample "
                                                   "instead of standard input")
    p.add_argument("--realtime", action="store_true", help="with --replay: pace the samples on the log's clock")
    p.add_argument("--json", action="store_true", help="one JSON object a line instead of CSV")
    p.add_argument("--state", metavar="FILE", help="load this saved state at the start (when the file exists) and "
                                                   "write the state there at the end, on SIGTERM and on Ctrl-C")
    g = p.add_argument_group("estimation")
    live = live_methods()
    g.add_argument("--method", default="auto", choices=["auto", *live], metavar="NAME",
                   help=f"auto ({default_method(True)}, default), {', '.join(live[:-1])} or {live[-1]}")
    g.add_argument("--extrinsic", metavar="NAME_OR_FILE",
                   help="static sensor-to-ground extrinsic (kitti_imu, or a file from 'imu-ground calibrate')")
    g.add_argument("--rate", type=float, default=10.0, metavar="HZ", help="frame rate, Hz (default 10)")
    g.add_argument("--camera", metavar="NAME_OR_FILE", help="a camera on the platform: lines gain plane_a .. plane_d")
    g.add_argument("--speed", default="auto", metavar="auto|none|FILE|COLUMN",
                   help="the speed (as estimate's): with --replay the log's or this; standard input: a 'speed' "
                        "column (auto), another column named, a speed FILE (merged by time), or none")
    add_reader_flags(p)
    p.set_defaults(func=run)


#: The largest state file ``--state`` reads, bytes.
MAX_STATE_BYTES = 16 * 1024 * 1024


def _load_state(est, path: Path) -> dict:
    """Load the saved state into ``est``; returns where a replay got to (``{}`` for none)."""
    from imu_ground.errors import ImuGroundError, OptionError
    try:
        if path.stat().st_size > MAX_STATE_BYTES:
            raise OptionError(f"{path}: {path.stat().st_size} bytes, larger than a saved state of 'imu-ground "
                              f"stream' can be ({MAX_STATE_BYTES} bytes); give another file to {{opt}}", "state",
                              flag="--state")
        state = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as e:
        raise OptionError(f"{path}: not a saved state of 'imu-ground stream' ({type(e).__name__}); give another "
                          "file to {opt}", "state", flag="--state") from None
    try:
        est.load_state_dict(state)
    except ImuGroundError as e:                     # StateError: another estimator's, settings' or a corrupt state
        raise OptionError(f"{path}: {' '.join(str(e).split())}; give another file to {{opt}}", "state",
                          flag="--state") from None
    where = state.get(_REPLAY_KEY)
    return where if isinstance(where, dict) else {}


#: The key of a state file that says how far a ``--replay`` got (beside the estimator's state).
_REPLAY_KEY = "stream_replay"


def _write_state(est, path: Path, where: dict | None = None) -> None:
    """The state (and where a replay got to: log, samples and speed samples fed), atomically."""
    from imu_ground.pipeline.output import atomic_path
    state = est.state_dict()
    if where is not None:
        state[_REPLAY_KEY] = where
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(state), encoding="utf-8")


class _Writer:
    """One line per frame on stdout, flushed: CSV (header first) or JSON."""

    def __init__(self, as_json: bool) -> None:
        self.as_json, self.header = as_json, False

    def write(self, frames) -> None:
        if not frames:
            return
        from imu_ground.pipeline.streaming import estimate_row
        out = sys.stdout
        for f in frames:
            row = estimate_row(f)
            if self.as_json:
                out.write(json.dumps({k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                                      for k, v in row.items()}) + "\n")
                continue
            if not self.header:
                out.write(",".join(row) + "\n")
                self.header = True
            out.write(",".join(_cell(v) for v in row.values()) + "\n")
        out.flush()


def _cell(v) -> str:
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "nan"
    text = str(v)
    return '"' + text.replace('"', '""') + '"' if ("," in text or '"' in text) else text


class _WholeSamples:
    """SIGTERM and Ctrl-C held while a sample is pushed and its frames written (main thread only): the saved state,
    the samples counted and the frames written agree."""

    def __init__(self) -> None:
        self.busy = False
        self.pending: BaseException | None = None
        self._old: dict = {}

    def _on_signal(self, signum, frame) -> None:
        from imu_ground.cli import Terminated
        exc: BaseException = Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()
        if not self.busy:
            raise exc
        self.pending = exc

    def done(self) -> None:
        """The sample's frames are written and counted: raise a signal held meanwhile."""
        self.busy = False
        if self.pending is not None:
            exc, self.pending = self.pending, None
            raise exc

    def __enter__(self) -> "_WholeSamples":
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT):
                self._old[sig] = signal.signal(sig, self._on_signal)
        return self

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def run(a: argparse.Namespace) -> int:
    from imu_ground.errors import OptionError
    from imu_ground.pipeline.streaming import StreamingEstimator
    from imu_ground.pipeline.estimate import live_policy
    est = StreamingEstimator(a.method, a.extrinsic, a.rate, a.camera, policy=live_policy(a.policy))
    state = None if a.state is None else Path(a.state)
    from imu_ground.pipeline.output import check_run_paths
    check_run_paths([("--state", state)], input_paths(a))      # the state's own file is its input and output
    where: dict = {}
    if state is not None:
        if state.exists():
            where = _load_state(est, state)
        elif not (state.parent if str(state.parent) else Path(".")).is_dir():
            raise OptionError(f"{state}: its folder does not exist; give a path in an existing folder to {{opt}}",
                              "state", flag="--state")
    if a.realtime and a.replay is None:
        raise OptionError("{opt} paces a replayed log: add --replay LOG", "realtime", flag="--realtime")
    out = _Writer(a.json)
    pos = None if a.replay is None else {"log": str(Path(a.replay).resolve()), "samples": 0, "speeds": 0}
    try:
        if pos is not None:
            out.write(_replay(est, a, out, where, pos))
        else:
            _stdin(est, a, out)
            out.write(est.flush())
    finally:
        if state is not None:
            _write_state(est, state, pos)
    return 0


def _replay(est, a, out, where: dict, pos: dict) -> list:
    """``--replay``: the log fed by :func:`~imu_ground.pipeline.live_replay.replay`; returns the flush's frames."""
    from imu_ground.cli._common import warn_line, warnings_as_lines
    from imu_ground.datasets import detect_format, read_imu
    from imu_ground.datasets.storage import local_input
    from imu_ground.errors import OptionError
    from imu_ground.pipeline.estimate import check_frame_rate, speed_samples
    from imu_ground.pipeline.live_replay import replay
    opts = reader_options(a)
    fmt = opts.pop("format", None)
    opts["policy"] = "recorded"         # the stamps as recorded, in file order: the estimator's clock retimes them
    with warnings_as_lines(a.replay), local_input(a.replay) as log:     # a URL: one local copy, said by its URL
        fmt = detect_format(log) if fmt is None else fmt
        imu = read_imu(log, format=fmt, **opts)
        check_frame_rate(a.rate, imu.t, log)
        sp = None
        if est.speed_aided and a.speed != "none":
            sp, _ = speed_samples(a.speed, log, fmt, imu)
    M = 0 if sp is None else len(sp[0])
    first = j = 0
    if where:                                       # the state was saved replaying a log
        n, m = where.get("samples"), where.get("speeds")
        if where.get("log") != pos["log"]:
            warn_line(f"the state given to --state was saved replaying {where.get('log')!r}, not this log: "
                      f"this log is fed from its start", a.replay)
        elif not (type(n) is int and type(m) is int and 0 <= n <= len(imu.t) and 0 <= m <= M):
            raise OptionError(f"{a.state}: says the replay got to sample {n!r:.20} and speed sample {m!r:.20} of a "
                              f"log of {len(imu.t)} and {M}: not this log's state; give another file to {{opt}}",
                              "state", flag="--state")
        else:
            first, j = n, m
    pos["samples"], pos["speeds"] = first, j
    t, start = imu.t, time.monotonic()

    def before(i: int) -> None:
        if a.realtime:
            wait = start + (t[i] - t[first]) - time.monotonic()
            if wait > 0:
                time.sleep(wait)
        whole.busy = True

    def after(frames: list, samples: int, speeds: int) -> None:
        out.write(frames)
        pos["samples"], pos["speeds"] = samples, speeds
        whole.done()

    with _WholeSamples() as whole:
        return replay(est, imu.t, imu.gyro, imu.accel, sp, start=(first, j), before=before, after=after)


def _stdin(est, a, out) -> None:
    from imu_ground.cli._common import warn_line
    from imu_ground.errors import OptionError
    from imu_ground.datasets.unit_checks import ACCEL_UNITS, GYRO_UNITS, TIME_UNITS
    ks = TIME_UNITS[a.time_unit or "s"]
    kg = GYRO_UNITS[a.gyro_unit or "rad/s"]
    ka = ACCEL_UNITS[a.accel_unit or "m/s^2"]
    src = sys.stdin
    header = src.readline().lstrip("\ufeff")          # a UTF-8 byte-order mark, as estimate reads it
    names = [c.strip().strip('"').lower() for c in header.strip().split(",")]
    missing = [c for c in _SAMPLE_COLUMNS if c not in names]
    if missing:
        raise OptionError(f"<stdin>: the header line {header.strip()[:80]!r} does not name {', '.join(missing)}; "
                          f"the first line names the columns: t,wx,wy,wz,ax,ay,az (and optionally speed)", None)
    idx = [names.index(c) for c in _SAMPLE_COLUMNS]
    i_speed, (fs_t, fs_v) = _stdin_speed(a, names, est)
    width, nan = len(names), math.nan
    j, M = 0, len(fs_t)
    bad_lines = 0
    with _WholeSamples() as whole:
        for lineno, line in enumerate(src, start=2):
            cells = line.split(",")
            if len(cells) < width:
                if not line.strip():
                    continue
                cells += [""] * (width - len(cells))
            vals = []
            bad = None
            for c, i in zip(_SAMPLE_COLUMNS, idx, strict=True):
                try:
                    vals.append(float(cells[i]))
                except ValueError:
                    vals.append(nan)           # a damaged line: a non-finite sample, skipped and said in the frame
                    bad = bad or (c, cells[i].strip())
            if bad is not None:
                bad_lines += 1
                if bad_lines <= _BAD_LINES_SAID:
                    more = "" if bad_lines < _BAD_LINES_SAID else f" (the first {_BAD_LINES_SAID}; later ones not said)"
                    warn_line(f"line {lineno}: column {bad[0]} is {bad[1][:40]!r}, not a number: sample skipped{more}",
                              "<stdin>")
            t = vals[0] * ks
            whole.busy = True
            while j < M and fs_t[j] <= t:
                est.push_speed(fs_t[j], fs_v[j])
                j += 1
            if i_speed is not None:
                try:
                    v = float(cells[i_speed])
                except ValueError:
                    v = nan
                est.push_speed(t, v)
            out.write(est.push_imu(t, (vals[1] * kg, vals[2] * kg, vals[3] * kg),
                                   (vals[4] * ka, vals[5] * ka, vals[6] * ka)))
            whole.done()
    while j < M:
        est.push_speed(fs_t[j], fs_v[j])
        j += 1


#: How many damaged lines of standard input are said one by one.
_BAD_LINES_SAID = 10


def _stdin_speed(a, names: list[str], est) -> tuple[int | None, tuple[list, list]]:
    """``--speed`` on standard input: ``(column index or None, (times, speeds) of a speed file))``."""
    from imu_ground.cli._common import warn_line
    from imu_ground.errors import OptionError
    choice = a.speed
    if choice == "none":
        return None, ([], [])
    if not est.speed_aided and choice != "auto":
        warn_line(f"--speed {choice}: method {est.method} takes no speed: ignored", "<stdin>")
        return None, ([], [])
    if choice == "auto":
        return (names.index("speed") if "speed" in names else None), ([], [])
    if choice.lower() in names:
        return names.index(choice.lower()), ([], [])
    p = Path(choice)
    if not p.is_file():
        raise OptionError(f"{choice}: neither a column of the header on standard input ({', '.join(names)}) nor a "
                          f"speed file; give a column, a file, auto or none to {{opt}}", "speed", flag="--speed")
    from imu_ground.datasets.speed import check_speed, read_speed_file
    ts, vs = read_speed_file(p)
    ts, vs, notes = check_speed(ts, vs, str(p))
    for note in notes:
        warn_line(note, p)
    return None, (ts.tolist(), vs.tolist())
