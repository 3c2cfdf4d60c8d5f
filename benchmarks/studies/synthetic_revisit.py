"""What the revisit check of the 1-sigma sees when the truth is exact: the same road driven twice.

    python benchmarks/studies/synthetic_revisit.py           # prints the table; make_results.py puts it in RESULTS.md

The revisit check of the 1-sigma (``benchmarks/studies/confidence.py``) takes, where a real drive
passes the same place twice, the RMS of ``difference / sqrt(sigma_1^2 + sigma_2^2)`` of the road's
attitude between the passes; it asked for 0.8-1.25, as if the two passes' errors were independent (now a
diagnostic, not a target).
Here each drive of the synthetic suite (seed 1, held out from the 1-sigma's fit) is driven a second
time on the same road (:func:`imu_ground.evaluation.simulate.second_pass`: the same vehicle and sensor
biases, its own white noise), with the same speed profile, 1.1 and 1.25 times as fast at every place,
or a new random profile of the drive's style. The default method
(:class:`~imu_ground.filters.suspension.SuspensionAwareFilter`) runs on each pass; the pairs are the
evaluation's (:func:`imu_ground.evaluation.revisit.revisit_pairs`: truth positions within 1 m,
headings within 15 deg, both above 3 m/s; the first 10 s of each pass left out, where the filter
starts), and the difference is that of the two passes' errors against the exact truth.

Rows per IMU grade and second pass: the pairs, the mean absolute speed difference at them (m/s), the first
pass's coverage (share of its paired frames within 1 sigma), the RMS error per pass and
``RMS(difference) / sqrt(2)`` (deg: equal when the passes' errors are independent, zero when they
repeat), and the z RMS of the check. For scale, the two real revisit drives with the same check
(default method, IMU only): their pairs' mean absolute speed difference (INS) and z RMS.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

from imu_ground.evaluation.drives import synthetic_drive
from imu_ground.evaluation.revisit import revisit_pairs
from imu_ground.evaluation.simulate import second_pass, simulate_suite
from imu_ground.filters.suspension import SuspensionAwareFilter

sys.path.insert(0, str(Path(__file__).resolve().parent))
from confidence import DATA, REVISIT_DRIVES, revisit_estimate, truth_at_frames  # noqa: E402  (the sibling study: one pairing)

DEG = math.pi / 180.0
#: Second passes: label -> ``second_pass`` keywords (speed_seed: a new random profile).
PASSES = {"same speed profile": {}, "1.1x as fast": {"speed_scale": 1.1}, "1.25x as fast": {"speed_scale": 1.25},
          "new speed profile": {"speed_seed": 1}}
SKIP_START = 10.0          # s of each pass left out (the filter's start)


def _pass(sim) -> dict:
    """The default method's errors and 1-sigma on one pass, with the truth's pose and the frames that may pair."""
    d = synthetic_drive(sim)
    tr = SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion)
    em, truth = d.egomotion, d.truth
    return dict(t=np.asarray(em.t, dtype=float), **truth_at_frames(d, ("x", "y", "heading")),
                speed=truth["speed"].to_numpy(), usable=truth["evaluate"].to_numpy(bool) & (np.asarray(em.t) > SKIP_START),
                e=np.stack([tr.pitch - truth["pitch"].to_numpy(), tr.roll - truth["roll"].to_numpy()], 1),
                std=np.stack([tr.pitch_std, tr.roll_std], 1))


def _pairs(a: dict, b: dict) -> tuple[np.ndarray, np.ndarray]:
    """The evaluation's pairs between pass ``a`` and pass ``b`` (indices into each)."""
    n = len(a["t"])
    offset = a["t"][-1] + 60.0                      # (the second pass later than the minimum separation)
    cat = {k: np.concatenate([a[k], b[k] + (offset if k == "t" else 0.0)]) for k in ("t", "x", "y", "heading", "speed")}
    i, j = revisit_pairs(cat["t"], cat["x"], cat["y"], cat["heading"], cat["speed"],
                         np.concatenate([a["usable"], b["usable"]]))
    cross = (i < n) & (j >= n)
    return i[cross], j[cross] - n


def _real_rows() -> list[dict]:
    """Mean absolute speed difference and z RMS at the real revisit drives' pairs (default method, IMU only)."""
    out = []
    for name in REVISIT_DRIVES:
        path = DATA / f"{name}.csv.gz"
        if not path.is_file():
            continue
        res, rp, ins = revisit_estimate(path, "none")
        tr, v = res.track, ins["speed"]
        row = {"drive": name, "second pass": "the drive's own", "pairs": len(rp),
               "mean abs speed difference, m/s": float(np.mean(np.abs(v[rp.j] - v[rp.i])))}
        for angle, ins in (("pitch", rp.ins_pitch), ("roll", rp.ins_roll)):
            road, s = ins - getattr(tr, angle), getattr(tr, f"{angle}_std")
            d = road[rp.j] - road[rp.i]
            row[f"{angle} RMS(difference) / sqrt(2), deg"] = float(np.sqrt(np.mean(d * d) / 2.0)) / DEG
            row[f"{angle} z RMS"] = float(np.sqrt(np.mean(d * d / (s[rp.i] ** 2 + s[rp.j] ** 2))))
        out.append(row)
    return out


def rows(n: int = 8, seed: int = 1) -> list[dict]:
    """The table of the module docstring: ``n`` drives a grade of the synthetic suite of ``seed``."""
    acc: dict = {}
    for sim in simulate_suite(n, seed=seed):
        first = _pass(sim)
        for label, kw in PASSES.items():
            second = _pass(second_pass(sim, **kw))
            i, j = _pairs(first, second)
            a = acc.setdefault((sim.imu_model.name, label), {"dv": [], "e1": [], "e2": [], "s1": [], "s2": []})
            a["dv"].append(np.abs(second["speed"][j] - first["speed"][i]))
            for k, p, idx in (("1", first, i), ("2", second, j)):
                a["e" + k].append(p["e"][idx])
                a["s" + k].append(p["std"][idx])
    out = []
    for (grade, label), a in acc.items():
        e1, e2, s1, s2 = (np.concatenate(a[k]) for k in ("e1", "e2", "s1", "s2"))
        d = e2 - e1
        row = {"drive": f"synthetic seed {seed}, {n} drives, {grade}", "second pass": label, "pairs": len(d),
               "mean abs speed difference, m/s": float(np.concatenate(a["dv"]).mean())}
        for c, angle in enumerate(("pitch", "roll")):
            row[f"{angle} first pass % within 1 sigma"] = 100.0 * float(np.mean(np.abs(e1[:, c]) <= s1[:, c]))
            row[f"{angle} RMS error per pass, deg"] = float(np.sqrt(0.5 * np.mean(e1[:, c] ** 2 + e2[:, c] ** 2))) / DEG
            row[f"{angle} RMS(difference) / sqrt(2), deg"] = float(np.sqrt(np.mean(d[:, c] ** 2) / 2.0)) / DEG
            row[f"{angle} z RMS"] = float(np.sqrt(np.mean(d[:, c] ** 2 / (s1[:, c] ** 2 + s2[:, c] ** 2))))
        out.append(row)
    return out + _real_rows()


def main() -> None:
    for r in rows():
        print("; ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()))


if __name__ == "__main__":
    main()
