"""Tests of imu_ground.evaluation.metrics against hand-computed values."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imu_ground import so3
from imu_ground.evaluation.metrics import (evaluate_drive, frame_errors, normal_angle,
                                normal_from_pitch_roll, summarize, per_drive_table, wrap_angle, wrap_pi)

D = math.radians


def test_normal_conventions():
    np.testing.assert_allclose(normal_from_pitch_roll(0.0, 0.0), [0, 0, 1], atol=1e-15)
    # nose down by 90 deg: the road's up axis points backwards in the body
    np.testing.assert_allclose(normal_from_pitch_roll(D(90), 0.0), [-1, 0, 0], atol=1e-15)
    # left side up by 30 deg: the road's up axis leans to the body's left (+y)
    np.testing.assert_allclose(normal_from_pitch_roll(0.0, D(30)), [0, 0.5, math.sqrt(3) / 2],
                               atol=1e-15)


def test_normal_matches_kitti_rotation_order():
    rng = np.random.default_rng(0)
    p, r = rng.uniform(-0.5, 0.5, (2, 50))
    expected = np.swapaxes(so3.roty(p) @ so3.rotx(r), -1, -2) @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(normal_from_pitch_roll(p, r), expected, atol=1e-14)
    np.testing.assert_allclose(np.linalg.norm(normal_from_pitch_roll(p, r), axis=-1), 1.0)


def test_normal_angle_values():
    assert normal_angle([1, 0, 0], [0, 1, 0]) == pytest.approx(90.0)
    assert normal_angle([1, 0, 0], [-1, 0, 0]) == pytest.approx(180.0)
    assert normal_angle([0, 0, 2], [0, 0, 1]) == 0.0
    # tiny angles survive (acos of the dot product would return 0 here)
    eps = 1e-9
    assert normal_angle([0, 0, 1], [0, math.sin(eps), math.cos(eps)]) == pytest.approx(
        math.degrees(eps), rel=1e-9)


def test_wrap_angle():
    np.testing.assert_allclose(wrap_angle([190.0, -190.0, 180.0, -180.0, 0.0, 359.0]),
                               [-170.0, 170.0, 180.0, 180.0, 0.0, -1.0])


def test_wrap_pi_is_wrap_angle_in_rad_on_the_half_open_range():
    a = np.linspace(-20.0, 20.0, 4001)
    w = wrap_pi(a)
    assert np.all((w >= -np.pi) & (w < np.pi))
    np.testing.assert_allclose(np.exp(1j * w), np.exp(1j * a), atol=1e-12)
    np.testing.assert_allclose(np.degrees(w[np.abs(w) < 3.0]), wrap_angle(np.degrees(a))[np.abs(w) < 3.0], atol=1e-9)
    assert wrap_pi(np.array([np.pi]))[0] == -np.pi


def test_frame_errors_hand_values():
    # estimate: pitch 3 deg, roll 0; truth: pitch 0, roll 4 deg
    err = frame_errors([D(3)], [0.0], [0.0], [D(4)])
    assert err["pitch"][0] == pytest.approx(3.0)
    assert err["roll"][0] == pytest.approx(-4.0)
    # n_est . n_true = cos 3 cos 4 (the x and y components are orthogonal)
    expected = math.degrees(math.acos(math.cos(D(3)) * math.cos(D(4))))
    assert err["angle"][0] == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(4.9985, abs=1e-4)


def test_frame_errors_pitch_only_and_sign():
    err = frame_errors(np.radians([1.0, -2.0]), np.radians([0.5, 0.5]))
    assert list(err.columns) == ["pitch"]
    np.testing.assert_allclose(err["pitch"], [0.5, -2.5])
    with pytest.raises(ValueError):
        frame_errors([0.0], [0.0], est_roll=[0.0])
    with pytest.raises(ValueError):
        frame_errors([0.0, 1.0], [0.0])


def test_pure_pitch_angle_equals_pitch_error():
    p = np.radians(np.linspace(-5, 5, 11))
    err = frame_errors(p, np.zeros_like(p), np.zeros_like(p), np.zeros_like(p))
    np.testing.assert_allclose(err["angle"], np.abs(np.degrees(p)), atol=1e-12)


def test_summarize_hand_values():
    s = summarize([1.0, -2.0, 3.0, -4.0])
    assert s["n"] == 4
    assert s["mean"] == pytest.approx(2.5)
    assert s["median"] == pytest.approx(2.5)
    assert s["rms"] == pytest.approx(math.sqrt(30.0 / 4.0))
    # |e| sorted 1,2,3,4: rank 0.95*3 = 2.85 -> 3 + 0.85 * (4 - 3)
    assert s["p95"] == pytest.approx(3.85)
    assert s["bias"] == pytest.approx(-0.5)
    assert s["n_nonfinite"] == 0


def test_summarize_mask_and_nonfinite():
    s = summarize([1.0, 100.0, np.nan, -3.0], mask=[True, False, True, True])
    assert s["n"] == 2 and s["n_nonfinite"] == 1
    assert s["mean"] == pytest.approx(2.0)
    assert s["bias"] == pytest.approx(-1.0)
    empty = summarize([1.0, 2.0], mask=[False, False])
    assert empty["n"] == 0 and math.isnan(empty["mean"])
    with pytest.raises(ValueError):
        summarize([1.0, 2.0], mask=[True])


def test_evaluate_drive_remove_mean():
    truth = np.zeros(3)
    est = np.radians([1.0, 2.0, 3.0])
    raw = evaluate_drive(est, truth)
    assert raw["pitch"]["mean"] == pytest.approx(2.0)
    centred = evaluate_drive(est, truth, remove_mean=True)
    # centred estimate -1, 0, 1 deg against 0
    assert centred["pitch"]["mean"] == pytest.approx(2.0 / 3.0)
    assert centred["pitch"]["rms"] == pytest.approx(math.sqrt(2.0 / 3.0))
    assert centred["pitch"]["bias"] == pytest.approx(0.0, abs=1e-12)
    # a constant offset between estimate and truth disappears entirely
    t = np.radians(np.array([0.3, -0.1, 0.5, 0.2]))
    off = evaluate_drive(t + D(1.7), t, t * 0 + D(-0.4), t * 0, remove_mean=True)
    for k in ("pitch", "roll", "angle"):
        assert off[k]["mean"] == pytest.approx(0.0, abs=1e-12)


def test_evaluate_drive_means_over_mask_only():
    est = np.radians([10.0, 1.0, 3.0])
    truth = np.radians([0.0, 0.0, 0.0])
    mask = np.array([False, True, True])
    r = evaluate_drive(est, truth, mask=mask, remove_mean=True)
    # mean of the masked estimate is 2: errors -1, +1
    assert r["pitch"]["n"] == 2
    assert r["pitch"]["mean"] == pytest.approx(1.0)


def test_evaluate_drive_nan_frames_left_out():
    est = np.radians([1.0, np.nan, 3.0])
    truth = np.radians([0.0, 0.0, np.nan])
    r = evaluate_drive(est, truth, remove_mean=True)
    assert r["pitch"]["n"] == 1 and r["pitch"]["mean"] == pytest.approx(0.0)


def test_evaluate_drive_with_roll_and_table():
    a = evaluate_drive(np.radians([1.0, 1.0]), np.zeros(2), np.radians([0.0, 0.0]),
                       np.radians([1.0, 1.0]))
    assert set(a) == {"pitch", "roll", "angle"}
    assert a["angle"]["mean"] == pytest.approx(
        math.degrees(math.acos(math.cos(D(1)) ** 2)), rel=1e-10)
    b = evaluate_drive(np.radians([2.0]), np.zeros(1))
    table = per_drive_table({"a": a, "b": b}, "pitch")
    assert table.loc["mean over drives", "mean"] == pytest.approx(1.5)
    assert table.loc["mean over drives", "n"] == 3
    assert list(per_drive_table({"a": a}, "pitch", stat="rms").columns) == ["rms"]
