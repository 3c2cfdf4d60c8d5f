"""SO(3) toolkit against scipy's Rotation and finite differences."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from imu_ground import so3

ANGLES = [0.0, 1e-12, 1e-9, 1e-6, 1e-4, 0.3, 1.5, 3.0, np.pi - 1e-3, np.pi - 1e-6]


def _axes(n, seed=0):
    a = np.random.default_rng(seed).normal(size=(n, 3))
    return a / np.linalg.norm(a, axis=1, keepdims=True)


def _phis():
    ax = _axes(len(ANGLES))
    return np.array(ANGLES)[:, None] * ax


def test_hat_vee():
    a, b = np.random.default_rng(1).normal(size=(2, 50, 3))
    assert np.allclose(so3.hat(a) @ b[..., None], np.cross(a, b)[..., None])
    assert np.allclose(so3.vee(so3.hat(a)), a)
    assert so3.hat(a[0]).shape == (3, 3)


def test_exp_matches_scipy_batch_and_single():
    phi = _phis()
    ref = Rotation.from_rotvec(phi).as_matrix()
    assert np.abs(so3.exp(phi) - ref).max() < 1e-15
    for p, r in zip(phi, ref, strict=True):
        assert np.abs(so3.exp(p) - r).max() < 1e-15
        assert np.abs(so3.exp_one(p) - r).max() < 1e-15


def test_log_matches_scipy_near_zero_and_pi():
    phi = _phis()
    r = Rotation.from_rotvec(phi).as_matrix()
    out = so3.log(r)
    # exact angles down to 1e-12 rad (relative) and up to pi - 1e-6
    assert np.allclose(out, phi, rtol=1e-9, atol=1e-15)
    for k, th in enumerate(ANGLES):
        assert np.linalg.norm(out[k]) == pytest.approx(th, rel=1e-9, abs=1e-15)
        assert np.allclose(so3.log_one(r[k]), out[k], rtol=1e-12, atol=1e-15)
    assert np.allclose(out, Rotation.from_matrix(r).as_rotvec(), rtol=1e-8, atol=1e-15)


def test_log_at_exactly_pi_either_sign():
    u = _axes(5, 3)
    r = so3.exp(np.pi * u)
    out = so3.log(r)
    assert np.allclose(np.linalg.norm(out, axis=1), np.pi)
    assert np.allclose(np.abs(np.sum(out * u, axis=1)), np.pi)
    assert np.allclose(so3.exp(out), r, atol=1e-14)


def test_batch_shapes():
    phi = np.random.default_rng(2).normal(size=(4, 5, 3))
    assert so3.exp(phi).shape == (4, 5, 3, 3)
    assert so3.log(so3.exp(phi)).shape == (4, 5, 3)
    assert so3.right_jacobian(phi).shape == (4, 5, 3, 3)


@pytest.mark.parametrize("th", [1e-9, 1e-5, 0.2, 1.3, 2.8, np.pi - 1e-3])
def test_jacobians_by_finite_differences(th):
    phi = th * _axes(1, 5)[0]
    eps = 1e-7
    Jr = so3.right_jacobian(phi)
    Jl = so3.left_jacobian(phi)
    R = so3.exp(phi)
    for i in range(3):
        d = np.zeros(3)
        d[i] = eps
        Rp, Rm = so3.exp(phi + d), so3.exp(phi - d)
        col_r = (so3.log(R.T @ Rp) - so3.log(R.T @ Rm)) / (2 * eps)
        col_l = (so3.log(Rp @ R.T) - so3.log(Rm @ R.T)) / (2 * eps)
        assert np.allclose(Jr[:, i], col_r, atol=1e-7)
        assert np.allclose(Jl[:, i], col_l, atol=1e-7)
    assert np.allclose(Jl, R @ Jr, atol=1e-12)          # J_l = R J_r
    assert np.allclose(so3.right_jacobian_inv(phi) @ Jr, np.eye(3), atol=1e-10)
    assert np.allclose(so3.left_jacobian_inv(phi) @ Jl, np.eye(3), atol=1e-10)


def test_jacobian_inverse_batch():
    phi = _phis()[:-1]
    prod = so3.right_jacobian_inv(phi) @ so3.right_jacobian(phi)
    assert np.allclose(prod, np.eye(3), atol=1e-9)


def test_project_restores_rotation():
    rng = np.random.default_rng(4)
    r = Rotation.random(100, random_state=5).as_matrix()
    noisy = r + 1e-4 * rng.normal(size=r.shape)
    p = so3.project(noisy)
    assert np.allclose(np.swapaxes(p, 1, 2) @ p, np.eye(3), atol=1e-13)
    assert np.allclose(np.linalg.det(p), 1.0)
    assert np.abs(p - r).max() < 1e-3
    assert np.allclose(so3.project(r), r, atol=1e-14)       # idempotent on rotations
    # a reflection is turned into the nearest proper rotation
    assert np.linalg.det(so3.project(np.diag([1.0, 1.0, -1.0]))) == pytest.approx(1.0)


def test_axis_rotations_match_scipy_and_convention():
    for f, ax in ((so3.rotx, "x"), (so3.roty, "y"), (so3.rotz, "z")):
        assert np.allclose(f(0.4), Rotation.from_euler(ax, 0.4).as_matrix())
    # KITTI: positive pitch is nose down
    assert (so3.roty(0.1) @ np.array([1.0, 0, 0]))[2] < 0


def test_flat_kernels_match_the_batch_functions():
    rng = np.random.default_rng(3)
    phi = np.vstack([_phis(), rng.normal(size=(20, 3))])
    for p in phi:
        R = so3.exp(p)
        np.testing.assert_allclose(np.reshape(so3.exp_flat(*p), (3, 3)), R, atol=1e-15)
        np.testing.assert_allclose(so3.log_flat(R.ravel()), so3.log(R), atol=1e-12)
        np.testing.assert_allclose(so3.exp_one(p), R, atol=1e-15)
        np.testing.assert_allclose(so3.log_one(R), so3.log(R), atol=1e-12)
        np.testing.assert_allclose(so3.log_one(R.tolist()), so3.log(R), atol=1e-12)    # nested lists too
    A, B = rng.normal(size=(2, 3, 3))
    a, b = A.ravel().tolist(), B.ravel().tolist()
    np.testing.assert_allclose(np.reshape(so3.mul_flat(a, b), (3, 3)), A @ B, atol=1e-15)
    np.testing.assert_allclose(np.reshape(so3.mul_nt_flat(a, b), (3, 3)), A @ B.T, atol=1e-15)


def test_renormalise_pulls_drifted_rotations_back():
    R = so3.exp(np.random.default_rng(2).normal(size=(5, 3)))
    drifted = R + 1e-9 * np.random.default_rng(3).normal(size=R.shape)
    fixed = so3.renormalise(drifted)
    err = lambda M: np.abs(np.swapaxes(M, -1, -2) @ M - np.eye(3)).max()   # noqa: E731
    assert err(drifted) > 1e-10 and err(fixed) < 1e-14
    np.testing.assert_allclose(fixed, so3.project(drifted), atol=1e-13)
    for k in range(5):
        np.testing.assert_allclose(np.reshape(so3.renormalise_flat(drifted[k].ravel()), (3, 3)), fixed[k],
                                   atol=1e-15)


def test_glossary_states_the_conventions_every_module_references():
    doc = so3.__doc__
    for phrase in ("R_{a<-b}", "v_a = R_{a<-b} @ v_b", "R_{a<-c} = R_{a<-b} @ R_{b<-c}",
                   "delta_R_k = R_{body_{k-1}<-body_k}", "R_gs = R_{ground<-sensor}", "nose down",
                   "left side", "FLU"):
        assert phrase in doc, phrase


def test_so3_imports_no_scipy():
    import subprocess
    import sys
    code = "import sys, imu_ground.so3; sys.exit('scipy' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_quaternion_helpers_round_trip_over_the_whole_range():
    R = so3.exp(_phis())
    R = np.concatenate([R, Rotation.random(200, random_state=4).as_matrix(), so3.rotx(np.array([np.pi])),
                        so3.roty(np.array([np.pi])), so3.rotz(np.array([-np.pi]))])
    for M in R:
        q = so3.quat_from_flat(M.ravel().tolist())
        assert q[0] >= 0.0 and abs(np.linalg.norm(q) - 1.0) < 1e-15
        np.testing.assert_allclose(np.reshape(so3.flat_from_quat(q), (3, 3)), M, atol=2e-15)
    a, b = Rotation.random(2, random_state=5).as_matrix()
    qab = so3.quat_mul(so3.quat_from_flat(a.ravel()), so3.quat_from_flat(b.ravel()))
    np.testing.assert_allclose(np.reshape(so3.flat_from_quat(qab), (3, 3)), a @ b, atol=1e-15)
    for p in _phis():
        np.testing.assert_allclose(np.reshape(so3.flat_from_quat(so3.quat_exp(*p)), (3, 3)), so3.exp(p), atol=1e-15)
    np.testing.assert_allclose(so3.quat_normalise((2.0, 0.0, 0.0, 0.0)), (1.0, 0.0, 0.0, 0.0))
    np.testing.assert_allclose(np.reshape(so3.hat_flat(1.0, 2.0, 3.0), (3, 3)), so3.hat([1.0, 2.0, 3.0]))
