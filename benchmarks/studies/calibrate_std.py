"""Fit the constants of the 1-sigma model of :mod:`imu_ground.filters.status` (``SUSPENSION_STD``, ``FILTER_STD``).

    python benchmarks/studies/calibrate_std.py                 # the shipped fit: synthetic (seed 0) + both revisit drives
    python benchmarks/studies/calibrate_std.py --holdout       # also: fit on one revisit drive, check on the other
                                                               # (rows(): the same, for make_results.py / RESULTS.md)

The suspension filter's model, per angle, ``sigma^2 = c_a^2 a + (g_x u_x)^2 + (g_y u_y)^2 + (h w)^2 + f^2
+ sigma_b^2`` (``w`` the yaw rate), is fitted by minimising

- the mean Gaussian negative log-likelihood of the errors against the exact truth on the moving
  frames (speed above the evaluation's minimum) of ``N`` synthetic drives a grade (navigation and
  MEMS, seed 0), plus
- ``weight * log(z)^2`` for each real revisit drive of the fit and each speed mode (IMU only and
  ``--speed auto``), ``z`` the RMS of ``difference / sqrt(sigma_1^2 + sigma_2^2)`` at the drive's
  revisit pairs (the evaluation's pairing, :mod:`imu_ground.evaluation.revisit`; the differences of
  ``INS angle - estimated angle`` between the passes, which see neither a drive-constant error nor
  one that repeats at the same place), plus
- ``10^4 (max(0, lo - c_g)^2 + max(0, c_g - hi)^2)`` for each grade ``g``, ``c_g`` the share of its
  synthetic errors within 1 sigma (``lo, hi``: :data:`COVERAGE_BAND`, a margin inside the 55-80 %
  target for drives other than the fit's), which makes the band nearly a constraint.

The two kinds of data disagree on the level (the synthetic drives' errors are larger than the
real drives' differences away from turns), and the real drives disagree with each other in turns
(roll differences of 2011_10_03_drive_0034 where one pass turns, few such pairs on
2011_09_30_drive_0020); ``--holdout`` prints each direction. The invariant filter's ``FILTER_STD``
(its covariance is a tuning) is a constant per angle: the smallest that keeps each grade of the
synthetic fit set at 66 % coverage or above (:data:`FILTER_COVERAGE`). Coverage on other drives and the revisit figures:
``benchmarks/studies/confidence.py`` (RESULTS.md).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from imu_ground.evaluation.drives import synthetic_drives
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.status import AngleStd
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.so3 import twist_angle
from imu_ground.units import DEG

sys.path.insert(0, str(Path(__file__).resolve().parent))
from confidence import DATA, REVISIT_DRIVES, revisit_estimate  # noqa: E402  (the sibling study: one pairing)

KEYS = ("a", "ux", "uy", "tvp", "tvr", "w")
#: Coverage band (share within 1 sigma) each grade of the synthetic fit set is held in, per angle (the target
#: is 55-80 % on other drives; the MEMS drives' coverage moves by up to ~8 points between suites, more in pitch).
COVERAGE_BAND = {"pitch": (0.68, 0.80), "roll": (0.62, 0.80)}
#: The invariant filter's constant keeps each grade of the fit set at this coverage or above.
FILTER_COVERAGE = 0.66


def _inputs(f: SuspensionAwareFilter, tr, em, gravity_P: np.ndarray) -> dict:
    """The model's inputs per frame of a suspension track (``f`` the filter that made it)."""
    sg2 = (1.0 - f.load_share) ** 2 * 0.5 * (gravity_P[:, 3, 3] + gravity_P[:, 4, 4])
    R = np.eye(3) if f._Rgs is None else f._Rgs          # ground <- sensor (None: the identity)
    w = np.abs(twist_angle(R @ np.asarray(em.delta_R) @ R.T)) / np.asarray(em.delta_t, dtype=float)
    return dict(a=0.5 * (tr.P[:, 0, 0] + tr.P[:, 1, 1]), ux=tr.load[:, 0], uy=tr.load[:, 1],
                tvp=sg2 * (tr.gains[:, 0] ** 2 + f.cross_gain ** 2), tvr=sg2 * tr.gains[:, 1] ** 2, w=w)


def components(drives, method: str) -> dict:
    """Per moving frame: errors ``ep, er`` (rad), the model's inputs and the grade, pooled over ``drives``."""
    cols: dict = {k: [] for k in ("ep", "er", "grade") + KEYS}
    for d in drives:
        ev = d.truth["evaluate"].to_numpy(bool)
        if method == "suspension":
            f = SuspensionAwareFilter(extrinsic=d.extrinsic)
            tr = f.run(d.egomotion)
            c = _inputs(f, tr, d.egomotion, GravityVelocityFilter(extrinsic=d.extrinsic).run(d.egomotion).P)
        else:
            tr = GroundNormalFilter(extrinsic=d.extrinsic).run(d.egomotion)
            c = {k: np.zeros(len(tr)) for k in KEYS}
        c.update(ep=tr.pitch - d.truth["pitch"].to_numpy(), er=tr.roll - d.truth["roll"].to_numpy(),
                 grade=np.full(len(tr), d.grade, dtype=object))
        for k, v in c.items():
            cols[k].append(np.asarray(v)[ev])
    out = {k: np.concatenate(v) for k, v in cols.items()}
    for k in ("ep", "er") + KEYS:
        out[k] = out[k].astype(float)
    return out


def revisit_components(name: str, speed: str) -> dict:
    """The model's inputs at both frames of each revisit pair of a real drive (default method, ``speed``
    ``"none"`` or ``"auto"``) and the differences ``dp, dr`` of ``INS angle - estimate`` between the passes, rad."""
    res, rp, _ = revisit_estimate(DATA / f"{name}.csv.gz", speed)
    tr, em = res.track, res.egomotion
    rot = np.asarray(res.meta["extrinsic"]["rotation"])
    f = SuspensionAwareFilter(extrinsic=rot)
    # (sigma_b^2 from the IMU-only gravity filter: it is zero with the default load share of 1)
    c = _inputs(f, tr, em, GravityVelocityFilter(extrinsic=rot).run(em).P)
    ok = np.asarray(tr.valid, dtype=bool)
    i, j = rp.i[ok[rp.i] & ok[rp.j]], rp.j[ok[rp.i] & ok[rp.j]]
    out = {k + s: v[idx] for k, v in c.items() for s, idx in (("1", i), ("2", j))}
    road_p, road_r = rp.ins_pitch - tr.pitch, rp.ins_roll - tr.roll
    out["dp"], out["dr"] = road_p[j] - road_p[i], road_r[j] - road_r[i]
    return out


def _variance(m: AngleStd, c: dict, angle: str, side: str = "") -> np.ndarray:
    tv = ("tvp" if angle == "pitch" else "tvr") + side
    return m.variance(c["a" + side], c["ux" + side], c["uy" + side], c[tv], c["w" + side])


def revisit_z_rms(m: AngleStd, r: dict, angle: str) -> float:
    """RMS of ``difference / sqrt(sigma_1^2 + sigma_2^2)`` at a drive's revisit pairs."""
    d = r["dp" if angle == "pitch" else "dr"]
    return float(np.sqrt(np.mean(d * d / (_variance(m, r, angle, "1") + _variance(m, r, angle, "2")))))


def coverage(m: AngleStd, c: dict, angle: str, grade: str | None = None) -> float:
    """Share of the synthetic errors (of one grade, or all) within 1 sigma."""
    e = c["ep" if angle == "pitch" else "er"]
    sel = np.ones(len(e), dtype=bool) if grade is None else c["grade"] == grade
    return float(np.mean(np.abs(e[sel]) <= np.sqrt(_variance(m, c, angle)[sel])))


def fit(c: dict, angle: str, revisit: list[dict], weight: float = 1.0) -> AngleStd:
    """The suspension filter's constants of one angle (``"pitch"`` or ``"roll"``): the objective of the
    module docstring over the synthetic components ``c`` and the revisit components ``revisit``."""
    e = c["ep" if angle == "pitch" else "er"]
    lo, hi = COVERAGE_BAND[angle]
    grades = sorted(set(c["grade"]))

    def model(p):
        ca, gx, gy, f, h = np.abs(p)
        return AngleStd(ca, gx * DEG, gy * DEG, f * DEG, h * DEG)

    def objective(p):
        m = model(p)
        v = _variance(m, c, angle)
        out = float(np.mean(np.log(v) + e * e / v))
        out += weight * sum(math.log(revisit_z_rms(m, r, angle)) ** 2 for r in revisit)
        for g in grades:
            cov = coverage(m, c, angle, g)
            out += 1e4 * (max(0.0, lo - cov) ** 2 + max(0.0, cov - hi) ** 2)
        return out
    best = None
    for h in (0.0, 0.5, 1.5, 3.0):              # several starts (the objective has local minima), each polished once
        x = [0.5, 0.03, 0.05, 0.08, h]
        for _ in range(2):
            res = minimize(objective, x, method="Nelder-Mead", options=dict(maxiter=8000, xatol=1e-6, fatol=1e-9))
            x = res.x
        if best is None or res.fun < best.fun:
            best = res
    return model(best.x)


def fit_constant(c: dict, angle: str) -> AngleStd:
    """A constant 1-sigma (the invariant filter's): the smallest that keeps each grade's coverage of the
    synthetic fit set at :data:`FILTER_COVERAGE` or above."""
    e = np.abs(c["ep" if angle == "pitch" else "er"])
    s = max(float(np.quantile(e[c["grade"] == g], FILTER_COVERAGE)) for g in sorted(set(c["grade"])))
    return AngleStd(0.0, 0.0, 0.0, s)


def describe(m: AngleStd) -> str:
    return (f"AngleStd({m.cov_scale:.3g}, {m.load_x / DEG:.3g} * DEG, {m.load_y / DEG:.3g} * DEG, "
            f"{m.floor / DEG:.3g} * DEG, {m.turn / DEG:.3g} * DEG)")


def rows(n: int = 10, seed: int = 0, weight: float = 1.0, holdout: bool = True) -> list[dict]:
    """The fits (shipped: synthetic + every revisit drive; with ``holdout`` also each revisit drive alone)
    with their fit-set coverage per grade and their revisit z RMS on every drive (held out or not)."""
    drives = synthetic_drives(n, seed=seed, progress=False)
    names = [nm for nm in REVISIT_DRIVES if (DATA / f"{nm}.csv.gz").is_file()]
    rev = {(nm, s): revisit_components(nm, s) for nm in names for s in ("none", "auto")}
    c = components(drives, "suspension")
    grades = sorted(set(c["grade"]))
    out = []
    for label, fit_on in [("synthetic + all revisit drives (shipped)", names)] + (
            [(f"synthetic + only {nm}", [nm]) for nm in names] if holdout and len(names) > 1 else []):
        for angle in ("pitch", "roll"):
            m = fit(c, angle, [r for k, r in rev.items() if k[0] in fit_on], weight)
            row = {"method": "suspension", "fitted on": f"seed {seed}, {label}", "angle": angle, "constants": describe(m)}
            row.update({f"fit-set {g} % within 1 sigma": 100 * coverage(m, c, angle, g) for g in grades})
            row["revisit drives held out"] = ", ".join(nm for nm in names if nm not in fit_on) or "none"
            row.update({f"z RMS {nm}, --speed {s}": revisit_z_rms(m, r, angle) for (nm, s), r in rev.items()})
            out.append(row)
    cf = components(drives, "filter")
    for angle in ("pitch", "roll"):
        m = fit_constant(cf, angle)
        row = {"method": "filter", "fitted on": f"seed {seed}, synthetic", "angle": angle, "constants": describe(m)}
        row.update({f"fit-set {g} % within 1 sigma": 100 * coverage(m, cf, angle, g) for g in grades})
        out.append(row)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=10, help="synthetic drives a grade")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--weight", type=float, default=1.0, help="weight of each revisit drive's log(z RMS)^2")
    ap.add_argument("--holdout", action="store_true", help="also fit on each revisit drive alone and check the other")
    a = ap.parse_args()
    for r in rows(a.n, a.seed, a.weight, a.holdout):
        print(f"{r['method']} {r['angle']} ({r['fitted on']}): {r['constants']}")
        print("    " + "; ".join(f"{k} {v:.2f}" for k, v in r.items() if isinstance(v, float)))


if __name__ == "__main__":
    main()
