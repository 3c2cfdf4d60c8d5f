"""Plain numeric CSV files parsed by the compiled kernel, straight into the columns, on threads.

The first thing :func:`~imu_ground.datasets.csvio.read_delimited` tries on a
plain (uncompressed) file: when every field is a decimal number
(``[+-]digits[.digits][e[+-]digits]``), the lines end in ``\\n`` or ``\\r\\n``
and every line has the header's number of fields, the compiled kernel
``imu_ground.datasets._csv_native`` reads the file in pieces cut at line ends,
counts each piece's lines, then parses each piece into its rows of the final
column arrays, pieces side by side on threads, without the GIL and without
pandas. Numbers are correctly rounded, as by pandas' default parser and by
Python's ``float``, so the columns are the ones the pandas parse gives, dtypes
included (a column of integers only is int64).

Anything else (quotes, blank fields or lines, spaces, ``nan`` words, a short
line, a byte-order mark, integers too large for a double to hold exactly, no C
compiler at install, ``IMU_GROUND_PURE_PYTHON=1``) returns None, and the caller
parses the file with pandas, the path that owns every error message.
"""
from __future__ import annotations

import collections
import itertools
import os
import threading
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from imu_ground._native import load_native

__all__ = ["line_cuts", "parse_numeric"]

#: The compiled kernel (None: not built, or switched off by IMU_GROUND_PURE_PYTHON).
_native = load_native("imu_ground.datasets._csv_native")
#: The longest header line taken (a longer one goes to pandas).
MAX_HEADER_BYTES = 1 << 16

_local = threading.local()


def _buffer(size: int) -> bytearray:
    """This thread's text buffer for a piece of ``size`` bytes and the kernel's sentinel (reused piece after piece)."""
    buf = getattr(_local, "buf", None)
    if buf is None or len(buf) < size + 1:
        buf = _local.buf = bytearray(size + 1)
    return buf


def _header(path: Path, sep: str) -> tuple[list[str], int] | None:
    """(column names, header bytes) as pandas reads them, or None for a header only pandas should judge."""
    with open(path, "rb") as f:
        head = f.readline(MAX_HEADER_BYTES)
    if not head.endswith(b"\n") or b'"' in head:
        return None
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return None
    names = text.rstrip("\n").removesuffix("\r").split(sep)
    if text.startswith("\ufeff") or "\r" in text[:-2] or any(not c.strip() for c in names) \
            or len(set(names)) != len(names):
        return None
    return names, len(head)


def line_cuts(path: Path, start: int, first: int, piece: int) -> list[int]:
    """Byte offsets from ``start`` to the file's end, each other one just after a ``\\n``, about ``piece`` apart.

    The first cut after ``start`` ends the line holding byte ``first``; each
    next one the line holding the byte ``piece`` further on.
    """
    size = path.stat().st_size
    cuts = [start]
    with open(path, "rb") as f:
        pos = first
        while pos < size:
            f.seek(pos)
            f.readline()
            pos = f.tell()
            if pos >= size:
                break
            cuts.append(pos)
            pos += piece
    cuts.append(size)
    return cuts


def _stack_layout(names: list[str], stack: Mapping[str, Sequence[str]] | None,
                  numeric: Callable[[str], bool]) -> dict[str, tuple[str, int]]:
    """Column -> (stack name, position) for the stacks that apply (see :func:`read_delimited`'s ``stack``)."""
    into: dict[str, tuple[str, int]] = {}
    for name, members in (stack or {}).items():
        at = names.index(members[0]) if members and members[0] in names else -1
        if (at >= 0 and name not in names and names[at:at + len(members)] == list(members)
                and all(numeric(c) for c in members)):
            into.update({c: (name, j) for j, c in enumerate(members)})
    return into


def parse_numeric(path: Path, sep: str, stack: Mapping[str, Sequence[str]] | None, *, piece_bytes: int,
                  threads: int, parallel_min_bytes: int) -> tuple[dict[str, np.ndarray], int, np.ndarray] | None:
    """The columns of a plain numeric CSV file, or None where pandas must parse it.

    Parameters
    ----------
    path : Path
        The file (a ``.gz`` / ``.bz2`` name returns None).
    sep : str
        Field separator (one character).
    stack : mapping of str to sequence of str, optional
        As :func:`~imu_ground.datasets.csvio.read_delimited`'s.
    piece_bytes : int
        Bytes of text per piece, at most.
    threads : int
        Threads to parse pieces on.
    parallel_min_bytes : int
        Files smaller than this are parsed on this thread alone.

    Returns
    -------
    (columns, rows, blank) or None
        Columns in file order (float64, int64 where every field is an integer,
        stacked ones as asked), the number of rows, and the blank-line
        positions (always none here: a blank line returns None).
    """
    if (_native is None or len(sep) != 1 or path.name.lower().endswith((".gz", ".bz2"))
            or not path.is_file() or sep in "\r\n.+-eE0123456789\"") or not sep.isascii():
        return None
    size = path.stat().st_size
    head = _header(path, sep)
    if head is None or head[1] >= size:
        return None
    names, start = head
    # one thread on Windows: its read is a seek and a read on the shared descriptor (no pread)
    threads = threads if size >= parallel_min_bytes and os.name != "nt" else 1
    step = max(1, min(piece_bytes, max(piece_bytes // 4, size // (4 * threads))))
    pieces = list(itertools.pairwise(line_cuts(path, start, start + step, step)))
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_BINARY", 0))
    pool = None
    try:
        if threads > 1 and len(pieces) > 1:
            from concurrent.futures import ThreadPoolExecutor
            pool = ThreadPoolExecutor(threads)
            run = pool.map
        else:
            run = map

        def count(p: tuple[int, int]) -> int:
            return _native.count_lines(fd, p[0], p[1], _buffer(p[1] - p[0]))

        lines = list(run(count, pieces))
        n = int(sum(lines))
        if n == 0:
            return None
        into = _stack_layout(names, stack, lambda c: True)
        width = collections.Counter(g for g, _ in into.values())     # stacked arrays: columns side by side
        arrays: dict[str, np.ndarray] = {}
        slot: dict[str, int] = {}
        layout = np.empty((len(names), 3), dtype=np.int64)           # (array, first item, stride) a column
        for k, c in enumerate(names):
            key, j = into.get(c, (c, 0))
            if key not in arrays:
                slot[key] = len(arrays)
                arrays[key] = np.empty((n, width[key])) if key in width else np.empty(n)
            layout[k] = (slot[key], j, width.get(key, 1))
        targets = tuple(arrays.values())
        rows0 = np.concatenate([[0], np.cumsum(lines)[:-1]]).tolist()
        failed = threading.Event()

        def parse(k: int) -> tuple[bytes, bytes] | None:
            if failed.is_set():
                return None
            (a, b), m = pieces[k], lines[k]
            try:
                return _native.parse_piece(fd, a, b, _buffer(b - a), sep.encode(), targets, layout, rows0[k], m)
            except (ValueError, OSError):
                failed.set()
                return None

        flags = list(run(parse, range(len(pieces))))
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
        os.close(fd)
        _local.__dict__.pop("buf", None)
    if failed.is_set() or any(f is None for f in flags):
        return None
    fractional = np.bitwise_or.reduce([np.frombuffer(f[0], dtype=np.uint8) for f in flags], axis=0)
    inexact = np.bitwise_or.reduce([np.frombuffer(f[1], dtype=np.uint8) for f in flags], axis=0)
    if (inexact & ~fractional).any():      # an all-integer column with an integer a double may not hold
        return None
    cols: dict[str, np.ndarray] = {}
    for k, c in enumerate(names):
        if c in into:
            cols.setdefault(into[c][0], arrays[into[c][0]])
        else:
            cols[c] = arrays[c] if fractional[k] else arrays[c].astype(np.int64)
    return cols, n, np.zeros(0, dtype=np.int64)
