"""ROS logs as files: open a ROS 1 bag, a ROS 2 bag folder or an MCAP file, list and choose topics, read raw messages.

With `rosbags <https://gitlab.com/ternaris/rosbags>`_ and ``mcap`` (the ``ros`` extra, imported when used);
an MCAP file of ROS 1 messages (profile ``ros1``, as ``mcap convert x.bag`` writes) is read by ``mcap`` and
deserialised by rosbags. Unreadable files raise :class:`~imu_ground.errors.MalformedFileError` naming
them; a missing or ambiguous topic :class:`~imu_ground.errors.ImuInputError` naming ``topic``.
"""
from __future__ import annotations

import sqlite3
import struct
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from imu_ground.errors import ImuGroundError, ImuInputError, MalformedFileError, require_extra

__all__ = ["is_rosbag", "rosbag_topics"]

PathLike = str | Path


def is_rosbag(path: PathLike) -> bool:
    """Whether ``path`` looks like a ROS log: a ``.bag`` or ``.mcap`` file, or a folder with ``metadata.yaml``."""
    p = Path(path)
    if p.is_dir():
        return (p / "metadata.yaml").is_file()
    return p.suffix.lower() in (".bag", ".mcap")


# --------------------------------------------------------------------------- opening
def _corrupt(path: Path, err: BaseException) -> MalformedFileError:
    detail = " ".join(str(err).split()) or type(err).__name__      # one line
    hint = ("; a ROS 1 bag whose recording was cut off needs 'rosbag reindex'" if path.suffix == ".bag" else
            "; 'mcap recover' salvages the complete messages of a cut-off MCAP file"
            if path.suffix == ".mcap" else "")
    return MalformedFileError(path, f"truncated or corrupt ROS log, cannot read it ({detail}){hint}")


def _read_errors() -> tuple[type[BaseException], ...]:
    from rosbags.highlevel import AnyReaderError
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error
    from rosbags.serde import SerdeError
    errors: tuple[type[BaseException], ...] = (AnyReaderError, Reader1Error, Reader2Error, SerdeError,
                                               sqlite3.DatabaseError, struct.error, EOFError, KeyError, IndexError,
                                               UnicodeDecodeError)
    try:
        from mcap.exceptions import McapError
    except ImportError:  # the mcap package is needed only for ROS 1 MCAP files
        return errors
    return (*errors, McapError)


def _mcap_profile(path: Path) -> str:
    """The profile (``"ros1"``, ``"ros2"``, ...) in an MCAP file's header record ('' when unreadable)."""
    with open(path, "rb") as f:
        head = f.read(8 + 1 + 8 + 4 + 64)
    if len(head) < 21 or not head.startswith(b"\x89MCAP") or head[8] != 0x01:
        return ""
    (n,) = struct.unpack_from("<I", head, 17)
    return head[21:21 + n].decode("utf-8", "replace")


class _Connection(NamedTuple):
    topic: str
    msgtype: str
    msgcount: int
    id: int


class _Ros1Mcap:
    """The part of rosbags' ``AnyReader`` used here, over an MCAP file of ROS 1 messages (rosbags reads ``ros2``)."""

    is2 = False

    def __init__(self, path: Path) -> None:
        self.path = path
        self.connections: list[_Connection] = []

    def open(self) -> None:
        make_reader = require_extra("mcap.reader", "ros", f"{self.path}: reading a ROS 1 MCAP file").make_reader
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        from rosbags.typesys.msg import normalize_msgtype

        self._file = open(self.path, "rb")  # noqa: SIM115 (closed by close())
        try:
            self._reader = make_reader(self._file)
            summary = self._reader.get_summary()
        except BaseException:
            self._file.close()
            raise
        if summary is None:
            self._file.close()
            raise EOFError("no summary section")
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        types: dict[str, Any] = {}
        for cid, ch in sorted(summary.channels.items()):
            schema = summary.schemas[ch.schema_id]
            msgtype = normalize_msgtype(schema.name)
            if schema.encoding == "ros1msg":
                types.update(get_types_from_msg(schema.data.decode(), msgtype))
            self.connections.append(_Connection(ch.topic, msgtype, int(counts.get(cid, 0)), cid))
        self.typestore = get_typestore(Stores.EMPTY)
        self.typestore.register(types)

    def close(self) -> None:
        self._file.close()

    def messages(self, connections: Sequence[_Connection] = ()) -> Iterator[tuple[_Connection, int, bytes]]:
        by_id = {c.id: c for c in (connections or self.connections)}
        for _, channel, message in self._reader.iter_messages(topics=sorted({c.topic for c in by_id.values()})):
            if channel.id in by_id:
                yield by_id[channel.id], message.log_time, message.data

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        return self.typestore.deserialize_ros1(raw, msgtype)


@contextmanager
def _open(path: PathLike) -> Iterator[Any]:
    """An open ``rosbags.highlevel.AnyReader``; unreadable files raise :class:`MalformedFileError` naming them."""
    AnyReader = require_extra("rosbags.highlevel", "ros", f"{path}: reading ROS logs").AnyReader
    typesys = require_extra("rosbags.typesys", "ros", f"{path}: reading ROS logs")
    Stores, get_typestore = typesys.Stores, typesys.get_typestore

    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if not is_rosbag(p):
        raise ImuGroundError(f"{p}: not a ROS log (expected a .bag or .mcap file, or a ROS 2 bag folder with "
                             f"metadata.yaml)")
    errors = _read_errors()
    try:
        if p.is_file() and p.suffix.lower() == ".mcap" and _mcap_profile(p) == "ros1":
            reader: Any = _Ros1Mcap(p)
        else:
            reader = AnyReader([p], default_typestore=get_typestore(
                Stores.ROS1_NOETIC if p.suffix == ".bag" else Stores.LATEST))
        reader.open()
    except errors as e:
        raise _corrupt(p, e) from e
    try:
        yield reader
    except errors as e:
        raise _corrupt(p, e) from e
    finally:
        reader.close()


def _topic_rows(reader: Any, connections: Sequence[Any], rates: bool = True) -> list[tuple[str, str, int, float]]:
    """(topic, msgtype, count, rate_hz) of ``connections``; rates (median of the record-time steps, nan below 2
    messages or without ``rates``) read every message."""
    counts: dict[tuple[str, str], int] = {}
    for c in connections:
        counts[(c.topic, c.msgtype)] = counts.get((c.topic, c.msgtype), 0) + c.msgcount
    times: dict[str, list[int]] = {}
    for conn, rec_ns, _ in (reader.messages(connections=connections) if connections and rates else ()):
        times.setdefault(conn.topic, []).append(rec_ns)
    hz = {}
    for topic, ts in times.items():
        d = np.diff(np.sort(np.asarray(ts, dtype=np.int64)))
        d = d[d > 0]
        hz[topic] = 1e9 / float(np.median(d)) if d.size else float("nan")
    return [(topic, msgtype, n, hz.get(topic, float("nan"))) for (topic, msgtype), n in sorted(counts.items())]


def rosbag_topics(path: PathLike, rates: bool = True) -> list[tuple[str, str, int, float]]:
    """Topics of a ROS log.

    Parameters
    ----------
    path : str or Path
        ``.bag``, ``.mcap`` or ROS 2 bag folder.
    rates : bool
        Measure each topic's rate (reads every message); False: counts from the index only.

    Returns
    -------
    list of (topic, msgtype, count, rate_hz)
        Sorted by topic; ``msgtype`` as rosbags spells it (``sensor_msgs/msg/Imu``), ``rate_hz`` the median
        rate of the record times (nan below 2 messages or without ``rates``).

    Raises
    ------
    MalformedFileError
        Truncated or corrupt file (the message names it).
    """
    with _open(path) as reader:
        return _topic_rows(reader, reader.connections, rates)


def _describe(rows: Sequence[tuple[str, str, int, float]]) -> str:
    return ", ".join(f"{t} ({m}, {n} messages" + (f", {r:.4g} Hz)" if np.isfinite(r) else ")")
                     for t, m, n, r in rows) or "no topics"


def _choose(reader: Any, path: Path, types: Sequence[str], topic: str | None, what: str) -> list[Any]:
    """Connections of the one topic of a type in ``types`` (or of ``topic``); clear errors otherwise."""
    conns = reader.connections
    if topic is not None:
        chosen = [c for c in conns if c.topic == topic]
        if not chosen:
            raise ImuInputError(f"{path}: no topic {topic!r}; topics: {_describe(_topic_rows(reader, conns, False))}",
                                option="topic", value=topic)
        if chosen[0].msgtype not in types:
            raise ImuInputError(f"{path}: topic {topic!r} carries {chosen[0].msgtype}, not {what} "
                                f"({' or '.join(types)})", option="topic", value=topic)
        return chosen
    matching = [c for c in conns if c.msgtype in types]
    names = sorted({c.topic for c in matching})
    if not names:
        raise ImuInputError(f"{path}: no {what} topic ({' or '.join(types)}); the log has "
                            f"{_describe(_topic_rows(reader, conns, False))}")
    if len(names) > 1:
        rows = _topic_rows(reader, matching)
        raise ImuInputError(f"{path}: {len(names)} {what} topics: {_describe(rows)}; choose one with {{hint}}",
                            option="topic", value=names[0])
    return matching


def _raw_messages(reader: Any, conns: Sequence[Any]) -> tuple[np.ndarray, list[bytes]]:
    """Record times (ns, int64) and serialised messages of ``conns``, in record order."""
    rec: list[int] = []
    raws: list[bytes] = []
    for _, rec_ns, raw in reader.messages(connections=conns):
        rec.append(rec_ns)
        raws.append(bytes(raw))
    return np.asarray(rec, dtype=np.int64), raws
