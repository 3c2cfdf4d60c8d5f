"""The same simulated road driven a second time (imu_ground.evaluation.simulate.second_pass)."""
import numpy as np
import pytest

from imu_ground.evaluation.simulate import remounted, second_pass, simulate
from scipy.spatial.transform import Rotation


@pytest.fixture(scope="module")
def first():
    return simulate(40.0, seed=4, imu="mems", name="d4")


def test_the_same_manoeuvre_with_the_same_noise_is_the_first_pass(first):
    again = second_pass(first, noise_seed=first.seed)
    assert again.name == "d4_second_pass"
    np.testing.assert_array_equal(again.imu.gyro, first.imu.gyro)
    np.testing.assert_array_equal(again.imu.accel, first.imu.accel)
    np.testing.assert_array_equal(again.truth.to_numpy(float), first.truth.to_numpy(float))


def test_faster_pass_is_at_the_same_place_on_the_same_road(first):
    k = 1.25
    fast = second_pass(first, speed_scale=k)
    assert fast.imu.duration == pytest.approx(first.imu.duration / k)
    # frame 4 j of the fast pass (t = 0.4 j) is where frame 5 j of the first (t = 0.5 j) was
    a = first.truth.iloc[::5].reset_index(drop=True)
    b = fast.truth.iloc[::4].reset_index(drop=True)
    m = min(len(a), len(b))
    a, b = a.iloc[:m], b.iloc[:m]
    for col in ("s", "road_grade", "road_bank", "heading", "curvature"):
        np.testing.assert_allclose(b[col], a[col], rtol=0, atol=1e-9, err_msg=col)
    np.testing.assert_allclose(b[["x", "y"]], a[["x", "y"]], rtol=0, atol=0.02)      # (integrated on other grids)
    np.testing.assert_allclose(b["speed"], k * a["speed"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b["acc_long"], k * k * a["acc_long"], rtol=1e-9, atol=1e-12)
    # the same sensor: its bias path, its own white noise
    n = len(fast.imu.t)
    np.testing.assert_array_equal(fast.bias_gyro, first.bias_gyro[:n])
    np.testing.assert_array_equal(fast.bias_accel, first.bias_accel[:n])
    noise = fast.imu.gyro - fast.imu_clean.gyro - fast.bias_gyro
    noise_first = first.imu.gyro[:n] - first.imu_clean.gyro[:n] - first.bias_gyro[:n]
    assert abs(np.corrcoef(noise[:, 0], noise_first[:, 0])[0, 1]) < 0.05
    assert noise.std() == pytest.approx(noise_first.std(), rel=0.05)


def test_new_speed_profile_covers_the_first_pass_road(first):
    other = second_pass(first, speed_seed=77)
    s1, s2 = first.truth["s"].to_numpy(), other.truth["s"].to_numpy()
    assert s2[-1] >= s1[-1] - 1e-9 or other.imu.duration == pytest.approx(first.imu.duration)
    assert s2[-1] <= s1[-1] + 0.1 * other.truth["speed"].max() + 1e-9        # stops on the frame past the end
    on = s2 <= s1[-1]
    v1 = np.interp(s2[on], s1, first.truth["speed"].to_numpy())
    assert np.abs(other.truth["speed"].to_numpy()[on] - v1).mean() > 0.5       # another profile
    # the road is a function of s: the grade at the same s, up to interpolating between frames
    g1 = np.interp(s2[on], s1, first.truth["road_grade"].to_numpy())
    assert np.abs(other.truth["road_grade"].to_numpy()[on] - g1).max() < 1e-3


def test_refuses_what_it_cannot_drive_again(first):
    moved = remounted(first, 20.0, Rotation.from_euler("y", 1.0, degrees=True).as_matrix())
    with pytest.raises(ValueError, match="second_pass needs a drive from simulate"):
        second_pass(moved)
    with pytest.raises(ValueError, match="speed_scale must be > 0"):
        second_pass(first, speed_scale=0.0)
