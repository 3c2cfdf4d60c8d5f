"""Where the real-drive pitch error is: by speed, slow against fast, shared between methods, against the reference.

Is the remaining error relative to the INS reference the estimator's or the
reference's? The reference's pitch relative to the road
takes the road grade from the INS velocities (``atan(vu / v)``), so an INS
vertical-velocity error ``dvu`` gives a grade error ``dvu / v``: an error that
falls as 1/speed and is the same whatever estimator is scored against it. Per
speed bin, over the valid frames of the shared drives (means removed per
drive, as the accuracy table), this prints:

- ``suspension_deg`` / ``paper_deg``: mean absolute pitch error of the default
  method and of the paper's;
- ``slow_rms_deg`` / ``fast_rms_deg``: RMS of the default method's error split
  by a 3 s centred mean (slow) and the rest (fast);
- ``slow_x_speed_mps``: RMS of slow error (rad) x speed, m/s: constant across
  bins when the slow error is a velocity error over the speed;
- ``slow_corr_paper``: correlation of the two methods' slow errors (they share
  nothing but the IMU and the reference; the paper's method ignores the
  accelerometer and the velocity);
- ``floor_002_deg`` / ``floor_003_deg``: mean absolute error a perfect estimator
  would score if the reference's vertical velocity had a 0.02 / 0.03 m/s error.

A last row gives the INS vertical velocity at standstill (speed < 0.05 m/s in
the 100 Hz log, true value 0): its RMS, median over the drives with at least
1 s of standstill.

Run: ``python benchmarks/studies/error_budget.py [--data ../shared/data/kitti_imu100]``;
``rows()`` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tune_paper import DEFAULT_DATA, parse_args, valid_drives

from imu_ground.evaluation.conditions import _centred_mean
from imu_ground.evaluation.runner import run_method

__all__ = ["BINS", "main", "rows"]

#: Speed bins, m/s.
BINS = [(3.0, 4.5), (4.5, 6.0), (6.0, 9.0), (9.0, 12.0), (12.0, 18.0), (18.0, 40.0)]
#: Half width of the slow part's centred mean, frames (10 Hz: 3 s in all).
SLOW_HALF = 15


def _errors(d, method: str) -> np.ndarray:
    """Per-frame pitch error, deg, estimate minus reference, drive means removed over the evaluated frames."""
    track, _ = run_method(method, d)
    use = d.truth["evaluate"].to_numpy(bool) & np.asarray(track.valid, dtype=bool)
    est, ref = np.asarray(track.pitch, float), d.truth["pitch"].to_numpy(float)
    use &= np.isfinite(est) & np.isfinite(ref)
    e = np.full(est.size, np.nan)
    e[use] = (est[use] - est[use].mean()) - (ref[use] - ref[use].mean())
    return np.degrees(e)


def _standstill_vu(drives) -> float:
    """Median over drives of the RMS INS vertical velocity at standstill, m/s (nan: no drive stands 1 s)."""
    rms = []
    for d in drives:
        x = d.imu.extra
        if not {"ve", "vn", "vu"} <= set(x.columns):
            continue
        still = np.hypot(x["ve"].to_numpy(float), x["vn"].to_numpy(float)) < 0.05
        if np.count_nonzero(still) >= d.imu.rate:
            rms.append(math.sqrt(float(np.mean(x["vu"].to_numpy(float)[still] ** 2))))
    return float(np.median(rms)) if rms else math.nan


def rows(data: Path = DEFAULT_DATA, drives: int = 0) -> list[dict]:
    """One row per speed bin and one for all frames, then the standstill row (see the module docstring)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = valid_drives(Path(data), drives)
    pooled: dict[str, list[np.ndarray]] = {k: [] for k in ("e", "ep", "slow", "slow_p", "v")}
    for d in ds:
        e, ep = _errors(d, "suspension"), _errors(d, "paper")
        pooled["e"].append(e)
        pooled["ep"].append(ep)
        pooled["slow"].append(_centred_mean(e, SLOW_HALF))
        pooled["slow_p"].append(_centred_mean(ep, SLOW_HALF))
        pooled["v"].append(d.truth["speed"].to_numpy(float))
    p = {k: np.concatenate(v) for k, v in pooled.items()}
    ok = np.isfinite(p["e"]) & np.isfinite(p["ep"])
    out = []
    for lo, hi in [*BINS, (3.0, math.inf)]:
        m = ok & (p["v"] > lo) & (p["v"] <= hi)
        if not np.any(m):
            continue
        e, slow, v = p["e"][m], p["slow"][m], p["v"][m]
        floor = {s: float(np.degrees(math.sqrt(2.0 / math.pi) * np.mean(s / v))) for s in (0.02, 0.03)}
        out.append({"speed_mps": f"{lo:g}-{hi:g}" if math.isfinite(hi) else f"all above {lo:g}",
                    "frames": int(m.sum()),
                    "suspension_deg": float(np.mean(np.abs(e))), "paper_deg": float(np.mean(np.abs(p["ep"][m]))),
                    "slow_rms_deg": float(np.sqrt(np.mean(slow ** 2))),
                    "fast_rms_deg": float(np.sqrt(np.mean((e - slow) ** 2))),
                    "slow_x_speed_mps": float(np.sqrt(np.mean((np.radians(slow) * v) ** 2))),
                    "slow_corr_paper": float(np.corrcoef(slow, p["slow_p"][m])[0, 1]),
                    "floor_002_deg": floor[0.02], "floor_003_deg": floor[0.03]})
    out.append({"speed_mps": "standstill (< 0.05 m/s): INS vertical velocity RMS, m/s (median over drives)",
                "frames": None, "slow_x_speed_mps": _standstill_vu(ds)})
    return out


def main(argv=None) -> None:
    args = parse_args(__doc__, argv)
    for r in rows(Path(args.data), args.drives):
        print("  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()
                        if v is not None))


if __name__ == "__main__":
    main()
