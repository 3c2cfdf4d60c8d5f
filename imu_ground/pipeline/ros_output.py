"""The ground estimate as ROS topics: a ROS 1 bag, a ROS 2 bag folder or an MCAP file.

It plays in Foxglove or RViz beside the recording: header stamps are the recording's clock
(``t0`` / ``t0_ns``), ``frame_id`` the IMU's. One message per valid, finite frame of the output
table (``PREFIX`` is ``topic_prefix``, default ``/ground``; types: :data:`ROS_OUTPUT_TOPICS`):

- ``PREFIX/normal``: unit ground normal, body frame; ``PREFIX/rotation``: residual rotation
  road <- body (the table's q); ``PREFIX/pitch_roll``: ``x`` roll, ``y`` pitch of the body relative
  to the road, rad (the table's signs), ``z`` 0;
- ``PREFIX/road_from_camera`` (``TransformStamped``, with a camera): road <- camera, ``frame_id``
  ``road``, ``child_frame_id`` ``camera``, translation m (the camera origin in the road frame);
- ``/tf`` (not prefixed): road -> sensor, ``frame_id`` ``road`` (``road_frame_id``: the road plane
  under the vehicle, z its normal, x along the heading), ``child_frame_id`` the IMU's; rotation the
  dynamic extrinsic road-ground <- sensor ``R = R(q) R_gs`` (what ``.tum`` holds), translation the
  static extrinsic's (m); with a camera also road -> camera. A recording whose tf tree already gives
  the IMU's frame a parent gets two parents: pass another ``frame_id`` (e.g. ``imu_link_road``);
- ``PREFIX/pose``: the same transform as a pose in the road frame, covariance (6 x 6 row-major,
  x y z then rotations about the road's x y z) ``[21]`` roll and ``[28]`` pitch variance, rad^2,
  every other entry 0; where the 1-sigma is finite;
- settings: the JSON in an ``.mcap`` metadata record ``imu_ground`` (``settings``, ``version``;
  :func:`read_mcap_settings`), else once on ``PREFIX/settings`` at the first stamp;
- ``PREFIX/pitch_roll_std``, ``PREFIX/road`` (``x`` bank, + left side up; ``y`` grade, + uphill)
  and ``PREFIX/road_std`` (rad), where estimated;
- ``PREFIX/status`` on *every* frame: one status named ``imu-ground PREFIX``, ``hardware_id`` the
  ``frame_id``, ``level`` :data:`DIAGNOSTIC_LEVELS`, ``message`` ``"status"`` or ``"status: reason"``,
  ``values`` ``status`` and ``reason``.

The last four and ``PREFIX/pose`` only when the table has their columns. Container from the
path: ``.bag`` ROS 1, ``.mcap`` one MCAP file (CDR, ``ros2msg`` schemas), no suffix a ROS 2 bag
folder (MCAP storage, ``storage="sqlite3"`` for ``.db3``).
"""
from __future__ import annotations

import functools
import json
import re
import shutil
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imu_ground.errors import ImuGroundError
from imu_ground.units import DEG

if TYPE_CHECKING:
    from typing_extensions import Self

__all__ = ["DIAGNOSTIC_LEVELS", "MCAP_METADATA_NAME", "ROS_OUTPUT_TOPICS", "RosWriter", "read_mcap_settings",
           "ros_output_kind", "serialize_stamped", "write_ros_output"]

#: Topic suffix -> message type (ROS 2 spelling) of what :func:`write_ros_output` writes (``tf``: on ``/tf``).
ROS_OUTPUT_TOPICS: dict[str, str] = {
    "normal": "geometry_msgs/msg/Vector3Stamped",
    "rotation": "geometry_msgs/msg/QuaternionStamped",
    "pitch_roll": "geometry_msgs/msg/Vector3Stamped",
    "tf": "tf2_msgs/msg/TFMessage",
    "settings": "std_msgs/msg/String",
    "pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "pitch_roll_std": "geometry_msgs/msg/Vector3Stamped",
    "road": "geometry_msgs/msg/Vector3Stamped",
    "road_std": "geometry_msgs/msg/Vector3Stamped",
    "status": "diagnostic_msgs/msg/DiagnosticArray",
}
#: Topics of the table's optional columns: written when the table has them.
_OPTIONAL = {"pitch_roll_std": ("roll_std_deg", "pitch_std_deg"), "road": ("road_bank_deg", "road_grade_deg"),
             "road_std": ("road_bank_std_deg", "road_grade_std_deg"), "status": ("status", "status_reason")}
#: ``diagnostic_msgs/DiagnosticStatus`` level of each status (0 OK, 1 WARN, 2 ERROR, 3 STALE).
DIAGNOSTIC_LEVELS = {"ok": 0, "standstill": 0, "converging": 1, "degraded": 2, "invalid": 2, "gap": 3}
#: Name of the MCAP metadata record holding the settings.
MCAP_METADATA_NAME = "imu_ground"

_TABLE_COLUMNS = ("t", "normal_x", "normal_y", "normal_z", "pitch_deg", "roll_deg", "qw", "qx", "qy", "qz")
_KINDS = {".bag": "ros1", ".mcap": "mcap", "": "ros2"}


def ros_output_kind(path: str | Path) -> str:
    """Container written for ``path``: ``"ros1"`` (``.bag``), ``"mcap"`` (``.mcap``) or ``"ros2"`` (a ROS 2 bag
    folder: a path without suffix, or an existing folder).

    Raises
    ------
    ImuGroundError
        Any other suffix; the message lists the supported ones.
    """
    p = Path(path)
    if p.is_dir():
        return "ros2"
    kind = _KINDS.get(p.suffix.lower())
    if kind is None:
        raise ImuGroundError(f"{p}: cannot write ROS output with suffix {p.suffix!r}: use .bag (ROS 1), "
                             f".mcap (MCAP, ROS 2 messages) or a folder name without suffix (ROS 2 bag)")
    return kind


#: Standard messages a type store may lack (rosbags' ROS 1 Noetic store has no tf2_msgs), by their definition.
_STANDARD_DEFINITIONS = {"tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms"}


class _Serializer:
    """Messages of one ROS version (``ros1``: ROS 1 Noetic, else ROS 2 Humble) built and serialised by rosbags."""

    path: Any = "ROS output"

    def __init__(self, ros1: bool) -> None:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        self.ros1 = ros1
        self.typestore = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        for name, text in _STANDARD_DEFINITIONS.items():         # (the ROS 1 md5 sums come out as ROS's)
            if name not in self.typestore.types:
                self.typestore.register(get_types_from_msg(text, name))

    def message(self, msgtype: str, **fields: Any) -> Any:
        """A message object of ``msgtype`` from this writer's type store (ROS 1 or ROS 2)."""
        return self.typestore.types[msgtype](**fields)

    def header(self, stamp_ns: int, frame_id: str, seq: int = 0) -> Any:
        """A ``std_msgs/Header`` with stamp ``stamp_ns`` (ns since the clock's epoch, >= 0)."""
        stamp_ns = int(stamp_ns)
        if stamp_ns < 0:
            raise ImuGroundError(f"{self.path}: negative ROS stamp {stamp_ns} ns; pass t0/t0_ns (the log's start time)")
        t = self.message("builtin_interfaces/msg/Time", sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
        return self.message("std_msgs/msg/Header", stamp=t, frame_id=frame_id, **({"seq": seq} if self.ros1 else {}))

    def serialize(self, msg: Any) -> bytes:
        """``msg`` serialised for this log (ROS 1 for ``.bag``, CDR otherwise)."""
        msgtype = msg.__msgtype__
        if self.ros1:
            return bytes(self.typestore.serialize_ros1(msg, msgtype))
        return bytes(self.typestore.serialize_cdr(msg, msgtype))

    def serialize_many(self, build: Callable[..., Any], stamps_ns: np.ndarray,
                       values: Mapping[str, np.ndarray] | None = None) -> list[bytes]:
        """N messages of one layout, each equal to serialising ``build(stamp, k, **values row k)``: one serialised
        by rosbags with sentinels, whose bytes show where each message's stamps (ROS 1 ``seq``: the row index)
        and float64 ``values`` go, patched in with numpy. ``build(stamp_ns, seq, **doubles)`` makes headers with
        ``self.header(stamp_ns, ..., seq)`` and every other field the same for all N."""
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        values = dict(values or {})
        n = len(stamps)
        sec, nsec, seq = 0x5EC05EC0, 0x3A5EC0DE, 0x5E0C5E0C          # sentinels (nsec < 1e9)
        marks = {k: float.fromhex(f"0x1.5ec0{i:04x}a53c7p-900") for i, k in enumerate(values)}
        template = self.serialize(build(sec * 10**9 + nsec, seq, **marks))
        raw = np.frombuffer(template, dtype=np.uint8)
        buf = np.tile(raw, (n, 1))

        def offsets(pattern: bytes) -> list[int]:           # (overlapping ones too)
            return [m.start() for m in re.finditer(b"(?=" + re.escape(pattern) + b")", template)]

        def put(at: int, column: np.ndarray, dtype: str) -> None:
            data = np.ascontiguousarray(column, dtype=dtype)
            buf[:, at:at + data.itemsize] = data.view(np.uint8).reshape(n, data.itemsize)

        stamp_at = offsets(np.array([sec, nsec], dtype="<u4").tobytes())
        if not stamp_at:
            raise ValueError("build() made no header with the stamp it was given")
        for at in stamp_at:
            put(at, stamps // 1_000_000_000, "<u4")
            put(at + 4, stamps % 1_000_000_000, "<u4")
        if self.ros1:
            for at in offsets(np.array([seq], dtype="<u4").tobytes()):
                put(at, np.arange(n), "<u4")
        for key, mark in marks.items():
            found = offsets(np.array([mark], dtype="<f8").tobytes())
            if len(found) != 1:
                raise ValueError(f"build() must put the double {key!r} in exactly one field, not {len(found)}")
            put(found[0], values[key], "<f8")
        whole, size = buf.tobytes(), len(template)
        return [whole[i * size:(i + 1) * size] for i in range(n)]


class RosWriter(_Serializer):
    """One ROS log being written, whatever the container; a context manager.

    Parameters
    ----------
    path : str or Path
        Output path; the container follows from it (:func:`ros_output_kind`). Written exactly there
        (nothing renamed); it must not exist unless ``overwrite``.
    storage : {"mcap", "sqlite3"}
        Storage of a ROS 2 bag folder (ignored for ``.bag`` and ``.mcap``).
    overwrite : bool
        Remove an existing file, or an existing ROS 2 bag folder (one with a ``metadata.yaml``), first.
    """

    def __init__(self, path: str | Path, *, storage: str = "mcap", overwrite: bool = False) -> None:
        self.path = Path(path)
        self.kind = ros_output_kind(self.path)
        if storage not in ("mcap", "sqlite3"):
            raise ValueError(f"storage must be 'mcap' or 'sqlite3', got {storage!r}")
        self.storage = storage
        if self.path.exists():
            _remove_existing(self.path, overwrite)
        super().__init__(self.kind == "ros1")
        self._writer: Any = None
        self._file: Any = None
        self._schemas: dict[str, int] = {}
        self.counts: dict[str, int] = {}

    # -- opening and closing ------------------------------------------------------------
    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, exc_type: object, exc: object, tb: object) -> None:
        self.close()

    def open(self) -> None:
        """Create the file or folder."""
        if self.kind == "ros1":
            from rosbags.rosbag1 import Writer as Writer1
            self._writer = Writer1(self.path)
            self._writer.open()
        elif self.kind == "ros2":
            from rosbags.rosbag2 import StoragePlugin
            from rosbags.rosbag2 import Writer as Writer2
            plugin = StoragePlugin.MCAP if self.storage == "mcap" else StoragePlugin.SQLITE3
            self._writer = Writer2(self.path, version=9, storage_plugin=plugin)
            self._writer.open()
        else:
            from mcap.writer import Writer as McapWriter
            self._file = open(self.path, "xb")  # noqa: SIM115 (closed by close(), after the index)
            self._writer = McapWriter(self._file)
            self._writer.start(profile="ros2", library="imu-ground")

    def close(self) -> None:
        """Write the index and close; the log is complete only after this."""
        if self._writer is None:
            return
        if self.kind == "mcap":
            self._writer.finish()
            self._file.close()
        else:
            self._writer.close()
        self._writer = None

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write an MCAP metadata record ``name`` (str -> str); ValueError for another container."""
        if self.kind != "mcap":
            raise ValueError(f"{self.path}: only an .mcap file holds metadata records, not a {self.kind} log")
        self._writer.add_metadata(name=name, data={str(k): str(v) for k, v in data.items()})

    # -- messages -------------------------------------------------------------------------
    def add_topic(self, topic: str, msgtype: str) -> Any:
        """Register ``topic`` of type ``msgtype`` (ROS 2 spelling, ``pkg/msg/Name``); returns its handle."""
        self.counts.setdefault(topic, 0)
        if self.kind != "mcap":
            return self._writer.add_connection(topic, msgtype, typestore=self.typestore), topic
        if msgtype not in self._schemas:
            msgdef, _ = self.typestore.generate_msgdef(msgtype, ros_version=2)
            self._schemas[msgtype] = self._writer.register_schema(
                name=msgtype, encoding="ros2msg", data=msgdef.encode())
        channel = self._writer.register_channel(topic=topic, message_encoding="cdr",
                                                schema_id=self._schemas[msgtype])
        return channel, topic

    def write(self, handle: Any, stamp_ns: int, msg: Any) -> None:
        """Write ``msg`` on the topic of ``handle`` with record (log) time ``stamp_ns``."""
        self.write_raw(handle, stamp_ns, self.serialize(msg))

    def write_raw(self, handle: Any, stamp_ns: int, data: bytes | memoryview) -> None:
        """Write an already serialised message (ROS 1 for ``.bag``, CDR otherwise)."""
        conn, topic = handle
        if self.kind == "mcap":
            self._writer.add_message(channel_id=conn, log_time=int(stamp_ns), publish_time=int(stamp_ns),
                                     data=bytes(data), sequence=self.counts[topic])
        else:
            self._writer.write(conn, int(stamp_ns), data)
        self.counts[topic] += 1


@functools.cache
def _serializer(ros1: bool) -> _Serializer:
    return _Serializer(ros1)


def serialize_stamped(stamps_ns: np.ndarray, frame_id: str, values: np.ndarray, ros1: bool) -> list[bytes]:
    """N serialised ``geometry_msgs/Vector3Stamped`` (K = 3: x, y, z) or ``QuaternionStamped`` (K = 4: x, y, z, w)
    (:meth:`RosWriter.serialize_many`; ROS 1 ``seq`` is the row index).

    Parameters
    ----------
    stamps_ns : ndarray (N,) of int64
        Header stamps, ns since the clock's epoch (>= 0).
    frame_id : str
    values : ndarray (N, K)
        The float64 fields after the header, in message order.
    ros1 : bool
        ROS 1 serialisation, else CDR.

    Returns
    -------
    list of bytes
    """
    s = _serializer(ros1)
    values = np.asarray(values, dtype=float)
    names = "xyzw"[:values.shape[1]]
    kind, field = ("Vector3", "vector") if len(names) == 3 else ("Quaternion", "quaternion")

    def build(ns: int, seq: int, **v: float) -> Any:
        return s.message(f"geometry_msgs/msg/{kind}Stamped", header=s.header(ns, frame_id, seq),
                         **{field: s.message(f"geometry_msgs/msg/{kind}", **v)})

    return s.serialize_many(build, stamps_ns, {c: values[:, j] for j, c in enumerate(names)})


def _remove_existing(path: Path, overwrite: bool) -> None:
    if not overwrite:
        raise FileExistsError(f"{path} exists already; remove it or pass overwrite=True")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise FileExistsError(f"{path} is a folder but not a ROS 2 bag (no metadata.yaml); not removing it")
        shutil.rmtree(path)
    else:
        path.unlink()


def _stamp_origin(t0: float | None, t0_ns: int | None, settings: Mapping[str, Any] | None) -> int:
    """The clock offset, ns, added to the table's ``t``: argument, else settings, else 0."""
    s = settings or {}
    if t0_ns is None and t0 is None:
        t0_ns, t0 = s.get("t0_ns"), s.get("t0")
    if t0_ns is not None:
        return int(t0_ns)
    return round(float(t0) * 1e9) if t0 is not None else 0


def _valid_rows(table: Any) -> dict[str, np.ndarray]:
    """The table's columns (float arrays) restricted to valid rows with finite values, and ``row``: their
    positions in the table."""
    missing = [c for c in _TABLE_COLUMNS if c not in table]
    if missing:
        raise ValueError(f"the output table lacks column(s) {missing}; expected {list(_TABLE_COLUMNS)} and valid")
    cols = {c: np.asarray(table[c], dtype=float) for c in _TABLE_COLUMNS}
    keep = np.all(np.isfinite(np.column_stack(list(cols.values()))), axis=1)
    if "valid" in table:
        keep &= np.asarray(table["valid"], dtype=bool)
    return {**{c: v[keep] for c, v in cols.items()}, "row": np.flatnonzero(keep)}


def read_mcap_settings(path: str | Path) -> dict | None:
    """The settings :func:`write_ros_output` recorded in an ``.mcap`` file (its metadata record), or None."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    try:
        with open(path, "rb") as fh:
            for record in make_reader(fh).iter_metadata():
                if record.name == MCAP_METADATA_NAME and "settings" in record.metadata:
                    got = json.loads(record.metadata["settings"])
                    return got if isinstance(got, dict) else None
    except (McapError, OSError, ValueError, EOFError):
        return None
    return None


def write_ros_output(path: str | Path, table: Any, *, frame_id: str = "imu",
                     settings: Mapping[str, Any] | None = None, topic_prefix: str = "/ground",
                     t0: float | None = None, t0_ns: int | None = None,
                     storage: str = "mcap", overwrite: bool = False, road_from_camera: Any = None,
                     camera_frame_id: str = "camera", extrinsic: Any = None,
                     road_frame_id: str = "road") -> dict[str, int]:
    """Write the per-frame ground estimate as ROS topics (the module docstring).

    Parameters
    ----------
    path : str or Path
        ``.bag`` (ROS 1), ``.mcap`` (MCAP file, ROS 2 CDR) or a folder name without suffix (ROS 2 bag).
        Written exactly there; the caller renames for atomicity.
    table : pandas.DataFrame or mapping of arrays
        THE output table (:func:`imu_ground.pipeline.output.track_table`); rows with ``valid`` false or a
        NaN are skipped.
    frame_id : str
        ``header.frame_id`` of every message: the IMU's frame.
    settings : mapping, optional
        The method's settings (JSON; others written with ``str``): an ``.mcap`` file's metadata record, else
        once on ``PREFIX/settings``. Its ``t0_ns`` / ``t0`` entries are used when the arguments are not given.
    topic_prefix : str
        Namespace of the topics.
    t0, t0_ns : optional
        The log's start time, s (float) or ns (int, exact; ``ImuData.meta["t0_ns"]``): each frame's stamp
        (and record time) is ``t0_ns + round(t * 1e9)`` ns. Default: ``settings``' entries, else 0.
    storage : {"mcap", "sqlite3"}
        Storage of a ROS 2 bag folder.
    overwrite : bool
        Replace an existing output (otherwise :class:`FileExistsError`).
    road_from_camera : ndarray (N, 4, 4), optional
        Per table row, the road <- camera transform
        (:attr:`GroundPlane.matrix <imu_ground.perception.GroundPlane.matrix>`), written where finite.
    camera_frame_id : str
        ``child_frame_id`` of those transforms.
    extrinsic : mapping or Extrinsic, optional
        The static extrinsic ``rotation`` (3 x 3, ground <- sensor) and ``translation`` (m, the sensor's
        origin in the ground frame), as ``EstimateResult.meta["extrinsic"]``. Default: identity, at the origin.
    road_frame_id : str
        ``header.frame_id`` of ``/tf``, ``PREFIX/pose`` and ``PREFIX/road_from_camera``.

    Returns
    -------
    dict
        Topic -> number of messages written.
    """
    rows = _valid_rows(table)
    origin = _stamp_origin(t0, t0_ns, settings)
    stamps = origin + np.round(rows["t"] * 1e9).astype(np.int64)
    if len(stamps) and stamps.min() < 0:
        raise ImuGroundError(f"{path}: negative ROS stamps (first valid t = {rows['t'][0]:g} s); pass t0 or t0_ns, "
                             f"the log's start time")
    prefix = "/" + topic_prefix.strip("/") if topic_prefix.strip("/") else ""
    r_gs, trans = _static_extrinsic(extrinsic)
    with RosWriter(path, storage=storage, overwrite=overwrite) as w:
        h = {k: w.add_topic(f"{prefix}/{k}", ROS_OUTPUT_TOPICS[k]) for k in ("normal", "rotation", "pitch_roll")}
        if settings is not None:
            text = json.dumps(dict(settings), default=str, sort_keys=True)
            if w.kind == "mcap":
                from imu_ground._version import __version__
                w.add_metadata(MCAP_METADATA_NAME, {"settings": text, "version": __version__})
            else:
                h["settings"] = w.add_topic(f"{prefix}/settings", ROS_OUTPUT_TOPICS["settings"])
                if len(stamps):
                    w.write(h["settings"], int(stamps[0]), w.message("std_msgs/msg/String", data=text))
        data = [serialize_stamped(stamps, frame_id, np.column_stack([rows[c] for c in cols]), w.ros1)
                for cols in (("normal_x", "normal_y", "normal_z"), ("qx", "qy", "qz", "qw"))]
        data.append(serialize_stamped(stamps, frame_id, np.column_stack(
            [rows["roll_deg"] * DEG, rows["pitch_deg"] * DEG, np.zeros(len(stamps))]), w.ros1))
        for k, ns in enumerate(stamps.tolist()):
            for topic, msgs in zip(("normal", "rotation", "pitch_roll"), data, strict=True):
                w.write_raw(h[topic], ns, msgs[k])
        camera = None
        if road_from_camera is not None:
            camera = _write_camera_transforms(w, f"{prefix}/road_from_camera", rows, stamps, road_from_camera,
                                              camera_frame_id, road_frame_id)
        std = None                                              # (F, 2) roll and pitch 1-sigma, rad
        if "roll_std_deg" in table and "pitch_std_deg" in table:
            std = np.column_stack([np.asarray(table[c], dtype=float) for c in ("roll_std_deg", "pitch_std_deg")]) * DEG
        _write_road_from_sensor(w, rows, stamps, r_gs, trans, road_frame_id, frame_id, camera, std, prefix)
        _write_optional(w, table, prefix, frame_id, origin)
        return dict(w.counts)


def _static_extrinsic(extrinsic: Any) -> tuple[np.ndarray, np.ndarray]:
    """``(rotation ground <- sensor, translation m)`` of ``extrinsic`` (mapping, Extrinsic or None)."""
    if extrinsic is None:
        return np.eye(3), np.zeros(3)
    get = extrinsic.get if isinstance(extrinsic, Mapping) else lambda k, d=None: getattr(extrinsic, k, d)
    rot = np.asarray(get("rotation", np.eye(3)) if get("rotation") is not None else np.eye(3), dtype=float)
    trans = np.asarray(get("translation") if get("translation") is not None else np.zeros(3), dtype=float)
    return rot.reshape(3, 3), trans.reshape(3)


def _write_raw_all(w: RosWriter, handle: Any, stamps: np.ndarray, messages: Sequence[bytes]) -> None:
    for ns, msg in zip(stamps.tolist(), messages, strict=True):
        w.write_raw(handle, ns, msg)


def _transform(w: _Serializer, ns: int, seq: int, parent: str, child: str, tx: float, ty: float, tz: float,
               qx: float, qy: float, qz: float, qw: float) -> Any:
    """A ``geometry_msgs/TransformStamped`` parent <- child (translation m, quaternion x y z w)."""
    return w.message("geometry_msgs/msg/TransformStamped", header=w.header(ns, parent, seq), child_frame_id=child,
                     transform=w.message("geometry_msgs/msg/Transform",
                                         translation=w.message("geometry_msgs/msg/Vector3", x=tx, y=ty, z=tz),
                                         rotation=w.message("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw)))


_TRANSFORM_KEYS = ("tx", "ty", "tz", "qx", "qy", "qz", "qw")


def _write_road_from_sensor(w: RosWriter, rows: dict[str, np.ndarray], stamps: np.ndarray, r_gs: np.ndarray,
                            trans: np.ndarray, road: str, sensor: str, camera: dict[str, Any] | None,
                            std: np.ndarray | None, prefix: str) -> None:
    """``/tf`` (road -> sensor, and road -> camera) and ``PREFIX/pose`` (``std``: every row's 1-sigma) of ``rows``."""
    from scipy.spatial.transform import Rotation
    q = np.column_stack([rows["qw"], rows["qx"], rows["qy"], rows["qz"]])
    # the dynamic extrinsic road-ground <- sensor: the residual road <- body after the static ground <- sensor
    quat = ((Rotation.from_quat(q, scalar_first=True) * Rotation.from_matrix(r_gs)).as_quat()
            if len(q) else np.zeros((0, 4)))                                                     # x y z w
    rot = {f"q{c}": quat[:, i] for i, c in enumerate("xyzw")}
    index = rows["row"].astype(int)
    camera_child = camera["child"] if camera else ""

    def tf(ns: int, seq: int, **v: float) -> Any:
        items = [_transform(w, ns, seq, road, sensor, trans[0], trans[1], trans[2], v["qx"], v["qy"], v["qz"], v["qw"])]
        if "ctx" in v:
            items.append(_transform(w, ns, seq, road, camera_child, *(v[f"c{c}"] for c in _TRANSFORM_KEYS)))
        return w.message("tf2_msgs/msg/TFMessage", transforms=items)

    with_camera = np.isin(index, camera["rows"]) if camera else np.zeros(len(index), dtype=bool)
    messages: list[bytes] = [b""] * len(index)
    for group in (with_camera, ~with_camera):
        values = {c: v[group] for c, v in rot.items()}
        if group is with_camera and group.any():
            at = np.searchsorted(camera["rows"], index[group])              # type: ignore[index]
            values.update({f"c{c}": camera["values"][at, i] for i, c in enumerate(_TRANSFORM_KEYS)})  # type: ignore[index]
        if group.any():
            for k, data in zip(np.flatnonzero(group).tolist(), w.serialize_many(tf, stamps[group], values), strict=True):
                messages[k] = data
    _write_raw_all(w, w.add_topic("/tf", ROS_OUTPUT_TOPICS["tf"]), stamps, messages)
    if std is None:
        return
    sd = std[index]
    keep = np.all(np.isfinite(sd), axis=1)

    def pose(ns: int, seq: int, qx: float, qy: float, qz: float, qw: float, roll: float, pitch: float) -> Any:
        cov = np.zeros(36)
        cov[21], cov[28] = roll, pitch                                   # rad^2 about the road's x and y axes
        return w.message("geometry_msgs/msg/PoseWithCovarianceStamped", header=w.header(ns, road, seq),
                         pose=w.message("geometry_msgs/msg/PoseWithCovariance", covariance=cov,
                                        pose=w.message("geometry_msgs/msg/Pose",
                                                       position=w.message("geometry_msgs/msg/Point", x=trans[0],
                                                                          y=trans[1], z=trans[2]),
                                                       orientation=w.message("geometry_msgs/msg/Quaternion", x=qx,
                                                                             y=qy, z=qz, w=qw))))
    poses = w.serialize_many(pose, stamps[keep], {**{c: v[keep] for c, v in rot.items()},
                                                  "roll": sd[keep, 0] ** 2, "pitch": sd[keep, 1] ** 2})
    _write_raw_all(w, w.add_topic(f"{prefix}/pose", ROS_OUTPUT_TOPICS["pose"]), stamps[keep], poses)


def _write_optional(w: RosWriter, table: Any, prefix: str, frame_id: str, origin: int) -> None:
    """The topics of the table's optional columns (:data:`_OPTIONAL`) that it has."""
    t = np.asarray(table["t"], dtype=float)
    valid = np.asarray(table["valid"], dtype=bool) if "valid" in table else np.ones(len(t), dtype=bool)
    stamps = origin + np.round(np.where(np.isfinite(t), t, 0.0) * 1e9).astype(np.int64)
    for topic, (x, y) in _OPTIONAL.items():
        if x not in table or y not in table:
            continue
        h = w.add_topic(f"{prefix}/{topic}", ROS_OUTPUT_TOPICS[topic])
        if topic == "status":
            _write_diagnostics(w, h, table, stamps, np.isfinite(t), prefix, frame_id)
            continue
        xy = np.column_stack([np.asarray(table[x], dtype=float), np.asarray(table[y], dtype=float)]) * DEG
        keep = valid & np.isfinite(t) & np.all(np.isfinite(xy), axis=1)
        _write_raw_all(w, h, stamps[keep], serialize_stamped(
            stamps[keep], frame_id, np.column_stack([xy[keep], np.zeros(keep.sum())]), w.ros1))


def _write_diagnostics(w: RosWriter, handle: Any, table: Any, stamps: np.ndarray, keep: np.ndarray, prefix: str,
                       frame_id: str) -> None:
    """One ``diagnostic_msgs/DiagnosticArray`` per row of ``table`` with ``keep`` (a finite ``t``)."""
    name = f"imu-ground {prefix}".rstrip()
    texts = [(str(st), "" if why is None else str(why)) for st, why in zip(table["status"], table["status_reason"], strict=True)]
    rows = np.flatnonzero(keep)
    messages: dict[int, bytes] = {}
    groups: dict[tuple[str, str], list[int]] = {}
    for k in rows.tolist():
        groups.setdefault(texts[k], []).append(k)
    for (st, why), ks in groups.items():                  # few distinct texts: one layout each
        def build(ns: int, seq: int, st: str = st, why: str = why) -> Any:
            kv = "diagnostic_msgs/msg/KeyValue"
            status = w.message("diagnostic_msgs/msg/DiagnosticStatus", level=DIAGNOSTIC_LEVELS.get(st, 1),
                               name=name, message=f"{st}: {why}" if why else st, hardware_id=frame_id,
                               values=[w.message(kv, key="status", value=st), w.message(kv, key="reason", value=why)])
            return w.message("diagnostic_msgs/msg/DiagnosticArray", header=w.header(ns, frame_id, seq),
                             status=[status])
        messages.update(zip(ks, w.serialize_many(build, stamps[ks]), strict=True))
    _write_raw_all(w, handle, stamps[rows], [messages[k] for k in rows.tolist()])


def _write_camera_transforms(w: RosWriter, topic: str, rows: dict[str, np.ndarray], stamps: np.ndarray,
                             transforms: Any, child: str, road: str = "road") -> dict[str, Any]:
    """Road <- camera on the written rows whose transform is finite; returns them for ``/tf``: ``child``, ``rows``
    (table rows) and ``values`` (translation xyz, m, and quaternion xyzw per row)."""
    from scipy.spatial.transform import Rotation
    m = np.asarray(transforms, dtype=float).reshape(-1, 4, 4)[rows["row"]]
    keep = np.all(np.isfinite(m.reshape(len(m), -1)), axis=1)
    m = m[keep]
    quat = Rotation.from_matrix(m[:, :3, :3]).as_quat() if len(m) else np.zeros((0, 4))     # x y z w
    values = np.column_stack([m[:, :3, 3], quat])

    def build(ns: int, seq: int, **v: float) -> Any:
        return _transform(w, ns, seq, road, child, *(v[c] for c in _TRANSFORM_KEYS))

    messages = w.serialize_many(build, stamps[keep], {c: values[:, i] for i, c in enumerate(_TRANSFORM_KEYS)})
    _write_raw_all(w, w.add_topic(topic, "geometry_msgs/msg/TransformStamped"), stamps[keep], messages)
    return {"child": child, "rows": rows["row"][keep], "values": values}
