"""Odometry pose readers (KITTI, TUM): round trips, relative rotations, clear errors."""
import numpy as np
import pytest
from imu_ground.datasets.poses import (
    read_kitti_poses,
    read_poses,
    read_tum_poses,
    relative_rotations,
    write_tum_poses,
)
from scipy.spatial.transform import Rotation


def _poses(n=20, seed=0):
    rng = np.random.default_rng(seed)
    r = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.05, size=(n, 3)), axis=0)).as_matrix()
    t = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    return r, t


def _write_kitti(path, r, t, index=None):
    m = np.concatenate([r, t[:, :, None]], axis=2).reshape(len(r), 12)
    if index is not None:
        m = np.column_stack([index, m])
    np.savetxt(path, m, fmt="%.17g")


def test_kitti_with_and_without_index(tmp_path):
    r, t = _poses()
    _write_kitti(tmp_path / "a.txt", r, t)
    _write_kitti(tmp_path / "b.txt", r, t, index=np.arange(1, 21))
    a, b = read_poses(tmp_path / "a.txt"), read_poses(tmp_path / "b.txt")
    assert np.allclose(a.rotations, r, atol=1e-15) and np.allclose(b.rotations, r, atol=1e-15)
    assert np.array_equal(a.index, np.arange(20)) and np.array_equal(b.index, np.arange(1, 21))
    assert np.allclose(b.translations, t)
    d = a.relative_rotations()
    # R_k = R_{k-1} dR_k rebuilds the trajectory
    acc = r[0]
    for k in range(len(d)):
        acc = acc @ d[k]
        assert np.allclose(acc, r[k + 1], atol=1e-13)


def test_tum_round_trip(tmp_path):
    r, t = _poses()
    ts = 100.0 + 0.1 * np.arange(20)
    write_tum_poses(tmp_path / "x.tum", ts, r, t)
    p = read_poses(tmp_path / "x.tum")
    assert p.t is not None and np.allclose(p.t, ts)
    assert np.allclose(p.rotations, r, atol=1e-8)
    assert np.allclose(relative_rotations(p.rotations), np.swapaxes(r[:-1], 1, 2) @ r[1:], atol=1e-8)


@pytest.mark.parametrize("content, reader, match", [
    ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1\n", read_kitti_poses, r"k\.txt:2: expected 12 numbers.*truncated"),
    ("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 x\n", read_kitti_poses, r"k\.txt:2: not a number"),
    ("1 0 0 0 0 1 0 0 0 0 1 nan\n", read_kitti_poses, r"NaN or inf"),
    ("2 0 0 0 0 1 0 0 0 0 1 0\n", read_kitti_poses, r"not rotations \(first at line 1"),
    ("", read_kitti_poses, r"empty file"),
    ("3 1 0 0 0 0 1 0 0 0 0 1 0\n2 1 0 0 0 0 1 0 0 0 0 1 0\n", read_kitti_poses, r"not strictly increasing at line 2"),
    ("0.1 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n", read_tum_poses, r"1 duplicate timestamps, first at pose 1"),
    ("0.2 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n", read_tum_poses, r"unsorted or duplicate"),
    ("0.1 0 0 0 0 0 0 2\n", read_tum_poses, r"norm 2.0000"),
])
def test_errors_name_the_problem(tmp_path, content, reader, match):
    p = tmp_path / "k.txt"
    p.write_text(content)
    with pytest.raises(ValueError, match=match):
        reader(p)


def test_missing_and_unknown_format(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.txt"):
        read_poses(tmp_path / "nope.txt")
    (tmp_path / "w.txt").write_text("1 2 3\n")
    with pytest.raises(ValueError, match="first line of 3 numbers"):
        read_poses(tmp_path / "w.txt")


def test_real_kitti_ground_truth_and_orbslam(shared_data):
    gt = read_poses(shared_data / "kitti_odometry" / "poses" / "00.txt")
    orb = read_poses(shared_data / "kitti_odometry" / "orbslam2_mono" / "00.txt")
    assert len(gt) == 4541 and len(orb) == 4540 and orb.index[0] == 1
    # sequence 00 drives ~3.7 km; its camera stays level: relative rotations are small
    assert 3000 < np.sum(np.linalg.norm(np.diff(gt.translations, axis=0), axis=1)) < 4500
    d = Rotation.from_matrix(gt.relative_rotations()).magnitude()
    assert np.rad2deg(d).max() < 10
