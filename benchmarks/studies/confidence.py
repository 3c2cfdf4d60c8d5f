"""How sure, and what the road does: the 1-sigma's calibration, the status, road grade and bank, mount changes.

    python benchmarks/studies/confidence.py              # prints the table; make_results.py puts it in RESULTS.md

Rows (``rows()``):

- **1-sigma coverage, synthetic**: share of moving frames with ``|error| <= 1 sigma`` for pitch and
  roll (target 55-80 %, aim 68 %), per method and IMU grade, on a suite (seed 1) other than the ones
  the constants were fitted on (seeds 2-4, ``benchmarks/studies/calibrate_std.py``); the time to converge
  (first frame whose status is not ``converging``) and the share of the truth's stationary frames
  whose status is ``standstill`` (target >= 90 %).
- **1-sigma on the revisit drives**: where a real drive passes the same place twice
  (the evaluation's pairing, :func:`imu_ground.evaluation.revisit.revisit_pairs`: valid 10 Hz frames
  above 3 m/s, positions within 1 m, headings within 15 deg, at least 30 s apart, each frame with its
  closest partner, each pair once), the road's attitude
  ``INS angle - estimated angle`` must repeat; RMS of ``difference / sqrt(sigma_1^2 + sigma_2^2)``
  (a diagnostic, no target: it measures how differently the two passes were driven as much as the 1-sigma,
  ``benchmarks/studies/synthetic_revisit.py``).
- **Road grade and bank**: synthetic navigation-grade drives with the true speed, mean absolute error
  with each drive's mean removed (target <= 0.15 deg); real revisit drives with ``--speed auto``,
  ``mean |difference| / sqrt(2)`` (targets 0.12 deg grade, 0.22 deg bank).
- **Mount change**: synthetic drives whose sensor turns by 1 deg in pitch halfway
  (:func:`imu_ground.evaluation.simulate.remounted`), with the true speed: the delay until the
  status is ``degraded``; false alarms on the same drives unchanged and on every shared drive of
  ``drives.csv`` with ``--speed auto``. With ``recalibrate_online``: the time from the alarm to the
  re-estimation, the change estimated (truth: 1 deg pitch, 0 roll) and the error of the sensor-frame
  normal (pitch, roll; each drive's mean over the moving frames after the re-estimation, against the
  remounted truth), with and without the flag; re-estimations on the shared drives.

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
def revisit_estimate(path: Path, speed: str) -> tuple:
    """The default method's estimate of a real drive (``estimate_log``, ``speed`` ``"none"`` or ``"auto"``;
    the readers' notes on the KITTI timestamps silenced), its INS at the frames and its revisit pairs by
    the evaluation's pairing (:func:`imu_ground.evaluation.revisit.revisit_pairs`: valid frames near a
    log sample).

    Returns
    -------
    res
        ``estimate_log``'s result.
    pairs : RevisitPairs
    ins : dict
        :func:`imu_ground.evaluation.revisit.ins_at_frames` of the log at the frames.
    """
    import pandas as pd

    from imu_ground.evaluation.revisit import RevisitPairs, ins_at_frames, revisit_pairs
    from imu_ground.pipeline import estimate_log
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = estimate_log(path, speed=speed)
    em = res.egomotion
    ins = ins_at_frames(pd.read_csv(path), em.t)
    usable = np.asarray(em.valid, dtype=bool) & ins["near"]
    i, j = revisit_pairs(em.t, ins["x"], ins["y"], ins["yaw"], ins["speed"], usable)
    return res, RevisitPairs(i, j, ins["pitch"], ins["roll"]), ins


def revisit_rows(data: Path = DATA) -> list[dict]:
    """1-sigma calibration and road repeatability on the revisit drives (default method)."""
    rows = []
    for name in REVISIT_DRIVES:
        path = data / f"{name}.csv.gz"
        if not path.is_file():
            continue
        for speed in ("none", "auto"):
            res, rp, _ = revisit_estimate(path, speed)
            tr = res.track
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
def truth_at_frames(d, columns=("road_grade", "road_bank", "speed", "stationary")) -> dict:
    """Columns of a synthetic drive's simulated truth at its ego-motion frames (the frame ends)."""
    st = d.sim.truth
    idx = np.clip(np.searchsorted(st["t"].to_numpy(), d.egomotion.t - 1e-6), 0, len(st) - 1)
    return {c: st[c].to_numpy()[idx] for c in columns}


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
                still = truth_at_frames(d)["stationary"].astype(bool)
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
            tt = truth_at_frames(d)
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
    from imu_ground.filters.estimator import pitch_roll_from_normal
    rows = []
    for grade in ("nav", "mems"):
        delays, false_alarms, recal = [], 0, {"after": [], "delta": [], "err": [], "err_off": [], "false": 0}
        for seed in range(n):
            sim = simulate(duration=240.0, seed=seed, imu=grade)
            for s, changed in ((sim, False), (remounted(sim, 120.0, roty(1.0 * DEG)), True)):
                d = synthetic_drive(s)
                speed = truth_at_frames(d)["speed"]
                tr = SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion, speed=speed)
                deg = np.flatnonzero(tr.status == DEGRADED)
                f = SuspensionAwareFilter(extrinsic=d.extrinsic, recalibrate_online=True)
                on = f.run(d.egomotion, speed=speed)
                if not changed:
                    false_alarms += bool(len(deg))
                    recal["false"] += f.recalibrator.count > 0
                    continue
                t = d.egomotion.t
                delays.append(t[deg[0]] - 120.0 if len(deg) else math.inf)
                if f.recalibrator.count == 0:
                    continue
                degon = np.flatnonzero(on.status == DEGRADED)
                recal["after"].append(t[degon[-1] + 1] - t[degon[0]])
                recal["delta"].append(f.recalibrator.delta[[1, 0]] / DEG)      # (pitch, roll)
                truth = pitch_roll_from_normal(d.truth[["normal_x", "normal_y", "normal_z"]].to_numpy())
                later = d.truth["evaluate"].to_numpy(bool) & (t > t[degon[-1] + 1])
                for key, track in (("err", on), ("err_off", tr)):
                    est = pitch_roll_from_normal(track.normal)
                    recal[key].append([np.mean(est[i][later] - truth[i][later]) / DEG for i in (0, 1)])
        rows.append({"imu": grade, "drives": n, "delays": delays, "false_alarms": false_alarms, "recal": recal})
    alarms, recalibrated, drives = [], [], 0
    index = data / "drives.csv"
    if index.is_file():
        for name in pd.read_csv(index)["drive"]:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                tr = estimate_log(data / f"{name}.csv.gz", speed="auto").track
                on = estimate_log(data / f"{name}.csv.gz", speed="auto", recalibrate_online=True).track
            drives += 1
            if (tr.status == DEGRADED).any():
                alarms.append(name)
            if (on.status == DEGRADED).any() or any(r.startswith("mount re-estimated") for r in on.status_reason):
                recalibrated.append(name)
    rows.append({"imu": "real", "drives": drives, "alarms": alarms, "recalibrated": recalibrated})
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
            out.append(_long("mount change: online re-estimation", f"shared drives of drives.csv, --speed auto, "
                             f"--recalibrate-online ({r['drives']})", "drives degraded or re-estimated",
                             ", ".join(r["recalibrated"]) or "none", "none", not r["recalibrated"]))
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
        rc = r["recal"]
        check = "mount change: online re-estimation (--recalibrate-online)"
        out.append(_long(check, scope, "re-estimations on the same drives unchanged", rc["false"], "0",
                         rc["false"] == 0))
        if not rc["after"]:
            out.append(_long(check, scope, "re-estimated drives", 0, "all (nav grade)" if nav else "",
                             False if nav else None))
            continue
        after, dl, err, off = (np.array(rc[k]) for k in ("after", "delta", "err", "err_off"))
        out.append(_long(check, scope, "re-estimated drives; time from the alarm to the re-estimation, s, "
                         "min-max", f"{len(after)} of {len(r['delays'])}; {after.min():.1f}-{after.max():.1f}"))
        out.append(_long(check, scope, "change estimated (truth 1 deg pitch, 0 roll), deg, pitch min-max / roll "
                         "min-max", f"{dl[:, 0].min():.2f}-{dl[:, 0].max():.2f} / {dl[:, 1].min():+.2f}"
                         f"..{dl[:, 1].max():+.2f}"))
        worst = float(np.abs(err).max())
        out.append(_long(check, scope, "sensor-frame normal after the re-estimation minus truth, deg, drive means "
                         "pitch min..max / roll min..max", f"{err[:, 0].min():+.3f}..{err[:, 0].max():+.3f} / "
                         f"{err[:, 1].min():+.3f}..{err[:, 1].max():+.3f}", "|mean| <= 0.1 (nav grade)" if nav else "",
                         bool(worst <= 0.1 and len(after) == len(r["delays"])) if nav else None))
        out.append(_long(check, scope, "the same without the flag, deg, pitch min..max / roll min..max",
                         f"{off[:, 0].min():+.3f}..{off[:, 0].max():+.3f} / {off[:, 1].min():+.3f}.."
                         f"{off[:, 1].max():+.3f}"))
    for r in revisit_rows():
        scope = f"{r['drive']}, --speed {r['speed']}, {r['pairs']} pairs"
        for a in ("pitch", "roll"):
            v = r[f"{a} z rms"]
            out.append(_long("1-sigma, real revisit pairs", scope, f"{a}: RMS of diff / sqrt(s1^2 + s2^2) "
                             "(diagnostic)", v))
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
