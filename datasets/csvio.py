"""Delimited text files: streamed decompression, a real CSV engine, bad lines found only on failure.

:func:`read_delimited` first tries :func:`~imu_ground.datasets.numeric_csv.parse_numeric`:
a plain file whose every field is a decimal number is parsed by the compiled
kernel straight into the columns (pieces on threads, no pandas). Any other file
(or without the compiled kernel) is parsed with pandas' C engine in chunks, from a
decompressing stream (``.gz``, ``.bz2``), so memory grows with the parsed columns,
not with the text. A plain (uncompressed) file of at least
:data:`PARALLEL_MIN_BYTES` is cut at line ends into pieces of
:data:`PIECE_BYTES` that threads parse side by side (the C engine releases the
GIL while it tokenises and converts); a file the pieces cannot represent
exactly (quotes, bare carriage returns, text columns, any parse error) is
parsed again the serial way, which owns every error message. Only when the
fast parse fails or looks suspicious (a short line fills the last column with
NaN) does :func:`locate_bad_lines` walk the file line by line to name the
first bad line (1-based file line) as before.
"""
from __future__ import annotations

import bz2
import gzip
import io
import os
import re
import threading
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from .numeric_csv import _stack_layout, line_cuts, parse_numeric
from .report import MalformedFileError

__all__ = ["Columns", "RowLines", "first_nonnumber", "locate_bad_lines", "numeric", "open_binary", "read_delimited",
           "return_free_memory"]

#: Rows per parsed chunk (bounded working memory on long logs).
CHUNK_ROWS = 1 << 19
#: Plain files at least this large (bytes) are parsed in pieces by several threads.
PARALLEL_MIN_BYTES = 8 << 20
#: Bytes of text per piece of a parallel parse (cut at a line end), at most.
PIECE_BYTES = 16 << 20
#: Bytes of the first piece, at most (parsed alone, for the header's column names).
FIRST_PIECE_BYTES = 1 << 20
#: Most threads a parallel parse uses (fewer when the process may use fewer CPUs).
MAX_THREADS = 4
#: Logs of at least this many samples return the freed heap memory to the system once read.
TRIM_SAMPLES = 1 << 20

Columns = dict[str, np.ndarray]


def open_binary(path: Path) -> io.BufferedIOBase:
    """The file as a binary stream, decompressed on the fly when it ends in ``.gz`` or ``.bz2``."""
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if not path.is_file():
        raise MalformedFileError(path, "is not a file")
    name = path.name.lower()
    if name.endswith(".gz"):
        return gzip.open(path, "rb")  # type: ignore[return-value]
    if name.endswith(".bz2"):
        return bz2.open(path, "rb")  # type: ignore[return-value]
    return open(path, "rb")


class RowLines:
    """Data row (0-based, blank lines skipped) -> 1-based file line.

    Parameters
    ----------
    blank : ndarray of int
        Positions, among the lines after the header, of the blank lines the
        parser saw (usually none: row ``r`` is then on line ``r + 2``).
    """

    def __init__(self, blank: np.ndarray) -> None:
        self.blank = np.asarray(blank, dtype=np.int64)

    def __call__(self, rows: np.ndarray) -> np.ndarray:
        rows = np.asarray(rows, dtype=np.int64)
        if not self.blank.size:
            return rows + 2
        # row r is the r-th non-blank position: shift by the blanks at or before it
        free = self.blank - np.arange(self.blank.size)  # rows before which each blank sits
        return rows + np.searchsorted(free, rows, side="right") + 2


def _iter_lines(path: Path) -> Iterator[tuple[int, bytes]]:
    with open_binary(path) as f:
        yield from enumerate(f, 1)


def locate_bad_lines(path: Path, sep: str = ",") -> MalformedFileError | None:
    """The error for the first line whose field count differs from the header's (None: all agree).

    Walks the whole file once (failure path only), so the message counts every bad line.
    """
    sep_b = sep.encode()
    numbers: list[int] = []
    counts: list[int] = []
    quoted = False
    for i, ln in _iter_lines(path):
        if not ln.strip():
            continue
        quoted = quoted or b'"' in ln
        numbers.append(i)
        counts.append(ln.count(sep_b) + 1)
    if quoted or not counts:  # quoted fields may hold the separator: let the parser judge
        return None
    c = np.asarray(counts)
    bad = np.flatnonzero(c != c[0])
    if not bad.size:
        return None
    k = int(bad[0])
    last = " (last line: truncated file?)" if k == c.size - 1 else ""
    lines = [numbers[j] for j in bad[:5]]
    return MalformedFileError(path, f"{c[k]} fields, expected {c[0]} as in the header{last}; "
                                    f"{bad.size} such line(s), first line numbers {lines}", line=numbers[k])


def _blank(x: np.ndarray) -> np.ndarray:
    """Missing or whitespace-only values (what a blank line leaves in a column)."""
    import pandas as pd
    empty = np.asarray(pd.isna(x))
    if x.dtype == object:
        empty = empty | np.array([isinstance(v, str) and not v.strip() for v in x], dtype=bool)
    return empty


def _drop_blank_rows(arrays: list[np.ndarray], first_row: int, blank: list[np.ndarray]) -> list[np.ndarray]:
    """The chunk's columns without its blank lines (all-NaN or whitespace rows), whose raw rows go to ``blank``."""
    empty = _blank(arrays[0])
    if empty.any():
        for x in arrays[1:]:
            empty &= _blank(x)
        if empty.any():
            blank.append(np.flatnonzero(empty) + first_row)
            arrays = [x[~empty] for x in arrays]
    return arrays


def _parse(path: Path, sep: str, stack: Mapping[str, Sequence[str]] | None) -> tuple[Columns, int, np.ndarray]:
    """Chunked C-engine parse: (columns, rows, blank-line positions)."""
    import pandas as pd
    parallel = _parse_parallel(path, sep, stack)
    if parallel is not None:
        return parallel
    source = open_binary(path)
    names: list[str] = []
    parts: dict[str, list[np.ndarray]] = {}
    n = 0
    raw_rows = 0
    blank: list[np.ndarray] = []
    suspect = False
    try:
        reader = pd.read_csv(source, sep=sep, engine="c", chunksize=CHUNK_ROWS, skip_blank_lines=False,
                             encoding="utf-8", low_memory=False)
        with reader:
            for chunk in reader:
                if not names:
                    names = [str(c) for c in chunk.columns]
                    parts = {c: [] for c in names}
                arrays = _drop_blank_rows([chunk[col].to_numpy() for col in chunk.columns], raw_rows, blank)
                suspect = suspect or bool(pd.isna(arrays[-1]).any())  # a short line leaves NaN at the end
                for c, x in zip(names, arrays):
                    parts[c].append(x)
                n += arrays[0].size
                raw_rows += len(chunk)
    finally:
        source.close()
    if suspect:
        err = locate_bad_lines(path, sep)
        if err is not None:
            raise err
    return _join_columns(names, parts, n, stack), n, _blank_rows(blank)


def _blank_rows(blank: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(blank) if blank else np.zeros(0, dtype=np.int64)


class _NotParallel(Exception):
    """A piece the parallel parse cannot represent exactly: parse the file the serial way."""


def _threads() -> int:
    """Threads for a parallel parse: the CPUs this process may use, at most :data:`MAX_THREADS`."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:              # not on Linux
        n = os.cpu_count() or 1
    return max(1, min(n, MAX_THREADS))


def _piece_offsets(path: Path, piece: int) -> list[int]:
    """Byte offsets cutting a plain file into pieces of about ``piece`` bytes, each after a ``\\n``.

    The first piece (with the header, parsed before the others start, for the
    column names) is at most :data:`FIRST_PIECE_BYTES`.
    """
    with open(path, "rb") as f:
        header = len(f.readline())      # the header stays in the first piece
    return line_cuts(path, 0, max(header, min(piece, FIRST_PIECE_BYTES)), piece)


class _PieceReader(io.RawIOBase):
    """A piece of the file held in a reused buffer, read without copying it whole (what the parser reads from)."""

    def __init__(self, view: memoryview) -> None:
        super().__init__()
        self.view, self.pos = view, 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = min(len(b), len(self.view) - self.pos)
        b[:n] = self.view[self.pos:self.pos + n]
        self.pos += n
        return n


#: One text buffer per parsing thread, reused piece after piece (no fresh pages to fault in per piece).
_buffers = threading.local()


def _parse_piece(fd: int, start: int, stop: int, sep: str, names: list[str] | None):
    """One piece's DataFrame (the first piece, ``names`` None, holds the header line)."""
    import pandas as pd
    size = stop - start
    buf = getattr(_buffers, "buf", None)
    if buf is None or len(buf) < size:
        buf = _buffers.buf = bytearray(size)
    n = os.preadv(fd, [memoryview(buf)[:size]], start)
    if buf.find(b'"', 0, n) >= 0 or (buf.find(b"\r", 0, n) >= 0 and buf.count(b"\r", 0, n) != buf.count(b"\r\n", 0, n)):
        raise _NotParallel("quoted fields or bare carriage returns")
    kw = {"header": None, "names": names, "index_col": False} if names is not None else {}
    try:
        # low_memory (the default) tokenises in short runs: about twice as fast on a piece; a column of
        # mixed types comes out as object and sends the file to the serial parse
        chunk = pd.read_csv(io.BufferedReader(_PieceReader(memoryview(buf)[:n]), 1 << 18), sep=sep, engine="c",
                            skip_blank_lines=False, encoding="utf-8", **kw)
    except Exception as e:             # the serial parse says what is wrong, with the file's line
        raise _NotParallel(str(e)) from e
    if any(chunk[c].dtype.kind not in "fiu" for c in chunk.columns):
        raise _NotParallel("a column that is not all numbers")
    return chunk


class _ColumnSink:
    """Numeric columns filled piece by piece, in file order, into arrays with room to spare.

    ``finish`` returns views of the filled rows (pages never written cost no memory).
    """

    def __init__(self, names: list[str], into: dict[str, tuple[str, int]], capacity: int) -> None:
        self.names, self.into, self.cap, self.n = names, into, capacity, 0
        width = {g: j + 1 for g, j in into.values()}
        self.arrays: dict[str, np.ndarray] = {g: np.empty((capacity, k)) for g, k in width.items()}

    def _resize(self, key: str, dtype: np.dtype, cap: int) -> np.ndarray:
        old = self.arrays.get(key)
        new = np.empty((cap,) + (old.shape[1:] if old is not None else ()), dtype=dtype)
        if old is not None:
            new[:self.n] = old[:self.n]
        self.arrays[key] = new
        return new

    def add(self, columns: list[np.ndarray]) -> None:
        m = columns[0].size
        if self.n + m > self.cap:                      # more rows than the estimate: grow
            self.cap = max(2 * self.cap, self.n + m)
            for key, a in list(self.arrays.items()):
                self._resize(key, a.dtype, self.cap)
        rows = slice(self.n, self.n + m)
        for c, x in zip(self.names, columns):
            if c in self.into:
                g, j = self.into[c]
                self.arrays[g][rows, j] = x
                continue
            dest = self.arrays.get(c)
            if dest is None or np.promote_types(dest.dtype, x.dtype) != dest.dtype:   # as np.concatenate
                dest = self._resize(c, x.dtype if dest is None else np.promote_types(dest.dtype, x.dtype),
                                    self.cap)
            dest[rows] = x
        self.n += m

    def finish(self) -> Columns:
        cols: Columns = {}
        for c in self.names:
            key = self.into[c][0] if c in self.into else c
            if key not in cols:
                cols[key] = self.arrays[key][:self.n]
        return cols


def _parse_parallel(path: Path, sep: str, stack: Mapping[str, Sequence[str]] | None
                    ) -> tuple[Columns, int, np.ndarray] | None:
    """:func:`_parse` by threads over pieces of a plain file; None where the serial parse must do it.

    The pieces are parsed by a pool of threads while this thread copies each
    finished piece, in order, into the columns (the copies release the GIL).
    """
    if (path.name.lower().endswith((".gz", ".bz2")) or not path.is_file()
            or path.stat().st_size < PARALLEL_MIN_BYTES or _threads() < 2 or len(sep) != 1):
        return None
    # pieces small enough for a few per thread (the last ones finish together), at most PIECE_BYTES
    size = path.stat().st_size
    offsets = _piece_offsets(path, min(PIECE_BYTES, max(PIECE_BYTES // 4, size // (4 * _threads()))))
    if len(offsets) < 3:
        return None
    from concurrent.futures import ThreadPoolExecutor
    fd = os.open(path, os.O_RDONLY)
    pool = ThreadPoolExecutor(_threads())
    futures: list = []
    try:
        first = _parse_piece(fd, offsets[0], offsets[1], sep, None)
        names = [str(c) for c in first.columns]
        if len(set(names)) != len(names):
            return None
        futures = [pool.submit(_parse_piece, fd, offsets[k], offsets[k + 1], sep, names)
                   for k in range(1, len(offsets) - 1)]
        rows_per_byte = len(first) / max(offsets[1] - offsets[0], 1)
        sink = _ColumnSink(names, _stack_layout(names, stack, lambda c: True),
                           int(rows_per_byte * offsets[-1] * 1.25) + 1024)
        blank: list[np.ndarray] = []
        raw_rows = 0
        for k in range(len(offsets) - 1):
            chunk = first if k == 0 else futures[k - 1].result()
            if k:
                futures[k - 1] = None          # the piece is freed once copied
            if list(chunk.columns) != names:
                return None
            columns = _drop_blank_rows([chunk[c].to_numpy() for c in names], raw_rows, blank)
            if columns[-1].dtype.kind == "f" and np.isnan(columns[-1]).any():
                return None                    # a short line: the serial parse finds and names it
            sink.add(columns)
            raw_rows += len(chunk)
            del chunk, columns
            first = None
        return sink.finish(), sink.n, _blank_rows(blank)
    except _NotParallel:
        return None
    finally:
        for f in futures:
            if f is not None:
                f.cancel()
        pool.shutdown(wait=True)
        os.close(fd)
        _buffers.__dict__.pop("buf", None)     # this thread's text buffer (the pool's went with its threads)


def read_delimited(path: str | Path, sep: str = ",", *,
                   stack: Mapping[str, Sequence[str]] | None = None) -> tuple[Columns, RowLines]:
    """Parse a delimited text file with a header line into named column arrays.

    Parameters
    ----------
    path : str or Path
        The file (``.gz`` / ``.bz2`` decompressed as a stream).
    sep : str
        Field separator.
    stack : mapping of str to sequence of str, optional
        New name -> columns to return side by side as one float64 array (N, k)
        under the new name (in their place), written there straight from the
        parsed chunks; only when they are consecutive in the header in this
        order, all numbers, and no column has the new name (else they come
        back one by one, as without ``stack``).

    Returns
    -------
    columns : dict of str to ndarray
        One array per column, in file order (float or int where every value is
        a number, else object), the stacked ones as asked.
    row_lines : RowLines
        Data row -> 1-based file line.

    Raises
    ------
    FileNotFoundError
        No such file.
    MalformedFileError
        Empty file, header only, a line with the wrong number of fields
        (first bad line and count), not UTF-8, truncated or corrupt compression.
    """
    path = Path(path)
    fast = parse_numeric(path, sep, stack, piece_bytes=PIECE_BYTES, threads=_threads(),
                         parallel_min_bytes=PARALLEL_MIN_BYTES)
    if fast is not None:                  # a plain all-numbers file: the compiled parse, no pandas
        return fast[0], RowLines(fast[2])
    import pandas as pd
    try:
        cols, n, blank = _parse(path, sep, stack)
    except pd.errors.EmptyDataError as e:
        raise MalformedFileError(path, "file is empty") from e
    except pd.errors.ParserError as e:
        err = locate_bad_lines(path, sep)
        if err is not None:
            raise err from None
        m = re.search(r"line (\d+)", str(e))
        raise MalformedFileError(path, f"cannot parse: {e}", line=int(m.group(1)) if m else None) from e
    except (EOFError, gzip.BadGzipFile, zlib.error, OSError) as e:
        if isinstance(e, FileNotFoundError):
            raise
        raise MalformedFileError(path, f"truncated or corrupt gzip file ({e})") from e
    except UnicodeDecodeError as e:
        raise MalformedFileError(path, f"not UTF-8 text ({e})") from e
    if n == 0:
        header = next((i for i, ln in _iter_lines(path) if ln.strip()), 1)
        raise MalformedFileError(path, "header only, no data rows", line=header)
    return cols, RowLines(blank)


def return_free_memory() -> None:
    """Give the C heap's free pages back to the system (glibc ``malloc_trim``; nothing elsewhere).

    A long parse and its validation free about as much as they keep (the
    chunks' frames, the pieces, the checks' temporaries); glibc keeps such
    memory in its heaps (one per parsing thread), where the arrays allocated
    later cannot always reuse it, so the peak RSS of the whole run would carry
    it. :func:`~imu_ground.datasets.skeleton.finish` calls this after reading a
    long log.
    """
    import ctypes
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):           # not glibc
        pass


def _join_columns(names: list[str], parts: dict[str, list[np.ndarray]], n: int,
                  stack: Mapping[str, Sequence[str]] | None = None) -> Columns:
    """Each column's chunks as one array (``parts`` is emptied); numeric columns joined by threads.

    ``stack`` (name -> columns) puts numeric columns side by side into one
    float64 array (N, k) under its name, written there straight from the chunks.
    """
    import functools
    into = _stack_layout(names, stack, lambda c: all(x.dtype.kind in "fiu" for x in parts[c]))
    groups = {g: np.empty((n, sum(1 for h, _ in into.values() if h == g))) for g, _ in into.values()}
    cols: Columns = {}
    jobs: list[tuple[np.ndarray, list[np.ndarray]]] = []
    for c in names:
        chunks = parts.pop(c)
        if c in into:
            name, j = into[c]
            if name not in cols:
                cols[name] = groups[name]
            jobs.append((groups[name][:, j], chunks))
        elif len(chunks) == 1:
            cols[c] = chunks[0] if chunks[0].flags.writeable else chunks[0].copy()
        elif all(x.dtype.kind in "fiu" for x in chunks):       # the dtype np.concatenate would give
            cols[c] = np.empty(n, dtype=functools.reduce(np.promote_types, {x.dtype for x in chunks}))
            jobs.append((cols[c], chunks))
        else:
            cols[c] = np.concatenate(chunks)

    def fill(job: tuple[np.ndarray, list[np.ndarray]]) -> None:
        out, chunks = job
        k = 0
        for x in chunks:
            out[k:k + x.size] = x
            k += x.size

    if len(jobs) > 1 and n * len(jobs) >= PIECE_BYTES // 8 and _threads() > 1:
        from concurrent.futures import ThreadPoolExecutor
        with ThreadPoolExecutor(_threads()) as pool:      # copies release the GIL: page faults in parallel
            list(pool.map(fill, jobs))
    else:
        for job in jobs:
            fill(job)
    return cols


def first_nonnumber(values: np.ndarray) -> tuple[int, int]:
    """(first row, count) of values in an object column that are not numbers (blank counts as NaN)."""
    import pandas as pd
    num = pd.to_numeric(pd.Series(values), errors="coerce").to_numpy()
    present = pd.notna(values)
    bad = np.flatnonzero(np.isnan(num.astype(float)) & present)
    return (int(bad[0]) if bad.size else -1), int(bad.size)


def numeric(values: np.ndarray, column: str, where: str | Path,
            row_lines: Callable[[np.ndarray], np.ndarray] | None) -> np.ndarray:
    """A column as float64; a non-number raises naming the column and the line (or row)."""
    if values.dtype.kind in "fiu":
        return values.astype(float, copy=False)
    r, count = first_nonnumber(values)
    if r >= 0:
        what = f"column {column!r}: {values[r]!r} is not a number ({count} such value(s) in this column)"
        if row_lines is not None:
            raise MalformedFileError(where, what, line=int(row_lines(np.array([r]))[0]))
        raise ValueError(f"{where}: {what.replace(':', f', row {r}:', 1)}")
    import pandas as pd
    return pd.to_numeric(pd.Series(values), errors="coerce").to_numpy(dtype=float)
