"""The evaluation: conditions, moving segments, the reference's uncertainty, the method list, evaluate."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.evaluation.baselines import ConstantNormal, EulerEKF
from imu_ground.evaluation.conditions import (
    CONDITIONS,
    MIN_SEGMENT_FRAMES,
    NEAR_STOP_S,
    TURN_YAW_RATE,
    condition_masks,
    frame_signals,
    moving_segments,
    reference_sigma,
    segment_centred,
)
from imu_ground.filters.estimator import GroundEstimator
from imu_ground.imu import EgoMotion

RATE = 10.0


def _egomotion(yaw_rate: np.ndarray, pitch_rate: np.ndarray | None = None) -> EgoMotion:
    n = len(yaw_rate)
    pr = np.zeros(n) if pitch_rate is None else pitch_rate
    d = so3.exp(np.stack([np.zeros(n), pr / RATE, yaw_rate / RATE], axis=1))
    return EgoMotion.from_rotations(d, t=(np.arange(n) + 1) / RATE, rate=RATE)


# ----------------------------------------------------------------------------- conditions
def test_signals_and_conditions_from_known_motion():
    n = 300
    t = (np.arange(n) + 1) / RATE
    speed = np.full(n, 10.0)
    speed[100:130] = 10.0 - 2.0 * (t[100:130] - t[100])          # braking at 2 m/s^2 to 4.2 m/s
    speed[130:] = speed[129]
    yaw = np.where((t > 20) & (t < 25), 0.2, 0.0)                  # a turn at 0.2 rad/s
    sig = frame_signals(_egomotion(yaw), np.eye(3), speed)
    np.testing.assert_allclose(sig["yaw_rate"], yaw, atol=1e-12)
    np.testing.assert_allclose(sig["acc_long"][106:125], -2.0, atol=1e-9)
    m = condition_masks(sig, t)
    assert list(m) == list(CONDITIONS)
    assert m["turning"].sum() == np.count_nonzero(np.abs(yaw) > TURN_YAW_RATE)
    assert m["braking"][106:125].all() and not m["braking"][:90].any() and not m["braking"][140:].any()
    assert m["speed_6_12"][:100].all() and m["speed_3_6"][121:].all() and not m["speed_over_12"].any()
    assert not m["near_stop"].any() and not m["rough"].any()


def test_near_stop_and_rough_road():
    n = 400
    t = (np.arange(n) + 1) / RATE
    speed = np.full(n, 8.0)
    speed[200:220] = 0.0                                            # a 2 s stop
    shake = np.where(t > 30, np.radians(3.0) * np.sin(2 * np.pi * 3.0 * t), 0.0)   # rough from 30 s
    sig = frame_signals(_egomotion(np.zeros(n), shake), np.eye(3), speed)
    m = condition_masks(sig, t)
    near = m["near_stop"]
    assert near[200:220].all()
    dist = np.minimum(np.abs(t - t[200]), np.abs(t - t[219]))
    np.testing.assert_array_equal(near, (dist <= NEAR_STOP_S + 1e-9) | ((t >= t[200]) & (t <= t[219])))
    assert m["rough"][320:].all() and not m["rough"][:280].any()


def test_moving_segments_and_per_segment_centring():
    speed = np.r_[np.full(50, 10.0), np.zeros(10), np.full(60, 8.0), np.zeros(5), np.full(20, 9.0)]
    seg = moving_segments(speed)
    assert set(seg[:50]) == {0} and set(seg[50:60]) == {-1} and set(seg[60:120]) == {1} and set(seg[125:]) == {2}
    ref = np.linspace(0.0, 0.01, speed.size)
    est = ref + np.where(seg == 0, 0.3, np.where(seg == 1, -0.2, 0.1))   # one offset per segment
    err = segment_centred(est, ref, speed > 3.0, seg)
    assert np.nanmax(np.abs(err)) < 1e-12
    assert np.isnan(err[125:]).all()                 # 20 frames: fewer than MIN_SEGMENT_FRAMES
    assert 20 < MIN_SEGMENT_FRAMES <= 50
    assert np.isfinite(err[:50]).all() and np.isnan(err[50:60]).all()
    # per drive the offsets would not cancel
    assert np.abs((est - est.mean()) - (ref - ref.mean())).mean() > 0.1


def test_reference_sigma():
    sigma = reference_sigma(np.array([4.0, 20.0, 0.0]))
    # 0.03 m/s of vertical velocity at 4 m/s is 0.43 deg of grade
    assert math.degrees(sigma[0]) == pytest.approx(math.degrees(math.hypot(0.03 / 4.0, math.radians(0.03))))
    assert 0.4 < math.degrees(sigma[0]) < 0.45 and sigma[1] < sigma[0] and np.isinf(sigma[2])


# ----------------------------------------------------------------------------- baselines on the protocol
@pytest.mark.parametrize("make", [lambda: ConstantNormal(), lambda: EulerEKF(follow_heading=True)])
def test_baselines_follow_the_protocol(make):
    rng = np.random.default_rng(1)
    n = 80
    em = _egomotion(0.1 * np.sin(np.arange(n) / 7.0), np.radians(2.0) * rng.standard_normal(n))
    est = make()
    assert isinstance(est, GroundEstimator)
    batch = est.run(em)
    est.reset()
    steps = [est.step(f) for f in em.frames()]
    np.testing.assert_allclose([s.pitch for s in steps], batch.pitch, atol=1e-12)
    np.testing.assert_allclose([s.roll for s in steps], batch.roll, atol=1e-12)
    np.testing.assert_array_equal(batch.t, em.t)
    assert batch.valid.all()
    # a bad frame raises and leaves the state as it was
    before = est.cumulative.copy()
    with pytest.raises(ValueError, match="not a rotation"):
        est.step(em.frame_at(0)._replace(delta_R=2.0 * np.eye(3)))
    np.testing.assert_array_equal(est.cumulative, before)


def test_euler_ekf_has_no_smoother():
    with pytest.raises(ValueError, match="no offline smoother"):
        EulerEKF().run(np.tile(np.eye(3), (3, 1, 1)), smooth=True)


# ----------------------------------------------------------------------------- the runner
def test_methods_are_constructors_on_the_protocol():
    from imu_ground.evaluation.runner import EVALUATION_METHODS, METHODS
    from imu_ground.filters import Extrinsic
    names = [m.name for m in EVALUATION_METHODS]
    assert {"suspension", "paper", "naive", "ekf", "paper-tuned"} <= set(names)
    assert len(set(names)) == len(names) and list(METHODS) == names
    for m in EVALUATION_METHODS:
        assert isinstance(m.factory(extrinsic=Extrinsic()), GroundEstimator), m.name


@pytest.fixture(scope="module")
def synthetic_results():
    from imu_ground.evaluation.runner import evaluate, synthetic_drives
    drives = synthetic_drives(1, seed=3, grades=("nav",), progress=False, duration_range=(60.0, 70.0))
    return drives, evaluate(drives, ["naive", "paper"], progress=False, keep_tracks=True)


def test_evaluate_reports_conditions_segments_and_reference(synthetic_results):
    from imu_ground.evaluation.runner import conditions_table, summary_table
    _, (res, _) = synthetic_results
    row = res.set_index("method").loc["paper"]
    assert row["n"] > 300 and np.isfinite(row["seg_pitch_mean"]) and row["seg_n"] <= row["n"]
    assert row["ref_floor"] == 0.0 and row["ref_share"] == 0.0          # exact synthetic truth
    speed_n = sum(row[f"cond_{k}_n"] for k in ("speed_3_6", "speed_6_12", "speed_over_12"))
    assert speed_n == row["n"]                                           # the speed bins cover every frame
    table = conditions_table(res)
    assert list(table.columns) == list(CONDITIONS.values()) + ["all"]
    assert table.loc[("synthetic-nav", "paper"), "all"] == pytest.approx(row["pitch_mean"])
    summary = summary_table(res)
    assert {"seg_pitch_deg", "ref_floor_deg", "ref_share"} <= set(summary.columns)


def test_evaluate_uses_valid_frames_only(synthetic_results):
    """Frames the estimator flags invalid do not count, however wrong they are."""
    from imu_ground.evaluation.runner import _drive_metrics
    drives, (_, tracks) = synthetic_results
    d = drives[0]
    track = tracks[(d.name, "paper")]
    base = _drive_metrics(d, track)
    bad = np.flatnonzero(d.truth["evaluate"].to_numpy())[50:80]
    track.pitch = track.pitch.copy()
    track.pitch[bad] += 0.5                                               # 29 deg off
    worse = _drive_metrics(d, track)
    assert worse["pitch_mean"] > 10 * base["pitch_mean"]
    track.valid = track.valid.copy()
    track.valid[bad] = False
    flagged = _drive_metrics(d, track)
    assert flagged["n"] == base["n"] - len(bad)
    assert flagged["pitch_mean"] < 1.2 * base["pitch_mean"]


def test_real_drive_metrics(shared_data):
    from imu_ground.evaluation.runner import evaluate, load_real_drives
    drives = load_real_drives(shared_data / "kitti_imu100", names=["2011_09_26_drive_0009", "2011_09_28_drive_0002"],
                              progress=False)
    assert all(d.valid for d in drives)
    res = evaluate(drives, ["naive"], progress=False)
    assert (res["ref_floor"] > 0).all() and ((res["ref_share"] > 0) & (res["ref_share"] <= 1)).all()
    assert (res["seg_pitch_mean"] <= res["pitch_mean"] + 0.05).all()


def test_pooled_ref_share_is_a_share():
    """Each drive explains at most its own squared error; the pooled share was sum(ref) / sum(err) (3.46)."""
    import pandas as pd
    from imu_ground.evaluation.runner import summary_table
    rows = [dict(drive=f"d{k}", method="paper", kind="real", grade="", valid=True, pitch_mean=0.1,
                 seg_pitch_mean=0.1, ref_floor=0.1, us_per_frame=1.0, ref_var_sum=ref, err_sq_sum=err)
            for k, (ref, err) in enumerate([(3.46, 1.0), (1.0, 4.0)])]
    share = summary_table(pd.DataFrame(rows)).loc[("real", "paper"), "ref_share"]
    assert share == pytest.approx((1.0 + 1.0) / 5.0)


def test_ref_share_and_floor_of_one_short_real_drive_are_bounded(shared_data, tmp_path, cli):
    """``evaluate --real`` on a folder with one 10 s drive printed ref_share 3.46."""
    import pandas as pd
    src = shared_data / "kitti_imu100" / "2011_09_26_drive_0009.csv.gz"
    df = pd.read_csv(src)
    folder = tmp_path / "short"
    folder.mkdir()
    df[df["t"] < 10.0].to_csv(folder / src.name, index=False)
    code, out, err = cli("evaluate", "--real", folder, "--methods", "naive,paper,suspension")
    assert code == 0, err
    lines = out.splitlines()
    head = lines[0].split()
    shares = [float(ln.split()[head.index("ref_share")]) for ln in lines[1:4]]
    assert all(0 < s <= 1 for s in shares), out
    # the floor of a perfect estimator was 0.129 deg, above every method's error (0.08-0.11 deg)
    for ln in lines[1:4]:
        cells = ln.split()
        assert 0 < float(cells[head.index("ref_floor_deg")]) <= float(cells[head.index("mean_deg")]), out


@pytest.mark.parametrize("sigma_deg, c_deg", [(0.5, 0.1), (0.05, 0.2)])
def test_ref_floor_is_the_normal_floor_at_most_the_drives_own_error(sigma_deg, c_deg):
    """Closed form: the track is the reference +-c alternately (|error| = c exactly with the mean removed), the
    reference's 1-sigma is constant: the floor is min(sqrt(2/pi) sigma, c); it was sqrt(2/pi) sigma (0.399 > 0.1)."""
    from types import SimpleNamespace

    import pandas as pd

    from imu_ground.evaluation.runner import _drive_metrics
    n = 200
    t = 0.1 * np.arange(n)
    pitch = 0.02 * np.sin(0.3 * t)
    zeros = np.zeros(n)
    truth = pd.DataFrame({"t": t, "pitch": pitch, "roll": np.nan, "speed": 10.0, "acc_long": zeros,
                          "yaw_rate": zeros, "pitch_rate_hf": zeros, "evaluate": True,
                          "ref_sigma": np.radians(sigma_deg)})
    drive = SimpleNamespace(truth=truth, has_roll=False, remove_mean=True)
    track = SimpleNamespace(pitch=pitch + np.radians(c_deg) * (-1.0) ** np.arange(n), roll=zeros,
                            valid=np.ones(n, bool))
    row = _drive_metrics(drive, track)
    assert row["pitch_mean"] == pytest.approx(c_deg, rel=1e-9)
    assert row["ref_floor"] == pytest.approx(min(math.sqrt(2.0 / math.pi) * sigma_deg, c_deg), rel=1e-9)
