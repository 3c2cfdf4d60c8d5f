"""Where a log or an output lives: a local path, or an fsspec URL (``s3://``, ``gs://``, ``memory://`` ...).

The one place that tells the two apart (:func:`is_url`; ``file://`` URLs are local paths). A URL goes through
`fsspec <https://filesystem-spec.readthedocs.io>`_: read from a local copy (:func:`local_input`; messages name
the URL), written whole to a local file and uploaded in one piece (:func:`staged_outputs`, :func:`put_file`),
listed (:func:`glob`, :func:`exists`). A protocol's package (``s3fs`` ...) missing is a
:class:`MissingFilesystemError` naming it; credentials and endpoints are the filesystem's own.
"""
from __future__ import annotations

import functools
import os
import posixpath
import re
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path, PurePosixPath
from typing import IO, Any, TypeGuard, TypeVar

from imu_ground.errors import ImuGroundError, MissingFilesystemError, StorageError

from .options import OptionText

__all__ = ["MissingFilesystemError", "StorageError", "check_bucket", "cli_refusal", "exists", "filesystem", "glob",
           "is_file_object", "is_url", "join", "local_input", "local_name", "open_file", "put_file", "reads_sources",
           "relabel", "rename", "source_label", "staged_folder", "staged_outputs", "url_name", "url_parts",
           "with_suffix", "write_bytes"]

_F = TypeVar("_F", bound=Callable[..., Any])

#: ``protocol://`` at the start of a string (a protocol of two or more characters: ``C:\\`` is a path).
_URL = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]+)(::[A-Za-z][A-Za-z0-9+.\-]+)*://")
#: Protocols whose "folders" are key prefixes (no folder to create before writing a file).
_FLAT = ("s3", "s3a", "gs", "gcs", "az", "abfs", "abfss", "adl", "memory", "oss", "r2")


def is_file_object(source: Any) -> bool:
    """Whether ``source`` is an open file object (has ``read``), not a path or URL."""
    return callable(getattr(source, "read", None)) and not isinstance(source, (str, os.PathLike))


def local_name(path: Any) -> Any:
    """``file://`` URLs as the local path they name; anything else as given."""
    if isinstance(path, str) and path[:7].lower() == "file://":
        from fsspec.implementations.local import LocalFileSystem
        return LocalFileSystem._strip_protocol(path)
    return path


def is_url(path: Any) -> TypeGuard[str]:
    """Whether ``path`` is an fsspec URL that is not a local file (``file://`` is one: see :func:`local_name`)."""
    return isinstance(path, str) and _URL.match(path) is not None and path[:7].lower() != "file://"


def _protocol(url: str) -> str:
    """The URL's protocol (the last of a chain such as ``simplecache::s3://``)."""
    return url.split("://", 1)[0].split("::")[-1].lower()


def filesystem(url: str) -> tuple[Any, str]:
    """``(fsspec filesystem, path inside it)`` of ``url``.

    Raises
    ------
    MissingFilesystemError
        The protocol's package is not installed (named).
    StorageError
        A protocol fsspec does not know.
    """
    import fsspec
    from fsspec.registry import known_implementations
    proto = _protocol(url)
    try:
        fsspec.get_filesystem_class(proto)
    except ImportError:
        cls = known_implementations.get(proto, {}).get("class", proto)
        raise MissingFilesystemError(url, proto, cls.split(".")[0]) from None
    except ValueError:
        raise StorageError(f"{url}: {proto}:// is not a storage protocol fsspec knows (local paths, file://, "
                           "s3://, gs://, az://, ... with their packages)") from None
    return fsspec.core.url_to_fs(url)


def cli_refusal(value: str, flag: str) -> str | None:
    """Why the command line cannot take ``value`` for ``flag`` (None: it can): ``memory://`` (the memory of
    another process), or a URL whose filesystem package is missing, named before any work."""
    if not is_url(value):
        return None
    if _protocol(value) == "memory":
        return (f"{value}: memory:// is the memory of one Python process, which a command cannot share; give "
                f"{flag} a local path, a file:// URL or object storage (s3://, gs://, ...)")
    try:
        filesystem(value)
    except StorageError as e:
        return str(e)
    return None


def exists(path: Any) -> bool:
    """Whether the file or folder exists (local or URL)."""
    path = local_name(path)
    if not is_url(path):
        return Path(path).exists()
    fs, p = filesystem(path)
    return bool(fs.exists(p))


def glob(pattern: str) -> list[str]:
    """The URLs a URL glob pattern matches (``s3://bucket/logs/**/*.csv.gz``), sorted, spelt with the protocol."""
    if is_url(pattern):
        fs, p = filesystem(pattern)
    else:
        from fsspec.implementations.local import LocalFileSystem
        fs, p = LocalFileSystem(), local_name(pattern)
    proto = pattern.split("://", 1)[0]
    out = []
    for m in fs.glob(p):
        url = fs.unstrip_protocol(m)
        out.append(proto + "://" + url.split("://", 1)[1] if "://" in url else url)
    return sorted(out)


def url_name(url: str) -> str:
    """The last part of a URL's path (its file or folder name)."""
    return PurePosixPath(url.split("://", 1)[-1].rstrip("/")).name


def url_parts(url: str) -> tuple[str, ...]:
    """The folders of a URL's path, bucket first (what :func:`~imu_ground.pipeline.batch.output_names`
    adds to names that clash)."""
    return PurePosixPath(url.split("://", 1)[-1].rstrip("/")).parent.parts


def join(base: str | Path, name: str) -> str | Path:
    """``base / name`` for a local folder, ``base/name`` for a URL."""
    base = local_name(base)
    if is_url(base):
        return str(base).rstrip("/") + "/" + name
    return Path(base) / name


def with_suffix(path: str | Path, suffix: str) -> str | Path:
    """``path`` with its last suffix replaced (a URL stays a string)."""
    if is_url(path):
        path = str(path)
        name = url_name(path)
        stem = name.rsplit(".", 1)[0] if "." in name else name
        return path[:len(path.rstrip("/")) - len(name)] + stem + suffix
    return Path(path).with_suffix(suffix)


def open_file(path: Any, mode: str = "rb", **kwargs: Any) -> IO:
    """A file (local path or URL) opened for reading, binary or text (``encoding`` defaults to UTF-8)."""
    if "b" not in mode:
        kwargs.setdefault("encoding", "utf-8")
    path = local_name(path)
    if not is_url(path):
        return open(path, mode, **kwargs)       # noqa: SIM115 (the caller closes it)
    fs, p = filesystem(path)
    return fs.open(p, mode, **kwargs)


def write_bytes(url: str, data: bytes) -> None:
    """Store ``data`` at ``url`` in one piece (see :func:`put_file`)."""
    with staged_outputs([url]) as (local,):
        Path(local).write_bytes(data)


def check_bucket(url: str, option: str) -> None:
    """Raise :class:`StorageError` naming ``option`` when ``url``'s bucket (object stores) does not exist,
    before any work (a prefix inside it needs no creating)."""
    if _protocol(url) not in _FLAT or _protocol(url) == "memory":
        return
    fs, p = filesystem(url)
    bucket = p.split("/", 1)[0]
    try:
        found = fs.exists(bucket)
    except (OSError, ValueError):       # e.g. no permission to look: the write will say
        return
    if not found:
        raise StorageError(f"{url}: no such bucket {bucket!r}; choose another {option}")


def put_file(local: str | Path, url: str) -> None:
    """Upload the local file to ``url`` in one piece (an object store's PUT: whole or absent).

    Raises
    ------
    StorageError
        The destination cannot be written (no such bucket, no permission ...): naming the URL.
    """
    fs, p = filesystem(url)
    try:
        if _protocol(url) not in _FLAT:
            fs.makedirs(posixpath.dirname(p), exist_ok=True)
        fs.put_file(str(local), p)
    except (OSError, ValueError) as e:          # s3fs: FileNotFoundError for a missing bucket, PermissionError ...
        if isinstance(e, ImuGroundError):
            raise
        raise StorageError(f"{url}: could not be written ({type(e).__name__}: {e}); choose another path") from None


@contextmanager
def staged_outputs(paths: Sequence[Any]) -> Iterator[list[Any]]:
    """Local stand-ins for ``paths``: a URL's is a temporary file (same name), uploaded in one piece when the block
    succeeds (in order: the first may exist without the last when an upload fails); local paths as they are."""
    tmp = Path(tempfile.mkdtemp(prefix="imu-ground-out-"))
    try:
        local = [tmp / str(i) / url_name(p) if is_url(p) else p for i, p in enumerate(paths)]
        for p in local:
            if isinstance(p, Path) and p.is_relative_to(tmp):
                p.parent.mkdir()
        yield local
        for url, p in zip(paths, local, strict=True):
            if is_url(url):
                put_file(p, url)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


@contextmanager
def staged_folder(path: Any) -> Iterator[Any]:
    """A folder to write files into: a local path as it is; for a URL a temporary folder whose files are
    uploaded (each in one piece, :func:`put_file`) to ``URL/<name>`` when the block succeeds."""
    path = local_name(path)
    if not is_url(path):
        yield path
        return
    tmp = Path(tempfile.mkdtemp(prefix="imu-ground-out-"))
    try:
        yield tmp
        for f in sorted(tmp.rglob("*")):
            if f.is_file():
                put_file(f, str(join(path, f.relative_to(tmp).as_posix())))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# ------------------------------------------------------------------------------------------ reading
def _sniffed_name(head: bytes) -> str:
    """A name whose suffix the readers' probes recognise, from the first bytes of a nameless stream."""
    for magic, name in ((b"\x1f\x8b", "log.csv.gz"), (b"BZh", "log.csv.bz2"), (b"PAR1", "log.parquet"),
                        (b"#ROSBAG", "log.bag"), (b"\x89MCAP", "log.mcap")):
        if head.startswith(magic):
            return name
    return "log.csv"


def _spool(source: IO, folder: Path) -> Path:
    """Write the rest of an open file object (binary, or text as UTF-8) into ``folder``; the copy's path."""
    part = folder / ".part"
    with open(part, "wb") as out:
        while block := source.read(1 << 20):
            out.write(block.encode("utf-8") if isinstance(block, str) else block)
    name = getattr(source, "name", None)
    if isinstance(name, (str, os.PathLike)) and Path(name).name:
        target = folder / Path(name).name
    else:
        with open(part, "rb") as f:
            target = folder / _sniffed_name(f.read(8))
    return part.rename(target)


@contextmanager
def local_input(source: Any, label: str | None = None) -> Iterator[Any]:
    """``source`` as something the readers open: a local path as it is, a URL or file object as a local copy.

    Parameters
    ----------
    source : str, Path, file object or anything else
        A local path or ``file://`` URL (given back as its path); an fsspec URL (the file or folder copied
        into a temporary folder, removed after the block); an open file object, binary or text (the rest
        copied, named as the file object is, else by its first bytes: ``.gz``, ``.bz2``, Parquet, ROS bag,
        MCAP, else ``log.csv``). Anything else (a DataFrame) is given back.
    label : str, optional
        How messages name a copied source (default: the URL, or the file object's name).

    Yields
    ------
    The local path (or ``source``); in the block, exceptions and warnings name the source, not the copy.

    Raises
    ------
    FileNotFoundError
        No such URL.
    """
    source = local_name(source)
    if not (is_url(source) or is_file_object(source)):
        yield source
        return
    tmp = Path(tempfile.mkdtemp(prefix="imu-ground-in-"))
    try:
        if is_url(source):
            fs, p = filesystem(source)
            if not fs.exists(p):
                raise FileNotFoundError(f"{source}: no such file or folder")
            local = tmp / (url_name(source) or "log")
            if fs.isdir(p):
                fs.get(p, str(local), recursive=True)
            else:
                fs.get_file(p, str(local))
        else:
            local = _spool(source, tmp)
        with _renamed(str(local), label or source_label(source)):
            yield local
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def source_label(source: Any) -> str:
    """How messages name a source: the URL or path, a file object's name, else ``<file object>``."""
    if is_file_object(source):
        name = getattr(source, "name", None)
        return str(name) if isinstance(name, (str, os.PathLike)) else "<file object>"
    return str(source)


def relabel(data: Any, old: str, new: str) -> Any:
    """``data`` naming ``new`` where it names the local copy ``old``, in place where it can: its ``source``,
    the strings of its ``meta`` (and of the dicts, lists and tuples inside), recursively; returns it."""
    def walk(x: Any, seen: set) -> Any:
        if isinstance(x, str):
            return _swap(x, old, new) if old in x else x
        if id(x) in seen:
            return x
        seen.add(id(x))
        if isinstance(x, dict):
            for k, v in x.items():
                x[k] = walk(v, seen)
        elif isinstance(x, list):
            x[:] = [walk(v, seen) for v in x]
        elif isinstance(x, tuple):
            items = [walk(v, seen) for v in x]
            if all(a is b for a, b in zip(items, x, strict=True)):
                return x
            return type(x)(*items) if hasattr(x, "_fields") else tuple(items)     # a NamedTuple keeps its type
        else:
            rename(x, old, new)
            if isinstance(getattr(x, "meta", None), dict):
                walk(x.meta, seen)
        return x
    return walk(data, set())


def reads_sources(fn: _F) -> _F:
    """Decorator: ``fn(path, ...)``, written for local paths, also takes a URL or a file object (:func:`local_input`);
    what it returns names the source, not the copy (:func:`relabel`)."""
    @functools.wraps(fn)
    def wrapper(path: Any, *args: Any, **kwargs: Any) -> Any:
        path = local_name(path)
        if not (is_url(path) or is_file_object(path)):
            return fn(path, *args, **kwargs)
        with local_input(path) as local:
            return relabel(fn(local, *args, **kwargs), str(local), source_label(path))
    return wrapper  # type: ignore[return-value]


def _swap(value: Any, old: str, new: str) -> Any:
    if isinstance(value, OptionText):
        return OptionText(str(value).replace(old, new), value.cli.replace(old, new))
    if isinstance(value, str):
        return value.replace(old, new)
    return value


def rename(obj: Any, old: str, new: str) -> Any:
    """Replace ``old`` by ``new`` in what an exception or warning says (args, template, path, filename)."""
    if isinstance(obj, BaseException):
        obj.args = tuple(_swap(a, old, new) for a in obj.args)
    for attr in ("template", "path", "filename", "filename2", "source"):
        v = getattr(obj, attr, None)
        if isinstance(v, str) and old in v:
            try:
                setattr(obj, attr, _swap(v, old, new))
            except (AttributeError, TypeError):
                pass
    return obj


@contextmanager
def _renamed(old: str, new: str) -> Iterator[None]:
    """Exceptions and warnings of the block that name ``old`` (a local copy) name ``new`` (its source)."""
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield
    except BaseException as e:
        rename(e, old, new)
        raise
    finally:
        seen = set()
        for w in caught:            # each once (recorded with "always": a reader's repeats would all come back)
            message = rename(w.message, old, new) if isinstance(w.message, Warning) else _swap(w.message, old, new)
            if (w.category, str(message), w.filename, w.lineno) not in seen:
                seen.add((w.category, str(message), w.filename, w.lineno))
                warnings.warn_explicit(message, w.category, w.filename, w.lineno)
