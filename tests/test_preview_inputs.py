"""``imu-ground preview``: memory bounded whatever the bird's-eye grid; a user's images and times."""
import tracemalloc
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

import imu_ground.cli.preview as preview_cli
from imu_ground.evaluation.preview import DRAWN_BEV_PIXELS, Preview, drawn_grid, render_preview
from imu_ground.evaluation.simulate.camera import render_road
from imu_ground.perception import BevGrid, Camera, GroundPlane, load_camera

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


def _small_preview(frames=1):
    """Two planes of a KITTI camera 2 at a tenth of its resolution (the grid, not the image, sets the cost)."""
    kitti = load_camera("kitti_cam2")
    k = kitti.K.copy()
    k[:2] *= 0.1
    cam = Camera(k, (124, 38), kitti.extrinsic, "small")
    plane = GroundPlane.from_pitch_roll(cam, np.radians([0.3] * frames), np.zeros(frames))
    img = render_road(GroundPlane.from_camera(cam), cam.image_size)
    return Preview(cam, {"static": plane, "dynamic": plane}, np.arange(frames, dtype=float), lambda k: img)


def _peak_bytes(fn):
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_fine_grid_is_drawn_in_bounded_memory():
    render_preview(_small_preview(1), "png", BevGrid(5.0, 45.0, -7.0, 7.0, 0.5))   # matplotlib loaded untraced
    fine = BevGrid(5.0, 45.0, -7.0, 7.0, 0.01)                  # 4000 x 1400 pixels: 5.6 M
    assert drawn_grid(fine).shape == (1000, 350) and drawn_grid(fine).res == pytest.approx(0.04)
    for fmt in ("png", "gif"):
        peak = _peak_bytes(lambda: render_preview(_small_preview(2), fmt, fine))  # noqa: B023 (called within this iteration)
        assert peak < 150e6, (fmt, peak / 1e6)                  # was 0.7 GB a panel: the warp's temporaries
    # the largest grid drawn at full size (a square of DRAWN_BEV_PIXELS a side) stays well under 1 GB; the
    # largest grid BevGrid accepts (49.6 M pixels) is drawn coarser, within that square
    square = BevGrid(0.0, DRAWN_BEV_PIXELS * 0.05, -600 * 0.05, 600 * 0.05, 0.05)
    assert drawn_grid(square) == square
    assert max(drawn_grid(BevGrid(5.0, 45.0, -7.0, 7.0, 0.00336)).shape) <= DRAWN_BEV_PIXELS
    peak = _peak_bytes(lambda: render_preview(_small_preview(1), "png", square))
    assert peak < 400e6, peak / 1e6


def test_a_drawn_grid_keeps_the_extent():
    g = BevGrid(5.0, 45.0, -7.0, 7.0, 0.0034)
    d = drawn_grid(g)
    assert (d.x0, d.x1, d.y0, d.y1) == (g.x0, g.x1, g.y0, g.y1)
    assert d.res == pytest.approx(g.res * np.ceil(max(g.shape) / DRAWN_BEV_PIXELS))
    assert drawn_grid(BevGrid(5.0, 45.0, -7.0, 7.0, 0.05)) == BevGrid(5.0, 45.0, -7.0, 7.0, 0.05)   # default: as is


@pytest.fixture
def kitti_images(tmp_path):
    """Two images of KITTI camera 2's size and their times on the example drive's clock."""
    cam = load_camera("kitti_cam2")
    folder = tmp_path / "images"
    folder.mkdir()
    for i in range(2):
        Image.fromarray(render_road(GroundPlane.from_camera(cam), cam.image_size, i)).save(folder / f"{i:06d}.png")
    times = tmp_path / "times.txt"
    times.write_text("10.0\n10.5\n")
    return folder, times


def test_images_without_camera_use_the_documented_default(tmp_path, kitti_images, cli, monkeypatch):
    folder, times = kitti_images
    seen = {}
    real = preview_cli.images_preview

    def spy(images, times_file, camera, *args, **kwargs):
        seen["camera"] = camera.name
        return real(images, times_file, camera, *args, **kwargs)

    monkeypatch.setattr(preview_cli, "images_preview", spy)
    code, stdout, err = cli("preview", EXAMPLE, "--images", folder, "--times", times, "-o", tmp_path / "p.png")
    assert code == 0, err
    assert seen["camera"] == load_camera(preview_cli.DEFAULT_CAMERA).name == load_camera("kitti_cam2").name
    with Image.open(tmp_path / "p.png") as im:
        assert im.format == "PNG"


def test_descending_image_times_are_refused_naming_times(tmp_path, kitti_images, cli, one_error):
    folder, times = kitti_images
    times.write_text("# image times\n10.5\n10.0\n")
    code, _, err = cli("preview", EXAMPLE, "--images", folder, "--times", times, "--camera", "kitti_cam2",
                       "-o", tmp_path / "p.png")
    assert code == 2
    one_error(err, f"{times}:3", "--times")
    assert not (tmp_path / "p.png").exists()


def test_captions_inside_a_gap_say_nan_as_the_csv_does(tmp_path, kitti_images, cli, monkeypatch):
    df = pd.read_csv(EXAMPLE)
    log = tmp_path / "gap.csv"
    df[(df["t"] < 20.0) | (df["t"] >= 30.0)].to_csv(log, index=False)       # a 10 s gap
    folder, times = kitti_images
    times.write_text("25.0\n35.0\n")                                        # inside the gap, after it
    labels = []

    def keep_labels(preview, fmt, grid):
        labels.extend(preview.labels)
        return render_preview(preview, fmt, grid)

    monkeypatch.setattr(preview_cli, "render_preview", keep_labels)
    code, _, err = cli("preview", log, "--images", folder, "--times", times, "--camera", "kitti_cam2",
                       "-o", tmp_path / "p.png")
    assert code == 0, err
    code, _, err = cli("estimate", log, "-o", tmp_path / "g.csv")
    assert code == 0, err
    table = pd.read_csv(tmp_path / "g.csv", comment="#")
    t = table["t"].to_numpy()
    for label, ti in zip(labels, (25.0, 35.0), strict=True):
        row = table.iloc[int(np.argmin(np.abs(t - ti)))]
        if np.isnan(row["pitch_deg"]):
            assert "pitch nan deg, roll nan deg" in label, label
        else:
            assert f"pitch {row['pitch_deg']:+.2f} deg" in label, label
    assert "nan" in labels[0] and "nan" not in labels[1]
