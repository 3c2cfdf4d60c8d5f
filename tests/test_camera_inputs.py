"""Camera specs and KITTI raw calibration folders as users give them: every bad one is one line
naming the file and key (or what to type), exit 2; none gives a wrong plane with exit 0."""
from pathlib import Path

import numpy as np
import pytest

from imu_ground.datasets.report import MalformedFileError
from imu_ground.perception import load_camera
from imu_ground.perception.kitti_calib import kitti_rectified_cameras

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"
#: velodyne (x forward, y left, z up) -> camera (x right, y down, z forward)
VELO_TO_CAM = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def _line(key, values):
    return f"{key}: " + " ".join(f"{v:.7e}" for v in np.ravel(values)) + "\n"


def kitti_folder(path: Path, **replace) -> Path:
    """A KITTI raw calibration folder, 7 digits as KITTI writes them; ``replace={file_key: values}`` swaps one entry."""
    path.mkdir(parents=True, exist_ok=True)
    c, s = np.cos(np.radians(0.4)), np.sin(np.radians(0.4))
    rect = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])          # a small rectifying rotation
    entries = {
        "calib_imu_to_velo.txt": {"R": np.eye(3), "T": [-0.81, 0.32, -0.8]},
        "calib_velo_to_cam.txt": {"R": VELO_TO_CAM, "T": [0.0, -0.08, -0.27]},
        "calib_cam_to_cam.txt": {"R_rect_00": rect, **{
            k: v for i in range(4) for k, v in ((f"S_rect_0{i}", [1242, 375]),
                                                (f"P_rect_0{i}", [[721.5, 0, 609.6, -i * 120.0],
                                                                  [0, 721.5, 172.9, 0], [0, 0, 1, 0]]))}},
    }
    for name, keys in entries.items():
        stem = name.removeprefix("calib_").removesuffix(".txt")
        text = "calib_time: 25-May-2012 16:47:16\n"
        for key, value in keys.items():
            text += _line(key, replace.get(f"{stem}_{key}", value))
        (path / name).write_text(text)
    return path


def test_the_synthetic_folder_is_a_valid_one(tmp_path):
    cams = kitti_rectified_cameras(kitti_folder(tmp_path / "day"))
    ext, k, size = cams[2]
    assert size == (1242, 375) and k[0, 0] == 721.5
    # camera 2's optical axis points forward, level within the 0.4 deg rectification
    assert np.degrees(np.arccos(ext.rotation[0, 2])) < 0.5


def _typo(angle_deg=26.0):
    """The velodyne -> camera rotation with one entry mistyped: 26 deg of false roll in one column."""
    r = VELO_TO_CAM.copy()
    r[1, 1] = -np.sin(np.radians(angle_deg))
    return r


@pytest.mark.parametrize("file, key, value", [
    ("calib_velo_to_cam.txt", "R", _typo()),
    ("calib_velo_to_cam.txt", "R", 2 * VELO_TO_CAM),
    ("calib_cam_to_cam.txt", "R_rect_00", 2 * np.eye(3)),
    ("calib_imu_to_velo.txt", "R", np.diag([1.0, 1.0, -1.0])),          # a reflection: det -1
])
def test_a_matrix_that_is_not_a_rotation_is_refused_naming_file_and_key(tmp_path, cli, file, key, value):
    stem = file.removeprefix("calib_").removesuffix(".txt")
    folder = kitti_folder(tmp_path / "day", **{f"{stem}_{key}": value})
    with pytest.raises(MalformedFileError, match="is not a rotation"):
        kitti_rectified_cameras(folder)
    out = tmp_path / "o.csv"
    code, _, err = cli("estimate", EXAMPLE, "--camera", f"{folder}:2", "-o", out)
    assert code == 2 and len(err.strip().splitlines()) == 1 and not out.exists()
    assert f"{folder / file}: '{key}' is not a rotation" in err and "--camera" in err


@pytest.mark.parametrize("damage, words", [
    (lambda d: (d / "calib_velo_to_cam.txt").write_text("R: nan 0 0 0 1 0 0 0 1\nT: 0 0 0\n"),
     ["calib_velo_to_cam.txt: 'R' has a value that is not finite"]),
    (lambda d: (d / "calib_cam_to_cam.txt").write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe" * 20),
     ["calib_cam_to_cam.txt: not a text file"]),
    (lambda d: kitti_folder(d, cam_to_cam_P_rect_02=np.zeros((3, 4))),
     ["calib_cam_to_cam.txt: 'P_rect_02' does not start with intrinsics"]),
])
def test_broken_calibration_files_are_named(tmp_path, cli, damage, words):
    """Were 'SVD did not converge', "'utf-8' codec can't decode", 'Singular matrix' without the file."""
    folder = kitti_folder(tmp_path / "day")
    damage(folder)
    code, _, err = cli("estimate", EXAMPLE, "--camera", f"{folder}:2", "-o", tmp_path / "o.csv")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--camera" in err, err
    for w in words:
        assert w in err, err


@pytest.mark.parametrize("suffix, words", [
    ("", ["needs the camera index", ":2"]),
    (":-1", ["camera index '-1' is not one of", "cameras 0 to 3"]),
    (":abc", ["camera index 'abc' is not one of"]),
    (":4", ["camera index '4' is not one of"]),
])
def test_camera_index_missing_or_invalid_is_said(tmp_path, cli, suffix, words):
    """Were 'camera file not found' though the folder exists."""
    folder = kitti_folder(tmp_path / "day")
    code, _, err = cli("estimate", EXAMPLE, "--camera", f"{folder}{suffix}", "-o", tmp_path / "o.csv")
    assert code == 2 and "not found" not in err and f"--camera {folder}" in err, err
    for w in words:
        assert w in err, err


def test_nan_in_a_camera_files_k_is_said_to_be_not_finite(tmp_path):
    from imu_ground.perception.camera import save_camera
    good = load_camera("kitti_cam2")
    path = tmp_path / "cam.txt"
    save_camera(good, path)
    text = path.read_text()
    k_line = next(ln for ln in text.splitlines() if ln.startswith("K:"))
    path.write_text(text.replace(k_line, "K: nan 0 609 0 721 172 0 0 1"))
    with pytest.raises(ValueError) as e:
        load_camera(path)
    assert str(path) in str(e.value) and "not finite" in str(e.value) and "shape" not in str(e.value)
