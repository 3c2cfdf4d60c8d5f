"""Cameras, the per-frame road plane in a camera's axes, bird's-eye homographies and the KITTI planes files."""
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.filters.extrinsics import Extrinsic, load_extrinsic
from imu_ground.perception import BevGrid, Camera, GroundPlane, load_camera, range_error, save_camera
from imu_ground.pipeline.output import COLUMNS
from imu_ground.pipeline.planes import PLANES_MARKER, read_kitti_planes, write_kitti_planes
from imu_ground.so3 import rotx, roty, rotz

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"



def one_error_line(err, *words):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, err)
    return lines[0]


def _random_planes(n=7, seed=0):
    rng = np.random.default_rng(seed)
    cam = load_camera("kitti_cam2")
    e = roty(rng.normal(0, 0.02, n)) @ rotx(rng.normal(0, 0.02, n)) @ rotz(rng.normal(0, 0.01, n))
    return cam, GroundPlane.from_camera(cam, e)


# ------------------------------------------------------------------------------------------ the plane
def test_points_on_the_plane_through_the_image_and_back_through_the_homography():
    cam, plane = _random_planes()
    grid = BevGrid(4.0, 60.0, -12.0, 12.0, 0.05)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(5, 60, 200), rng.uniform(-10, 10, 200)
    uv = plane.pixel_from_road(x, y)                                              # (N, 200, 2)
    # projection checked independently: camera <- road transform, then K
    m = np.linalg.inv(plane.matrix)
    cam_pts = np.einsum("nij,kj->nki", m[:, :3, :3], np.c_[x, y, np.zeros_like(x)]) + m[:, None, :3, 3]
    direct = cam_pts @ cam.K.T
    assert np.allclose(uv, direct[..., :2] / direct[..., 2:], atol=1e-9)
    to_bev = plane.to_bev(grid)
    hom = np.einsum("nij,nkj->nki", to_bev, np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1))
    bev = hom[..., :2] / hom[..., 2:]
    road = np.einsum("ij,nkj->nki", grid.road_from_bev, np.concatenate([bev, np.ones(bev.shape[:-1] + (1,))], -1))
    assert np.abs(road[..., :2] / road[..., 2:] - np.c_[x, y]).max() < 1e-9
    back = plane.road_from_pixel(uv[..., 0], uv[..., 1], per_frame=True)
    assert np.abs(back - np.c_[x, y]).max() < 1e-9
    assert np.allclose(plane.from_bev(grid) @ to_bev, np.eye(3) * (plane.from_bev(grid) @ to_bev)[:, 2:, 2:],
                       atol=1e-9)


def test_plane_equation_depth_and_points():
    cam, plane = _random_planes()
    n, d = plane.normal, plane.height
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert np.all(n[:, 1] < -0.99) and np.allclose(d, 1.659, atol=0.04)        # up is about -y; 1.66 m up
    u, v = np.meshgrid(np.linspace(0, 1241, 9), np.linspace(230, 374, 5))
    p = plane.point_from_pixel(u, v)
    assert np.abs(np.einsum("ni,n...i->n...", n, p) + d[:, None, None]).max() < 1e-9   # on the plane
    assert np.allclose(plane.depth(u, v), p[..., 2])
    assert np.isnan(plane.depth(600.0, 10.0)).all()                               # sky: no road point
    coeffs = plane.coefficients
    assert coeffs.shape == (7, 4) and np.allclose(coeffs[:, :3], n)
    assert np.allclose(plane.matrix[:, 3], [0, 0, 0, 1])


def test_from_normal_in_any_frame_matches_from_camera():
    cam = load_camera("kitti_cam2")
    e = roty(np.radians([0.3, -0.7])) @ rotx(np.radians([0.2, 0.4]))
    plane = GroundPlane.from_camera(cam, e)
    n_body = e[:, 2, :]                                                          # road normal, body frame
    other = GroundPlane.from_normal(cam.K, n_body, plane.height, rotation=cam.extrinsic.rotation.T)
    assert np.allclose(other.normal, plane.normal, atol=1e-12)
    assert np.allclose(other.coefficients, plane.coefficients, atol=1e-12)
    # the same road points from the same pixels (road frames differ by an in-plane move only)
    u, v = np.array([300.0, 600.0, 900.0]), np.array([250.0, 300.0, 360.0])
    assert np.allclose(other.point_from_pixel(u, v), plane.point_from_pixel(u, v), atol=1e-9)


def test_range_error_example_and_first_order():
    # 0.5 deg at 50 m, camera 1.65 m up: about 13 m first order; exact -10.5 m or +18 m
    fo = range_error(50.0, math.radians(0.5), 0.0, 1.65, first_order=True)
    assert fo == pytest.approx(-50.0 ** 2 * math.radians(0.5) / 1.65, rel=2e-3) and abs(fo) == pytest.approx(13.2,
                                                                                                          abs=0.05)
    ex = range_error(50.0, np.radians([0.5, -0.5]), 0.0, 1.65)
    assert ex[0] == pytest.approx(-10.5, abs=0.05) and ex[1] == pytest.approx(18.0, abs=0.05)
    # exact: the tilted ray (depression atan(h/d) + dpitch) meets the level road at h / tan(...)
    alpha = math.atan(1.65 / 50.0)
    assert ex[0] == pytest.approx(1.65 / math.tan(alpha + math.radians(0.5)) - 50.0, rel=1e-12)
    # first order is the derivative at zero (finite differences), roll with a lateral offset too
    for dp, dr, y in ((1e-6, 0.0, 0.0), (0.0, 1e-6, 3.0), (1e-6, -1e-6, -2.0)):
        assert range_error(30.0, dp, dr, 1.5, y) == pytest.approx(range_error(30.0, dp, dr, 1.5, y, True),
                                                                  rel=1e-4)
    assert np.isnan(range_error(50.0, -0.1, 0.0, 1.65))                            # ray above the tilted horizon


def test_range_error_matches_the_plane_geometry():
    """The closed form equals re-projecting through GroundPlane for a level camera above its foot point."""
    k = np.array([[700.0, 0, 600], [0, 700.0, 180], [0, 0, 1]])
    r_gc = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])                      # level: ground <- camera
    cam = Camera(k, (1200, 360), Extrinsic(r_gc, [0.0, 0.0, 1.65]))
    truth = GroundPlane.from_camera(cam)                                        # road origin below the camera
    dp, dr = math.radians(0.4), math.radians(-0.3)
    est = GroundPlane(k, roty(dp) @ rotx(dr) @ truth.rotation, np.array([[0.0, 0.0, 1.65]]))
    uv = truth.pixel_from_road(40.0, 2.0)
    got = est.road_from_pixel(uv[..., 0], uv[..., 1])[0, 0]
    assert np.hypot(*got) - np.hypot(40.0, 2.0) == pytest.approx(range_error(40.0, dp, dr, 1.65, 2.0), abs=1e-9)
    assert est.range_error(40.0, dp, dr, 2.0)[0] == pytest.approx(range_error(40.0, dp, dr, 1.65, 2.0))


def test_bev_grid_checks():
    g = BevGrid(5, 45, -7, 7, 0.05)
    assert g.shape == (800, 280)
    assert np.allclose(g.bev_from_road(44.975, 6.975), [0, 0])
    with pytest.raises(ValueError, match="X0 < X1"):
        BevGrid(45, 5, -7, 7, 0.05)


def test_warp_of_a_rendered_view_shows_the_lanes_where_they_are():
    from imu_ground.evaluation.simulate.camera import render_road
    from imu_ground.perception import warp_to_bev
    cam = load_camera("kitti_cam2")
    plane = GroundPlane.from_pitch_roll(cam, 0.004, -0.003)
    img = render_road(plane, cam.image_size)
    grid = BevGrid(8, 20, -3, 3, 0.05)
    bev = warp_to_bev(img, plane.from_bev(grid)[0], grid).astype(float).mean(axis=2)
    cols = bev.mean(axis=0)                                                     # lane lines: the brightest columns
    y = grid.y1 - (np.arange(grid.shape[1]) + 0.5) * grid.res
    left, right = y[np.argmax(np.where(y > 0, cols, 0))], y[np.argmax(np.where(y < 0, cols, 0))]
    assert left == pytest.approx(1.75, abs=0.08) and right == pytest.approx(-1.75, abs=0.08)


# ------------------------------------------------------------------------------------------ cameras
def test_shipped_cameras_and_file_round_trip(tmp_path):
    from imu_ground.perception import available_cameras
    assert set(available_cameras()) >= {"kitti_cam0", "kitti_cam1", "kitti_cam2", "kitti_cam3"}
    c0, c2 = load_camera("kitti_cam0"), load_camera("kitti_cam2")
    assert c0.image_size == (1242, 375) and c0.K[0, 0] == pytest.approx(721.5377)
    # rectified cameras share a rotation; camera 2 is 6 cm left of camera 0 (KITTI set-up)
    assert np.allclose(c0.extrinsic.rotation, c2.extrinsic.rotation, atol=1e-12)
    assert c2.extrinsic.translation[1] - c0.extrinsic.translation[1] == pytest.approx(0.06, abs=0.01)
    save_camera(c2, tmp_path / "cam.txt")
    back = load_camera(tmp_path / "cam.txt")
    assert np.array_equal(back.K, c2.K) and back.image_size == c2.image_size
    assert np.array_equal(back.extrinsic.rotation, c2.extrinsic.rotation)


@pytest.mark.parametrize("text, match", [
    ("R: 1 0 0 0 1 0 0 0 1\n", "not a camera file"),
    ("R: 1 0 0 0 1 0 0 0 1\nK: 1 0 0 0 1 0 0 0\nimage_size: 10 10\n", "'K' needs 9 numbers"),
    ("R: 1 0 0 0 1 0 0 0 1\nK: 1 0 0 0 1 0 0 0 1\nimage_size: 10.5 10\n", "whole numbers"),
    ("R: 1 0 0 0 1 0 0 0 1\nK: 1 0 0 0 1 0 0 0 2\nimage_size: 10 10\n", "K must be"),
])
def test_bad_camera_files_name_the_file(tmp_path, text, match):
    p = tmp_path / "cam.txt"
    p.write_text(text)
    with pytest.raises(ValueError, match=match) as e:
        load_camera(p)
    assert str(p) in str(e.value)


def test_kitti_raw_folder_gives_the_shipped_cameras(shared_data):
    folder = shared_data / "kitti_raw" / "2011_09_26"
    for i in range(4):
        direct, shipped = load_camera(f"{folder}:{i}"), load_camera(f"kitti_cam{i}")
        assert np.allclose(direct.K, shipped.K, atol=1e-12) and direct.image_size == shipped.image_size
        assert np.allclose(direct.extrinsic.rotation, shipped.extrinsic.rotation, atol=1e-15)
        assert np.allclose(direct.extrinsic.translation, shipped.extrinsic.translation, atol=1e-15)
    with pytest.raises(ValueError, match="cameras 0 to 3"):
        load_camera(f"{folder}:4")


# ------------------------------------------------------------------------------------------ planes files
def _kitti_loader(path):
    """How KITTI object loaders (OpenPCDet's get_road_plane, AVOD's) read a planes file."""
    with open(path) as f:
        lines = f.readlines()
    plane = np.asarray([float(i) for i in lines[3].split()])
    if plane[1] > 0:                       # normal facing up in rectified camera axes
        plane = -plane
    return plane / np.linalg.norm(plane[0:3])


def test_planes_files_parse_as_kittis_do(tmp_path):
    _, plane = _random_planes()
    abcd = plane.coefficients
    abcd[3] = np.nan                                                             # a gap frame
    files = write_kitti_planes(tmp_path / "planes", abcd)
    assert [f.name for f in files] == [f"{i:06d}.txt" for i in range(7)]
    for i, f in enumerate(files):
        assert f.read_text().splitlines()[:3] == ["# Matrix", "WIDTH 4", "HEIGHT 1"]
        if i == 3:
            assert np.isnan(read_kitti_planes(f)).all()
            continue
        assert np.allclose(_kitti_loader(f), abcd[i], rtol=1e-8)                 # already up and unit
        assert np.allclose(read_kitti_planes(f), abcd[i], rtol=1e-8)
    # rewriting a shorter run replaces the folder: no stale frame, no temporary folder left
    write_kitti_planes(tmp_path / "planes", abcd[:2] * 0 + [0, -1, 0, 1.65])
    assert np.allclose(read_kitti_planes(files[0]), [0, -1, 0, 1.65])
    assert sorted(p.name for p in (tmp_path / "planes").iterdir()) == [PLANES_MARKER, "000000.txt", "000001.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["planes"]
    # a folder with files of the user's is refused, untouched
    (tmp_path / "planes" / "notes.md").write_text("mine")
    with pytest.raises(ValueError, match="notes.md"):
        write_kitti_planes(tmp_path / "planes", abcd)
    assert (tmp_path / "planes" / "notes.md").read_text() == "mine"


# ------------------------------------------------------------------------------------------ estimate
def test_estimate_with_a_camera_on_the_example(tmp_path, cli):
    out, planes = tmp_path / "g.csv", tmp_path / "planes"
    code, stdout, err = cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "--bev", 5, 45, -7, 7, 0.1,
                            "--planes", planes, "-o", out)
    assert code == 0, err
    df = pd.read_csv(out, comment="#")
    assert list(df.columns) == [*COLUMNS, "plane_a", "plane_b", "plane_c", "plane_d",       # the order stays
                                *[f"bev_h{i}{j}" for i in range(3) for j in range(3)]]
    files = sorted(planes.glob("*.txt"))
    assert len(files) == len(df)
    ok = df["valid"].to_numpy(bool)
    got = np.array([read_kitti_planes(f) for f in files])
    assert np.allclose(got[ok], df.loc[ok, ["plane_a", "plane_b", "plane_c", "plane_d"]].to_numpy(), rtol=1e-8)
    assert np.isnan(got[~ok]).all()
    # the normal: the residual's road normal in the body frame, rotated into the camera
    from scipy.spatial.transform import Rotation
    e = Rotation.from_quat(df[["qw", "qx", "qy", "qz"]].to_numpy()[ok], scalar_first=True).as_matrix()
    cam = load_camera("kitti_cam2")
    assert np.allclose(e[:, 2, :] @ cam.extrinsic.rotation, got[ok, :3], atol=1e-7)
    assert "planes files" in stdout


def test_estimate_camera_errors_are_one_line(tmp_path, cli):
    code, _, err = cli("estimate", EXAMPLE, "--camera", "no_cam", "-o", tmp_path / "g.csv")
    assert code == 2 and "--camera" in one_error_line(err, "no_cam", "kitti_cam2")
    code, _, err = cli("estimate", EXAMPLE, "--planes", tmp_path / "p", "-o", tmp_path / "g.csv")
    assert code == 2 and "--camera" in one_error_line(err, "--planes")
    code, _, err = cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "--bev", 5, 1, -7, 7, 0.1,
                       "-o", tmp_path / "g.csv")
    assert code == 2 and one_error_line(err, "--bev")
    (tmp_path / "file").write_text("x")
    code, _, err = cli("estimate", EXAMPLE, "--camera", "kitti_cam2", "--planes", tmp_path / "file",
                       "-o", tmp_path / "g.csv")
    assert code == 2 and one_error_line(err, "--planes", "file")
    assert not (tmp_path / "g.csv").exists()


def test_kitti_drive_plane_is_the_csv_normal_in_camera_2(shared_data, tmp_path, cli):
    drives = pd.read_csv(shared_data / "kitti_imu100" / "drives.csv")
    log = shared_data / "kitti_imu100" / f"{drives['drive'].iloc[0]}.csv.gz"
    out = tmp_path / "d.csv"
    code, _, err = cli("estimate", log, "--extrinsic", "kitti_imu", "--camera", "kitti_cam2", "-o", out)
    assert code == 0, err
    df = pd.read_csv(out, comment="#")
    ok = df["valid"].to_numpy(bool) & np.isfinite(df["plane_a"].to_numpy())
    assert ok.sum() > 100
    cam, imu = load_camera("kitti_cam2"), load_extrinsic("kitti_imu")
    r_cam_imu = cam.extrinsic.rotation.T @ imu.rotation                         # camera 2 <- IMU, by the calibration
    n_cam = df.loc[ok, ["normal_x", "normal_y", "normal_z"]].to_numpy() @ r_cam_imu.T
    plane = df.loc[ok, ["plane_a", "plane_b", "plane_c"]].to_numpy()
    cosang = np.einsum("ij,ij->i", n_cam, plane) / np.linalg.norm(n_cam, axis=1) / np.linalg.norm(plane, axis=1)
    assert np.degrees(np.arccos(np.clip(cosang, -1, 1))).max() < 0.01
    assert np.abs(df.loc[ok, "plane_d"].to_numpy() - 1.65).max() < 0.1


def test_ros_output_has_the_road_from_camera_topic(tmp_path):
    pytest.importorskip("rosbags")
    from imu_ground.pipeline.estimate import estimate_log
    from imu_ground.pipeline.output import result_table, write_outputs
    res = estimate_log(EXAMPLE, camera="kitti_cam2")
    table = result_table(res)
    write_outputs([tmp_path / "g.mcap"], table, res.meta)
    from rosbags.highlevel import AnyReader
    with AnyReader([tmp_path / "g.mcap"]) as reader:
        conns = [c for c in reader.connections if c.topic == "/ground/road_from_camera"]
        assert conns and conns[0].msgtype == "geometry_msgs/msg/TransformStamped"
        msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=conns)]
    valid = table["valid"].to_numpy(bool)
    assert len(msgs) == valid.sum()
    m = res.meta["plane"].matrix[valid][0]
    assert msgs[0].transform.translation.z == pytest.approx(m[2, 3])
    assert msgs[0].child_frame_id == "camera" and msgs[0].header.frame_id == "road"


def test_gap_frames_get_nan_planes_and_keep_the_indices(tmp_path, cli):
    df = pd.read_csv(EXAMPLE)
    t = df["t"].to_numpy()
    log = tmp_path / "gap.csv"
    df[~((t > 20.0) & (t < 23.0))].to_csv(log, index=False)
    out, planes = tmp_path / "g.csv", tmp_path / "planes"
    code, _, err = cli("estimate", log, "--camera", "kitti_cam2", "--planes", planes, "-o", out)
    assert code == 0, err
    table = pd.read_csv(out, comment="#")
    gap = ~table["valid"].to_numpy(bool)
    assert gap.sum() >= 20
    got = np.array([read_kitti_planes(planes / f"{i:06d}.txt") for i in range(len(table))])
    assert np.isnan(got[gap]).all() and np.isfinite(got[~gap]).all()
    assert np.isnan(table.loc[gap, "plane_d"]).all()
    # the frame after the gap is the table's row of the same index
    i = int(np.flatnonzero(gap)[-1]) + 1
    assert np.allclose(got[i], table.loc[i, ["plane_a", "plane_b", "plane_c", "plane_d"]].to_numpy(float), rtol=1e-8)
