"""Delimited text files: one parse through pandas' C engine, in chunks; bad lines found only on failure.

:func:`read_delimited` takes the columns of :func:`pandas.read_csv` chunk by chunk (the working memory
follows the columns, not the text). Only when the parse fails or looks suspicious (a short line leaves NaN
in the last column) does :func:`locate_bad_lines` walk the file to name the first bad line.
"""
from __future__ import annotations

import bz2
import contextlib
import ctypes
import functools
import gzip
import io
import os
import re
import zlib
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Literal

import numpy as np

from imu_ground.errors import ImuGroundError, MalformedFileError

__all__ = ["Columns", "RowLines", "detect_dialect", "first_nonnumber", "locate_bad_lines", "numeric", "open_binary",
           "open_gzip", "read_delimited", "return_free_memory"]

#: Rows per parsed chunk (bounded working memory on long logs; larger chunks parse faster).
CHUNK_ROWS = 1 << 20
#: Rows a thread copies at a time into a stacked (N, k) array, and the threads that copy (see :func:`_fill_stack`).
STACK_BLOCK = 1 << 16
STACK_THREADS = min(4, os.cpu_count() or 1)
#: Logs of at least this many samples return the freed heap memory to the system once read.
TRIM_SAMPLES = 1 << 20

Columns = dict[str, np.ndarray]


def _isal_errors() -> tuple[type[BaseException], ...]:
    """python-isal's error for a corrupt deflate stream (none without the package)."""
    try:
        from isal.isal_zlib import error
    except ImportError:
        return ()
    return (error,)  # type: ignore[return-value]  # (isal's stub declares the error class an instance)


def open_gzip(path: Path) -> io.BufferedIOBase:
    """A ``.gz`` file's decompressed bytes: python-isal's igzip in a thread of its own when installed (the ``fast``
    extra), else the standard :mod:`gzip`."""
    try:
        from isal import igzip_threaded
    except ImportError:
        return gzip.open(path, "rb")
    return igzip_threaded.open(path, "rb", threads=1)


def open_binary(path: Path) -> io.BufferedIOBase:
    """The file as a binary stream, decompressed on the fly when it ends in ``.gz`` or ``.bz2``."""
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if not path.is_file():
        raise MalformedFileError(path, "is not a file")
    name = path.name.lower()
    if name.endswith(".gz"):
        return gzip.open(path, "rb")
    if name.endswith(".bz2"):
        return bz2.open(path, "rb")
    return open(path, "rb")


#: Field separators told from a header line, in order of preference on a tie.
SEPARATORS = (",", "\t", ";")
#: A number written with a decimal comma (``-1,25``, ``9,81e-3``).
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d*,\d+([eE][-+]?\d+)?\s*$")


def _first_lines(path: Path, count: int) -> list[str]:
    """The first ``count`` non-blank lines (fewer in a shorter file), as text ('' for bytes that are not UTF-8)."""
    out: list[str] = []
    for _, ln in _iter_lines(path):
        if ln.strip():
            out.append(ln.decode("utf-8", "replace").rstrip("\r\n"))
            if len(out) == count:
                break
    return out


def detect_dialect(path: str | Path) -> tuple[str, str]:
    """The field separator and decimal mark of a delimited text file with a header line.

    The separator: a tab for ``.tsv`` (``.gz``, ``.bz2``), else the one of :data:`SEPARATORS` that splits the
    header into the most fields (a comma when none does). The decimal mark: a comma when fields are not
    comma-separated and the first data row has a number written so (``9,81``) and none with a point.

    Returns
    -------
    sep, decimal : str
    """
    path = Path(path)
    lines = _first_lines(path, 2)
    name = path.name.lower()
    if re.search(r"\.tsv(\.gz|\.bz2)?$", name):
        sep = "\t"
    else:
        header = lines[0] if lines else ""
        sep = max(SEPARATORS, key=lambda c: (header.count(c), -SEPARATORS.index(c)))
        if not header.count(sep):
            sep = ","
    decimal = "."
    if sep != "," and len(lines) > 1:
        fields = lines[1].split(sep)
        if any(_DECIMAL_COMMA.match(f) for f in fields) and not any("." in f for f in fields):
            decimal = ","
    return sep, decimal


class RowLines:
    """Data row (0-based, blank lines skipped) -> 1-based file line.

    Parameters
    ----------
    blank : ndarray of int
        Positions, among the lines after the header, of the blank lines (none: row ``r`` is on line ``r + 2``).
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
    """The error for the first line whose field count differs from the header's (None: all agree), counting all."""
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
    """Missing or whitespace-only values (what a blank line leaves)."""
    import pandas as pd
    empty = np.asarray(pd.isna(x))
    if x.dtype == object:
        empty = empty | np.array([isinstance(v, str) and not v.strip() for v in x], dtype=bool)
    return empty


def _drop_blank_rows(arrays: list[np.ndarray], first_row: int, blank: list[np.ndarray]) -> list[np.ndarray]:
    """The chunk's columns without its blank lines, whose raw rows go to ``blank``."""
    empty = _blank(arrays[0])
    if empty.any():
        for x in arrays[1:]:
            empty &= _blank(x)
        if empty.any():
            blank.append(np.flatnonzero(empty) + first_row)
            arrays = [x[~empty] for x in arrays]
    return arrays


def _parse(path: Path, sep: str, stack: Mapping[str, Sequence[str]] | None,
           decimal: str = ".") -> tuple[Columns, int, np.ndarray]:
    """Chunked C-engine parse: (columns, rows, blank-line positions)."""
    import pandas as pd
    open_binary(path).close()           # the missing-file and not-a-file messages
    names: list[str] = []
    parts: dict[str, list[np.ndarray]] = {}
    n = 0
    raw_rows = 0
    blank: list[np.ndarray] = []
    suspect = False
    compressions: dict[str, Literal["gzip", "bz2"]] = {".gz": "gzip", ".bz2": "bz2"}
    compression = compressions.get(path.suffix.lower())
    # a plain file whole (pandas parses it in byte ranges on several threads); a compressed one in chunks
    # (the decompression sets the pace, and the chunks bound the working memory); gzip through open_gzip
    source = open_gzip(path) if compression == "gzip" else path
    with contextlib.ExitStack() as scope:
        if source is not path:
            scope.enter_context(source)
        # chunks (a TextFileReader) when compressed, else the DataFrame: which one, the stubs' overloads cannot tell
        reader: Any = pd.read_csv(source, sep=sep, engine="c", chunksize=CHUNK_ROWS if compression else None,
                             skip_blank_lines=False, encoding="utf-8", decimal=decimal,
                             compression=None if source is not path else compression)
        with (reader if compression else contextlib.nullcontext([reader])) as chunks:
            for chunk in chunks:
                if not names:
                    names = [str(c) for c in chunk.columns]
                    parts = {c: [] for c in names}
                arrays = _drop_blank_rows([chunk[col].to_numpy() for col in chunk.columns], raw_rows, blank)
                suspect = suspect or bool(pd.isna(arrays[-1]).any())  # a short line leaves NaN at the end
                for c, x in zip(names, arrays, strict=True):
                    parts[c].append(x)
                n += arrays[0].size
                raw_rows += len(chunk)
                del chunk, arrays
            del chunks
    if suspect:
        err = locate_bad_lines(path, sep)
        if err is not None:
            raise err
    return _join_columns(names, parts, n, stack), n, np.concatenate(blank) if blank else np.zeros(0, dtype=np.int64)


def read_delimited(path: str | Path, sep: str | None = ",", *,
                   stack: Mapping[str, Sequence[str]] | None = None,
                   decimal: str | None = ".") -> tuple[Columns, RowLines]:
    """Parse a delimited text file with a header line into named column arrays.

    Parameters
    ----------
    path : str or Path
        The file (``.gz`` / ``.bz2`` decompressed as a stream).
    sep, decimal : str or None
        Field separator and decimal mark (``"."`` or ``","``); None: told from the file (:func:`detect_dialect`).
    stack : mapping of str to sequence of str, optional
        New name -> columns returned side by side as one float64 array (N, k) in their place, when they are
        consecutive in the header in this order, all numbers, and no column has the new name.

    Returns
    -------
    columns : dict of str to ndarray
        One array per column, in file order (float or int where every value is a number, else object), maybe
        read-only (pandas' own).
    row_lines : RowLines
        Data row -> 1-based file line.

    Raises
    ------
    FileNotFoundError
        No such file.
    MalformedFileError
        Empty file, header only, a line with the wrong number of fields (first bad line and count), not
        UTF-8, truncated or corrupt compression.
    """
    import pandas as pd
    path = Path(path)
    corrupt: tuple[type[BaseException], ...] = (EOFError, zlib.error, OSError, *_isal_errors())  # (BadGzipFile too)
    if sep is None or decimal is None:
        open_binary(path).close()               # the missing-file, not-a-file and permission messages, as they are
    try:
        if sep is None or decimal is None:
            found = detect_dialect(path)
            sep, decimal = sep or found[0], decimal or found[1]
        try:
            cols, n, blank = _parse(path, sep, stack, decimal)
        except pd.errors.ParserError as e:  # (a corrupt gzip stream may first show as lines of the wrong length)
            err = locate_bad_lines(path, sep)
            if err is not None:
                raise err from None
            m = re.search(r"line (\d+)", str(e))
            raise MalformedFileError(path, f"cannot parse: {e}", line=int(m.group(1)) if m else None) from e
    except pd.errors.EmptyDataError as e:
        raise MalformedFileError(path, "file is empty") from e
    except corrupt as e:
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
    """Give the C heap's free pages back to the system (glibc ``malloc_trim``; nothing elsewhere), after a long read."""
    try:
        ctypes.CDLL(None).malloc_trim(0)
    except (OSError, AttributeError):           # not glibc
        pass


def _join_columns(names: list[str], parts: dict[str, list[np.ndarray]], n: int,
                  stack: Mapping[str, Sequence[str]] | None = None) -> Columns:
    """Each column's chunks as one array, the ``stack`` ones side by side (``parts`` is emptied)."""
    groups: dict[str, Sequence[str]] = {}       # the stacks that apply (see read_delimited)
    for name, members in (stack or {}).items():
        at = names.index(members[0]) if members and members[0] in names else -1
        if (at >= 0 and name not in names and names[at:at + len(members)] == list(members)
                and all(x.dtype.kind in "fiu" for c in members for x in parts[c])):
            groups[name] = members
    into = {c: name for name, members in groups.items() for c in members}
    cols: Columns = {}
    for c in names:
        if c in into:
            if into[c] not in cols:
                cols[into[c]] = _fill_stack(n, [parts.pop(m) for m in groups[into[c]]])
            continue
        chunks = parts.pop(c)
        if len(chunks) == 1:            # pandas' own array (read-only under copy-on-write): not copied
            cols[c] = chunks[0]
        elif all(x.dtype.kind in "fiu" for x in chunks):       # the dtype np.concatenate would give
            cols[c] = np.empty(n, dtype=functools.reduce(np.promote_types, {x.dtype for x in chunks}))
            _fill(cols[c], chunks)
        else:
            cols[c] = np.concatenate(chunks)
        del chunks
    return cols


def _fill(out: np.ndarray, chunks: list[np.ndarray]) -> None:
    """Copy the chunks one after the other into ``out``, emptying the list as it goes."""
    k = 0
    while chunks:
        x = chunks.pop(0)
        out[k:k + x.size] = x
        k += x.size


def _fill_stack(n: int, columns: list[list[np.ndarray]]) -> np.ndarray:
    """The columns (each a list of equal chunks) side by side, (n, k), emptying the lists.

    In blocks of :data:`STACK_BLOCK` rows on up to :data:`STACK_THREADS` threads: the copy is the array's first
    touch, whose page faults can cost more than the copy on one thread.
    """
    out = np.empty((n, len(columns)))
    threads = min(STACK_THREADS, -(-n // STACK_BLOCK))
    with contextlib.ExitStack() as scope:
        pool = scope.enter_context(ThreadPoolExecutor(threads)) if threads > 1 else None
        k = 0
        while columns[0]:
            chunk = [col.pop(0) for col in columns]
            rows = out[k:k + chunk[0].size]

            def copy(lo: int, rows: np.ndarray = rows, chunk: list[np.ndarray] = chunk) -> None:
                for j, x in enumerate(chunk):
                    rows[lo:lo + STACK_BLOCK, j] = x[lo:lo + STACK_BLOCK]

            blocks = range(0, rows.shape[0], STACK_BLOCK)
            list(pool.map(copy, blocks) if pool is not None else map(copy, blocks))
            k += rows.shape[0]
            del chunk, rows, copy
    return out


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
        raise ImuGroundError(f"{where}: {what.replace(':', f', row {r}:', 1)}")
    import pandas as pd
    return pd.to_numeric(pd.Series(values), errors="coerce").to_numpy(dtype=float)
