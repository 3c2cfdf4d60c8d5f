"""Tests of imu_ground.imu.preintegration: closed forms, Forster's recursion, finite
differences, Monte Carlo, batch == streaming, boundary splitting, gaps, and the
KITTI attitude check."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.imu.data import ImuData
from imu_ground.imu.preintegration import (
    FrameDeltas,
    PreintegratedImu,
    PreintegrationParams,
    StreamingPreintegrator,
    make_frame_times,
    preintegrate,
)

SG, SA = 0.01, 0.1          # noise densities used in the comparisons


# ---------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------
def random_log(n=600, seed=0, dt=0.01, jitter=0.2):
    rng = np.random.default_rng(seed)
    t = np.cumsum(dt * (1 + jitter * rng.uniform(-1, 1, n)))
    t -= t[0]
    tt = t[:, None]
    gyro = 0.6 * np.sin(tt * [1.3, 0.7, 2.1] + [0.1, 0.5, 1.0]) + rng.normal(0, 0.05, (n, 3))
    accel = 2.0 * np.cos(tt * [0.9, 1.7, 0.4]) + [0.3, -0.2, 9.8] + rng.normal(0, 0.2, (n, 3))
    return t, gyro, accel


def stream(t, gyro, accel, **kw) -> list[PreintegratedImu]:
    sp = StreamingPreintegrator(**kw)
    out = []
    for i in range(len(t)):
        out += sp.push(t[i], gyro[i].tolist(), accel[i].tolist())
    return out


def assert_same(frames: list[PreintegratedImu], fd: FrameDeltas, tol=1e-12):
    assert len(frames) == len(fd)
    for i, f in enumerate(frames):
        assert f.t_start == fd.t_start[i] and f.t_end == fd.t_end[i]
        assert f.valid == fd.valid[i]
        assert f.n_intervals == fd.n_intervals[i]
        np.testing.assert_allclose(f.delta_t, fd.delta_t[i], rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(f.delta_R, fd.delta_R[i], rtol=0, atol=tol)
        scale_v = 1 + np.abs(fd.delta_v[i]).max()
        np.testing.assert_allclose(f.delta_v, fd.delta_v[i], rtol=0, atol=tol * scale_v)
        scale_p = 1 + np.abs(fd.delta_p[i]).max()
        np.testing.assert_allclose(f.delta_p, fd.delta_p[i], rtol=0, atol=tol * scale_p)
        J = fd.bias_jacobian[i]
        np.testing.assert_allclose(f.bias_jacobian, J, rtol=0, atol=tol * np.abs(J).max())
        C = fd.covariance[i]
        np.testing.assert_allclose(f.covariance, C, rtol=0, atol=tol * max(np.abs(C).max(), 1e-300))


def forster_reference(dts, ws, fs, bg=np.zeros(3), ba=np.zeros(3), sg=0.0, sa=0.0):  # noqa: B008 (read-only defaults, never modified)
    """Textbook Forster recursion (right error, 9x9 A Sigma A^T + B Q B^T, appendix Jacobians)."""
    R, v, p = np.eye(3), np.zeros(3), np.zeros(3)
    S = np.zeros((9, 9))
    dRg = np.zeros((3, 3))
    dVg, dVa, dPg, dPa = (np.zeros((3, 3)) for _ in range(4))
    for dt, w, f in zip(dts, ws, fs, strict=True):
        w = np.asarray(w) - bg
        f = np.asarray(f) - ba
        dR = so3.exp(w * dt)
        Jr = so3.right_jacobian(w * dt)
        fx = so3.hat(f)
        A = np.eye(9)
        A[0:3, 0:3] = dR.T
        A[3:6, 0:3] = -R @ fx * dt
        A[6:9, 0:3] = -0.5 * R @ fx * dt * dt
        A[6:9, 3:6] = np.eye(3) * dt
        B = np.zeros((9, 6))
        B[0:3, 0:3] = Jr * dt
        B[3:6, 3:6] = R * dt
        B[6:9, 3:6] = 0.5 * R * dt * dt
        Q = np.diag([sg ** 2 / dt] * 3 + [sa ** 2 / dt] * 3)
        S = A @ S @ A.T + B @ Q @ B.T
        dPg = dPg + dVg * dt - 0.5 * R @ fx @ dRg * dt * dt
        dPa = dPa + dVa * dt - 0.5 * R * dt * dt
        dVg = dVg - R @ fx @ dRg * dt
        dVa = dVa - R * dt
        dRg = dR.T @ dRg - Jr * dt
        p = p + v * dt + 0.5 * R @ f * dt * dt
        v = v + R @ f * dt
        R = R @ dR
    J = np.zeros((9, 6))
    J[0:3, 0:3], J[3:6, 0:3], J[6:9, 0:3], J[3:6, 3:6], J[6:9, 3:6] = dRg, dVg, dPg, dVa, dPa
    return R, v, p, S, J


# ---------------------------------------------------------------------------
# kernels and the reference recursion
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("hold", ["left", "midpoint"])
def test_batch_and_streaming_equal_textbook_forster_recursion(hold):
    t, gyro, accel = random_log(300, seed=2)
    bg, ba = np.array([0.02, -0.01, 0.03]), np.array([0.1, -0.2, 0.05])
    kw = dict(bias_gyro=bg, bias_accel=ba, gyro_noise_density=SG, accel_noise_density=SA, hold=hold)
    fd = preintegrate((t, gyro, accel), frame_times=[t[0], t[-1]], **kw)
    if hold == "left":
        ws, fs = gyro[:-1], accel[:-1]
    else:
        ws, fs = 0.5 * (gyro[1:] + gyro[:-1]), 0.5 * (accel[1:] + accel[:-1])
    R, v, p, S, J = forster_reference(np.diff(t), ws, fs, bg, ba, SG, SA)
    np.testing.assert_allclose(fd.delta_R[0], R, atol=1e-13)
    np.testing.assert_allclose(fd.delta_v[0], v, atol=1e-12 * np.abs(v).max())
    np.testing.assert_allclose(fd.delta_p[0], p, atol=1e-12 * np.abs(p).max())
    np.testing.assert_allclose(fd.covariance[0], S, atol=1e-11 * np.abs(S).max())
    np.testing.assert_allclose(fd.bias_jacobian[0], J, atol=1e-12 * np.abs(J).max())
    pim = stream(t, gyro, accel, frame_times=[t[0], t[-1]], **kw)[0]
    np.testing.assert_allclose(pim.covariance, S, atol=1e-11 * np.abs(S).max())
    np.testing.assert_allclose(pim.bias_jacobian, J, atol=1e-12 * np.abs(J).max())


def test_value_type_integrate_reset_copy():
    rng = np.random.default_rng(3)
    dts = rng.uniform(0.005, 0.02, 50)
    ws, fs = rng.normal(0, 1, (50, 3)), rng.normal(0, 3, (50, 3))
    pim = PreintegratedImu(bias_gyro=[0.01, 0.0, -0.02], gyro_noise_density=SG, accel_noise_density=SA)
    for dt, w, f in zip(dts, ws, fs, strict=True):
        pim.integrate(dt, w, f)                  # numpy rows accepted
    R, v, p, S, J = forster_reference(dts, ws, fs, np.array([0.01, 0.0, -0.02]), np.zeros(3), SG, SA)
    assert pim.n_intervals == 50 and pim.delta_t == pytest.approx(dts.sum(), rel=1e-15)
    np.testing.assert_allclose(pim.delta_R, R, atol=1e-13)
    np.testing.assert_allclose(pim.delta_v, v, atol=1e-12)
    np.testing.assert_allclose(pim.delta_p, p, atol=1e-12)
    np.testing.assert_allclose(pim.covariance, S, atol=1e-12 * np.abs(S).max())
    np.testing.assert_allclose(pim.d_R_d_bg, J[0:3, 0:3], atol=1e-13)
    np.testing.assert_allclose(pim.d_v_d_bg, J[3:6, 0:3], atol=1e-12)
    np.testing.assert_allclose(pim.d_p_d_bg, J[6:9, 0:3], atol=1e-12)
    np.testing.assert_allclose(pim.d_v_d_ba, J[3:6, 3:6], atol=1e-12)
    np.testing.assert_allclose(pim.d_p_d_ba, J[6:9, 3:6], atol=1e-12)
    c = pim.copy()
    pim.reset()
    assert pim.n_intervals == 0 and pim.delta_t == 0.0
    np.testing.assert_array_equal(pim.delta_R, np.eye(3))
    assert np.all(pim.covariance == 0) and np.all(pim.bias_jacobian == 0)
    np.testing.assert_allclose(c.delta_R, R, atol=1e-13)      # the copy is independent
    with pytest.raises(ValueError):
        pim.integrate(0.0, [0, 0, 0], [0, 0, 0])


# ---------------------------------------------------------------------------
# closed forms
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("hold", ["left", "midpoint"])
def test_constant_rate_gives_exp_wT(hold):
    rng = np.random.default_rng(4)
    n = 401
    t = np.cumsum(np.full(n, 0.01) + rng.uniform(-0.002, 0.002, n))
    w = np.array([0.4, -1.1, 0.7])
    gyro = np.tile(w, (n, 1))
    accel = np.zeros((n, 3))
    fd = preintegrate((t, gyro, accel), rate=10.0, hold=hold)      # boundaries between samples
    assert np.any(fd.n_intervals == 11)
    for i in range(len(fd)):
        T = fd.t_end[i] - fd.t_start[i]
        np.testing.assert_allclose(fd.delta_R[i], so3.exp(w * T), atol=1e-14)
    frames = stream(t, gyro, accel, rate=10.0, hold=hold)
    assert_same(frames, fd)


def test_constant_accel_zero_rate():
    t = np.linspace(0.0, 3.0, 301) + 0.123
    a = np.array([1.5, -0.4, 9.81])
    fd = preintegrate((t, np.zeros((301, 3)), np.tile(a, (301, 1))), rate=4.0)
    T = fd.t_end - fd.t_start
    np.testing.assert_allclose(fd.delta_R, np.broadcast_to(np.eye(3), (len(fd), 3, 3)), atol=0)
    np.testing.assert_allclose(fd.delta_v, T[:, None] * a, rtol=1e-13)
    np.testing.assert_allclose(fd.delta_p, 0.5 * (T * T)[:, None] * a, rtol=1e-13)


def _closed_form_const(w, a, T):
    """Exact deltas for a body rate w and body specific force a, both constant."""
    n = np.linalg.norm(w)
    K = so3.hat(w)
    K2 = K @ K
    th = n * T
    iv = T * np.eye(3) + (1 - np.cos(th)) / n ** 2 * K + (T / n ** 2 - np.sin(th) / n ** 3) * K2
    ip = (T * T / 2 * np.eye(3) + (th - np.sin(th)) / n ** 3 * K
          + (T * T / 2 - (1 - np.cos(th)) / n ** 2) / n ** 2 * K2)
    return so3.exp(w * T), iv @ a, ip @ a


def test_constant_rate_and_accel_against_closed_form():
    """Forster's discretisation rotates the specific force with the attitude at the
    start of each interval: exact rotation, first-order velocity and position."""
    w = np.array([0.3, -0.5, 0.9])
    a = np.array([1.0, 2.0, 9.8])
    T = 2.0
    Rx, vx, px = _closed_form_const(w, a, T)
    errs = []
    for h in (0.01, 0.005, 0.0025):
        n = int(round(T / h)) + 1
        t = np.linspace(0.0, T, n)
        fd = preintegrate((t, np.tile(w, (n, 1)), np.tile(a, (n, 1))), frame_times=[0.0, T])
        np.testing.assert_allclose(fd.delta_R[0], Rx, atol=1e-13)
        ev = np.linalg.norm(fd.delta_v[0] - vx) / np.linalg.norm(vx)
        ep = np.linalg.norm(fd.delta_p[0] - px) / np.linalg.norm(px)
        assert ev < np.linalg.norm(w) * h and ep < np.linalg.norm(w) * h
        errs.append((ev, ep))
    errs = np.array(errs)
    ratio = errs[:-1] / errs[1:]
    assert np.all((ratio > 1.9) & (ratio < 2.1)), ratio        # first order, converging


# ---------------------------------------------------------------------------
# bias Jacobians and covariance
# ---------------------------------------------------------------------------
def test_bias_jacobians_match_finite_differences():
    t, gyro, accel = random_log(250, seed=5)
    b0g, b0a = np.array([0.01, 0.02, -0.03]), np.array([0.05, 0.1, -0.1])
    frames = [t[0], t[120] + 0.004, t[-1]]

    def run(bg, ba):
        return preintegrate((t, gyro, accel), frame_times=frames, bias_gyro=bg, bias_accel=ba)

    fd = run(b0g, b0a)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        for which, h in (("g", 1e-5), ("a", 1e-4)):
            plus = run(b0g + h * e, b0a) if which == "g" else run(b0g, b0a + h * e)
            minus = run(b0g - h * e, b0a) if which == "g" else run(b0g, b0a - h * e)
            for i in range(len(fd)):
                Rt = fd.delta_R[i].T
                dphi = (so3.log(Rt @ plus.delta_R[i]) - so3.log(Rt @ minus.delta_R[i])) / (2 * h)
                dv = (plus.delta_v[i] - minus.delta_v[i]) / (2 * h)
                dp = (plus.delta_p[i] - minus.delta_p[i]) / (2 * h)
                col = 3 * (which == "a") + k
                J = fd.bias_jacobian[i][:, col]
                fdiff = np.concatenate([dphi, dv, dp])
                if which == "a":
                    np.testing.assert_allclose(dphi, 0, atol=1e-12)
                    J, fdiff = J[3:], fdiff[3:]
                rel = np.linalg.norm(fdiff - J) / np.linalg.norm(J)
                assert rel < 1e-6, (which, k, i, rel)


def test_bias_correction_without_reintegration():
    t, gyro, accel = random_log(200, seed=6)
    fd = preintegrate((t, gyro, accel), rate=5.0)
    dbg, dba = np.array([2e-3, -1e-3, 1.5e-3]), np.array([0.02, 0.01, -0.03])
    R1, v1, p1 = fd.corrected(dbg, dba)
    ref = preintegrate((t, gyro, accel), rate=5.0, bias_gyro=dbg, bias_accel=dba)
    err_corr = so3.angle(np.swapaxes(R1, 1, 2) @ ref.delta_R)
    err_none = so3.angle(np.swapaxes(fd.delta_R, 1, 2) @ ref.delta_R)
    assert np.all(err_corr < 1e-3 * err_none)
    assert np.all(np.linalg.norm(v1 - ref.delta_v, axis=1) < 1e-2 * np.linalg.norm(fd.delta_v - ref.delta_v, axis=1))
    assert np.all(np.linalg.norm(p1 - ref.delta_p, axis=1) < 1e-2 * np.linalg.norm(fd.delta_p - ref.delta_p, axis=1))
    pim = fd.frame(2)
    Rc, vc, pc = pim.corrected(dbg, dba)
    np.testing.assert_allclose(Rc, R1[2], atol=1e-14)
    np.testing.assert_allclose(vc, v1[2], atol=1e-13)
    np.testing.assert_allclose(pc, p1[2], atol=1e-13)


def test_covariance_matches_monte_carlo():
    """M noisy realisations of one 1-s segment, back to back, one frame each."""
    rng = np.random.default_rng(7)
    h, per, M = 0.01, 100, 3000
    sg, sa = 0.005, 0.05
    n = per * M + 1
    t = np.arange(n) * h
    ph = (np.arange(n) % per) * h
    gyro = np.stack([0.5 * np.sin(2 * ph), 0.8 * np.cos(3 * ph), 0.3 + ph], axis=1)
    accel = np.stack([2 * np.cos(ph), np.sin(4 * ph), 9.8 + 0 * ph], axis=1)
    frames = t[::per]
    clean = preintegrate((t, gyro, accel), frame_times=frames[:2], hold="left",
                         gyro_noise_density=sg, accel_noise_density=sa)
    noisy = preintegrate((t, gyro + rng.normal(0, sg / math.sqrt(h), (n, 3)),
                          accel + rng.normal(0, sa / math.sqrt(h), (n, 3))),
                         frame_times=frames, hold="left")
    e = np.concatenate([so3.log(clean.delta_R[0].T @ noisy.delta_R),
                        noisy.delta_v - clean.delta_v[0], noisy.delta_p - clean.delta_p[0]], axis=1)
    S = clean.covariance[0]
    L = np.linalg.cholesky(S)
    z = np.linalg.solve(L, e.T).T
    C = np.cov(z, rowvar=False)
    # variance estimates of unit-variance Gaussians have std sqrt(2 / M); correlations 1 / sqrt(M)
    assert np.all(np.abs(np.diag(C) - 1) < 5 * math.sqrt(2 / M)), np.diag(C)
    off = C[~np.eye(9, dtype=bool)]
    assert np.all(np.abs(off) < 5 / math.sqrt(M)), np.abs(off).max()
    assert np.all(np.abs(z.mean(axis=0)) < 5 / math.sqrt(M))
    assert np.mean(np.sum(z * z, axis=1)) == pytest.approx(9, abs=5 * math.sqrt(18 / M))


# ---------------------------------------------------------------------------
# batch == streaming, frame boundaries, composition
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("hold", ["midpoint", "left"])
def test_batch_equals_streaming(hold):
    t, gyro, accel = random_log(1500, seed=8)
    kw = dict(bias_gyro=[0.01, -0.02, 0.005], bias_accel=[0.1, 0.0, -0.2],
              gyro_noise_density=SG, accel_noise_density=SA, hold=hold)
    # camera-like irregular frames: one on a sample, one within the snapping
    # tolerance of a sample, and one ~7-s frame (cut into blocks and merged)
    rng = np.random.default_rng(9)
    cam = np.concatenate([[t[3], t[40] + 3e-10], t[41] + np.cumsum(rng.uniform(0.05, 0.12, 60)),
                          [t[41] + 12.0], t[1300] + np.cumsum(rng.uniform(0.05, 0.12, 20))])
    cam = cam[cam < t[-1]]
    for fkw in (dict(frame_times=cam), dict(rate=10.0), dict(rate=3.0, t_origin=-0.05), dict(every=7)):
        fd = preintegrate((t, gyro, accel), **fkw, **kw)
        frames = stream(t, gyro, accel, **fkw, **kw)
        assert_same(frames, fd)
        if "frame_times" in fkw:
            assert fd.n_intervals.max() > 40 * np.median(fd.n_intervals)   # really cut into blocks


def test_without_uncertainty_same_deltas():
    t, gyro, accel = random_log(800, seed=19)
    frames = np.concatenate([t[:100:10], t[500:780:7]])      # one long frame -> blocks
    full = preintegrate((t, gyro, accel), frame_times=frames, gyro_noise_density=SG)
    lean = preintegrate((t, gyro, accel), frame_times=frames, uncertainty=False)   # the streaming kernel's deltas
    np.testing.assert_allclose(lean.delta_R, full.delta_R, rtol=0, atol=1e-14)     # (to rounding: another order)
    np.testing.assert_allclose(lean.delta_v, full.delta_v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(lean.delta_p, full.delta_p, rtol=0, atol=1e-12)
    assert lean.covariance is None and lean.d_p_d_ba is None
    with pytest.raises(ValueError, match="uncertainty=False"):
        lean.corrected(np.zeros(3), np.zeros(3))


def test_streaming_accepts_tuples_lists_and_arrays():
    t, gyro, accel = random_log(300, seed=10)
    ref = stream(t, gyro, accel, rate=10.0)
    for conv in (tuple, list, np.asarray):
        sp = StreamingPreintegrator(rate=10.0)
        out = []
        for i in range(len(t)):
            out += sp.push(np.float64(t[i]), conv(gyro[i]), conv(accel[i]))
        assert len(out) == len(ref)
        for a, b in zip(out, ref, strict=True):
            np.testing.assert_array_equal(a.delta_R, b.delta_R)
            np.testing.assert_array_equal(a.delta_p, b.delta_p)


@pytest.mark.parametrize("hold", ["midpoint", "left"])
def test_split_boundary_equals_integrating_the_pieces(hold):
    """A boundary between two samples splits their interval; the two frames
    compose to the integration of the log with a knot inserted at the boundary
    (interpolated value for the midpoint hold, the left sample's for the left hold)."""
    t, gyro, accel = random_log(200, seed=12)
    tb = t[80] + 0.3 * (t[81] - t[80])
    kw = dict(gyro_noise_density=SG, accel_noise_density=SA, hold=hold)
    parts = preintegrate((t, gyro, accel), frame_times=[t[0], tb, t[-1]], **kw)
    assert parts.n_intervals.tolist() == [81, 119]
    w = (tb - t[80]) / (t[81] - t[80]) if hold == "midpoint" else 0.0
    t2 = np.insert(t, 81, tb)
    g2 = np.insert(gyro, 81, gyro[80] + (gyro[81] - gyro[80]) * w, axis=0)
    a2 = np.insert(accel, 81, accel[80] + (accel[81] - accel[80]) * w, axis=0)
    whole = preintegrate((t2, g2, a2), frame_times=[t[0], t[-1]], **kw)
    for merged in (parts.frame(0).combine(parts.frame(1)),
                   *[a.combine(b) for a, b in [stream(t, gyro, accel, frame_times=[t[0], tb, t[-1]], **kw)]]):
        np.testing.assert_allclose(merged.delta_R, whole.delta_R[0], atol=1e-14)
        np.testing.assert_allclose(merged.delta_v, whole.delta_v[0], atol=1e-13)
        np.testing.assert_allclose(merged.delta_p, whole.delta_p[0], atol=1e-13)
        np.testing.assert_allclose(merged.covariance, whole.covariance[0],
                                   atol=1e-13 * np.abs(whole.covariance[0]).max())
        np.testing.assert_allclose(merged.bias_jacobian, whole.bias_jacobian[0], atol=1e-13)
    if hold == "left":      # the rotation of a zero-order hold does not even see the split
        unsplit = preintegrate((t, gyro, accel), frame_times=[t[0], t[-1]], **kw)
        np.testing.assert_allclose(merged.delta_R, unsplit.delta_R[0], atol=1e-14)


def test_combine_frames_equals_longer_frame():
    t, gyro, accel = random_log(400, seed=13)
    kw = dict(gyro_noise_density=SG, accel_noise_density=SA, bias_gyro=[0.0, 0.01, 0.0])
    T = make_frame_times(t, every=20)          # boundaries on samples: no extra knots
    fine = preintegrate((t, gyro, accel), frame_times=T, **kw)
    coarse = preintegrate((t, gyro, accel), frame_times=T[::2], **kw)
    for i in range(len(coarse)):
        m = fine.frame(2 * i).combine(fine.frame(2 * i + 1))
        assert m.t_start == coarse.t_start[i] and m.t_end == coarse.t_end[i]
        np.testing.assert_allclose(m.delta_R, coarse.delta_R[i], atol=1e-14)
        np.testing.assert_allclose(m.delta_p, coarse.delta_p[i], atol=1e-13)
        np.testing.assert_allclose(m.covariance, coarse.covariance[i], atol=1e-13 * np.abs(coarse.covariance[i]).max())
        np.testing.assert_allclose(m.bias_jacobian, coarse.bias_jacobian[i], atol=1e-13)


def test_long_frame_stays_orthonormal():
    n = 36_000
    rng = np.random.default_rng(14)
    t = np.arange(n) * 0.01
    gyro = rng.normal(0, 1.0, (n, 3))
    fd = preintegrate((t, gyro, np.zeros((n, 3))), frame_times=[t[0], t[-1]])
    R = fd.delta_R[0]
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-13
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)


def test_make_frame_times():
    t = np.arange(0, 101) * 0.01 + 0.005
    T = make_frame_times(t, rate=10.0)
    np.testing.assert_allclose(T, 0.005 + np.arange(11) / 10.0)
    np.testing.assert_array_equal(make_frame_times(t, every=25), t[::25])
    T = make_frame_times(t, rate=4.0, t_origin=-0.1)
    np.testing.assert_allclose(T, [0.15, 0.4, 0.65, 0.9])
    with pytest.raises(ValueError):
        make_frame_times(t, rate=4.0, every=3)


# ---------------------------------------------------------------------------
# gaps and bad timestamps
# ---------------------------------------------------------------------------
def test_gap_raises_with_time_and_length():
    t, gyro, accel = random_log(400, seed=15)
    t = t.copy()
    t[200:] += 1.5
    gap_t, gap_len = t[199], t[200] - t[199]
    with pytest.raises(ValueError, match="gap") as ei:
        preintegrate((t, gyro, accel), rate=10.0, max_gap=0.1)
    assert f"{gap_t:.6f}" in str(ei.value) and f"{gap_len:.6g}" in str(ei.value)
    with pytest.raises(ValueError, match="gap") as es:
        stream(t, gyro, accel, rate=10.0, max_gap=0.1)
    assert f"{gap_t:.6f}" in str(es.value) and f"{gap_len:.6g}" in str(es.value)
    # a gap outside every frame does not matter
    fd = preintegrate((t, gyro, accel), frame_times=[t[0], t[150]], max_gap=0.1)
    assert fd.valid.all()


def test_gap_flagged_per_frame():
    t, gyro, accel = random_log(400, seed=16)
    t = t.copy()
    t[200:] += 1.5
    kw = dict(rate=10.0, max_gap=0.1, on_gap="flag", gyro_noise_density=SG, accel_noise_density=SA)
    fd = preintegrate((t, gyro, accel), **kw)
    overlap = (fd.t_end > t[199]) & (fd.t_start < t[200])
    np.testing.assert_array_equal(~fd.valid, overlap)
    assert overlap.sum() >= 15                      # 1.5 s of 0.1-s frames inside the gap
    assert_same(stream(t, gyro, accel, **kw), fd)


def test_non_increasing_timestamps_raise():
    t, gyro, accel = random_log(100, seed=17)
    t = t.copy()
    t[50] = t[49]
    with pytest.raises(ValueError, match="strictly increasing"):
        preintegrate((t, gyro, accel), rate=10.0)
    with pytest.raises(ValueError, match="strictly increasing"):
        stream(t, gyro, accel, rate=10.0)
    t[50] = t[49] - 0.05
    with pytest.raises(ValueError, match=r"t\[50\]"):
        preintegrate(ImuData(t, gyro, accel), rate=10.0)


def test_frame_times_outside_the_log_raise():
    t, gyro, accel = random_log(100, seed=18)
    with pytest.raises(ValueError, match="inside the log"):
        preintegrate((t, gyro, accel), frame_times=[t[0] - 0.1, t[50]])
    with pytest.raises(ValueError, match="inside the log"):
        preintegrate((t, gyro, accel), frame_times=[t[0], t[-1] + 0.1])
    with pytest.raises(ValueError, match="increasing"):
        preintegrate((t, gyro, accel), frame_times=[t[10], t[5]])
    with pytest.raises(ValueError, match="before the first sample"):
        stream(t, gyro, accel, frame_times=[t[0] - 0.1, t[50]])


# ---------------------------------------------------------------------------
# real data: gyro-integrated attitude change vs the OXTS attitude, 10-s windows
# ---------------------------------------------------------------------------
def _load_kitti(path):
    import warnings

    from imu_ground.datasets import read_kitti_imu100
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")         # the dropped out-of-order samples are reported
        imu = read_kitti_imu100(path)
    d = imu.to_dataframe()
    R = so3.rotz(d["yaw"].to_numpy()) @ so3.roty(d["pitch"].to_numpy()) @ so3.rotx(d["roll"].to_numpy())
    return imu, R


@pytest.mark.shared
def test_kitti_gyro_attitude_change_matches_oxts(shared_data, kitti_index):
    """10-s windows, sliding by 1 s, every drive: angle of R_oxts(t0)^T R_oxts(t1) vs delta_R.

    Frames of 100 samples (1 s) are preintegrated; a window is the product of
    10 consecutive valid frames. The OXTS attitude is a GPS/INS blend whose
    heading is corrected by the filter (it even drifts at standstill), so the
    agreement is ~0.1-0.2 deg typical with a tail of 1-2 deg in heading; a
    frame or order mistake (transposed delta_R, wrong axes) gives several to
    tens of degrees. The test also prints how the agreement changes when the
    OXTS attitude is taken a few samples earlier or later: it is best about
    5-6 samples (50-60 ms) earlier, i.e. in these files the attitude lags the
    angular rates of the same row.
    """
    files = sorted((shared_data / "kitti_imu100").glob("*.csv.gz"))
    assert [f.name for f in files] == sorted(f"{n}.csv.gz" for n in kitti_index["drive"])
    errs, wrong, tilt = [], [], []
    shifts = np.arange(-8, 3)
    by_shift = [[] for _ in shifts]          # OXTS attitude taken `shift` samples off
    for f in files:
        imu, Roxts = _load_kitti(f)
        idx = np.arange(0, len(imu), 100)
        fd = preintegrate(imu, frame_times=imu.t[idx], on_gap="flag", max_gap=0.1)
        F = len(fd)
        if F < 10:
            continue
        P = np.empty((F + 1, 3, 3))
        P[0] = np.eye(3)
        for k in range(F):          # loop over 1-s frames only
            P[k + 1] = P[k] @ fd.delta_R[k]
        ok = np.convolve(fd.valid.astype(int), np.ones(10, int), "valid") == 10
        i0 = np.flatnonzero(ok)
        i1 = i0 + 10
        dR = np.swapaxes(P[i0], 1, 2) @ P[i1]
        Ro0, Ro1 = Roxts[idx[i0]], Roxts[idx[i1]]
        rel = np.swapaxes(Ro0, 1, 2) @ Ro1
        errs.append(np.degrees(so3.angle(np.swapaxes(rel, 1, 2) @ dR)))
        wrong.append(np.degrees(so3.angle(np.swapaxes(rel, 1, 2) @ np.swapaxes(dR, 1, 2))))
        e_nav = so3.log((Ro0 @ dR) @ np.swapaxes(Ro1, 1, 2))      # error in the level frame
        tilt.append(np.degrees(np.hypot(e_nav[:, 0], e_nav[:, 1])))
        for j, sh in enumerate(shifts):
            a, b = idx[i0] + sh, idx[i1] + sh
            m = (a >= 0) & (b < len(imu))
            rs = np.swapaxes(Roxts[a[m]], 1, 2) @ Roxts[b[m]]
            by_shift[j].append(np.degrees(so3.angle(np.swapaxes(rs, 1, 2) @ dR[m])))
    e = np.concatenate(errs)
    w = np.concatenate(wrong)
    tl = np.concatenate(tilt)
    med, p95 = np.median(e), np.percentile(e, 95)
    print(f"\nKITTI 10-s windows: n={e.size}, attitude-change error median {med:.3f} deg, "
          f"p95 {p95:.3f} deg, max {e.max():.3f} deg; tilt part median {np.median(tl):.3f} deg, "
          f"p95 {np.percentile(tl, 95):.3f} deg; transposed delta_R would give median "
          f"{np.median(w):.2f} deg")
    med_shift = np.array([np.median(np.concatenate(x)) for x in by_shift])
    best = int(np.argmin(med_shift))
    print(f"OXTS attitude shifted by {shifts[best]} samples: median "
          f"{med_shift[best]:.3f} deg, p95 {np.percentile(np.concatenate(by_shift[best]), 95):.3f} deg "
          f"(medians for shifts {shifts.tolist()}: {np.round(med_shift, 3).tolist()})")
    assert e.size > 1000
    assert med < 0.5 and p95 < 3.0
    assert np.median(tl) < 0.3
    assert np.median(w) > 10 * med


def test_streaming_deltas_only_matches_batch_and_refuses_covariance():
    rng = np.random.default_rng(42)
    n = 2000
    t = np.arange(n) * 0.01 + 0.002 * rng.random(n)
    w = rng.normal(scale=0.2, size=(n, 3))
    f = rng.normal(size=(n, 3)) + [0.0, 0.0, 9.8]
    ref = preintegrate((t, w, f), rate=10.0, t_origin=t[0] + 0.0035, bias_gyro=[1e-3, 0, -2e-3])
    full = StreamingPreintegrator(rate=10.0, t_origin=t[0] + 0.0035, bias_gyro=[1e-3, 0, -2e-3])
    lean = StreamingPreintegrator(rate=10.0, t_origin=t[0] + 0.0035, bias_gyro=[1e-3, 0, -2e-3],
                                  uncertainty=False)
    a, b = [], []
    for i in range(n):
        a += full.push(t[i], w[i], f[i])
        b += lean.push(t[i], w[i], f[i])
    assert len(a) == len(b) > 10
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        assert np.allclose(y.delta_R, ref.delta_R[i], atol=1e-14)
        assert np.allclose(y.delta_v, x.delta_v, atol=1e-13) and np.allclose(y.delta_p, x.delta_p, atol=1e-13)
    with pytest.raises(ValueError, match="uncertainty=False"):
        _ = b[0].covariance
    with pytest.raises(ValueError, match="uncertainty=False"):
        _ = b[0].d_R_d_bg


# ---------------------------------------------------------------------------
# GTSAM (an independent implementation of the same discrete model)
# ---------------------------------------------------------------------------
def _gtsam_pim(gtsam, bg, ba, sg, sa, g):
    p = gtsam.PreintegrationParams.MakeSharedU(g)
    p.setGyroscopeCovariance(sg ** 2 * np.eye(3))
    p.setAccelerometerCovariance(sa ** 2 * np.eye(3))
    p.setIntegrationCovariance(np.zeros((3, 3)))
    return gtsam.PreintegratedImuMeasurementsManifold(p, gtsam.imuBias.ConstantBias(ba, bg))


def test_matches_gtsam_manifold_preintegration():
    """Zero-order hold (GTSAM's model): deltas, 9x9 covariance (GTSAM orders it
    [rotation, position, velocity], in the end body frame), the bias Jacobians through a bias-corrected
    prediction, and the navigation-state prediction, against GTSAM's
    ``PreintegratedImuMeasurements`` (manifold) and ``PreintegratedRotation``."""
    gtsam = pytest.importorskip("gtsam")
    t, gyro, accel = random_log(400, seed=21)
    bg, ba = np.array([0.01, -0.02, 0.005]), np.array([0.1, -0.05, 0.2])
    params = PreintegrationParams(bias_gyro=bg, bias_accel=ba, gyro_noise_density=SG,
                                  accel_noise_density=SA, hold="left")
    fd = preintegrate((t, gyro, accel), frame_times=[t[0], t[-1]], params=params)
    pim = _gtsam_pim(gtsam, bg, ba, SG, SA, params.gravity)
    rot = gtsam.PreintegratedRotation(gtsam.PreintegratedRotationParams())
    for k in range(len(t) - 1):
        dt = t[k + 1] - t[k]
        pim.integrateMeasurement(accel[k], gyro[k], dt)
        rot.integrateGyroMeasurement(gyro[k], bg, dt)
    np.testing.assert_allclose(fd.delta_t[0], pim.deltaTij(), rtol=1e-14)
    np.testing.assert_allclose(fd.delta_R[0], pim.deltaRij().matrix(), atol=1e-14)
    np.testing.assert_allclose(fd.delta_v[0], pim.deltaVij(), atol=1e-13 * np.abs(fd.delta_v[0]).max())
    np.testing.assert_allclose(fd.delta_p[0], pim.deltaPij(), atol=1e-13 * np.abs(fd.delta_p[0]).max())
    # ours [rot, vel, pos] with vel/pos errors in the start body frame -> GTSAM's NavState tangent
    # [rot, pos, vel] with every error in the end body frame (retract p + R dp)
    order = np.r_[0:3, 6:9, 3:6]
    D = np.kron(np.eye(3), fd.delta_R[0].T)
    D[0:3, 0:3] = np.eye(3)
    C = D @ fd.covariance[0][np.ix_(order, order)] @ D.T
    np.testing.assert_allclose(C, pim.preintMeasCov(), rtol=0, atol=1e-12 * np.abs(C).max())
    np.testing.assert_allclose(fd.d_R_d_bg[0], rot.delRdelBiasOmega(), atol=1e-13)
    # a state moved across the interval, at the integration bias and at a nearby one
    R0 = so3.exp([0.1, -0.2, 0.3])
    v0, p0 = np.array([10.0, -1.0, 0.5]), np.array([1.0, 2.0, 3.0])
    state = gtsam.NavState(gtsam.Rot3(R0), p0, v0)
    frame = fd.frame(0)
    for dbg, dba in ((np.zeros(3), np.zeros(3)), (np.array([2e-4, -1e-4, 3e-4]), np.array([0.01, 0.02, -0.01]))):
        ref = pim.predict(state, gtsam.imuBias.ConstantBias(ba + dba, bg + dbg))
        dR, dv, dp = frame.corrected(bg + dbg, ba + dba)
        g = np.array([0.0, 0.0, -params.gravity])
        T = frame.delta_t
        np.testing.assert_allclose(R0 @ dR, ref.attitude().matrix(), atol=1e-13)
        np.testing.assert_allclose(v0 + g * T + R0 @ dv, ref.velocity(), atol=1e-11)
        np.testing.assert_allclose(p0 + v0 * T + 0.5 * g * T * T + R0 @ dp, ref.position(), atol=1e-10)
    Rp, vp, pp = frame.predict(R0, v0, p0)
    ref = pim.predict(state, gtsam.imuBias.ConstantBias(ba, bg))
    np.testing.assert_allclose(Rp, ref.attitude().matrix(), atol=1e-13)
    np.testing.assert_allclose(vp, ref.velocity(), atol=1e-11)
    np.testing.assert_allclose(pp, ref.position(), atol=1e-10)


def test_params_value_type():
    p = PreintegrationParams(bias_gyro=np.array([1.0, 2.0, 3.0]), hold="left")
    assert p.bias_gyro == (1.0, 2.0, 3.0) and p.hold == "left"
    q = PreintegrationParams.coerce(p, gyro_noise_density=0.5, bias_accel=None)
    assert q.gyro_noise_density == 0.5 and q.bias_accel == p.bias_accel and q.hold == "left"
    assert PreintegrationParams.coerce(p) is p
    with pytest.raises(TypeError, match="unknown preintegration option"):
        PreintegrationParams.coerce(p, gyro_noise=1.0)
    with pytest.raises(ValueError, match="hold"):
        PreintegrationParams(hold="cubic")
    with pytest.raises(ValueError, match="on_gap"):
        PreintegrationParams(on_gap="skip")
    with pytest.raises(ValueError, match="gyro_noise_density"):
        PreintegrationParams(gyro_noise_density=-1.0)
    with pytest.raises(ValueError, match="bias_gyro"):
        PreintegrationParams(bias_gyro=[1.0, 2.0])
    # every entry point takes the same params (or its fields as keywords), with the same result
    t, gyro, accel = random_log(300, seed=22)
    par = PreintegrationParams(bias_gyro=[0.01, 0.0, 0.0], gyro_noise_density=SG, accel_noise_density=SA)
    a = preintegrate((t, gyro, accel), rate=10.0, params=par)
    b = preintegrate((t, gyro, accel), rate=10.0, bias_gyro=[0.01, 0.0, 0.0], gyro_noise_density=SG,
                     accel_noise_density=SA)
    np.testing.assert_array_equal(a.covariance, b.covariance)
    assert a.params == par
    assert_same(stream(t, gyro, accel, rate=10.0, params=par), a)


def test_quaternion_round_trip_covers_every_branch():
    """The kernel keeps delta_R as a quaternion; matrices go in (combine, FrameDeltas.frame) and out."""
    from imu_ground.imu.preint_kernel import quaternion_from_rotation, rotation_from_quaternion
    rng = np.random.default_rng(23)
    phis = [rng.normal(size=3) for _ in range(50)]
    phis += [np.array([np.pi, 0, 0]), np.array([0, np.pi, 0]), np.array([0, 0, np.pi]),
             np.array([0.0, 0.0, 0.0]), np.array([np.pi - 1e-9, 1e-9, 0.0])]
    for phi in phis:
        R = so3.exp(phi)
        q = quaternion_from_rotation(tuple(R.reshape(9).tolist()))
        assert abs(sum(v * v for v in q) - 1.0) < 1e-15
        np.testing.assert_allclose(np.array(rotation_from_quaternion(q)).reshape(3, 3), R, atol=4e-16 * 8)


def test_predict_equals_dead_reckoning_and_current_is_a_snapshot():
    from imu_ground.imu.dead_reckoning import dead_reckon
    t, gyro, accel = random_log(300, seed=24)
    fd = preintegrate((t, gyro, accel), frame_times=[t[0], t[150], t[-1]], gyro_noise_density=SG)
    R0, v0, p0 = so3.exp([0.2, -0.1, 0.5]), np.array([3.0, 0.5, -0.2]), np.array([1.0, 2.0, 3.0])
    nav = dead_reckon(fd, R0, v0, p0)
    R1, v1, p1 = fd.frame(0).predict(R0, v0, p0)
    R2, v2, p2 = fd.frame(1).predict(R1, v1, p1)
    np.testing.assert_allclose(R2, nav.R[2], atol=1e-13)
    np.testing.assert_allclose(v2, nav.v[2], atol=1e-11)
    np.testing.assert_allclose(p2, nav.p[2], atol=1e-10)
    sp = StreamingPreintegrator(frame_times=[t[0], t[-1]])
    for i in range(100):
        sp.push(t[i], gyro[i], accel[i])
    snap = sp.current
    assert snap.n_intervals == 99 and snap.delta_t == pytest.approx(t[99] - t[0], rel=1e-14)
    sp.push(t[100], gyro[100], accel[100])
    assert snap.n_intervals == 99 and sp.current.n_intervals == 100


@pytest.mark.parametrize("frames", [{"rate": 10.0}, {"every": 7}])
def test_streaming_copies_and_pickles_continue_identically(frames):
    import copy
    import pickle
    t, gyro, accel = random_log(300, seed=4)
    sp = StreamingPreintegrator(**frames)
    for i in range(150):
        sp.push(t[i], gyro[i].tolist(), accel[i].tolist())
    copies = [copy.deepcopy(sp), pickle.loads(pickle.dumps(sp))]
    outs = [[], [], []]
    for i in range(150, 300):
        for out, s in zip(outs, [sp, *copies], strict=True):
            out += s.push(t[i], gyro[i].tolist(), accel[i].tolist())
    assert len(outs[0]) > 5
    for other in outs[1:]:
        assert [(f._s, f._u, f.n_intervals, f.t_end) for f in other] == \
            [(f._s, f._u, f.n_intervals, f.t_end) for f in outs[0]]
