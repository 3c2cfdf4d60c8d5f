"""Revisit consistency: pairing against a brute-force search, the metric on passes with known errors, the report."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from imu_ground.cli import main
from imu_ground.evaluation.revisit import (
    RevisitPairs,
    revisit_consistency,
    revisit_differences,
    revisit_pairs,
    revisit_table,
)

REVISIT_DRIVES = ("2011_09_30_drive_0020", "2011_10_03_drive_0034")


def _loop_track(seed: int = 0):
    """A 10 Hz track: a 400 m loop driven twice (GPS-like noise), then part of it backwards, with a stop."""
    rng = np.random.default_rng(seed)
    r = 400.0 / (2 * math.pi)
    s = np.concatenate([np.arange(0, 800, 1.0), np.full(50, 800.0), 800 - np.arange(0, 150, 1.2)])
    t = np.arange(len(s)) * 0.1
    ang = s / r
    backwards = np.arange(len(s)) >= 850
    x = r * np.cos(ang) + rng.normal(0, 0.3, len(s))
    y = r * np.sin(ang) + rng.normal(0, 0.3, len(s))
    heading = ang + math.pi / 2 + np.where(backwards, math.pi, 0.0) + rng.normal(0, math.radians(5), len(s))
    speed = np.gradient(s, t)
    speed = np.abs(speed)
    speed[800:850] = 0.0
    return t, x, y, heading, speed


def _brute_force(t, x, y, heading, speed, max_distance=1.0, max_heading=math.radians(15),  # noqa: B008 (a float)
                 min_sep=30.0):
    n = len(t)
    best = {}
    for i in range(n):
        if speed[i] <= 3:
            continue
        cands = []
        for j in range(n):
            if j == i or speed[j] <= 3 or abs(t[i] - t[j]) < min_sep:
                continue
            dh = (heading[i] - heading[j] + math.pi) % (2 * math.pi) - math.pi
            d = math.hypot(x[i] - x[j], y[i] - y[j])
            if d <= max_distance and abs(dh) <= max_heading:
                cands.append((d, j))
        if cands:
            best[i] = min(cands)[1]
    return sorted({(min(i, j), max(i, j)) for i, j in best.items()})


def test_pairs_match_brute_force():
    t, x, y, heading, speed = _loop_track()
    i, j = revisit_pairs(t, x, y, heading, speed)
    expected = _brute_force(t, x, y, heading, speed)
    assert len(expected) > 100                      # the loop's second lap pairs with its first
    assert list(zip(i.tolist(), j.tolist(), strict=True)) == expected
    # the backwards leg (opposite heading) and the stop pair with nothing
    assert np.all(j < 800) and np.all(i < 800)
    assert np.all(t[j] - t[i] >= 30.0)


def test_pairs_respect_usable_mask_and_thresholds():
    t, x, y, heading, speed = _loop_track(1)
    usable = np.ones(len(t), bool)
    usable[::3] = False
    i, j = revisit_pairs(t, x, y, heading, speed, usable)
    assert usable[i].all() and usable[j].all()
    i2, _ = revisit_pairs(t, x, y, heading, speed, max_distance=0.3)
    assert 0 < len(i2) < len(revisit_pairs(t, x, y, heading, speed)[0])
    i3, _ = revisit_pairs(t, x, y, heading, speed, min_separation=1e6)
    assert len(i3) == 0


def _passes(n: int, est_err_1, est_err_2, seed: int = 2):
    """Two passes over the same road: INS = road + body; the estimate = body + error (rad)."""
    rng = np.random.default_rng(seed)
    road_p, road_r = rng.normal(0, 0.02, n), rng.normal(0, 0.02, n)
    body = rng.normal(0, 0.01, (2, n, 2))
    mount = np.radians([0.7, -0.4])                         # a static offset: cancels
    ins_p = np.concatenate([road_p, road_p]) + np.concatenate([body[0, :, 0], body[1, :, 0]]) + mount[0]
    ins_r = np.concatenate([road_r, road_r]) + np.concatenate([body[0, :, 1], body[1, :, 1]]) + mount[1]
    err = np.concatenate([est_err_1, est_err_2])
    pitch = np.concatenate([body[0, :, 0], body[1, :, 0]]) + err[:, 0]
    roll = np.concatenate([body[0, :, 1], body[1, :, 1]]) + err[:, 1]
    pairs = RevisitPairs(np.arange(n), np.arange(n) + n, ins_p, ins_r)
    return pairs, pitch, roll


def test_metric_perfect_estimate_is_zero():
    n = 300
    pairs, pitch, roll = _passes(n, np.zeros((n, 2)), np.zeros((n, 2)))
    m = revisit_consistency(*revisit_differences(pairs, pitch, roll))
    assert m["n"] == n
    assert m["pitch_deg"] == pytest.approx(0.0, abs=1e-9) and m["roll_deg"] == pytest.approx(0.0, abs=1e-9)


def test_metric_constant_opposite_errors():
    """Errors +e on one pass and -e on the other: |difference| = 2 e, metric sqrt(2) e (per angle, signs kept)."""
    n = 200
    e = np.radians([0.05, 0.12])
    pairs, pitch, roll = _passes(n, np.tile(e, (n, 1)), np.tile(-e, (n, 1)))
    dp, dr = revisit_differences(pairs, pitch, roll)
    # road = INS - estimate: an estimate too high by e makes the road too low by e
    assert np.allclose(dp, 2 * e[0]) and np.allclose(dr, 2 * e[1])
    m = revisit_consistency(dp, dr)
    assert m["pitch_deg"] == pytest.approx(math.sqrt(2) * 0.05, rel=1e-9)
    assert m["roll_deg"] == pytest.approx(math.sqrt(2) * 0.12, rel=1e-9)


def test_metric_independent_errors_give_per_pass_mean_error():
    """Independent N(0, s^2) errors on both passes: metric -> E|N(0, s^2)| = s sqrt(2/pi)."""
    n = 200_000
    rng = np.random.default_rng(5)
    s = np.radians([0.1, 0.2])
    pairs, pitch, roll = _passes(n, rng.normal(0, 1, (n, 2)) * s, rng.normal(0, 1, (n, 2)) * s)
    m = revisit_consistency(*revisit_differences(pairs, pitch, roll))
    assert m["pitch_deg"] == pytest.approx(0.1 * math.sqrt(2 / math.pi), rel=0.01)
    assert m["roll_deg"] == pytest.approx(0.2 * math.sqrt(2 / math.pi), rel=0.01)


def test_invalid_frames_drop_their_pairs():
    n = 50
    pairs, pitch, roll = _passes(n, np.zeros((n, 2)), np.zeros((n, 2)))
    valid = np.ones(2 * n, bool)
    valid[[3, n + 7]] = False
    dp, _ = revisit_differences(pairs, pitch, roll, valid)
    assert len(dp) == n - 2
    assert revisit_consistency(dp[:0], dp[:0])["n"] == 0


def test_revisit_table_pools_pairs():
    res = pd.DataFrame({"drive": ["a", "b", "c"], "method": "m", "valid": True, "revisit_n": [10, 30, 0],
                        "revisit_pitch_sum": [1.0, 1.0, 0.0], "revisit_roll_sum": [2.0, 6.0, 0.0]})
    tab = revisit_table(res)
    assert list(tab.index.get_level_values(0)) == ["a", "b", "pooled"]
    assert tab.loc[("pooled", "m"), "pairs"] == 40
    assert tab.loc[("pooled", "m"), "pitch_deg"] == pytest.approx(2.0 / 40 / math.sqrt(2))
    assert tab.loc[("a", "m"), "roll_deg"] == pytest.approx(0.2 / math.sqrt(2))


def test_evaluate_reports_revisit_on_shared_drives(shared_data, tmp_path, capsys):
    folder = tmp_path / "drives"
    folder.mkdir()
    for name in REVISIT_DRIVES:
        (folder / f"{name}.csv.gz").symlink_to(shared_data / "kitti_imu100" / f"{name}.csv.gz")
    csv = tmp_path / "res.csv"
    md = tmp_path / "summary.md"
    code = main(["evaluate", "--real", str(folder), "--methods", "suspension,naive", "--no-progress",
                 "--csv", str(csv), "--markdown", str(md)])
    out = capsys.readouterr().out
    assert code == 0
    assert "revisit" in out
    assert "reference's own uncertainty" in out
    assert "Revisit consistency" in md.read_text() and "| pooled | suspension |" in md.read_text()
    res = pd.read_csv(csv)
    tab = revisit_table(res)
    for name in REVISIT_DRIVES:
        assert tab.loc[(name, "naive"), "pairs"] > 150
        assert name in out
    pooled = tab.loc[("pooled", "suspension")]
    assert pooled["pairs"] == tab.loc[[(n, "suspension") for n in REVISIT_DRIVES], "pairs"].sum()
    # the constant normal's differences are the INS attitude's own: the road's pitch and roll do repeat
    assert 0.02 < tab.loc[(REVISIT_DRIVES[0], "naive"), "pitch_deg"] < 0.2
    # the suspension model beats the constant normal in pitch on both drives
    for name in REVISIT_DRIVES:
        assert tab.loc[(name, "suspension"), "pitch_deg"] < tab.loc[(name, "naive"), "pitch_deg"]


def test_sigma_table_pools_frames_per_bin():
    from imu_ground.evaluation.runner import SIGMA_BINS, sigma_table
    nb = len(SIGMA_BINS) - 1
    rows = []
    for method, err in (("a", 1.0), ("b", 2.0)):
        for drive, n in (("d1", 10), ("d2", 30)):
            row = {"drive": drive, "method": method, "kind": "real", "valid": True}
            for b in range(nb):
                k = n if b == 2 else 0                        # every frame in the third bin
                row.update({f"sigma{b}_n": k, f"sigma{b}_sum": err * k, f"sigma{b}_ref_sum": 0.12 * k})
            rows.append(row)
    rows.append({"drive": "d3", "method": "a", "kind": "real", "valid": False})
    tab = sigma_table(pd.DataFrame(rows))
    assert len(tab) == 1                                        # empty bins are left out
    lo, hi = SIGMA_BINS[2], SIGMA_BINS[3]
    row = tab.loc[f"{lo:g}-{hi:g}"]
    assert row["frames"] == 40 and row["a"] == pytest.approx(1.0) and row["b"] == pytest.approx(2.0)
    assert row["ref_floor_deg"] == pytest.approx(math.sqrt(2 / math.pi) * 0.12)
