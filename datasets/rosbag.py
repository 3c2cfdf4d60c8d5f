"""ROS logs: ``sensor_msgs/Imu``, poses and speeds from ROS 1 bags, ROS 2 bags and MCAP files.

The files are opened by :mod:`~imu_ground.datasets.rosbag_files`. Times: the header stamps
(``time_source="header"``) by default, else the record times; one
:class:`~imu_ground.errors.TimestampWarning` when the two disagree (median or spread of record - header
beyond ``stamp_tolerance``, s); all-zero header stamps fall back to the record times, with a warning.
``ImuData.t`` starts at 0, ``meta["t0_ns"]`` (int, ns) and ``meta["t0"]`` (s) hold the first stamp. Poses
and speeds are in s since ``t0_ns`` when given, else since the epoch. Frames: REP 103 (``"FLU"``), or
``"RDF"`` for an ``*optical*`` frame_id (in ``meta["frame_id"]``).
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.errors import MalformedFileError, TimestampWarning, warn_user
from imu_ground.imu.data import ImuData

from .rosbag_files import PathLike, _choose, _open, _raw_messages, is_rosbag, rosbag_topics
from .skeleton import finish, register_format, with_finish_parameters

__all__ = ["IMU_TYPE", "POSE_TYPES", "SPEED_TYPES", "is_rosbag", "read_rosbag_imu", "read_rosbag_poses",
           "read_rosbag_speed", "rosbag_topics", "speed_topics"]

#: Message type read by :func:`read_rosbag_imu` (rosbags' ROS 2 spelling; ROS 1's ``sensor_msgs/Imu``).
IMU_TYPE = "sensor_msgs/msg/Imu"
#: Message types read by :func:`read_rosbag_poses`.
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped",
              "geometry_msgs/msg/PoseWithCovarianceStamped")
#: Message types read by :func:`read_rosbag_speed`.
SPEED_TYPES = ("geometry_msgs/msg/TwistStamped", "nav_msgs/msg/Odometry",
               "geometry_msgs/msg/TwistWithCovarianceStamped")


#: float64 fields of sensor_msgs/Imu after its header: orientation (4), angular_velocity (3 at 13),
#: linear_acceleration (3 at 25), each followed by its covariance (9).
_IMU_DOUBLES = 37


def _imu_columns(raws: Sequence[bytes], ros1: bool) -> tuple[np.ndarray, str, np.ndarray] | None:
    """``(stamps ns, frame_id, doubles (N, 37))`` of serialised ``sensor_msgs/Imu`` decoded by numpy: ROS 1 or
    little-endian CDR messages of one length (else None: each is deserialised)."""
    size = len(raws[0])
    if size < 16 or any(len(r) != size for r in raws):
        return None
    length = int.from_bytes(raws[0][12:16], "little")
    if ros1:
        start, name = 16 + length, raws[0][16:16 + length]
    else:
        if raws[0][:2] != b"\x00\x01":
            return None
        start, name = 4 + -(-(12 + length) // 8) * 8, raws[0][16:16 + length].rstrip(b"\x00")
    if start + 8 * _IMU_DOUBLES != size:
        return None
    buf = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), size)
    # both formats: sec at byte 4, nanoseconds at byte 8 (after seq / the encapsulation header)
    sec = np.ascontiguousarray(buf[:, 4:8]).view("<u4" if ros1 else "<i4")[:, 0]
    nsec = np.ascontiguousarray(buf[:, 8:12]).view("<u4")[:, 0]
    stamps = sec.astype(np.int64) * 1_000_000_000 + nsec.astype(np.int64)
    doubles = np.ascontiguousarray(buf[:, start:]).view("<f8")
    return stamps, name.decode("utf-8", "replace"), doubles


def _header_ns(msgs: Sequence[Any]) -> np.ndarray:
    return np.fromiter((m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs),
                       dtype=np.int64, count=len(msgs))


def _stamps(path: Path, hdr: np.ndarray, rec: np.ndarray, time_source: str,
            tolerance: float) -> tuple[np.ndarray, str]:
    """Message times, ns: header stamps ``hdr`` or record times ``rec``; one warning when they disagree."""
    if time_source not in ("header", "record"):
        raise ValueError(f"time_source must be 'header' or 'record', got {time_source!r}")
    if time_source == "record" or not len(hdr):
        return rec, "record"
    if not hdr.any():
        warn_user(f"{path}: every header stamp is zero; using the record times instead", TimestampWarning)
        return rec, "record (header stamps are zero)"
    d = (rec - hdr) * 1e-9
    med = float(np.median(d))
    spread = float(np.percentile(np.abs(d - med), 99)) if d.size else 0.0
    if abs(med) > tolerance or spread > tolerance:
        warn_user(f"{path}: the header stamps disagree with the record times (record - header: median "
                  f"{med:.6g} s, 99th percentile of its deviation {spread:.3g} s, tolerance {tolerance:g} s); "
                  f"using the header stamps (time_source='record' for the record times)", TimestampWarning)
    return hdr, "header"


def _vectors(msgs: Sequence[Any], attr: str) -> np.ndarray:
    out = np.empty((len(msgs), 3))
    for k, m in enumerate(msgs):
        v = getattr(m, attr)
        out[k] = (v.x, v.y, v.z)
    return out


def _imu_slow(msgs: Sequence[Any]) -> tuple[np.ndarray, str, np.ndarray]:
    """:func:`_imu_columns`' result from deserialised messages."""
    quat = [(m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w) for m in msgs]
    d = np.column_stack([quat, [m.orientation_covariance for m in msgs], _vectors(msgs, "angular_velocity"),
                         [m.angular_velocity_covariance for m in msgs], _vectors(msgs, "linear_acceleration"),
                         [m.linear_acceleration_covariance for m in msgs]]).astype(float, copy=False)
    return _header_ns(msgs), str(msgs[0].header.frame_id), d


def _orientation(d: np.ndarray) -> np.ndarray | None:
    """The IMU's own attitude (w, x, y, z), or None when not provided (covariance[0] = -1, or zeros)."""
    if d[0, 4] == -1 or not np.any(d[:, :4]):
        return None
    return d[:, [3, 0, 1, 2]]


@with_finish_parameters
def read_rosbag_imu(path: PathLike, *, topic: str | None = None, time_source: str = "header",
                    stamp_tolerance: float = 0.1, validate: bool = True, policy: str = "retime",
                    **validate_kw: Any) -> ImuData:
    """Read the ``sensor_msgs/Imu`` messages of a ROS log.

    Parameters
    ----------
    path : str or Path
        ROS 1 bag (``.bag``), ROS 2 bag folder (sqlite3 or MCAP storage) or MCAP file.
    topic : str, optional
        The IMU topic; needed only when the log has more than one.
    time_source : {"header", "record"}
    stamp_tolerance : float
        See the module docstring.
    {finish_parameters}

    Returns
    -------
    ImuData
        ``t`` s from the first stamp, ``gyro`` (``angular_velocity``) rad/s, ``accel``
        (``linear_acceleration``) m/s^2, in the message's frame; ``extra`` the IMU's own attitude ``qw, qx,
        qy, qz`` when the messages carry one; ``meta``: ``format="rosbag"``, ``topic``, ``frame_id``,
        ``t0_ns`` / ``t0``, ``time_source``, ``record_t0_ns``.

    Raises
    ------
    ImuInputError
        No IMU topic (the message lists the topics), several (listed with counts and rates, naming
        ``topic``), or ``topic`` is not an IMU topic.
    MalformedFileError
        Truncated or corrupt file, or no IMU message.
    """
    import pandas as pd

    p = Path(path)
    with _open(p) as reader:
        conns, rec, raws = _topic(reader, p, (IMU_TYPE,), topic, "IMU")
        fast = _imu_columns(raws, ros1=not reader.is2)
        hdr, frame_id, d = fast or _imu_slow([reader.deserialize(raw, conns[0].msgtype) for raw in raws])
    ns, used = _stamps(p, hdr, rec, time_source, stamp_tolerance)
    q = _orientation(d)
    extra = pd.DataFrame(q, columns=["qw", "qx", "qy", "qz"]) if q is not None else pd.DataFrame()
    meta = {"format": "rosbag", "topic": conns[0].topic, "frame_id": frame_id, "t0_ns": int(ns[0]),
            "t0": int(ns[0]) / 1e9, "t0_clock": f"{used} time of the first message",
            "time_source": used, "record_t0_ns": int(rec[0])}
    imu = ImuData((ns - ns[0]) / 1e9, d[:, 13:16], d[:, 25:28], "RDF" if "optical" in frame_id else "FLU", extra,
                  {c: "1" for c in extra.columns}, str(p), meta)
    return finish(imu, validate=validate, policy=policy, **validate_kw)


def _times(ns: np.ndarray, t0_ns: int | None) -> np.ndarray:
    return (ns - (0 if t0_ns is None else int(t0_ns))) / 1e9


def _topic(reader: Any, p: Path, types: Sequence[str], topic: str | None,
           what: str) -> tuple[list[Any], np.ndarray, list[bytes]]:
    """The chosen topic's connections, record times (ns) and serialised messages; none raises."""
    conns = _choose(reader, p, types, topic, what)
    rec, raws = _raw_messages(reader, conns)
    if not raws:
        raise MalformedFileError(p, f"{what} topic {conns[0].topic!r} has no messages")
    return conns, rec, raws


def _read_typed(path: PathLike, types: Sequence[str], topic: str | None, what: str,
                time_source: str, stamp_tolerance: float) -> tuple[Path, str, np.ndarray, list[Any]]:
    p = Path(path)
    with _open(p) as reader:
        conns, rec, raws = _topic(reader, p, types, topic, what)
        msgs = [reader.deserialize(raw, conns[0].msgtype) for raw in raws]
    ns, _ = _stamps(p, _header_ns(msgs), rec, time_source, stamp_tolerance)
    return p, conns[0].msgtype, ns, msgs


def read_rosbag_poses(path: PathLike, topic: str | None = None, *, t0_ns: int | None = None,
                      time_source: str = "header", stamp_tolerance: float = 0.1) -> Any:
    """Poses from a ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped`` or ``PoseWithCovarianceStamped`` topic.

    Parameters
    ----------
    path : str or Path
        ROS log.
    topic : str, optional
        The pose topic; needed only when the log has more than one.
    t0_ns : int, optional
        Clock origin, ns, of the returned times (the IMU's ``meta["t0_ns"]``); default: the epoch.
    time_source, stamp_tolerance
        As in :func:`read_rosbag_imu`.

    Returns
    -------
    PoseSequence
        ``rotations`` world <- sensor (``header.frame_id`` <- ``child_frame_id``/the pose's frame),
        ``translations`` m, ``t`` s, ``index`` 0..N-1.
    """
    from imu_ground.datasets.poses import PoseSequence
    from scipy.spatial.transform import Rotation

    p, _, ns, msgs = _read_typed(path, POSE_TYPES, topic, "pose", time_source, stamp_tolerance)
    poses = [m.pose.pose if hasattr(m.pose, "pose") else m.pose for m in msgs]
    quat = np.array([(x.orientation.x, x.orientation.y, x.orientation.z, x.orientation.w) for x in poses])
    bad = np.flatnonzero(~(np.abs(np.linalg.norm(quat, axis=1) - 1.0) < 1e-3))
    if bad.size:
        raise MalformedFileError(p, f"{bad.size} pose(s) with a non-unit orientation quaternion, first message "
                                    f"{int(bad[0]) + 1} (1-based)")
    return PoseSequence(rotations=Rotation.from_quat(quat).as_matrix(), translations=_vectors(poses, "position"),
                        t=_times(ns, t0_ns), index=np.arange(len(poses)), source=str(p))


def speed_topics(path: PathLike) -> list[str]:
    """The topics of the ROS log ``path`` that carry a speed (:data:`SPEED_TYPES`), sorted (from the index only)."""
    with _open(Path(path)) as reader:
        return sorted({c.topic for c in reader.connections if c.msgtype in SPEED_TYPES})


def read_rosbag_speed(path: PathLike, topic: str | None = None, *, t0_ns: int | None = None,
                      time_source: str = "header",
                      stamp_tolerance: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle speed from a ``TwistStamped``, ``TwistWithCovarianceStamped`` or ``nav_msgs/Odometry`` topic.

    Parameters
    ----------
    path, topic, t0_ns, time_source, stamp_tolerance
        As in :func:`read_rosbag_poses` (``topic``: the twist topic).

    Returns
    -------
    t, speed : ndarray (N,)
        s; m/s: ``nav_msgs/Odometry`` the signed forward speed ``twist.linear.x`` (body frame, REP 105), twist
        messages (frame not known to be the body's) the norm of ``linear``, unsigned.
    """
    _, msgtype, ns, msgs = _read_typed(path, SPEED_TYPES, topic, "speed", time_source, stamp_tolerance)
    twists = [m.twist.twist if hasattr(m.twist, "twist") else m.twist for m in msgs]
    v = _vectors(twists, "linear")
    speed = v[:, 0] if msgtype == "nav_msgs/msg/Odometry" else np.linalg.norm(v, axis=1)
    return _times(ns, t0_ns), speed


register_format("rosbag", is_rosbag, read_rosbag_imu,
                "ROS 1 *.bag, *.mcap, or a ROS 2 bag folder with metadata.yaml (sensor_msgs/Imu)",
                priority=35, options=("topic",))
