"""Delimited text files: streamed decompression, a real CSV engine, bad lines found only on failure.

:func:`read_delimited` parses with pandas' C engine in chunks, from a
decompressing stream (``.gz``, ``.bz2``), so memory grows with the parsed columns,
not with the text. Only when the fast parse fails or looks suspicious (a short
line fills the last column with NaN) does :func:`locate_bad_lines` walk the file
line by line to name the first bad line (1-based file line) as before.
"""
from __future__ import annotations

import bz2
import gzip
import io
import re
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from .report import MalformedFileError

__all__ = ["Columns", "RowLines", "first_nonnumber", "locate_bad_lines", "numeric", "open_binary", "read_delimited"]

#: Rows per parsed chunk (bounded working memory on long logs).
CHUNK_ROWS = 1 << 19

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


def _parse(path: Path, sep: str) -> tuple[list[str], dict[str, list[np.ndarray]], int, np.ndarray]:
    """Chunked C-engine parse: (names, column chunks, rows, blank-line positions)."""
    import pandas as pd
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
                arrays = [chunk[col].to_numpy() for col in chunk.columns]
                empty = _blank(arrays[0])
                if empty.any():  # blank lines are all-NaN (or whitespace) rows: note where, then leave them out
                    for x in arrays[1:]:
                        empty &= _blank(x)
                    if empty.any():
                        blank.append(np.flatnonzero(empty) + raw_rows)
                        arrays = [x[~empty] for x in arrays]
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
    return names, parts, n, (np.concatenate(blank) if blank else np.zeros(0, dtype=np.int64))


def read_delimited(path: str | Path, sep: str = ",") -> tuple[Columns, RowLines]:
    """Parse a delimited text file with a header line into named column arrays.

    Parameters
    ----------
    path : str or Path
        The file (``.gz`` / ``.bz2`` decompressed as a stream).
    sep : str
        Field separator.

    Returns
    -------
    columns : dict of str to ndarray
        One array per column, in file order (float or int where every value is
        a number, else object).
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
    import pandas as pd
    path = Path(path)
    try:
        names, parts, n, blank = _parse(path, sep)
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
    cols: Columns = {}
    for c in names:
        chunks = parts.pop(c)
        one = chunks[0] if len(chunks) == 1 else None
        cols[c] = (one if one.flags.writeable else one.copy()) if one is not None else np.concatenate(chunks)
        del chunks
    return cols, RowLines(blank)


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
