"""Fit the constants of the 1-sigma model of :mod:`imu_ground.filters.status` on synthetic drives.

    python benchmarks/studies/calibrate_std.py            # fit on the suite of seed 0, check on seed 1

The model ``sigma^2 = c_a^2 a + (g_x u_x)^2 + (g_y u_y)^2 + f^2 + sigma_b^2`` (per angle) is
fitted by Gaussian likelihood of the errors, then scaled so that 68 % of them lie within 1 sigma (for the invariant filter, whose covariance is a tuning,
a constant: the 68th percentile of the errors) against the exact truth on the moving frames
(speed above the evaluation's minimum) of ``N`` drives a grade (navigation and MEMS); the
printed constants go into ``SUSPENSION_STD`` and ``FILTER_STD``. With ``--revisit DRIVE`` the fit of the
suspension method also pulls the RMS of the normalised differences at that real drive's revisit
pairs towards 1 (``--weight``), so that the other revisit drive checks it out of sample. The coverage it reaches on
drives it was not fitted on is reported by ``benchmarks/studies/confidence.py`` (RESULTS.md).
"""
from __future__ import annotations

import argparse
import math

import numpy as np
from scipy.optimize import minimize

from imu_ground.evaluation.drives import synthetic_drives
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.status import AngleStd
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.units import DEG


def components(drives, method: str) -> dict:
    """Per moving frame: errors (rad) and the model's inputs, pooled over ``drives``."""
    cols: dict = {k: [] for k in ("ep", "er", "a", "ux", "uy", "tvp", "tvr")}
    for d in drives:
        ev = d.truth["evaluate"].to_numpy(bool)
        if method == "suspension":
            f = SuspensionAwareFilter(extrinsic=d.extrinsic)
            tr = f.run(d.egomotion)
            gp = GravityVelocityFilter(extrinsic=d.extrinsic).run(d.egomotion).P
            sg2 = (1.0 - f.load_share) ** 2 * 0.5 * (gp[:, 3, 3] + gp[:, 4, 4])
            ux, uy = tr.load[:, 0], tr.load[:, 1]
            tvp, tvr = sg2 * (tr.gains[:, 0] ** 2 + f.cross_gain ** 2), sg2 * tr.gains[:, 1] ** 2
        else:
            tr = GroundNormalFilter(extrinsic=d.extrinsic).run(d.egomotion)
            ux = uy = tvp = tvr = np.zeros(len(tr))
        a = 0.5 * (tr.P[:, 0, 0] + tr.P[:, 1, 1])
        for k, v in dict(ep=tr.pitch - d.truth["pitch"].to_numpy(), er=tr.roll - d.truth["roll"].to_numpy(),
                         a=a, ux=ux, uy=uy, tvp=tvp, tvr=tvr).items():
            cols[k].append(np.asarray(v, dtype=float)[ev])
    return {k: np.concatenate(v) for k, v in cols.items()}


def revisit_components(name: str) -> dict:
    """The model's inputs at the revisit pairs of a real drive (default method, IMU only) and the
    differences of the road's attitude (``INS angle - estimate``) between the passes, rad."""
    import sys
    import warnings
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from confidence import DATA, _ins_at, revisit_pairs

    from imu_ground.pipeline import estimate_log
    path = DATA / f"{name}.csv.gz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = estimate_log(path)
    tr = res.track
    ins = _ins_at(path, tr.t)
    pairs = revisit_pairs(tr.t, np.column_stack([ins["px"], ins["py"]]), ins["yaw"], ins["speed"])
    f = SuspensionAwareFilter()
    gp = GravityVelocityFilter(extrinsic=np.asarray(res.meta["extrinsic"]["rotation"])).run(res.egomotion).P
    sg2 = (1.0 - f.load_share) ** 2 * 0.5 * (gp[:, 3, 3] + gp[:, 4, 4])
    out = {}
    for side, idx in (("1", pairs[:, 0]), ("2", pairs[:, 1])):
        out["a" + side] = 0.5 * (tr.P[idx, 0, 0] + tr.P[idx, 1, 1])
        out["ux" + side], out["uy" + side] = tr.load[idx, 0], tr.load[idx, 1]
        out["tvp" + side] = sg2[idx] * (tr.gains[idx, 0] ** 2 + f.cross_gain ** 2)
        out["tvr" + side] = sg2[idx] * tr.gains[idx, 1] ** 2
    i, j = pairs[:, 0], pairs[:, 1]
    out["dp"] = (ins["pitch"] - tr.pitch)[i] - (ins["pitch"] - tr.pitch)[j]
    out["dr"] = (ins["roll"] - tr.roll)[i] - (ins["roll"] - tr.roll)[j]
    return out


def revisit_z_rms(m: AngleStd, r: dict, angle: str) -> float:
    """RMS of ``difference / sqrt(sigma_1^2 + sigma_2^2)`` at a drive's revisit pairs."""
    tv = "tvp" if angle == "pitch" else "tvr"
    v = sum(m.variance(r["a" + k], r["ux" + k], r["uy" + k], r[tv + k]) for k in "12")
    d = r["dp" if angle == "pitch" else "dr"]
    return float(np.sqrt(np.mean(d * d / v)))


def fit(c: dict, angle: str, loads: bool, revisit: dict | None = None, weight: float = 1.0) -> AngleStd:
    """Maximum-likelihood constants of one angle (``"pitch"`` or ``"roll"``); with ``revisit``
    (:func:`revisit_components` of one drive) plus ``weight * log(z RMS)^2`` of that drive."""
    e = c["ep" if angle == "pitch" else "er"]
    tv = c["tvp" if angle == "pitch" else "tvr"]
    if not loads:                   # a covariance that is a tuning: a constant, the 68th percentile of |error|
        return AngleStd(0.0, 0.0, 0.0, float(np.quantile(np.abs(e), 0.68)))

    def model(p):
        ca, gx, gy, f = np.abs(p)
        return AngleStd(ca, gx * DEG, gy * DEG, f * DEG) if loads else AngleStd(ca, 0.0, 0.0, f * DEG)

    def nll(p):
        m = model(p)
        v = m.variance(c["a"], c["ux"], c["uy"], tv)
        extra = 0.0 if revisit is None else weight * math.log(revisit_z_rms(m, revisit, angle)) ** 2
        return float(np.mean(np.log(v) + e * e / v)) + extra
    res = minimize(nll, [0.5, 0.1, 0.1, 0.05], method="Nelder-Mead", options=dict(maxiter=6000, xatol=1e-5))
    m = model(res.x)
    if revisit is not None:
        return m
    # The errors have heavier tails than a Gaussian, so the likelihood's sigma covers more than 68 %:
    # keep its shape and scale it so that 68 % of the fit's errors lie within 1 sigma.
    z = np.abs(e) / np.sqrt(m.variance(c["a"], c["ux"], c["uy"], tv))
    k = float(np.quantile(z, 0.68))
    return AngleStd(m.cov_scale * k, m.load_x * k, m.load_y * k, m.floor * k)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=10, help="drives a grade")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--revisit", default=None, help="a real revisit drive to fit on too (e.g. 2011_09_30_drive_0020)")
    ap.add_argument("--weight", type=float, default=1.0, help="weight of its log(z RMS)^2")
    a = ap.parse_args()
    drives = synthetic_drives(a.n, seed=a.seed, progress=False)
    rev = None if a.revisit is None else revisit_components(a.revisit)
    for method in ("suspension", "filter"):
        c = components(drives, method)
        for angle in ("pitch", "roll"):
            m = fit(c, angle, method == "suspension", rev if method == "suspension" else None, a.weight)
            print(f"{method} {angle}: AngleStd({m.cov_scale:.3g}, {m.load_x / DEG:.3g} * DEG, "
                  f"{m.load_y / DEG:.3g} * DEG, {m.floor / DEG:.3g} * DEG)")


if __name__ == "__main__":
    main()
