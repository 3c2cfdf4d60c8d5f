"""``imu-ground preview``: the synthetic picture shows what it says, and a user's images with their log."""
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from imu_ground.evaluation.ground_effect import drive_ground_errors, ground_errors
from imu_ground.evaluation.preview import PNG_KEY, read_preview_errors, synthetic_preview
from imu_ground.perception import GroundPlane, load_camera, save_camera

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"



def test_ground_errors_of_a_pitch_error_match_the_closed_form():
    """A camera right above the road origin: the range error is range_error's (whose tilted plane keeps the
    camera's height; the estimate's turns about the road origin: they differ to second order)."""
    from imu_ground.filters.extrinsics import Extrinsic
    from imu_ground.perception import Camera, range_error
    kitti = load_camera("kitti_cam2")
    cam = Camera(kitti.K, kitti.image_size, Extrinsic(kitti.extrinsic.rotation, [0.0, 0.0, 1.65]))
    d = np.array([20.0, 40.0, 60.0])
    e = drive_ground_errors(cam, np.radians([0.5, 0.0]), [0.0, 0.0], [0.0, np.radians(-0.5)], [0.0, 0.0],
                            distances=d)
    assert np.abs(e["truth"]["range"]).max() < 1e-9 and np.abs(e["static"]["range"][0]).max() < 1e-9
    assert np.allclose(e["dynamic"]["range"][0], range_error(d, np.radians(0.5), 0.0, 1.65), rtol=0.01)
    # the static plane of a body pitched 0.5 deg nose up is off by the same +0.5 deg: the same error
    assert np.allclose(e["static"]["range"][1], e["dynamic"]["range"][0], rtol=1e-3)
    # a pitch error scales lateral distances by the same factor as the range
    ratio = (e["dynamic"]["lane_width"][0] + 3.5) / 3.5
    assert np.allclose(ratio, (d + e["dynamic"]["range"][0]) / d, rtol=2e-3)


def test_synthetic_preview_png_shows_what_it_says(tmp_path, cli):
    out = tmp_path / "out" / "bev.png"
    code, stdout, err = cli("preview", "-o", out)
    assert code == 0, err
    with Image.open(out) as im:
        assert im.format == "PNG" and im.size[0] > 1000 and im.size[1] > 600
    plotted = read_preview_errors(out)
    d = np.array(plotted["distance_m"])
    static, dynamic = np.array(plotted["static"]), np.array(plotted["dynamic"])
    assert d[0] == 5.0 and d[-1] == 60.0
    # the static extrinsic's lane-width error grows with distance and the estimate cuts it
    assert np.all(np.diff(static) > 0) and np.all(dynamic < 0.5 * static)
    # independently: the same drive's errors recomputed from its planes
    pv = synthetic_preview(frames=1)
    assert set(pv.lane_error) == set(plotted)
    for key, values in plotted.items():
        assert np.allclose(pv.lane_error[key], values, rtol=1e-12)
    i40 = int(np.flatnonzero(d == 40.0)[0])
    assert f"40 m: static {static[i40]:.3f} m, dynamic {dynamic[i40]:.3f} m" in stdout


def test_synthetic_preview_gif_animates(tmp_path, cli):
    out = tmp_path / "bev.gif"
    code, _, err = cli("preview", "-o", out, "--frames", 3)
    assert code == 0, err
    with Image.open(out) as im:
        assert im.format == "GIF" and im.n_frames == 3


@pytest.fixture(scope="module")
def small_camera(tmp_path_factory):
    """A KITTI camera 2 at a tenth of the resolution (fast images)."""
    d = tmp_path_factory.mktemp("cam")
    cam = load_camera("kitti_cam2")
    k = cam.K.copy()
    k[:2] *= 0.1
    from imu_ground.perception import Camera
    small = Camera(k, (124, 38), cam.extrinsic, "small")
    save_camera(small, d / "small.txt")
    return d / "small.txt", small


@pytest.fixture
def user_images(tmp_path, small_camera):
    from imu_ground.evaluation.simulate.camera import render_road
    _, cam = small_camera
    folder = tmp_path / "images"
    folder.mkdir()
    for i in range(3):
        Image.fromarray(render_road(GroundPlane.from_camera(cam), cam.image_size, i)).save(folder / f"{i:06d}.png")
    (tmp_path / "times.txt").write_text("10.0\n10.5\n11.0\n")
    return folder, tmp_path / "times.txt"


def test_user_images_preview(tmp_path, small_camera, user_images, cli):
    folder, times = user_images
    out = tmp_path / "mine.gif"
    code, stdout, err = cli("preview", EXAMPLE, "--images", folder, "--times", times, "--camera",
                            small_camera[0], "-o", out)
    assert code == 0, err
    with Image.open(out) as im:
        assert im.n_frames == 3
    code, _, err = cli("preview", EXAMPLE, "--images", folder, "--times", times, "--camera",
                       small_camera[0], "-o", tmp_path / "one.png")
    assert code == 0, err
    with Image.open(tmp_path / "one.png") as im:
        assert PNG_KEY not in im.text                   # no truth, no lane-width plot


def _one_line(err):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_user_images_errors_name_the_file(tmp_path, small_camera, user_images, cli):
    folder, times = user_images
    cam = str(small_camera[0])
    args = ["preview", EXAMPLE, "--images", folder, "--times", times, "--camera", cam, "-o", tmp_path / "x.png"]
    # an image of another size
    Image.new("RGB", (100, 30)).save(folder / "000001.png")
    code, _, err = cli(*args)
    assert code == 2 and "000001.png" in _one_line(err) and "124x38" in err
    # an unreadable image
    (folder / "000001.png").write_bytes(b"not an image")
    code, _, err = cli(*args)
    assert code == 2 and "000001.png" in _one_line(err) and "unreadable" in err
    Image.new("RGB", (124, 38)).save(folder / "000001.png")
    # a time outside the log
    times.write_text("10.0\n500.0\n11.0\n")
    code, _, err = cli(*args)
    assert code == 2 and f"{times}:2" in _one_line(err) and "outside" in err
    # not a time, and counts that differ
    times.write_text("10.0\nten\n11.0\n")
    code, _, err = cli(*args)
    assert code == 2 and f"{times}:2" in _one_line(err)
    times.write_text("10.0\n")
    code, _, err = cli(*args)
    assert code == 2 and "1 times for 3 images" in _one_line(err)
    # a log without its images
    code, _, err = cli("preview", EXAMPLE, "-o", tmp_path / "x.png")
    assert code == 2 and "--images" in _one_line(err)
    code, _, err = cli("preview", "-o", tmp_path / "x.jpg")
    assert code == 2 and ".png or .gif" in _one_line(err)
    assert not (tmp_path / "x.png").exists()


def test_lane_width_errors_are_zero_with_the_truth():
    cam = load_camera("kitti_cam2")
    truth = GroundPlane.from_pitch_roll(cam, [0.01, -0.005], [0.003, 0.0])
    e = ground_errors(truth, truth)
    assert np.abs(e["range"]).max() < 1e-9 and np.abs(e["lane_width"]).max() < 1e-9


def test_the_bird_s_eye_images_show_the_lane_widths_the_geometry_gives():
    """In the pictured frame, the lane lines found in the warped images are as far apart as ground_errors says."""
    from imu_ground.evaluation.preview import PREVIEW_GRID as grid
    from imu_ground.perception import warp_to_bev
    pv = synthetic_preview(frames=1)
    img = pv.image(0)
    y = grid.y1 - (np.arange(grid.shape[1]) + 0.5) * grid.res
    for name in ("static", "dynamic", "truth"):
        plane = pv.planes[name]
        bev = warp_to_bev(img, plane.from_bev(grid)[0], grid).astype(float)
        rows = slice(*sorted(int(round((grid.x1 - x) / grid.res)) for x in (26.0, 22.0)))   # 22-26 m ahead
        white = (bev[rows, :, 2] > 170).mean(axis=0)                          # lane paint: blue-rich white
        inner = np.abs(y) < 3.0
        left = np.average(y[inner & (y > 0)], weights=white[inner & (y > 0)])
        right = np.average(y[inner & (y < 0)], weights=white[inner & (y < 0)])
        # the lane width ground_errors gives where the plane puts road points 24 m ahead
        dists = np.linspace(10.0, 60.0, 501)
        e = ground_errors(pv.planes["truth"], plane, dists)
        expected = np.interp(24.0, dists + e["range"][0], 3.5 + e["lane_width"][0])
        assert left - right == pytest.approx(expected, abs=0.05), name


def test_synthetic_preview_says_when_the_drive_has_fewer_frames_than_asked(tmp_path, cli, monkeypatch, small_camera):
    """--frames beyond the synthetic drive's frames gives them all and says so (it said only the count); a drive
    too short to reach 3 m/s has no lane-width errors (it was a bug exit)."""
    import functools

    import imu_ground.cli.preview as command
    monkeypatch.setattr(command, "synthetic_preview", functools.partial(command.synthetic_preview, duration=2.0))
    out, camera = tmp_path / "bev.gif", small_camera[0]
    code, said, err = cli("preview", "-o", out, "--frames", 30, "--bev", 5, 45, -7, 7, 1, "--camera", camera)
    assert code == 0, err
    with Image.open(out) as im:
        n = im.n_frames
    assert n < 30 and f"({n} frames" in said and f"--frames 30: the synthetic drive has {n}" in said, said
    code, said, err = cli("preview", "-o", out, "--frames", 3, "--bev", 5, 45, -7, 7, 1, "--camera", camera)
    assert code == 0 and "the synthetic drive has" not in said, said
