"""The ROS outputs Foxglove and RViz read: ``/tf``, the pose with its covariance, the status as diagnostics,
the settings as an MCAP metadata record; read back with rosbags and with ``mcap`` + ``mcap-ros2-support``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("rosbags")

from imu_ground.filters import Extrinsic
from imu_ground.pipeline.estimate import estimate_log
from imu_ground.pipeline.output import read_output_settings, result_table, write_outputs
from imu_ground.pipeline.ros_output import read_mcap_settings, write_ros_output
from imu_ground.so3 import rotx, roty

EXAMPLE = Path(__file__).resolve().parent.parent / "datasets" / "fixtures" / "example_drive.csv"
T0_NS = 1_700_000_000_123_456_789
#: Where each container kind is written (a folder name without suffix: a ROS 2 bag).
NAMES = {"ros1": "g.bag", "mcap": "g.mcap", "ros2-mcap": "g_ros2", "ros2-sqlite3": "g_db3"}
#: The diagnostic level each status must get (0 OK, 1 WARN, 2 ERROR, 3 STALE).
LEVELS = {"ok": 0, "standstill": 0, "converging": 1, "degraded": 2, "invalid": 2, "gap": 3}
TILTED = Extrinsic(rotation=rotx(0.03) @ roty(-0.05), translation=[0.4, -0.1, 1.2])


@pytest.fixture(scope="module", params=[None, TILTED], ids=["identity", "tilted"])
def estimate(request):
    res = estimate_log(EXAMPLE, extrinsic=request.param)
    return res, result_table(res)


def _written(table: pd.DataFrame) -> pd.DataFrame:
    """The rows the per-frame topics carry: valid, finite."""
    cols = ["t", "normal_x", "normal_y", "normal_z", "pitch_deg", "roll_deg", "qw", "qx", "qy", "qz"]
    keep = table["valid"].to_numpy(bool) & np.all(np.isfinite(table[cols].to_numpy(float)), axis=1)
    return table[keep]


def _quat_matrix(x, y, z, w) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    return Rotation.from_quat([x, y, z, w]).as_matrix()


@pytest.mark.parametrize("kind", list(NAMES))
def test_tf_is_road_to_sensor_and_its_rotation_the_dynamic_extrinsic(tmp_path, estimate, kind, read_ros_topics):
    """``/tf``: parent road, child the IMU's frame; ``R^T e_z`` is the table's normal (the sign check), the
    quaternion the table's (identity extrinsic) and a ``.tum`` output's, the translation the extrinsic's."""
    res, table = estimate
    path = tmp_path / NAMES[kind]
    write_ros_output(path, table, frame_id="imu_link", extrinsic=res.meta["extrinsic"], t0_ns=T0_NS,
                     storage="sqlite3" if kind == "ros2-sqlite3" else "mcap")
    tf = read_ros_topics(path)["/tf"]
    rows = _written(table)
    assert len(tf) == len(rows) > 100
    assert [ns for ns, _ in tf] == (T0_NS + np.round(rows["t"].to_numpy() * 1e9).astype(np.int64)).tolist()
    assert {len(m.transforms) for _, m in tf} == {1}
    first = [m.transforms[0] for _, m in tf]
    assert {(x.header.frame_id, x.child_frame_id) for x in first} == {("road", "imu_link")}
    assert [x.header.stamp.sec * 10**9 + x.header.stamp.nanosec for x in first] == [ns for ns, _ in tf]
    if kind == "ros1":
        assert [x.header.seq for x in first] == list(range(len(first)))
    q = np.array([(x.transform.rotation.x, x.transform.rotation.y, x.transform.rotation.z, x.transform.rotation.w)
                  for x in first])
    up = np.array([_quat_matrix(*qk).T @ [0.0, 0.0, 1.0] for qk in q])      # the road's up axis, sensor frame
    np.testing.assert_allclose(up, rows[["normal_x", "normal_y", "normal_z"]].to_numpy(), atol=1e-12)
    translation = np.array([(x.transform.translation.x, x.transform.translation.y, x.transform.translation.z)
                            for x in first])
    np.testing.assert_array_equal(translation, np.broadcast_to(res.meta["extrinsic"]["translation"], translation.shape))
    tum = tmp_path / "g.tum"
    write_outputs([tum], table, res.meta)
    tq = np.loadtxt(tum)[:, 4:8]                                                # qx qy qz qw
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", q, tq)), 1.0, atol=1e-7)   # TUM: 9 decimals
    if res.meta["extrinsic"]["rotation"] == np.eye(3).tolist():
        np.testing.assert_allclose(q, rows[["qx", "qy", "qz", "qw"]].to_numpy(), atol=1e-15)


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_pose_carries_the_one_sigma_as_covariance(tmp_path, estimate, kind, read_ros_topics):
    res, table = estimate
    path = tmp_path / NAMES[kind]
    counts = write_ros_output(path, table, extrinsic=res.meta["extrinsic"])
    got = read_ros_topics(path)
    rows = _written(table)
    pose = got["/ground/pose"]
    assert counts["/ground/pose"] == len(pose) == len(rows)
    cov = np.array([m.pose.covariance for _, m in pose])
    assert cov.shape == (len(rows), 36)
    np.testing.assert_allclose(cov[:, 21], np.radians(rows["roll_std_deg"].to_numpy()) ** 2, rtol=1e-12)
    np.testing.assert_allclose(cov[:, 28], np.radians(rows["pitch_std_deg"].to_numpy()) ** 2, rtol=1e-12)
    rest = np.delete(cov, [21, 28], axis=1)
    assert not rest.any()
    assert {m.header.frame_id for _, m in pose} == {"road"}
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in pose] == [ns for ns, _ in pose]
    tf = got["/tf"]
    for (_, p), (_, t) in zip(pose[:: 50], tf[:: 50], strict=True):
        r = t.transforms[0].transform.rotation
        assert (p.pose.pose.orientation.x, p.pose.pose.orientation.w) == (r.x, r.w)
        assert p.pose.pose.position.z == t.transforms[0].transform.translation.z


def _status_table() -> pd.DataFrame:
    """A small table whose frames take every status (and a frame with NaN time, not written)."""
    statuses = ["converging", "converging", "ok", "ok", "standstill", "gap", "gap", "degraded", "invalid", "ok"]
    n = len(statuses)
    t = 0.1 * np.arange(1, n + 1)
    t[-1] = np.nan
    return pd.DataFrame({"t": t, "normal_x": 0.0, "normal_y": 0.0, "normal_z": 1.0, "pitch_deg": 0.1,
                         "roll_deg": -0.2, "qw": 1.0, "qx": 0.0, "qy": 0.0, "qz": 0.0,
                         "valid": [s != "gap" for s in statuses], "pitch_std_deg": 0.3, "roll_std_deg": 0.25,
                         "status": statuses, "status_reason": [
                             "1-sigma above 0.15 deg", "1-sigma above 0.15 deg", "", "slow", "", "gap of 0.2 s",
                             "gap of 0.2 s", "the mount moved", "bad frame", ""]})


@pytest.mark.parametrize("kind", list(NAMES))
def test_status_is_a_diagnostic_array_with_the_level_of_each_status(tmp_path, kind, read_ros_topics):
    table = _status_table()
    path = tmp_path / NAMES[kind]
    write_ros_output(path, table, frame_id="imu_link", storage="sqlite3" if kind == "ros2-sqlite3" else "mcap")
    got = read_ros_topics(path)["/ground/status"]
    shown = table[np.isfinite(table["t"])]
    assert len(got) == len(shown) == len(table) - 1             # every frame with a time, also the gaps
    for (_, msg), (_, row) in zip(got, shown.iterrows(), strict=True):
        (st,) = msg.status
        assert st.level == LEVELS[row["status"]], row["status"]
        assert st.message == (f"{row['status']}: {row['status_reason']}" if row["status_reason"] else row["status"])
        assert st.hardware_id == "imu_link" and st.name == "imu-ground /ground"
        values = {kv.key: kv.value for kv in st.values}
        assert values == {"status": row["status"], "reason": row["status_reason"]}
        assert msg.header.frame_id == "imu_link"
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in got] == [ns for ns, _ in got] == \
        np.round(shown["t"].to_numpy() * 1e9).astype(np.int64).tolist()


def test_mcap_output_reads_with_mcap_ros2_support(tmp_path, estimate):
    """The MCAP's schemas decode with the ROS 2 tools' own decoder (as Foxglove's), the settings are its metadata."""
    pytest.importorskip("mcap_ros2")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    res, table = estimate
    out = tmp_path / "g.mcap"
    write_outputs([out], table, res.meta)
    by_topic: dict[str, list] = {}
    with open(out, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for schema, channel, _message, decoded in reader.iter_decoded_messages():
            by_topic.setdefault(channel.topic, []).append((schema.name, decoded))
        summary = reader.get_summary()
        fh.seek(0)
        meta = {m.name: m.metadata for m in make_reader(fh).iter_metadata()}
    assert {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()} == {
        "/ground/normal": "geometry_msgs/msg/Vector3Stamped", "/ground/rotation": "geometry_msgs/msg/QuaternionStamped",
        "/ground/pitch_roll": "geometry_msgs/msg/Vector3Stamped", "/tf": "tf2_msgs/msg/TFMessage",
        "/ground/pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
        "/ground/pitch_roll_std": "geometry_msgs/msg/Vector3Stamped", "/ground/road": "geometry_msgs/msg/Vector3Stamped",
        "/ground/road_std": "geometry_msgs/msg/Vector3Stamped", "/ground/status": "diagnostic_msgs/msg/DiagnosticArray"}
    assert {t: v[0][0] for t, v in by_topic.items()}.items() <= {
        c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}.items()
    rows = _written(table)
    tf = [m.transforms[0] for _, m in by_topic["/tf"]]
    assert tf[0].header.frame_id == "road" and tf[0].child_frame_id == res.meta["frame_id"]
    q = np.array([(x.transform.rotation.x, x.transform.rotation.y, x.transform.rotation.z, x.transform.rotation.w)
                  for x in tf])
    up = np.array([_quat_matrix(*qk).T @ [0.0, 0.0, 1.0] for qk in q])
    np.testing.assert_allclose(up, rows[["normal_x", "normal_y", "normal_z"]].to_numpy(), atol=1e-12)
    cov = np.array([m.pose.covariance for _, m in by_topic["/ground/pose"]])
    np.testing.assert_allclose(np.sqrt(cov[:, 28]), np.radians(rows["pitch_std_deg"].to_numpy()), rtol=1e-12)
    levels = [m.status[0].level for _, m in by_topic["/ground/status"]]
    assert levels == [LEVELS[s] for s in table["status"]]
    assert set(meta) == {"imu_ground"} and set(meta["imu_ground"]) == {"settings", "version"}
    settings = read_output_settings(out)
    assert settings == read_mcap_settings(out)
    assert settings["method"] == res.meta["method"] and settings["options"] == res.meta["settings"]["options"]


def test_ros1_tf_message_has_ros_own_definition(tmp_path):
    """rosbags' ROS 1 store lacks tf2_msgs: the type registered from its definition has ROS's md5 sum."""
    from rosbags.rosbag1 import Reader

    path = tmp_path / "g.bag"
    write_ros_output(path, _status_table())
    with Reader(path) as reader:
        conns = {c.topic: c for c in reader.connections}
    assert conns["/tf"].msgtype == "tf2_msgs/msg/TFMessage"
    assert conns["/tf"].digest == "94810edda583a504dfda3829e70d7eec"          # tf2_msgs/TFMessage in ROS 1
    assert conns["/ground/status"].digest == "60810da900de1dd6ddd437c3503511da"  # diagnostic_msgs/DiagnosticArray


def test_tf_holds_the_camera_beside_the_sensor(tmp_path, read_ros_topics):
    res = estimate_log(EXAMPLE, camera="kitti_cam2")
    table = result_table(res)
    write_outputs([tmp_path / "g.mcap"], table, res.meta)
    tf = read_ros_topics(tmp_path / "g.mcap")["/tf"]
    cam = read_ros_topics(tmp_path / "g.mcap")["/ground/road_from_camera"]
    assert len(tf) == len(cam) == table["valid"].sum()
    assert {tuple(x.child_frame_id for x in m.transforms) for _, m in tf} == {(res.meta["frame_id"], "camera")}
    for (_, m), (_, c) in zip(tf, cam, strict=True):
        x = m.transforms[1]
        assert x.header.stamp == c.header.stamp and x.header.frame_id == c.header.frame_id == "road"
        assert (x.transform.translation.z, x.transform.rotation.x) == (c.transform.translation.z,
                                                                        c.transform.rotation.x)


def test_bag_outputs_keep_the_settings_topic(tmp_path, read_ros_topics):
    """A ROS 1 bag and a ROS 2 bag folder have no metadata record: the settings stay a topic."""
    for name in ("g.bag", "g_ros2"):
        write_ros_output(tmp_path / name, _status_table(), settings={"method": "paper"})
        got = read_ros_topics(tmp_path / name)
        assert [m.data for _, m in got["/ground/settings"]] == ['{"method": "paper"}']
    assert read_output_settings(tmp_path / "g.bag") is None


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_patched_messages_are_what_rosbags_serialises(tmp_path, kind):
    """/tf (with a camera), the pose and the diagnostics are serialised once and patched (RosWriter.serialize_many):
    every message re-serialises from its decoded self to the same bytes."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    res = estimate_log(EXAMPLE, camera="kitti_cam2", extrinsic=TILTED)
    path = tmp_path / NAMES[kind]
    write_ros_output(path, result_table(res), road_from_camera=res.meta["plane"].matrix,
                     extrinsic=res.meta["extrinsic"])
    seen = set()
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        store = reader.typestore
        conns = [c for c in reader.connections if c.topic in ("/tf", "/ground/pose", "/ground/status")]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            again = (store.serialize_ros1 if kind == "ros1" else store.serialize_cdr)(msg, conn.msgtype)
            assert bytes(again) == bytes(raw), conn.topic
            seen.add(conn.topic)
    assert seen == {"/tf", "/ground/pose", "/ground/status"}
