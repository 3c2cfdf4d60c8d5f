"""InvariantEKF against filterpy's linear Kalman filter, chi-square consistency, long runs."""
import numpy as np
import pytest
from filterpy.common import Saver
from filterpy.kalman import KalmanFilter, rts_smoother as kf_rts
from scipy.stats import chi2

from imu_ground import so3
from imu_ground.filters.invariant_ekf import InvariantEKF
from imu_ground.units import RENORM_EVERY


def test_defaults_are_the_papers():
    f = InvariantEKF()
    assert np.array_equal(f.x, np.eye(3))
    assert np.array_equal(f.Q, 1e-2 * np.eye(3))
    assert np.array_equal(f.R, np.eye(3))
    assert np.array_equal(f.P, np.eye(3))


def test_filterpy_saver_records_every_attribute():
    f = InvariantEKF(P=0.1, Q=1e-3, R=1e-2)
    s = Saver(f)
    rng = np.random.default_rng(0)
    for _ in range(10):
        f.predict(rng.normal(scale=0.01, size=3))
        f.update(so3.exp(rng.normal(scale=0.1, size=3)))
        s.save()
    s.to_array()
    for key in ("x", "P", "Q", "R", "x_prior", "P_prior", "x_post", "P_post", "y", "K", "S", "SI",
                "log_likelihood", "likelihood", "mahalanobis"):
        assert len(s[key]) == 10, key
    assert s.x.shape == (10, 3, 3) and s.K.shape == (10, 3, 3)
    assert np.all(np.isfinite(s.log_likelihood)) and np.all(s.mahalanobis >= 0)


def test_likelihood_and_mahalanobis_match_scipy():
    from scipy.stats import multivariate_normal
    f = InvariantEKF(P=0.2, Q=0.0, R=0.1)
    f.predict()
    f.update(so3.exp([0.1, -0.2, 0.05]))
    assert f.log_likelihood == pytest.approx(multivariate_normal(np.zeros(3), f.S).logpdf(f.y))
    assert f.mahalanobis == pytest.approx(np.sqrt(f.y @ np.linalg.inv(f.S) @ f.y))


@pytest.mark.parametrize("error", ["left", "right"])
def test_small_angles_agree_with_linear_kalman_filter(error):
    """For small rotations the IEKF is a linear KF on the rotation vector, to first order."""
    rng = np.random.default_rng(1)
    Q, R, P0 = 1e-8, 1e-6, 1e-6
    truth = np.array([1e-3, -2e-3, 5e-4])
    f = InvariantEKF(P=P0, Q=Q, R=R, error=error)
    kf = KalmanFilter(dim_x=3, dim_z=3)
    kf.x = np.zeros(3)
    kf.P *= P0
    kf.Q *= Q
    kf.R *= R
    kf.F = np.eye(3)
    kf.H = np.eye(3)
    for _ in range(50):
        z = truth + rng.normal(scale=1e-3, size=3)
        f.predict()
        f.update(so3.exp(z))
        kf.predict()
        kf.update(z)
        # covariance recursion is identical; the state differs at second order (~angle^2)
        assert np.allclose(f.P, kf.P, rtol=1e-9)
        assert np.allclose(so3.log(f.x), kf.x, atol=2e-7)
    assert np.allclose(f.K, kf.K, rtol=1e-9)


def _nees_runs(measure, runs=400, steps=15, seed=7, error="left"):
    rng = np.random.default_rng(seed)
    P0, R = 0.1 ** 2, 0.05 ** 2
    nees = np.zeros((runs, steps))
    for m in range(runs):
        X = so3.exp(rng.normal(size=3))
        xi0 = rng.normal(scale=0.1, size=3)
        f = InvariantEKF(x=X @ so3.exp(-xi0), P=P0, Q=1e-12, R=R, error=error)
        for k in range(steps):
            f.predict()
            if measure == "rotation":
                z = X @ so3.exp(rng.normal(scale=0.05, size=3))
            else:
                z = X @ np.array([0.0, 0.0, 1.0]) + rng.normal(scale=0.05, size=3)
            f.update(z)
            err = so3.log(f.x.T @ X) if error == "left" else so3.log(X @ f.x.T)
            nees[m, k] = err @ np.linalg.solve(f.P, err)
    return nees


@pytest.mark.parametrize("measure, error", [("rotation", "left"), ("up", "left"), ("rotation", "right")])
def test_nees_is_chi_square_consistent(measure, error):
    runs = 400
    nees = _nees_runs(measure, runs=runs, error=error)
    lo, hi = chi2.ppf([0.0005, 0.9995], 3 * runs) / runs
    mean = nees.mean(axis=0)
    # at most one of the 15 steps outside the 99.9% band, and the overall mean near 3
    assert np.sum((mean < lo) | (mean > hi)) <= 1, mean
    assert 2.7 < mean.mean() < 3.3


def test_direction_measurement_observes_tilt_not_yaw():
    f = InvariantEKF(P=0.1, Q=0.0, R=1e-4)
    tilt = so3.rotx(0.05)
    for _ in range(200):
        f.predict()
        f.update(tilt @ np.array([0.0, 0.0, 1.0]))
    assert np.allclose(f.x @ [0, 0, 1.0], tilt @ [0, 0, 1.0], atol=1e-6)
    assert f.P[2, 2] == pytest.approx(0.1)          # yaw untouched
    assert f.P[0, 0] < 1e-3


def test_batch_filter_matches_sequential_and_rts_matches_filterpy():
    rng = np.random.default_rng(3)
    n = 60
    us = so3.exp(rng.normal(scale=1e-4, size=(n, 3)))
    truth = np.cumsum(rng.normal(scale=1e-4, size=(n, 3)), axis=0)
    zs = so3.exp(truth + rng.normal(scale=1e-3, size=(n, 3)))
    f1 = InvariantEKF(P=1e-4, Q=1e-8, R=1e-6)
    Xs, Ps, Xp, Pp = f1.batch_filter(zs, us=us)
    f2 = InvariantEKF(P=1e-4, Q=1e-8, R=1e-6)
    for k in range(n):
        f2.predict(us[k])
        assert np.allclose(f2.x, Xp[k]) and np.allclose(f2.P, Pp[k])
        f2.update(zs[k])
        assert np.array_equal(f2.x, Xs[k]) and np.array_equal(f2.P, Ps[k])
    Xsm, Psm, Cs, _ = f1.rts_smoother(Xs, Ps, us=us)
    # linear reference: small increments enter as F = I with a known input (first order)
    kf = KalmanFilter(dim_x=3, dim_z=3)
    kf.P *= 1e-4
    kf.Q *= 1e-8
    kf.R *= 1e-6
    kf.F = np.eye(3)
    kf.H = np.eye(3)
    means, covs = [], []
    cum = np.zeros(3)
    for k in range(n):
        cum = cum + so3.log(us[k])
        kf.predict()
        kf.update(so3.log(zs[k]) - cum)
        means.append(kf.x.ravel().copy())
        covs.append(kf.P.copy())
    ms, Pss, _, _ = kf_rts(np.array(means), np.array(covs), [np.eye(3)] * n, [kf.Q] * n)
    cums = np.cumsum(so3.log(us), axis=0)
    assert np.allclose(Psm, Pss, rtol=1e-6, atol=1e-15)
    # second-order (BCH) differences ~1e-7, against a smoothing correction of ~1e-3
    assert np.allclose(so3.log(Xsm), ms + cums, atol=5e-7)
    assert np.abs(so3.log(Xsm) - so3.log(Xs)).max() > 1e-4
    # smoothing never increases the uncertainty
    assert np.all(np.trace(Psm, axis1=1, axis2=2) <= np.trace(Ps, axis1=1, axis2=2) + 1e-15)


def test_hours_of_steps_stay_orthonormal_and_positive_definite():
    """200,000 predict/update pairs (5.5 h of 10 Hz frames, over 3,000 renormalisations), both measurements."""
    rng = np.random.default_rng(11)
    us = so3.exp(rng.normal(scale=0.05, size=(1000, 3)))
    zs_rot = so3.exp(rng.normal(scale=1.0, size=(1000, 3)))
    zs_dir = rng.normal(size=(1000, 3))
    zs_dir /= np.linalg.norm(zs_dir, axis=1, keepdims=True)
    f = InvariantEKF(P=1.0, Q=np.diag([1e-2, 2e-2, 5e-3]), R=np.diag([1.0, 0.5, 2.0]))
    predict, update = f.predict, f.update
    worst_sym = worst_orth = 0.0
    for k in range(200_000):
        j = k % 1000
        predict(us[j])
        update(zs_rot[j] if k % 2 else zs_dir[j])
        if k % 10_000 == 9_999:
            worst_orth = max(worst_orth, np.abs(f.x.T @ f.x - np.eye(3)).max())
            worst_sym = max(worst_sym, np.abs(f.P - f.P.T).max())
            assert np.linalg.eigvalsh(f.P).min() > 0
    assert f._updates == 200_000 and f._updates // RENORM_EVERY > 3000
    assert worst_orth < 1e-13
    assert worst_sym == 0.0
    assert np.linalg.det(f.x) == pytest.approx(1.0, abs=1e-13)


def _reference_step(x, P, u, z, Q, R, error, b=np.array([0.0, 0.0, 1.0])):  # noqa: B008 (read-only defaults, never modified)
    """The module's equations in numpy, Joseph form throughout (an independent reference)."""
    x = x @ u
    if error == "left":
        P = u.T @ P @ u + Q
    else:
        P = P + x @ Q @ x.T
    if z.shape == (3, 3):
        y = so3.log(x.T @ z) if error == "left" else so3.log(z @ x.T)
        H, Rn = np.eye(3), (R if error == "left" else x @ R @ x.T)
    elif error == "left":
        y, H, Rn = x.T @ z - b, -so3.hat(b), x.T @ R @ x
    else:
        y, H, Rn = z - x @ b, -so3.hat(x @ b), R
    S = H @ P @ H.T + Rn
    K = P @ H.T @ np.linalg.inv(S)
    x = x @ so3.exp(K @ y) if error == "left" else so3.exp(K @ y) @ x
    IKH = np.eye(3) - K @ H
    return x, IKH @ P @ IKH.T + K @ Rn @ K.T, y, K, S


@pytest.mark.parametrize("error", ["left", "right"])
@pytest.mark.parametrize("measure", ["rotation", "direction"])
def test_scalar_kernels_match_the_numpy_equations(error, measure):
    rng = np.random.default_rng(4)
    Q, R = np.diag([1e-2, 2e-2, 5e-3]), np.array([[1.0, 0.1, 0.0], [0.1, 0.5, 0.05], [0.0, 0.05, 2.0]])
    f = InvariantEKF(x=so3.exp([0.3, -0.2, 1.0]), P=np.diag([0.5, 0.3, 0.2]), Q=Q, R=R, error=error)
    x, P = f.x.copy(), f.P.copy()
    for _ in range(RENORM_EVERY - 1):                  # before the first renormalisation
        u = so3.exp(rng.normal(scale=0.05, size=3))
        z = so3.exp(rng.normal(scale=0.5, size=3)) if measure == "rotation" else \
            so3.exp(rng.normal(scale=0.2, size=3)) @ np.array([0.0, 0.0, 1.0])
        x, P, y, K, S = _reference_step(x, P, u, z, Q, R, error)
        f.predict(u)
        f.update(z)
        np.testing.assert_allclose(f.x, x, atol=1e-12)
        np.testing.assert_allclose(f.P, P, rtol=1e-10, atol=1e-14)
        np.testing.assert_allclose(f.y, y, atol=1e-12)
        np.testing.assert_allclose(f.K, K, rtol=1e-10, atol=1e-13)
        np.testing.assert_allclose(f.S, S, rtol=1e-12)
        np.testing.assert_allclose(f.SI, np.linalg.inv(S), rtol=1e-10)
        assert np.array_equal(f.P, f.P.T)
        np.testing.assert_allclose(f.z, z)


@pytest.mark.parametrize("angle", [1e-9, 1e-5, 0.5, 3.0, np.pi - 1e-6])
def test_rotation_innovation_is_the_logarithm_over_the_whole_range(angle):
    X = so3.exp([0.3, -1.0, 2.0])
    f = InvariantEKF(x=X, P=1e-3, Q=0.0, R=1.0)
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    f.predict()
    f.update(X @ so3.exp(angle * axis))
    np.testing.assert_allclose(f.y, so3.log(so3.exp(angle * axis)), rtol=1e-9, atol=1e-15)


def test_filterpy_assignments_and_in_place_changes_are_seen():
    a, b = InvariantEKF(P=0.5, R=0.2), InvariantEKF(P=0.5, R=0.2)
    u, z = so3.exp([0.01, 0.02, 0.1]), so3.exp([0.2, -0.1, 0.3])
    a.P *= 2.0                                         # filterpy idiom: in place on the handed-out array
    b.P = 2.0 * np.eye(3) * 0.5
    a.Q[2, 2] = 0.5
    b.Q = np.diag([1e-2, 1e-2, 0.5])
    a.x[:] = so3.rotx(0.1)
    b.x = so3.rotx(0.1)
    for f in (a, b):
        f.predict(u)
        f.update(z)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.P, b.P)
    np.testing.assert_array_equal(a.x_prior, b.x_prior)
    assert a.P is a.P and a.x_post is not a.x_post      # state cached, snapshots fresh copies
    a.update(None)                                      # skipped update: filterpy's convention
    assert a.z is None and np.array_equal(a.y, np.zeros(3)) and np.array_equal(a.x_post, a.x)
    with pytest.raises(ValueError, match="P must be a 3x3 matrix"):
        a.P = np.eye(2)


def test_matches_gtsam_invariant_ekf_rot3():
    """GTSAM's InvariantEKFRot3 (left-invariant, X <- X U, P <- Ad_{U^-1} P Ad^T + Q, Joseph update,
    retract X Exp(dx); its covariance reset after the update turned off: ours, like filterpy's, has none)."""
    gtsam = pytest.importorskip("gtsam")
    rng = np.random.default_rng(9)
    Q, R = np.diag([1e-2, 2e-2, 5e-3]), np.diag([1.0, 0.5, 2.0])
    for measure in ("rotation", "direction"):
        f = InvariantEKF(P=1.0, Q=Q, R=R)
        g = gtsam.InvariantEKFRot3(gtsam.Rot3(), np.eye(3))
        ez = np.array([0.0, 0.0, 1.0])
        for _ in range(200):
            u = so3.exp(rng.normal(scale=0.05, size=3))
            f.predict(u)
            g.predict(gtsam.Rot3(u), Q)
            X = g.state().matrix()
            if measure == "rotation":
                z = so3.exp(rng.normal(scale=0.3, size=3))
                f.update(z)
                g.updateWithVector(np.zeros(3), np.eye(3), gtsam.Rot3.Logmap(gtsam.Rot3(X.T @ z)), R, False)
            else:
                z = so3.exp(rng.normal(scale=0.1, size=3)) @ ez
                f.update(z)
                g.updateWithVector(ez, -so3.hat(ez), X.T @ z, X.T @ R @ X, False)
            np.testing.assert_allclose(f.x, g.state().matrix(), atol=1e-12)
            np.testing.assert_allclose(f.P, g.covariance(), atol=1e-12)


def test_bad_inputs_are_named():
    f = InvariantEKF()
    with pytest.raises(ValueError, match="z must be a 3x3 rotation or a unit vector"):
        f.update(np.zeros(4))
    with pytest.raises(ValueError, match="rotation increment"):
        f.predict(np.zeros(2))
    with pytest.raises(ValueError, match="error must be"):
        InvariantEKF(error="middle")
    with pytest.raises(ValueError, match="Q must be"):
        InvariantEKF(Q=np.zeros((2, 2)))


def test_copies_and_pickles_continue_identically():
    """The state buffer is copied with the filter: copies go on alone, equal."""
    import copy
    import pickle
    f = InvariantEKF(P=0.3, Q=np.diag([1e-2, 2e-2, 5e-3]), R=0.5, error="right")
    f.predict(so3.rotz(0.2))
    f.update(so3.exp([0.1, -0.2, 0.3]))
    _ = f.P, f.x                                        # arrays handed out: part of what is copied
    g, h = copy.deepcopy(f), pickle.loads(pickle.dumps(f))
    for e in (f, g, h):
        e.predict(so3.rotx(0.1))
        e.update(np.array([0.0, 0.6, 0.8]))
    g.update(so3.roty(0.3))                              # g alone moves on
    assert np.array_equal(f.P, h.P) and np.array_equal(f.x, h.x) and np.array_equal(f.K, h.K)
    assert not np.array_equal(f.P, g.P)


@pytest.mark.parametrize("error", ["left", "right"])
@pytest.mark.parametrize("z", [so3.exp([0.1, 0.2, 0.3]), np.array([0.0, 0.6, 0.8])])
def test_singular_innovation_raises_and_leaves_the_state_unchanged(error, z):
    f = InvariantEKF(P=0.0, Q=0.0, R=0.0, error=error)
    f.predict(so3.rotx(0.1))
    _ = f.x                                             # (the rotation matrix cached: what a direction update reads)
    before = f.kernel_state()
    with pytest.raises(np.linalg.LinAlgError, match=r"innovation covariance is singular \(det = 0\.0\)"):
        f.update(z)
    assert np.array_equal(np.array(f.kernel_state()), np.array(before), equal_nan=True)


@pytest.mark.parametrize("error", ["left", "right"])
def test_every_argument_form_gives_the_float64_result(error):
    """Lists, ints, float32, Fortran order and scalars are taken as the float64 arrays they stand for."""
    kw = dict(x=so3.exp([0.3, -0.2, 1.0]), P=0.4, Q=np.diag([1e-2, 2e-2, 5e-3]), R=np.diag([1.0, 0.5, 2.0]),
              error=error)
    f, g = InvariantEKF(**kw), InvariantEKF(**kw)
    u, z, d = so3.rotz(0.4), so3.exp([0.2, 0.1, -0.3]), np.array([0.0, 0.6, 0.8])
    f.predict(u.tolist(), Q=1e-3)
    g.predict(u, Q=1e-3 * np.eye(3))
    f.update(np.asfortranarray(z), R=np.asfortranarray(0.5 * np.eye(3)))
    g.update(z, R=0.5)
    f.predict([0.01, 0.02, 0.03])
    g.predict(np.array([0.01, 0.02, 0.03]))
    f.update(np.eye(3, dtype=int))
    g.update(np.eye(3))
    f.update(d.astype(np.float32))
    g.update(d.astype(np.float32).astype(float))
    f.update(None)
    g.update(None)
    assert np.array_equal(np.array(f.kernel_state()), np.array(g.kernel_state()), equal_nan=True)


def test_no_leaks_over_many_calls():
    """1e5 predict/update pairs allocate nothing that stays; the inputs' refcounts are unchanged."""
    import gc
    import sys
    import tracemalloc
    f = InvariantEKF(P=1.0, Q=np.diag([1e-2, 2e-2, 5e-3]), R=0.5)
    u, zr, zd = so3.exp([0.01, -0.02, 0.03]), so3.exp([0.1, 0.2, -0.1]), np.array([0.0, 0.6, 0.8])
    refs = [sys.getrefcount(o) for o in (u, zr, zd, f._s)]
    predict, update = f.predict, f.update
    for k in range(2000):
        predict(u)
        update(zr if k % 2 else zd)
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    for k in range(100_000):
        predict(u)
        update(zr if k % 2 else zd)
    gc.collect()
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    assert grown < 16 * 1024, grown
    assert [sys.getrefcount(o) for o in (u, zr, zd, f._s)] == refs
    assert np.array_equal(f.P, f.P.T) and np.isfinite(f.kernel_state()[97])
