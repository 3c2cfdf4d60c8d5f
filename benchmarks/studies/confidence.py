"""How sure, and what the road does: the 1-sigma's calibration, the status, road grade and bank, mount changes.

    python benchmarks/studies/confidence.py              # prints the table; make_results.py puts it in RESULTS.md

Rows (``rows()``):

- **1-sigma coverage, synthetic**: share of moving frames with ``|error| <= 1 sigma`` for pitch and
  roll (target 55-80 %, aim 68 %), per method and IMU grade, on a suite (seed 1) other than the one
  the constants were fitted on (seed 0, ``benchmarks/studies/calibrate_std.py``); the time to converge
  (first frame whose status is not ``converging``) and the share of the truth's stationary frames
  whose status is ``standstill`` (target >= 90 %).
- **1-sigma on the revisit drives**: where a real drive passes the same place twice
  (the evaluation's pairing, :func:`imu_ground.evaluation.revisit.revisit_pairs`: valid 10 Hz frames
  above 3 m/s, positions within 1 m, headings within 15 deg, at least 30 s apart, each frame with its
  closest partner, each pair once), the road's attitude
  ``INS angle - estimated angle`` must repeat; RMS of ``difference / sqrt(sigma_1^2 + sigma_2^2)``
  (target 0.8-1.25).
- **Road grade and bank**: synthetic navigation-grade drives with the true speed, mean absolute error
  with each drive's mean removed (target <= 0.15 deg); real revisit drives with ``--speed auto``,
  ``mean |difference| / sqrt(2)`` (targets 0.12 deg grade, 0.22 deg bank).
- **Mount change**: synthetic drives whose sensor turns by 1 deg in pitch halfway
  (:func:`imu_ground.evaluation.simulate.remounted`), with the true speed: the delay until the
  status is ``degraded``; false alarms on the same drives unchanged and on every shared drive of
  ``drives.csv`` with ``--speed auto``.

Rows are long-format: ``check``,
``scope`` (method, IMU grade or drive), ``quantity``, ``figure``, ``target``, ``passed``.
"""
from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[2] / "shared" / "data" / "kitti_imu100"
REVISIT_DRIVES = ("2011_09_30_drive_0020", "2011_10_03_drive_0034")
DEG = math.pi / 180.0


# ----------------------------------------------------------------------------- revisit pairs
def revisit_of(path: Path, res):
    """The revisit pairs of a real drive's estimate (``estimate_log``'s result), by the evaluation's pairing
    (:func:`imu_ground.evaluation.revisit.revisit_pairs`: valid frames near a log sample)."""
    import pandas as pd

    from imu_ground.evaluation.revisit import RevisitPairs, ins_at_frames, revisit_pairs
    em = res.egomotion
    ins = ins_at_frames(pd.read_csv(path), em.t)
    usable = np.asarray(em.valid, dtype=bool) & ins["near"]
    i, j = revisit_pairs(em.t, ins["x"], ins["y"], ins["yaw"], ins["speed"], usable)
    return RevisitPairs(i, j, ins["pitch"], ins["roll"])


def revisit_rows(data: Path = DATA) -> list[dict]:
    """1-sigma calibration and road repeatability on the revisit drives (default method)."""
    from imu_ground.pipeline import estimate_log
    rows = []
    for name in REVISIT_DRIVES:
        path = data / f"{name}.csv.gz"
        if not path.is_file():
            continue
        for speed in ("none", "auto"):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")             # (the readers' notes on the KITTI timestamps)
                res = estimate_log(path, speed=speed)
            tr = res.track
            rp = revisit_of(path, res)
            i, j = rp.i, rp.j
            row = {"drive": name, "speed": speed, "pairs": len(rp)}
            for angle, ins_angle in (("pitch", rp.ins_pitch), ("roll", rp.ins_roll)):
                road = ins_angle - getattr(tr, angle)
                s = getattr(tr, f"{angle}_std")
                z = (road[i] - road[j]) / np.sqrt(s[i] ** 2 + s[j] ** 2)
                row[f"{angle} z rms"] = float(np.sqrt(np.nanmean(z ** 2)))
                row[f"{angle} mean|d|/sqrt2 deg"] = float(np.nanmean(np.abs(road[i] - road[j])) / math.sqrt(2) / DEG)
            for q in ("road_grade", "road_bank"):
                v = getattr(tr, q)
                d = v[i] - v[j]
                some = bool(np.isfinite(d).any())
                row[f"{q} mean|d|/sqrt2 deg"] = float(np.nanmean(np.abs(d)) / math.sqrt(2) / DEG) if some else math.nan
                s = getattr(tr, f"{q}_std")
                row[f"{q} z rms"] = (float(np.sqrt(np.nanmean((d / np.sqrt(s[i] ** 2 + s[j] ** 2)) ** 2)))
                                     if np.isfinite(d).any() else math.nan)
            rows.append(row)
    return rows


# ----------------------------------------------------------------------------- synthetic
def _truth_at(d) -> dict:
    st = d.sim.truth
    idx = np.clip(np.searchsorted(st["t"].to_numpy(), d.egomotion.t - 1e-6), 0, len(st) - 1)
    return {c: st[c].to_numpy()[idx] for c in ("road_grade", "road_bank", "speed", "stationary")}


def _span(shares) -> str:
    return f"{100 * min(shares):.0f}-{100 * max(shares):.0f}"


def synthetic_rows(n: int = 10, seed: int = 1) -> list[dict]:
    """Coverage of the 1-sigma, convergence, standstill and road accuracy on a synthetic suite."""
    from imu_ground.evaluation.drives import synthetic_drives
    from imu_ground.filters.ground import GroundNormalFilter
    from imu_ground.filters.status import CONVERGED_STD, FILTER_CONVERGED_STD, STANDSTILL
    from imu_ground.filters.suspension import SuspensionAwareFilter
    drives = synthetic_drives(n, seed=seed, progress=False)
    rows = []
    for grade in ("nav", "mems"):
        ds = [d for d in drives if d.grade == grade]
        for method, make in (("suspension", SuspensionAwareFilter), ("filter", GroundNormalFilter)):
            hit = {"pitch": [], "roll": []}
            conv, stand, per_drive = [], [], {"pitch": [], "roll": []}
            for d in ds:
                tr = make(extrinsic=d.extrinsic).run(d.egomotion)
                ev = d.truth["evaluate"].to_numpy(bool)
                for a in ("pitch", "roll"):
                    h = np.abs(getattr(tr, a) - d.truth[a].to_numpy()) <= getattr(tr, f"{a}_std")
                    hit[a].append(h[ev])
                    per_drive[a].append(h[ev].mean())
                thr = CONVERGED_STD if method == "suspension" else FILTER_CONVERGED_STD
                c = np.flatnonzero(np.maximum(tr.pitch_std, tr.roll_std) <= thr)
                conv.append(tr.t[c[0]] - tr.t[0] + d.egomotion.delta_t[0] if len(c) else math.inf)
                still = _truth_at(d)["stationary"].astype(bool)
                stand.append((tr.status[still] == STANDSTILL).mean() if still.any() else math.nan)
            rows.append({"check": "1-sigma coverage (synthetic)", "method": method, "imu": grade, "drives": len(ds),
                         "pitch % within 1 sigma": 100 * np.concatenate(hit["pitch"]).mean(),
                         "roll % within 1 sigma": 100 * np.concatenate(hit["roll"]).mean(),
                         "per drive pitch min-max %": _span(per_drive["pitch"]),
                         "per drive roll min-max %": _span(per_drive["roll"]),
                         "time to converge median / max s": f"{np.median(conv):.1f} / {max(conv):.1f}",
                         "standstill % of stationary frames (min over drives)": 100 * np.nanmin(stand)})
        g_err, b_err, g_cov, b_cov = [], [], [], []
        for d in ds:
            tt = _truth_at(d)
            tr = SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion, speed=tt["speed"])
            ev = d.truth["evaluate"].to_numpy(bool) & np.isfinite(tr.road_grade)
            eg, eb = (tr.road_grade - tt["road_grade"])[ev], (tr.road_bank - tt["road_bank"])[ev]
            g_err.append(np.mean(np.abs(eg - eg.mean())) / DEG)
            b_err.append(np.mean(np.abs(eb - eb.mean())) / DEG)
            g_cov.append(np.mean(np.abs(eg) <= tr.road_grade_std[ev]))
            b_cov.append(np.mean(np.abs(eb) <= tr.road_bank_std[ev]))
        rows.append({"check": "road grade/bank (synthetic, true speed)", "method": "suspension", "imu": grade,
                     "drives": len(ds), "grade mean abs err (mean removed) deg, mean / max":
                     f"{np.mean(g_err):.3f} / {max(g_err):.3f}",
                     "bank mean abs err (mean removed) deg, mean / max": f"{np.mean(b_err):.3f} / {max(b_err):.3f}",
                     "grade % within 1 sigma": 100 * np.mean(g_cov), "bank % within 1 sigma": 100 * np.mean(b_cov)})
    return rows


def mount_rows(n: int = 6, data: Path = DATA) -> list[dict]:
    """Detection delay of a 1 deg remount halfway through synthetic drives; false alarms."""
    import pandas as pd

    from imu_ground.evaluation.drives import synthetic_drive
    from imu_ground.evaluation.simulate import remounted, simulate
    from imu_ground.filters.status import DEGRADED
    from imu_ground.filters.suspension import SuspensionAwareFilter
    from imu_ground.pipeline import estimate_log
    from imu_ground.so3 import roty
    rows = []
    for grade in ("nav", "mems"):
        delays, false_alarms = [], 0
        for seed in range(n):
            sim = simulate(duration=240.0, seed=seed, imu=grade)
            for s, changed in ((sim, False), (remounted(sim, 120.0, roty(1.0 * DEG)), True)):
                d = synthetic_drive(s)
                speed = _truth_at(d)["speed"]
                tr = SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion, speed=speed)
                deg = np.flatnonzero(tr.status == DEGRADED)
                if changed:
                    delays.append(d.egomotion.t[deg[0]] - 120.0 if len(deg) else math.inf)
                else:
                    false_alarms += bool(len(deg))
        rows.append({"imu": grade, "drives": n, "delays": delays, "false_alarms": false_alarms})
    alarms, drives = [], 0
    index = data / "drives.csv"
    if index.is_file():
        for name in pd.read_csv(index)["drive"]:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                tr = estimate_log(data / f"{name}.csv.gz", speed="auto").track
            drives += 1
            if (tr.status == DEGRADED).any():
                alarms.append(name)
    rows.append({"imu": "real", "drives": drives, "alarms": alarms})
    return rows


def _long(check: str, scope: str, quantity: str, figure, target: str = "", passed=None) -> dict:
    return {"check": check, "scope": scope, "quantity": quantity, "figure": figure, "target": target,
            "passed": passed}


def rows(n: int = 10, drives: int | None = None) -> list[dict]:
    """Every row of the module docstring (``n`` synthetic drives a grade)."""
    out = []
    for r in synthetic_rows(n=n):
        scope = f"{r['method']}, {r['imu']}, {r['drives']} drives"
        if r["check"].startswith("1-sigma"):
            for a in ("pitch", "roll"):
                v = r[f"{a} % within 1 sigma"]
                out.append(_long("1-sigma coverage, synthetic (seed 1)", scope,
                                 f"{a}: % of moving frames within 1 sigma",
                                 v, "55-80 (aim 68)", bool(55 <= v <= 80)))
                out.append(_long("1-sigma coverage, synthetic (seed 1)", scope, f"{a}: per drive min-max %",
                                 r[f"per drive {a} min-max %"]))
            out.append(_long("convergence, synthetic", scope, "time to converge (1-sigma first <= threshold), "
                             "median / max s", r["time to converge median / max s"]))
            v = r["standstill % of stationary frames (min over drives)"]
            out.append(_long("standstill, synthetic", scope, "% of the truth's stationary frames with status "
                             "standstill (worst drive)", v, ">= 90", bool(v >= 90) if v == v else None))
        else:
            for q in ("grade", "bank"):
                fig = r[f"{q} mean abs err (mean removed) deg, mean / max"]
                mean = float(fig.split(" / ")[0])
                out.append(_long("road, synthetic, true speed", scope, f"{q}: mean abs error (drive mean removed), "
                                 "deg, mean / max over drives", fig, "<= 0.15 (nav)" if r["imu"] == "nav" else "",
                                 bool(mean <= 0.15) if r["imu"] == "nav" else None))
                out.append(_long("road, synthetic, true speed", scope, f"{q}: % within 1 sigma",
                                 r[f"{q} % within 1 sigma"]))
    for r in mount_rows():
        if r["imu"] == "real":
            out.append(_long("mount change: false alarms", f"shared drives of drives.csv, --speed auto ({r['drives']})",
                             "drives flagged degraded", ", ".join(r["alarms"]) or "none", "none",
                             not r["alarms"]))
            continue
        scope = f"suspension, {r['imu']}, {r['drives']} drives of 240 s, true speed"
        dl = np.array(r["delays"])
        found = np.isfinite(dl)
        fig = (f"{np.median(dl[found]):.1f} / {dl[found].max():.1f} ({found.sum()} of {len(dl)} flagged)" if found.any()
               else "not flagged: the monitor stays silent (the gyro's drift is above its limit)")
        nav = r["imu"] == "nav"
        out.append(_long("mount change: 1 deg pitch at 120 s", scope, "delay until degraded, s, median / max",
                         fig, "<= 20 s (nav grade)" if nav else "", bool(found.all() and dl.max() <= 20) if nav else None))
        out.append(_long("mount change: 1 deg pitch at 120 s", scope, "false alarms on the same drives unchanged",
                         r["false_alarms"], "0", r["false_alarms"] == 0))
    for r in revisit_rows():
        scope = f"{r['drive']}, --speed {r['speed']}, {r['pairs']} pairs"
        for a in ("pitch", "roll"):
            v = r[f"{a} z rms"]
            out.append(_long("1-sigma, real revisit pairs", scope, f"{a}: RMS of diff / sqrt(s1^2 + s2^2)", v,
                             "0.8-1.25", bool(0.8 <= v <= 1.25)))
            out.append(_long("1-sigma, real revisit pairs", scope, f"{a}: mean |diff| / sqrt(2), deg",
                             r[f"{a} mean|d|/sqrt2 deg"]))
        if r["speed"] == "auto":
            for q, tgt in (("road_grade", 0.12), ("road_bank", 0.22)):
                v = r[f"{q} mean|d|/sqrt2 deg"]
                out.append(_long("road, real revisit pairs", scope, f"{q}: mean |diff| / sqrt(2), deg", v,
                                 f"<= {tgt}", bool(v <= tgt)))
                out.append(_long("road, real revisit pairs", scope, f"{q}: RMS of diff / sqrt(s1^2 + s2^2)",
                                 r[f"{q} z rms"]))
    return out


if __name__ == "__main__":
    sys.path.insert(0, str(HERE.parent))          # benchmarks/, where make_results lives
    from make_results import markdown
    print(markdown(rows()))
