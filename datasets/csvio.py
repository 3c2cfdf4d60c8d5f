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
from typing import Any

import numpy as np

from .report import MalformedFileError

__all__ = ["Columns", "RowLines", "locate_bad_lines", "open_binary", "read_delimited"]

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


class _Counting(io.RawIOBase):
    """Pass-through reader counting newlines, so the row -> line map is known without a second pass."""

    def __init__(self, raw: io.BufferedIOBase) -> None:
        self.raw, self.newlines, self.last, self.size = raw, 0, b"", 0

    def readable(self) -> bool:
        return True

    def readinto(self, b: Any) -> int:
        data = self.raw.read(len(b))
        n = len(data)
        b[:n] = data
        if n:
            self.newlines += data.count(b"\n")
            self.last = data[-1:]
            self.size += n
        return n

    @property
    def lines(self) -> int:
        """Number of lines read (a last line without newline counts)."""
        return self.newlines + (1 if self.size and self.last != b"\n" else 0)


class RowLines:
    """Data row (0-based) -> 1-based file line; computed by a scan only when asked and needed.

    Parameters
    ----------
    path : Path
        The file.
    simple : bool
        True when the file has no blank line: row ``r`` is on line ``r + 2``.
    """

    def __init__(self, path: Path, simple: bool) -> None:
        self.path, self.simple = path, simple
        self._lines: np.ndarray | None = None

    def __call__(self, rows: np.ndarray) -> np.ndarray:
        rows = np.asarray(rows, dtype=np.int64)
        if self.simple:
            return rows + 2
        if self._lines is None:
            with open_binary(self.path) as f:
                self._lines = np.array([i for i, ln in enumerate(f, 1) if ln.strip()], dtype=np.int64)[1:]
        return self._lines[rows]


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


def _short_line_suspect(chunk: Any) -> bool:
    """A short line leaves NaN in the last column: worth a look for a field-count error."""
    last = chunk.iloc[:, -1]
    return bool(last.isna().any())


def _parse(path: Path, sep: str, counter: _Counting) -> tuple[list[str], dict[str, list[np.ndarray]], int]:
    import pandas as pd
    reader = pd.read_csv(io.BufferedReader(counter, buffer_size=1 << 20), sep=sep, engine="c",
                         chunksize=CHUNK_ROWS, skip_blank_lines=True, encoding="utf-8")
    names: list[str] = []
    parts: dict[str, list[np.ndarray]] = {}
    n = 0
    suspect = False
    with reader:
        for chunk in reader:
            if not names:
                names = [str(c) for c in chunk.columns]
                parts = {c: [] for c in names}
            suspect = suspect or _short_line_suspect(chunk)
            for c, col in zip(names, chunk.columns):
                parts[c].append(chunk[col].to_numpy())
            n += len(chunk)
    if suspect:
        err = locate_bad_lines(path, sep)
        if err is not None:
            raise err
    return names, parts, n


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
    raw = open_binary(path)
    counter = _Counting(raw)
    try:
        names, parts, n = _parse(path, sep, counter)
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
    finally:
        raw.close()
    simple = counter.lines == n + 1
    if n == 0:
        header = next((i for i, ln in _iter_lines(path) if ln.strip()), 1)
        raise MalformedFileError(path, "header only, no data rows", line=header)
    cols: Columns = {}
    for c in names:
        chunks = parts.pop(c)
        one = chunks[0] if len(chunks) == 1 else None
        cols[c] = (one if one.flags.writeable else one.copy()) if one is not None else np.concatenate(chunks)
        del chunks
    return cols, RowLines(path, simple)


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
