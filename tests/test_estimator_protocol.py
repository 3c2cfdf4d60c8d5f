"""The estimator protocol: step(EgoFrame) and run(EgoMotion) agree, tracks carry times and validity, the
output table, the method registry, the frame rate taken from the ego-motion, the shared rotation helpers."""
from __future__ import annotations


import numpy as np
import pytest

import imu_ground
from imu_ground import so3
from imu_ground.evaluation.simulate import simulate
from imu_ground.filters import GroundEstimator, GroundTrack
from imu_ground.filters.design import IIRFilter, foh_filter
from imu_ground.filters.estimator import pitch_roll_from_normal
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.methods import METHODS, default_method, estimate, make_estimator
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import EgoMotion, imu_to_egomotion
from imu_ground.pipeline.output import track_table
from imu_ground.so3 import as_rotations, euler_zyx, matrix_from_quat, quat_from_matrix, twist_angle

ESTIMATORS = {
    "filter": lambda: GroundNormalFilter(),
    "paper": lambda: GroundNormalFilter.paper(),
    "up": lambda: GroundNormalFilter(measurement="up", extrinsic=so3.rotz(0.1) @ so3.roty(0.02)),
    "forward": lambda: GroundNormalFilter.reference_code(),
    "general-Q": lambda: GroundNormalFilter(Q=np.diag([1e-2, 2e-2, 1e-3])),
    "suspension": lambda: SuspensionAwareFilter(),
    "suspension-online": lambda: SuspensionAwareFilter(online_gains=True, response=(1.5, 0.6),
                                                       extrinsic=so3.rotx(0.02)),
}


@pytest.fixture(scope="module")
def drive():
    sim = simulate(60.0, seed=5, imu="mems")
    return sim, imu_to_egomotion(sim.imu)


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_step_and_run_agree_through_the_protocol(drive, name):
    _, em = drive
    a, b = ESTIMATORS[name](), ESTIMATORS[name]()
    assert isinstance(a, GroundEstimator)
    ests = [a.step(fr) for fr in em.frames()]
    tr = b.run(em)
    assert isinstance(tr, GroundTrack) and len(tr) == len(em)
    assert all(e.valid for e in ests) and tr.valid.all()
    np.testing.assert_array_equal(tr.t, em.t)
    for field in ("pitch", "roll", "normal", "residual", "extrinsic", "P"):
        np.testing.assert_allclose(np.array([getattr(e, field) for e in ests]), getattr(tr, field),
                                   rtol=1e-10, atol=1e-12, err_msg=field)
    np.testing.assert_allclose(a.x, b.x, atol=1e-12)
    np.testing.assert_allclose(a.cumulative, b.cumulative, atol=1e-12)
    # the kernel's pitch and roll are those of the residual it returns
    p, r = pitch_roll_from_normal(tr.residual[:, 2, :])
    np.testing.assert_allclose([e.pitch for e in ests], p, atol=1e-12)
    np.testing.assert_allclose([e.roll for e in ests], r, atol=1e-12)


def test_bare_rotation_and_egoframe_give_the_same_estimate(drive):
    _, em = drive
    a, b = GroundNormalFilter(), GroundNormalFilter()
    for k in range(50):
        ea, eb = a.step(em.delta_R[k]), b.step(em.frame_at(k))
        assert ea.pitch == eb.pitch and ea.roll == eb.roll
    normal, pitch, roll, residual, extrinsic, P = ea            # the former named tuple still unpacks
    assert pitch == ea.pitch and np.array_equal(normal, ea.normal)


@pytest.mark.parametrize("make", [GroundNormalFilter, SuspensionAwareFilter, GroundNormalFilter.reference_code])
def test_empty_run(make):
    empty = EgoMotion.from_rotations(np.zeros((0, 3, 3)))
    f = make()
    for smooth in (False, True):
        tr = f.run(empty, smooth=smooth)
        assert len(tr) == 0 and tr.normal.shape == (0, 3) and tr.t.shape == (0,) and tr.valid.shape == (0,)
        assert len(track_table(tr)) == 0
    assert GroundNormalFilter().run(np.zeros((0, 3, 3))).residual.shape == (0, 3, 3)


def test_track_table_columns_quaternion_and_long_gaps(drive):
    _, em = drive
    tr = GroundNormalFilter().run(em)
    tr.valid[10:12] = False                          # a short gap keeps its values
    tr.valid[100:110] = False                        # a long one is blanked
    df = track_table(tr)
    assert list(df.columns) == ["t", "normal_x", "normal_y", "normal_z", "pitch_deg", "roll_deg",
                                "qw", "qx", "qy", "qz", "valid", "pitch_std_deg", "roll_std_deg", "road_grade_deg",
                                "road_bank_deg", "road_grade_std_deg", "road_bank_std_deg", "status", "status_reason"]
    assert df["valid"].dtype == bool and df["t"].tolist() == em.t.tolist()
    ok = df["valid"].to_numpy()
    np.testing.assert_allclose(df["pitch_deg"][ok], np.degrees(tr.pitch[ok]))
    q = df[["qw", "qx", "qy", "qz"]].to_numpy()
    np.testing.assert_allclose(matrix_from_quat(q[ok]), tr.residual[ok], atol=1e-12)
    assert np.all(q[ok, 0] >= 0)
    text = ["t", "valid", "status", "status_reason"]
    road = ["road_grade_deg", "road_bank_deg", "road_grade_std_deg", "road_bank_std_deg"]   # (no speed: none)
    assert df.iloc[10:12]["pitch_deg"].notna().all() and df.iloc[100:110].drop(columns=text).isna().all().all()
    assert df.iloc[12:100].drop(columns=road).notna().all().all()
    assert imu_ground.track_table is track_table


def test_streaming_import_loads_neither_scipy_nor_pandas(heavy_modules_loaded):
    """A streaming step loads nothing heavy beyond numba (and the part of scipy numba imports itself)."""
    assert heavy_modules_loaded("imu_ground.GroundNormalFilter().step(np.eye(3))") == []


# ----------------------------------------------------------------------------- methods
def test_method_registry(drive):
    _, em = drive
    assert list(METHODS) == ["suspension", "suspension-offline", "filter", "paper", "naive"]
    assert default_method(True) == "suspension" and default_method(False) == "filter"
    for name, spec in METHODS.items():
        assert spec.name == name and spec.description and "\n" not in spec.description
        assert isinstance(make_estimator(name), GroundEstimator)
    assert METHODS["suspension-offline"].smooth and not METHODS["suspension"].smooth
    np.testing.assert_array_equal(estimate(em).pitch, SuspensionAwareFilter().run(em).pitch)
    np.testing.assert_array_equal(estimate(em, "paper", Q=0.1).pitch, GroundNormalFilter.paper(Q=0.1).run(em).pitch)
    poses = EgoMotion.from_rotations(em.delta_R, t=em.t)
    np.testing.assert_array_equal(estimate(poses).pitch, GroundNormalFilter().run(em).pitch)
    with pytest.raises(ValueError, match="needs accelerometer data"):
        estimate(poses, "suspension")
    naive = estimate(poses, "naive")                        # the constant normal: a method like the others
    np.testing.assert_array_equal(naive.residual, np.tile(np.eye(3), (len(em), 1, 1)))
    np.testing.assert_array_equal(naive.pitch, 0.0)


def test_methods_reject_options_they_do_not_use_and_bad_noise():
    with pytest.raises(ValueError, match=r"method 'suspension' does not take option\(s\) Q, R; it takes: gains"):
        make_estimator("suspension", Q=0.1, R=1.0)
    with pytest.raises(ValueError, match="unknown method 'kalman'"):
        make_estimator("kalman")
    with pytest.raises(ValueError, match="Q must be a positive .*got -1"):
        make_estimator("filter", Q=-1)
    with pytest.raises(ValueError, match="R must be a positive .*got 0"):
        make_estimator("paper", R=0)
    f = make_estimator("filter", Q=0.05, R=2.0)
    assert f.Q[0, 0] == 0.05 and f.R[2, 2] == 2.0


def test_suspension_Q_stays_the_configured_noise(drive):
    _, em = drive
    f = SuspensionAwareFilter(q_time=0.2)
    Q0 = f.Q.copy()
    f.run(em)
    for fr in list(em.frames())[:20]:
        f.step(fr)
    np.testing.assert_array_equal(f.Q, Q0)
    assert f.Q_last[0, 0] != Q0[0, 0]                    # the last frame's noise is kept apart


# ----------------------------------------------------------------------------- frame rate
def test_design_follows_the_egomotion_rate():
    sim = simulate(240.0, seed=8, imu="nav")
    kw = dict(online_gains=True, gains=(0.0, 0.0), gain_prior_seconds=10.0)
    tracks = {}
    for rate in (10.0, 20.0):
        em = imu_to_egomotion(sim.imu, rate=rate)
        assert em.rate == rate
        f = SuspensionAwareFilter(**kw)
        tracks[rate] = (em, f.run(em), f.gains.copy())
    # the same drive at 10 and 20 frames a second: the same gains and the same pitch (a band-pass
    # designed for 10 Hz on 20 Hz frames gives roll gain +0.67 instead of -0.19 deg per m/s^2, pitch 0.29 deg off)
    # (tolerance: 15 % of the larger gain, the smaller one being near zero on some drives)
    np.testing.assert_allclose(tracks[20.0][2], tracks[10.0][2], rtol=0, atol=0.15 * np.abs(tracks[10.0][2]).max())
    em10, tr10, _ = tracks[10.0]
    em20, tr20, _ = tracks[20.0]
    p20 = np.interp(em10.t, em20.t, tr20.pitch)
    assert np.degrees(np.abs(p20 - tr10.pitch))[50:].max() < 0.15
    # an ImuData is preintegrated at the filter's frame rate
    tr = SuspensionAwareFilter(frame_rate=20.0, **kw).run(sim.imu)
    np.testing.assert_allclose(tr.t, em20.t)
    with pytest.raises(ValueError, match="designed for 20 Hz frames but got 10 Hz"):
        SuspensionAwareFilter(frame_rate=20.0, **kw).run(em10)


def test_foh_filter_matches_scipy_first_order_hold():
    from scipy.signal import cont2discrete, lfilter
    w = 2 * np.pi * 1.7
    A = np.array([[0.0, 1.0], [-w * w, -2 * 0.4 * w]])
    B = np.array([[0.0], [w * w]])
    Ad, Bd, Cd, Dd, _ = cont2discrete((A, B, np.eye(2), np.zeros((2, 1))), 0.05, method="foh")
    u = np.sin(np.linspace(0, 9, 300)) + np.linspace(0, 1, 300)
    x, states = np.zeros(2), []
    for k in range(len(u)):                           # cont2discrete's foh: y_k = C xi_k + D u_k
        states.append(Cd @ x + Dd[:, 0] * u[k])
        x = Ad @ x + Bd[:, 0] * u[k]
    num_x, num_v, den = foh_filter(1.7, 0.4, 0.05)
    np.testing.assert_allclose(lfilter(num_x, den, u), np.array(states)[:, 0], atol=1e-10)
    np.testing.assert_allclose(lfilter(num_v, den, u), np.array(states)[:, 1], atol=1e-8)
    f = IIRFilter(num_x, den, 1)
    np.testing.assert_allclose(np.concatenate([f.step(u[:1]), f.run(u[1:, None])[:, 0]]),
                               lfilter(num_x, den, u), atol=1e-12)


# ----------------------------------------------------------------------------- rotation helpers
def test_rotation_helpers():
    rng = np.random.default_rng(3)
    R = so3.exp(rng.normal(size=(200, 3)))
    q = quat_from_matrix(R)
    assert np.all(q[:, 0] >= 0)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    np.testing.assert_allclose(matrix_from_quat(q), R, atol=1e-14)
    e = euler_zyx(R)
    np.testing.assert_allclose(so3.rotz(e[:, 2]) @ so3.roty(e[:, 1]) @ so3.rotx(e[:, 0]), R, atol=1e-12)
    psi = rng.uniform(-3, 3, 50)
    swing = so3.exp(np.column_stack([rng.normal(scale=0.1, size=(50, 2)), np.zeros(50)]))
    np.testing.assert_allclose(twist_angle(so3.rotz(psi) @ swing), psi, atol=0.02)
    np.testing.assert_allclose(twist_angle(so3.rotz(psi)), psi, atol=1e-12)
    pose = np.eye(4)
    pose[:3, :3] = R[0]
    assert np.array_equal(as_rotations(pose), R[0]) and as_rotations(R[:3]).shape == (3, 3, 3)
    assert np.array_equal(as_rotations(R[0]), R[0])                 # (3, 3) is one matrix
    np.testing.assert_allclose(as_rotations(np.array([0.0, 0.0, 0.1])), so3.rotz(0.1), atol=1e-15)
    with pytest.raises(ValueError, match="delta_R must be a 3x3 rotation"):
        as_rotations(np.zeros((2, 2)))
