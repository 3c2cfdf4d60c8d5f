"""Baselines: the constant normal and the Euler-angle EKF on filterpy."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_ground import so3
from imu_ground.evaluation.baselines import ConstantNormal, EulerEKF, euler_zyx, from_euler_zyx
from imu_ground.filters.extrinsics import load_extrinsic
from imu_ground.filters.ground import GroundNormalFilter


def _drive(n=400, yaw_rate=0.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n + 1) * 0.1
    pitch = np.radians(0.8) * np.sin(2 * np.pi * 0.9 * t) + np.radians(0.3) * rng.normal(size=t.size) * 0.1
    roll = np.radians(0.5) * np.sin(2 * np.pi * 0.7 * t + 1.0)
    R = so3.rotz(yaw_rate * t) @ so3.roty(pitch) @ so3.rotx(roll)
    return np.swapaxes(R[:-1], 1, 2) @ R[1:], pitch[1:], roll[1:]


def test_euler_convention_matches_scipy():
    e = np.array([[0.1, -0.2, 2.9], [-0.3, 0.05, -3.1], [0.0, 0.0, 0.0]])
    ref = Rotation.from_euler("ZYX", e[:, ::-1]).as_matrix()        # yaw, pitch, roll intrinsic
    assert np.allclose(from_euler_zyx(e), ref)
    assert np.allclose(euler_zyx(ref), e)


def test_constant_normal_is_the_static_normal():
    cam = load_extrinsic("kitti_cam0")
    d, _, _ = _drive(50)
    d_cam = cam.rotation.T @ d @ cam.rotation
    tr = ConstantNormal(cam).run(d_cam)
    assert np.allclose(tr.normal, cam.normal) and np.allclose(tr.pitch, 0) and np.allclose(tr.roll, 0)
    assert len(tr) == 50


def test_euler_ekf_agrees_with_the_invariant_filter_to_first_order():
    d, pitch, roll = _drive()
    e = EulerEKF(Q=1e-2, R=1.0, follow_heading=False).run(d)
    i = GroundNormalFilter.paper().run(d)
    # same model, same noise: the estimates differ at second order in the small angles
    assert np.degrees(np.abs(e.pitch - i.pitch)).max() < 0.01
    assert np.degrees(np.abs(e.roll - i.roll)).max() < 0.01
    # and both follow the body wobble far better than a constant normal
    assert np.abs(e.pitch - pitch)[50:].mean() < 0.5 * np.abs(pitch)[50:].mean()


@pytest.mark.parametrize("follow_heading", [True, False])
def test_euler_ekf_through_two_full_turns(follow_heading):
    """Yaw wraps through +-pi twice: the wrapped innovation keeps the residual bounded."""
    d, pitch, _ = _drive(n=480, yaw_rate=np.radians(15.0))       # 720 deg in 48 s
    tr = EulerEKF(follow_heading=follow_heading).run(d)
    yaw_left = np.degrees(np.abs(np.arctan2(tr.residual[:, 1, 0], tr.residual[:, 0, 0])))
    assert yaw_left.max() < (0.1 if follow_heading else 20.0)
    assert np.degrees(np.abs(tr.pitch - pitch))[50:].mean() < 0.3
    assert np.all(np.isfinite(tr.P)) and np.all(np.linalg.eigvalsh(tr.P) > 0)
