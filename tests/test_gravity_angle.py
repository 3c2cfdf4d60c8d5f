"""gravity_angle (pipeline/input_checks.py): the mean specific force's angle from the extrinsic's up axis.

The all-finite fast path (no copy of the finite rows) gives the same angle, to the bit, as the mean
of the finite rows; rows with NaN or inf are left out; too little force is NaN.
"""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_ground.pipeline.input_checks import gravity_angle


def _reference(a: np.ndarray, up=np.array([0.0, 0.0, 1.0])) -> float:  # noqa: B008 (read-only defaults, never modified)
    a = a[np.all(np.isfinite(a), axis=1)]
    f = a.mean(axis=0)
    return float(np.degrees(np.arccos(np.clip(f @ up / np.linalg.norm(f), -1.0, 1.0))))


@pytest.mark.parametrize("seed", range(3))
def test_the_angle_equals_the_finite_rows_mean(seed):
    rng = np.random.default_rng(seed)
    a = rng.normal(0.0, 2.0, (50_000, 3)) + np.array([0.5, -1.0, 9.7])
    assert gravity_angle(a) == _reference(a)
    assert gravity_angle(np.asfortranarray(a)) == pytest.approx(_reference(a), abs=1e-12)
    bad = a.copy()
    bad[[3, 70, 4000], [0, 2, 1]] = [np.nan, np.inf, -np.inf]
    assert gravity_angle(bad) == _reference(bad) != gravity_angle(a)
    tilt = Rotation.from_euler("x", 20, degrees=True).as_matrix()
    assert gravity_angle(a, tilt) == pytest.approx(_reference(a, tilt[2]), abs=1e-12)


def test_no_force_or_no_finite_row_is_nan():
    assert np.isnan(gravity_angle(np.full((10, 3), np.nan)))
    assert np.isnan(gravity_angle(np.zeros((10, 3))))
    assert np.isnan(gravity_angle(np.zeros((0, 3))))
