"""ROS logs in and out: every container kind written at test time from the shipped example drive.

Bags are written with rosbags' own writers (through
:class:`imu_ground.pipeline.ros_output.RosWriter`, which wraps them; the plain
MCAP file is the storage file of a rosbags-written ROS 2 bag), read back with
:mod:`imu_ground.datasets.rosbag`, and compared with the CSV reader's result.
"""
from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from imu_ground.datasets import read_table
from imu_ground.datasets.options import READER_OPTIONS, ImuInputError
from imu_ground.datasets.rosbag import (
    _imu_columns,
    _imu_slow,
    _open,
    is_rosbag,
    read_rosbag_imu,
    read_rosbag_poses,
    read_rosbag_speed,
    rosbag_topics,
)
from imu_ground.datasets.validation import MalformedFileError, TimestampWarning

from imu_ground.pipeline.output import read_output_settings
from imu_ground.pipeline.ros_output import (
    RosWriter,
    read_mcap_settings,
    ros_output_kind,
    serialize_stamped,
    write_ros_output,
)

EXAMPLE = Path(__file__).resolve().parent.parent / "datasets" / "fixtures" / "example_drive.csv"
T0_NS = 1_700_000_000_123_456_789          # an absolute epoch, as a real recording has
KINDS = ("ros1", "ros2-sqlite3", "ros2-mcap", "mcap", "ros1-mcap")


@pytest.fixture(scope="module")
def csv_imu():
    return read_table(EXAMPLE)


def _bag_path(tmp: Path, kind: str) -> Path:
    return {"ros1": tmp / "drive.bag", "ros2-sqlite3": tmp / "drive_db3", "ros2-mcap": tmp / "drive_mcap",
            "mcap": tmp / "drive.mcap", "ros1-mcap": tmp / "drive1.mcap"}[kind]


def _bag_to_ros1_mcap(bag: Path, path: Path) -> None:
    """What ``mcap convert x.bag x.mcap`` does: ROS 1 messages in MCAP (profile ros1, ros1msg schemas)."""
    from mcap.writer import Writer
    from rosbags.rosbag1 import Reader
    from rosbags.typesys.msg import denormalize_msgtype

    with Reader(bag) as reader, open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros1", library="test")
        channels = {}
        for c in reader.connections:
            sid = w.register_schema(name=denormalize_msgtype(c.msgtype), encoding="ros1msg",
                                    data=c.msgdef.data.encode())
            channels[c.id] = w.register_channel(topic=c.topic, message_encoding="ros1", schema_id=sid,
                                                metadata={"md5sum": c.digest})
        for c, ns, raw in reader.messages():
            w.add_message(channel_id=channels[c.id], log_time=ns, publish_time=ns, data=bytes(raw))
        w.finish()


def make_log(path: Path, kind: str, fill) -> Path:
    """A log of ``kind`` at ``path`` whose content ``fill(writer)`` writes (rosbags' writers underneath)."""
    if kind == "mcap":   # the storage file of a ROS 2 bag written by rosbags is a plain MCAP file
        folder = make_log(path.with_suffix(""), "ros2-mcap", fill)
        shutil.move(str(next(folder.glob("*.mcap"))), path)
        shutil.rmtree(folder)
        return path
    if kind == "ros1-mcap":
        bag = make_log(path.with_suffix(".bag"), "ros1", fill)
        _bag_to_ros1_mcap(bag, path)
        bag.unlink()
        return path
    with RosWriter(path, storage="sqlite3" if kind == "ros2-sqlite3" else "mcap") as w:
        fill(w)
    return path


def _imu_msg(w: RosWriter, ns: int, frame_id: str, k: int, gyro, accel):
    vec = "geometry_msgs/msg/Vector3"
    return w.message(
        "sensor_msgs/msg/Imu", header=w.header(ns, frame_id, k),
        orientation=w.message("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.r_[-1.0, np.zeros(8)],
        angular_velocity=w.message(vec, x=gyro[0], y=gyro[1], z=gyro[2]),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=w.message(vec, x=accel[0], y=accel[1], z=accel[2]),
        linear_acceleration_covariance=np.zeros(9))


def write_bag(path: Path, kind: str, imu, *, topics=("/imu/data",), frame_ids=("imu_link",),
              record_offset_ns: int = 0, zero_stamps: bool = False, extra=None) -> Path:
    """A log of ``kind`` with the IMU samples of ``imu`` on each of ``topics``; ``extra(w)`` adds more."""
    def fill(w: RosWriter) -> None:
        handles = [w.add_topic(t, "sensor_msgs/msg/Imu") for t in topics]
        stamps = T0_NS + np.round(imu.t * 1e9).astype(np.int64)
        for k, ns in enumerate(stamps.tolist()):
            for h in handles:
                msg = _imu_msg(w, 0 if zero_stamps else ns, frame_ids[k % len(frame_ids)], k,
                               imu.gyro[k], imu.accel[k])
                w.write(h, ns + record_offset_ns, msg)
        if extra is not None:
            extra(w)
    return make_log(path, kind, fill)


@pytest.fixture(scope="module", params=KINDS)
def bag(request, tmp_path_factory, csv_imu):
    kind = request.param
    return kind, write_bag(_bag_path(tmp_path_factory.mktemp(kind), kind), kind, csv_imu)


# --------------------------------------------------------------------------- reading
def test_is_rosbag(tmp_path, bag):
    _, path = bag
    assert is_rosbag(path)
    assert not is_rosbag(EXAMPLE)
    assert not is_rosbag(tmp_path)          # a folder without metadata.yaml


def test_imu_equals_csv_reader(bag, csv_imu):
    _, path = bag
    imu = read_rosbag_imu(path)
    assert imu.t[0] == 0.0
    np.testing.assert_allclose(imu.t, csv_imu.t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(imu.gyro, csv_imu.gyro, rtol=0, atol=1e-12)
    np.testing.assert_allclose(imu.accel, csv_imu.accel, rtol=0, atol=1e-12)
    assert imu.frame == "FLU" and imu.meta["frame_id"] == "imu_link"
    assert imu.meta["topic"] == "/imu/data" and imu.meta["t0_ns"] == T0_NS
    assert imu.meta["time_source"] == "header"
    assert "validation" in imu.meta
    assert len(imu.extra) == 0               # orientation_covariance[0] = -1: no attitude


def test_estimate_equals_csv_estimate(bag, csv_imu):
    from imu_ground.filters import GroundNormalFilter, SuspensionAwareFilter
    from imu_ground.imu import imu_to_egomotion

    _, path = bag
    em_bag, em_csv = imu_to_egomotion(read_rosbag_imu(path)), imu_to_egomotion(csv_imu)
    for a, b in ((SuspensionAwareFilter().run(em_bag), SuspensionAwareFilter().run(em_csv)),
                 (GroundNormalFilter().run(em_bag.delta_R), GroundNormalFilter().run(em_csv.delta_R))):
        assert len(a) == len(b) > 100
        np.testing.assert_allclose(a.normal, b.normal, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.pitch, b.pitch, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.roll, b.roll, rtol=0, atol=1e-12)


def test_topics_lists_counts_and_rates(bag, csv_imu):
    _, path = bag
    (topic, msgtype, count, rate), = rosbag_topics(path)
    assert (topic, msgtype, count) == ("/imu/data", "sensor_msgs/msg/Imu", len(csv_imu))
    assert rate == pytest.approx(100.0, rel=1e-6)
    (_, _, count, rate), = rosbag_topics(path, rates=False)
    assert count == len(csv_imu) and np.isnan(rate)


@pytest.mark.parametrize("kind", ["ros1", "ros2-mcap", "ros1-mcap"])
def test_numpy_decoder_equals_rosbags_deserializer(tmp_path, csv_imu, kind):
    path = write_bag(_bag_path(tmp_path, kind), kind, csv_imu.select(np.arange(50)), frame_ids=("imu_lnk",))
    with _open(path) as reader:
        conns = reader.connections
        raws = [bytes(raw) for _, _, raw in reader.messages(connections=conns)]
        msgs = [reader.deserialize(raw, conns[0].msgtype) for raw in raws]
        fast = _imu_columns(raws, ros1=not reader.is2)
    slow = _imu_slow(msgs)
    assert fast is not None
    np.testing.assert_array_equal(fast[0], slow[0])
    assert fast[1] == slow[1] == "imu_lnk"
    np.testing.assert_array_equal(fast[2], slow[2])


@pytest.mark.parametrize("kind", ["ros1", "mcap", "ros1-mcap"])
def test_messages_of_different_lengths_read_one_by_one(tmp_path, csv_imu, kind):
    """frame_ids of two lengths defeat the numpy decoder; the per-message path gives the same data."""
    part = csv_imu.select(np.arange(1000))
    path = write_bag(_bag_path(tmp_path, kind), kind, part, frame_ids=("imu", "imu_link"))
    imu = read_rosbag_imu(path)
    np.testing.assert_allclose(imu.t, part.t, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(imu.gyro, part.gyro)
    np.testing.assert_array_equal(imu.accel, part.accel)
    assert imu.meta["frame_id"] == "imu"


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_the_imus_own_attitude_goes_to_extra(tmp_path, csv_imu, kind):
    part = csv_imu.select(np.arange(100))
    yaw = 0.01 * np.arange(100)

    def fill(w: RosWriter) -> None:
        h = w.add_topic("/imu", "sensor_msgs/msg/Imu")
        for k in range(100):
            ns = T0_NS + round(part.t[k] * 1e9)
            msg = _imu_msg(w, ns, "imu", k, part.gyro[k], part.accel[k])
            msg.orientation = w.message("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=np.sin(yaw[k] / 2),
                                        w=np.cos(yaw[k] / 2))
            msg.orientation_covariance = np.full(9, 1e-4)
            w.write(h, ns, msg)

    imu = read_rosbag_imu(make_log(_bag_path(tmp_path, kind), kind, fill))
    assert list(imu.extra.columns) == ["qw", "qx", "qy", "qz"]
    np.testing.assert_array_equal(imu.extra["qz"], np.sin(yaw / 2))
    np.testing.assert_array_equal(imu.extra["qw"], np.cos(yaw / 2))
    assert not imu.extra["qx"].any()


def test_optical_frame_is_not_flu(tmp_path, csv_imu):
    path = write_bag(tmp_path / "o.bag", "ros1", csv_imu.select(np.arange(20)), frame_ids=("cam_imu_optical_frame",))
    imu = read_rosbag_imu(path)
    assert imu.frame == "RDF" and imu.meta["frame_id"] == "cam_imu_optical_frame"


# --------------------------------------------------------------------------- times
def test_record_times_disagreeing_warn_once(tmp_path, csv_imu):
    path = write_bag(tmp_path / "late.bag", "ros1", csv_imu, record_offset_ns=500_000_000)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        imu = read_rosbag_imu(path)
    ours = [w for w in caught if issubclass(w.category, TimestampWarning) and "record times" in str(w.message)]
    assert len(ours) == 1 and "late.bag" in str(ours[0].message) and "0.5 s" in str(ours[0].message)
    assert imu.meta["t0_ns"] == T0_NS and imu.meta["record_t0_ns"] == T0_NS + 500_000_000
    rec = read_rosbag_imu(path, time_source="record")
    assert rec.meta["t0_ns"] == T0_NS + 500_000_000
    np.testing.assert_allclose(rec.t, csv_imu.t, rtol=0, atol=1e-12)


def test_agreeing_record_times_do_not_warn(tmp_path, csv_imu):
    path = write_bag(tmp_path / "ok.bag", "ros1", csv_imu, record_offset_ns=2_000_000)   # 2 ms latency
    with warnings.catch_warnings():
        warnings.simplefilter("error", TimestampWarning)
        read_rosbag_imu(path)


def test_zero_header_stamps_fall_back_to_record_times(tmp_path, csv_imu):
    path = write_bag(tmp_path / "zero.mcap", "mcap", csv_imu, zero_stamps=True)
    with pytest.warns(TimestampWarning, match="header stamp is zero"):
        imu = read_rosbag_imu(path)
    assert imu.meta["time_source"].startswith("record")
    np.testing.assert_allclose(imu.t, csv_imu.t, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- errors
def _odometry(w: RosWriter, n: int = 30, topic: str = "/odom"):
    h = w.add_topic(topic, "nav_msgs/msg/Odometry")
    for k in range(n):
        ns = T0_NS + k * 100_000_000
        yaw = 0.01 * k
        pose = w.message("geometry_msgs/msg/Pose",
                         position=w.message("geometry_msgs/msg/Point", x=1.0 * k, y=0.5, z=-0.25),
                         orientation=w.message("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=np.sin(yaw / 2),
                                               w=np.cos(yaw / 2)))
        twist = w.message("geometry_msgs/msg/Twist",
                          linear=w.message("geometry_msgs/msg/Vector3", x=-2.0 if k == 0 else 10.0, y=0.0, z=0.0),
                          angular=w.message("geometry_msgs/msg/Vector3", x=0.0, y=0.0, z=0.1))
        w.write(h, ns, w.message(
            "nav_msgs/msg/Odometry", header=w.header(ns, "odom", k), child_frame_id="base_link",
            pose=w.message("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=np.zeros(36)),
            twist=w.message("geometry_msgs/msg/TwistWithCovariance", twist=twist, covariance=np.zeros(36))))


@pytest.mark.parametrize("kind", KINDS)
def test_no_imu_topic(tmp_path, kind):
    path = make_log(_bag_path(tmp_path, kind), kind, _odometry)
    with pytest.raises(ImuInputError) as e:
        read_rosbag_imu(path)
    msg = str(e.value)
    assert str(path) in msg and "no IMU topic" in msg and "/odom (nav_msgs/msg/Odometry, 30 messages)" in msg
    assert "\n" not in msg


@pytest.mark.parametrize("kind", KINDS)
def test_two_imu_topics(tmp_path, csv_imu, kind):
    short = csv_imu.select(np.arange(200))
    path = write_bag(_bag_path(tmp_path, kind), kind, short, topics=("/imu/a", "/imu/b"))
    with pytest.raises(ImuInputError) as e:
        read_rosbag_imu(path)
    msg = str(e.value)
    assert str(path) in msg and "2 IMU topics" in msg and "\n" not in msg
    assert "/imu/a (sensor_msgs/msg/Imu, 200 messages, 100 Hz)" in msg and "/imu/b" in msg
    assert "topic='/imu/a'" in msg and "--topic /imu/a" in e.value.cli_message()
    imu = read_rosbag_imu(path, topic="/imu/b")
    assert imu.meta["topic"] == "/imu/b" and len(imu) == 200


def test_topic_option_in_reader_options():
    assert READER_OPTIONS["topic"].flag == "--topic"


@pytest.mark.parametrize("kind", ["ros1", "ros2-sqlite3", "mcap"])
def test_read_imu_detects_ros_logs_and_passes_topic(tmp_path, csv_imu, kind):
    from imu_ground.datasets import detect_format, read_imu

    short = csv_imu.select(np.arange(300))
    path = write_bag(_bag_path(tmp_path, kind), kind, short, topics=("/imu/a", "/imu/b"))
    assert detect_format(path) == "rosbag"
    with pytest.raises(ImuInputError, match="2 IMU topics"):
        read_imu(path)
    imu = read_imu(path, topic="/imu/a")
    assert imu.meta["format"] == "rosbag" and imu.meta["topic"] == "/imu/a"
    np.testing.assert_allclose(imu.t, short.t, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(imu.gyro, short.gyro)


def test_unknown_or_wrong_topic(tmp_path, csv_imu):
    path = write_bag(tmp_path / "x.bag", "ros1", csv_imu.select(np.arange(20)), extra=_odometry)
    with pytest.raises(ImuInputError, match="no topic '/nope'"):
        read_rosbag_imu(path, topic="/nope")
    with pytest.raises(ImuInputError, match="carries nav_msgs/msg/Odometry, not IMU"):
        read_rosbag_imu(path, topic="/odom")


@pytest.mark.parametrize("keep", [0.5, 0.0])
@pytest.mark.parametrize("kind", KINDS)
def test_truncated_file(tmp_path, csv_imu, kind, keep):
    path = write_bag(_bag_path(tmp_path, kind), kind, csv_imu.select(np.arange(2000)))
    data_file = path if path.is_file() else next(f for f in path.iterdir() if f.name != "metadata.yaml")
    data_file.write_bytes(data_file.read_bytes()[: int(data_file.stat().st_size * keep)])
    with pytest.raises(MalformedFileError) as e:
        read_rosbag_imu(path)
    msg = str(e.value)
    assert msg.startswith(str(path)) and "truncated or corrupt" in msg and "\n" not in msg


def test_corrupt_metadata_is_one_line(tmp_path):
    folder = tmp_path / "bag2"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: [\n")
    with pytest.raises(MalformedFileError) as e:
        read_rosbag_imu(folder)
    assert str(e.value).startswith(str(folder)) and "\n" not in str(e.value)


def test_not_a_rosbag(tmp_path):
    with pytest.raises(ValueError, match="not a ROS log"):
        read_rosbag_imu(EXAMPLE)
    with pytest.raises(FileNotFoundError, match="missing.bag"):
        read_rosbag_imu(tmp_path / "missing.bag")


# --------------------------------------------------------------------------- poses and speed
@pytest.mark.parametrize("kind", ["ros1", "mcap", "ros1-mcap"])
def test_poses_and_speed_from_odometry(tmp_path, kind):
    path = make_log(_bag_path(tmp_path, kind), kind, _odometry)
    poses = read_rosbag_poses(path)
    assert len(poses) == 30 and poses.source == str(path)
    np.testing.assert_allclose(poses.t, (T0_NS + np.arange(30) * 100_000_000) / 1e9, rtol=0, atol=1e-6)
    np.testing.assert_allclose(poses.translations[:, 0], np.arange(30.0))
    yaw = np.arctan2(poses.rotations[:, 1, 0], poses.rotations[:, 0, 0])
    np.testing.assert_allclose(yaw, 0.01 * np.arange(30), atol=1e-12)
    np.testing.assert_allclose(poses.relative_rotations()[:, 0, 1], -np.sin(0.01), atol=1e-12)
    t, speed = read_rosbag_speed(path, t0_ns=T0_NS)
    np.testing.assert_allclose(t, np.arange(30) * 0.1, rtol=0, atol=1e-12)
    assert speed[0] == -2.0 and np.all(speed[1:] == 10.0)        # signed forward speed


def test_speed_from_twist_stamped_is_the_norm(tmp_path):
    path = tmp_path / "twist.mcap"
    with RosWriter(path) as w:
        h = w.add_topic("/vel", "geometry_msgs/msg/TwistStamped")
        for k in range(5):
            ns = T0_NS + k * 50_000_000
            v = w.message("geometry_msgs/msg/Vector3", x=3.0, y=-4.0, z=0.0)
            w.write(h, ns, w.message("geometry_msgs/msg/TwistStamped", header=w.header(ns, "map", k),
                                     twist=w.message("geometry_msgs/msg/Twist", linear=v, angular=v)))
    t, speed = read_rosbag_speed(path, t0_ns=T0_NS)
    np.testing.assert_allclose(t, 0.05 * np.arange(5), atol=1e-12)
    np.testing.assert_array_equal(speed, 5.0)


# --------------------------------------------------------------------------- output
def _table(n: int = 40):
    import pandas as pd

    t = 0.1 * np.arange(1, n + 1)
    pitch, roll = 0.5 * np.sin(t), 0.2 * np.cos(t)            # deg
    normal = np.column_stack([np.sin(pitch * np.pi / 180), -np.sin(roll * np.pi / 180), np.ones(n)])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    q = np.column_stack([np.ones(n), 0.001 * t, 0.002 * t, 0.0 * t])
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    valid = np.ones(n, dtype=bool)
    valid[5:8] = False
    df = pd.DataFrame({"t": t, "normal_x": normal[:, 0], "normal_y": normal[:, 1], "normal_z": normal[:, 2],
                       "pitch_deg": pitch, "roll_deg": roll, "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2],
                       "qz": q[:, 3], "valid": valid})
    if n > 10:
        df.loc[10, "normal_x"] = np.nan                       # a NaN row is skipped too
    return df


@pytest.mark.parametrize("name", ["est.bag", "est.mcap", "est_ros2"])
def test_ros_output_round_trip(tmp_path, name, read_ros_topics):
    table = _table()
    path = tmp_path / name
    counts = write_ros_output(path, table, frame_id="imu_link", settings={"method": "suspension"},
                              t0_ns=T0_NS)
    keep = table["valid"].to_numpy() & np.isfinite(table["normal_x"].to_numpy())
    rows = table[keep]
    mcap = name.endswith(".mcap")          # an .mcap file keeps the settings in a metadata record, not a topic
    assert counts == {"/ground/normal": len(rows), "/ground/rotation": len(rows), "/ground/pitch_roll": len(rows),
                      "/tf": len(rows), **({} if mcap else {"/ground/settings": 1})}
    got = read_ros_topics(path)
    stamps = T0_NS + np.round(rows["t"].to_numpy() * 1e9).astype(np.int64)
    for topic in ("/ground/normal", "/ground/rotation", "/ground/pitch_roll"):
        msgs = got[topic]
        assert [ns for ns, _ in msgs] == stamps.tolist()
        assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in msgs] == stamps.tolist()
        assert {m.header.frame_id for _, m in msgs} == {"imu_link"}
    n = np.array([(m.vector.x, m.vector.y, m.vector.z) for _, m in got["/ground/normal"]])
    np.testing.assert_array_equal(n, rows[["normal_x", "normal_y", "normal_z"]].to_numpy())
    q = np.array([(m.quaternion.w, m.quaternion.x, m.quaternion.y, m.quaternion.z) for _, m in got["/ground/rotation"]])
    np.testing.assert_array_equal(q, rows[["qw", "qx", "qy", "qz"]].to_numpy())
    pr = np.array([(m.vector.x, m.vector.y, m.vector.z) for _, m in got["/ground/pitch_roll"]])
    np.testing.assert_allclose(pr[:, 0], np.radians(rows["roll_deg"].to_numpy()), rtol=1e-15, atol=0)
    np.testing.assert_allclose(pr[:, 1], np.radians(rows["pitch_deg"].to_numpy()), rtol=1e-15, atol=0)
    assert not pr[:, 2].any()
    if mcap:
        assert "/ground/settings" not in got
        assert read_mcap_settings(path) == read_output_settings(path) == {"method": "suspension"}
    else:
        assert '"method": "suspension"' in got["/ground/settings"][0][1].data


def test_ros_output_of_a_bag_estimate_lines_up_with_the_recording(tmp_path, csv_imu, read_ros_topics):
    """Estimate a bag, write it with the bag's t0_ns: the output stamps fall on the recording's clock."""
    import pandas as pd

    from imu_ground.filters import SuspensionAwareFilter
    from imu_ground.imu import imu_to_egomotion

    imu = read_rosbag_imu(write_bag(tmp_path / "in.bag", "ros1", csv_imu))
    em = imu_to_egomotion(imu)
    track = SuspensionAwareFilter().run(em)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(track), 1))
    table = pd.DataFrame({"t": em.t, "normal_x": track.normal[:, 0], "normal_y": track.normal[:, 1],
                          "normal_z": track.normal[:, 2], "pitch_deg": np.degrees(track.pitch),
                          "roll_deg": np.degrees(track.roll), "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2],
                          "qz": q[:, 3], "valid": em.valid})
    out = tmp_path / "out.mcap"
    write_ros_output(out, table, frame_id=imu.meta["frame_id"], settings={"t0_ns": imu.meta["t0_ns"]})
    normals = read_ros_topics(out)["/ground/normal"]
    assert normals[0][0] == T0_NS + round(float(em.t[em.valid][0]) * 1e9)
    assert T0_NS < normals[-1][0] <= T0_NS + round(float(csv_imu.t[-1]) * 1e9)


@pytest.mark.parametrize("frame_id", ["", "a", "imu", "imu_lin", "imu_link", "base_link_imu"])
@pytest.mark.parametrize("ros1", [True, False])
def test_serialize_stamped_equals_rosbags(frame_id, ros1):
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    rng = np.random.default_rng(3)
    stamps = T0_NS + np.array([0, 1, 999_999_999, 1_000_000_000, 123_456_789_012])
    for msgtype, field, names in (("geometry_msgs/msg/Vector3Stamped", "vector", "xyz"),
                                  ("geometry_msgs/msg/QuaternionStamped", "quaternion", "xyzw")):
        values = rng.normal(size=(len(stamps), len(names)))
        got = serialize_stamped(stamps, frame_id, values, ros1)
        for i, ns in enumerate(stamps.tolist()):
            t = ts.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
            hdr = ts.types["std_msgs/msg/Header"](**({"seq": i} if ros1 else {}), stamp=t, frame_id=frame_id)
            body = ts.types[msgtype.replace("Stamped", "")](**dict(zip(names, values[i], strict=True)))
            msg = ts.types[msgtype](header=hdr, **{field: body})
            assert got[i] == bytes(serialize(msg, msgtype)), (msgtype, i)


def test_negative_stamps_need_t0(tmp_path):
    table = _table()
    table["t"] -= 1.0
    with pytest.raises(ValueError, match="negative ROS stamps.*t0"):
        write_ros_output(tmp_path / "neg.mcap", table)
    write_ros_output(tmp_path / "neg.mcap", table, t0=100.0)


def test_ros_output_paths(tmp_path, read_ros_topics):
    assert ros_output_kind("a.bag") == "ros1" and ros_output_kind("a.mcap") == "mcap"
    assert ros_output_kind(tmp_path / "folder") == "ros2"
    with pytest.raises(ValueError, match=r"\.csv.*use \.bag"):
        ros_output_kind("a.csv")
    path = tmp_path / "x.mcap"
    write_ros_output(path, _table())
    with pytest.raises(FileExistsError, match="x.mcap"):
        write_ros_output(path, _table())
    write_ros_output(path, _table(10), overwrite=True)
    assert len(read_ros_topics(path)["/ground/normal"]) == 7      # 10 frames, 3 invalid
    with pytest.raises(ValueError, match="lacks column"):
        write_ros_output(tmp_path / "y.mcap", _table().drop(columns="qw"))


# --------------------------------------------------------------------------- --speed auto on IMU-only logs
def test_imu_only_log_of_every_kind_runs_imu_only_by_default(bag, tmp_path, cli):
    """Default options (``--speed auto``) on a log with nothing but ``sensor_msgs/Imu``: IMU only, the reason
    in the summary (every kind was refused asking for a speed topic)."""
    _, path = bag
    code, out, err = cli("estimate", path, "-o", tmp_path / "g.csv")
    assert code == 0, err
    assert "speed none (a ROS log without a twist or odometry topic)" in out.splitlines()[0]


@pytest.mark.parametrize("kind", ["ros1", "ros2-sqlite3", "mcap"])
def test_explicit_speed_topic_is_read_or_refused(tmp_path, csv_imu, kind, cli):
    """``--speed TOPIC`` names a twist / odometry topic of the log; a missing one is refused naming --speed."""
    (tmp_path / "a").mkdir()
    imu_only = write_bag(_bag_path(tmp_path / "a", kind), kind, csv_imu)
    code, _, err = cli("estimate", imu_only, "--speed", "/odom", "-o", tmp_path / "a.csv")
    assert code == 2 and "--speed /odom" in err and "no topic '/odom'" in err and "Traceback" not in err
    (tmp_path / "b").mkdir()
    with_odom = write_bag(_bag_path(tmp_path / "b", kind), kind, csv_imu, extra=_odometry)
    code, out, err = cli("estimate", with_odom, "--speed", "/odom", "-o", tmp_path / "b.csv")
    assert code == 0, err
    # the odometry spans 0 .. 2.9 s: the 29 frames (t - 0.1, t] inside it, t = 0.1 .. 2.9 s
    assert "speed /odom (29 of 600 frames)" in out.splitlines()[0]


def test_two_speed_topics_name_the_speed_option(tmp_path, csv_imu, cli):
    """``--speed auto`` with two twist/odometry topics: choose one with --speed (not --topic, the IMU's)."""
    def both(w):
        _odometry(w, topic="/odom_a")
        _odometry(w, topic="/odom_b")
    path = write_bag(tmp_path / "two.bag", "ros1", csv_imu, extra=both)
    code, _, err = cli("estimate", path, "-o", tmp_path / "o.csv")
    assert code == 2 and "2 speed topics (/odom_a, /odom_b)" in err and "--speed /odom_a" in err, err
    code, out, err = cli("estimate", path, "--speed", "/odom_b", "-o", tmp_path / "o.csv")
    assert code == 0 and "speed /odom_b (29 of 600 frames)" in out, err
