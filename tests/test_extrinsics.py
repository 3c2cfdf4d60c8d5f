"""Tests of the shipped extrinsics and their loader."""
import numpy as np
import pytest

from imu_ground.filters.extrinsics import Extrinsic, available_extrinsics, load_extrinsic, save_extrinsic


def test_shipped_kitti_extrinsics_load_and_are_rotations():
    assert {"kitti_cam0", "kitti_imu"} <= set(available_extrinsics())
    cam = load_extrinsic("kitti_cam0")
    assert np.allclose(cam.rotation.T @ cam.rotation, np.eye(3), atol=1e-12)
    assert np.linalg.det(cam.rotation) == pytest.approx(1.0)
    # camera frame x right, y down, z forward: up is about -y, forward about +z
    assert cam.normal @ np.array([0.0, -1.0, 0.0]) > 0.9999
    assert cam.rotation.T @ np.array([1.0, 0.0, 0.0]) @ np.array([0.0, 0.0, 1.0]) > 0.9999
    assert cam.translation[2] == pytest.approx(1.65, abs=0.03)     # KITTI: cameras 1.65 m up
    imu = load_extrinsic("kitti_imu")
    assert np.array_equal(imu.rotation, np.eye(3))
    assert imu.translation[2] == pytest.approx(0.93)


def test_round_trip(tmp_path):
    r = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    e = Extrinsic(r, [0.1, 0.2, 1.5], {"platform": "test"})
    save_extrinsic(e, tmp_path / "x.txt", comment="made by a test")
    back = load_extrinsic(tmp_path / "x.txt")
    assert np.array_equal(back.rotation, r) and np.array_equal(back.translation, e.translation)
    assert back.meta["platform"] == "test"


@pytest.mark.parametrize("text, match", [
    ("R: 1 0 0 0 1 0 0 0\n", r"x\.txt:1: 'R' needs 9 numbers, got 8"),
    ("R: 1 0 0 0 1 0 0 0 one\n", r"x\.txt:1: 'R' has a value that is not a number"),
    ("t: 0 0 1\n", r"no 'R:' line"),
    ("# c\nR: 1 0 0 0 1 0 0 0 2\n", r"x\.txt:2: .*not a rotation"),
    ("R: 1 0 0 0 1 0 0 0 -1\n", r"not a rotation.*det = -1"),
    ("R 1 0 0 0 1 0 0 0 1\n", r"x\.txt:1: expected 'key: value'"),
])
def test_loader_errors_name_file_and_line(tmp_path, text, match):
    p = tmp_path / "x.txt"
    p.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_extrinsic(p)


def test_missing_file_and_unknown_name():
    with pytest.raises(FileNotFoundError, match="no_such.txt"):
        load_extrinsic("no_such.txt")
    with pytest.raises(FileNotFoundError, match="available: .*kitti_cam0"):
        load_extrinsic("no_such_platform")


def test_derivation_reproduces_shipped_files(shared_data):
    from imu_ground.calib.derive_kitti import derive_kitti_extrinsics
    derived = derive_kitti_extrinsics(shared_data / "kitti_raw" / "2011_09_26")
    for name, e in derived.items():
        shipped = load_extrinsic(name)
        assert np.allclose(shipped.rotation, e.rotation, atol=1e-15)
        assert np.allclose(shipped.translation, e.translation, atol=1e-15)
    # independent check of the chain: the velodyne is 1.73 m up (KITTI set-up)
    from imu_ground.calib.derive_kitti import read_kitti_calib
    iv = read_kitti_calib(shared_data / "kitti_raw" / "2011_09_26" / "calib_imu_to_velo.txt")
    velo_in_imu = -iv["R"].reshape(3, 3).T @ iv["T"]
    assert 0.93 + velo_in_imu[2] == pytest.approx(1.73, abs=0.01)
