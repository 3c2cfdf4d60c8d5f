"""``calibrate`` says what a drive lacks (no driving, too short), which tilt source it used and why, and a
calibration file with non-finite values is refused where it is loaded."""
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.cli import main
from imu_ground.datasets import read_imu
from imu_ground.evaluation.simulate import simulate
from imu_ground.filters import calibrate

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(scope="module")
def parked(tmp_path_factory):
    """60 s standing still: gravity plus sensor noise, never moving."""
    rng = np.random.default_rng(0)
    n = 6000
    df = pd.DataFrame({"t": np.arange(n) * 0.01, **{c: rng.normal(0, 1e-3, n) for c in ("wx", "wy", "wz")},
                       "ax": rng.normal(0, 0.02, n), "ay": rng.normal(0, 0.02, n), "az": 9.81 + rng.normal(0, 0.02, n)})
    path = tmp_path_factory.mktemp("parked") / "parked.csv"
    df.to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def sim():
    return simulate(120.0, seed=3, imu="mems")


def _frames(em, sel):
    from imu_ground.imu import EgoMotion
    return EgoMotion(em.t[sel], em.delta_R[sel], em.delta_v[sel], em.delta_t[sel], em.stationary[sel], em.valid[sel])


def _one_error_line(capsys) -> str:
    """The one error line on stderr (warnings, ``file: warning: ...``, may stand before it, one line each)."""
    lines = capsys.readouterr().err.strip().splitlines()
    errors = [ln for ln in lines if ": warning: " not in ln]
    assert len(errors) == 1 and errors[0].startswith("imu-ground ") and ": error: " in errors[0], lines
    return errors[0]


def test_a_log_that_never_moves_cannot_give_gains(parked, tmp_path, capsys):
    out = tmp_path / "car.txt"
    assert main(["calibrate", str(parked), "-o", str(out), "--lever-arm", "0.3", "0", "0.9"]) == 2
    err = _one_error_line(capsys)
    assert "never moves" in err and "--lever-arm" in err and str(parked) in err
    assert not out.exists()
    # the tilt alone is fine (from the standstill), the yaw stays the sensor's x axis, said
    assert main(["calibrate", str(parked), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert "yaw not determined" in captured.err and "tilt_source: standstill" in captured.out


def test_five_seconds_of_driving_are_refused_saying_how_much_is_needed(sim, tmp_path, capsys):
    df = pd.DataFrame({"t": sim.imu.t, "wx": sim.imu.gyro[:, 0], "wy": sim.imu.gyro[:, 1], "wz": sim.imu.gyro[:, 2],
                       "ax": sim.imu.accel[:, 0], "ay": sim.imu.accel[:, 1], "az": sim.imu.accel[:, 2]})
    moving = np.flatnonzero(sim.imu.t > 40)[0]
    log = tmp_path / "five.csv"
    df.iloc[moving:moving + 500].to_csv(log, index=False)
    assert main(["calibrate", str(log), "-o", str(tmp_path / "car.txt"), "--lever-arm", "0.3", "0", "0.9"]) == 2
    err = _one_error_line(capsys)
    assert "too little data for the tilt" in err and "20 s of cruise" in err and "--tilt" in err


def test_five_seconds_with_a_standstill_leave_yaw_at_its_default_and_refuse_gains(sim):
    from imu_ground.imu import imu_to_egomotion
    em = imu_to_egomotion(sim.imu)
    still = np.flatnonzero(em.stationary)
    assert still.size, "the simulated drive has a standstill"
    k = still[0]
    part = _frames(em, slice(max(0, k - 25), k + 25))
    with pytest.warns(UserWarning, match="yaw not determined"):
        cal = calibrate(part, gains=False)
    up = cal.rotation[2]
    x = np.array([1.0, 0.0, 0.0]) - up[0] * up                  # the sensor's x axis on the ground plane
    np.testing.assert_allclose(cal.rotation[0], x / np.linalg.norm(x), atol=1e-12)
    assert cal.stats["yaw_source"].startswith("assumed (sensor x axis)")
    from imu_ground.filters.calibration import TooLittleDataError
    with pytest.raises(TooLittleDataError, match="suspension gains need"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            calibrate(part, gains=True)


def test_auto_tilt_says_which_source_and_why(sim):
    from imu_ground.imu import imu_to_egomotion
    em = imu_to_egomotion(sim.imu)
    with pytest.warns(UserWarning, match=r"tilt \('up'\) from the (all|standstill) frames: .* cruise needs 20 s"):
        cal = calibrate(em, gains=False)
    assert cal.stats["tilt_reason"] and "cruise needs 20 s" in cal.stats["tilt_reason"]
    assert "tilt_reason" in str(cal)


def test_calibration_files_with_non_finite_values_are_refused_on_load(tmp_path, capsys):
    good = ("R: 1 0 0 0 1 0 0 0 1\nt: 0 0 0\n")
    for name, text, what in [("gains.txt", good + "suspension_gains: nan nan\n", "suspension_gains"),
                             ("rot.txt", "R: nan 0 0 0 1 0 0 0 1\n", "'R'"),
                             ("trans.txt", "R: 1 0 0 0 1 0 0 0 1\nt: 0 inf 0\n", "'t'")]:
        path = tmp_path / name
        path.write_text(text)
        assert main(["estimate", str(EXAMPLE), "--extrinsic", str(path), "-o", str(tmp_path / "o.csv")]) == 2
        err = _one_error_line(capsys)
        assert str(path) in err and what in err and "not finite" in err
        assert not (tmp_path / "o.csv").exists()


@pytest.mark.parametrize("flag, values, said", [
    ("--lever-arm", ["nan", "0", "0.9"], "must be 3 finite numbers"),
    ("--lever-arm", ["0", "inf", "0.9"], "must be 3 finite numbers"),
    ("--translation", ["0", "0", "inf"], "must be 3 finite numbers"),
    ("--lever-arm", ["300", "0", "900"], "300 0 900: over 50 m"),      # mm for m: a 0.9 km lever arm, exit 0
    ("--translation", ["0", "-1e9", "1"], "0 -1e+09 1: over 50 m"),
])
def test_non_finite_or_far_lever_arm_or_translation_is_refused_naming_the_flag(tmp_path, cli, flag, values, said):
    """Was written as 'suspension_gains: nan nan' with exit 0."""
    out = tmp_path / "car.txt"
    code, _, err = cli("calibrate", EXAMPLE, "-o", out, flag, *values)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and not out.exists(), err
    assert f"error: {flag} {said}" in lines[0]
    with pytest.raises(ValueError, match=flag.removeprefix("--").replace("-", "_")):
        calibrate(read_imu(EXAMPLE), **{flag.removeprefix("--").replace("-", "_"): [float(v) for v in values]})

def test_calibrate_warnings_carry_the_file_prefix(tmp_path, cli):
    """The example has 2.6 s of cruising: 'up' from the standstills, said as 'LOG: warning: ...'."""
    code, _, err = cli("calibrate", EXAMPLE, "-o", tmp_path / "car.txt", "--lever-arm", "0.3", "0", "0.9")
    assert code == 0, err
    lines = [ln for ln in err.splitlines() if "tilt" in ln]
    assert lines and all(ln.startswith(f"{EXAMPLE}: warning: calibration:") for ln in lines), err
