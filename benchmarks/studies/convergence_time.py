"""How long the suspension filter's 1-sigma needs before it means what it says: the moving time its status latch
waits for (:data:`~imu_ground.filters.status.CONVERGED_MOVING_SECONDS`), chosen on synthetic drives with exact
truth and scored on held-out ones.

    python benchmarks/studies/convergence_time.py     # prints the tables; make_results.py puts them in RESULTS.md

The 1-sigma's drive terms (the road's roughness and the drive's mean load, :class:`~imu_ground.filters.status.
DriveStatistics`) start from their prior (a smooth road, no offset) and grow in over the first tens of seconds of
moving frames; before that the 1-sigma is too small. Suites: :data:`DRIVES_PER_GRADE` drives a grade (navigation
and MEMS) of :data:`DURATION` s, the default method with the true speed (as ``estimate`` runs with a speed) and
IMU only. Part 1: the share of moving frames (above 3 m/s) within 1 sigma per bin of the moving seconds seen so
far, on the fit suites (:data:`FIT_SEEDS`) and the held-out ones (:data:`HELD_OUT_SEEDS`). Part 2: for each
candidate wait, the share within 1 sigma of the first 30 s of frames the status calls ``ok`` (the frames a user
is told to trust first), fit and held out; the shipped wait is the shortest candidate whose fit-suite share is at
least :data:`MIN_SHARE` for each grade and angle, in both speed modes (:func:`chosen_wait`).
"""
from __future__ import annotations

import sys
import numpy as np

from imu_ground.evaluation.drives import synthetic_drive
from imu_ground.evaluation.simulate import simulate_suite
from imu_ground.filters.status import CONVERGED_MOVING_SECONDS, OK, SLOW_SPEED
from imu_ground.filters.suspension import SuspensionAwareFilter

FIT_SEEDS, HELD_OUT_SEEDS = (2, 3), (5, 6)
DRIVES_PER_GRADE, DURATION = 4, (120.0, 300.0)
#: Edges of the moving-seconds bins of part 1, s.
BINS = (0.0, 5.0, 10.0, 20.0, 30.0, 45.0, 60.0, 90.0, np.inf)
#: Candidate waits of part 2, s.
CANDIDATES = (0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0)
#: The share within 1 sigma the first ok frames must reach on the fit suites: the per-drive target's floor (50-85 %;
#: the pooled target's 55 % is not reached by the MEMS-grade IMU-only pitch at any wait up to 45 s, 54-61 %).
MIN_SHARE = 0.50
#: Seconds of first ok frames scored in part 2.
FIRST_OK_SECONDS = 30.0


def _suite(seed: int):
    return [synthetic_drive(s) for s in simulate_suite(DRIVES_PER_GRADE, seed=seed, duration_range=DURATION)]


def _track(d, with_speed: bool, wait: float):
    f = SuspensionAwareFilter(extrinsic=d.extrinsic)
    f.sigma.min_moving_seconds = wait
    return f.run(d.egomotion, speed=d.truth["speed"].to_numpy(float) if with_speed else None)


def _scores(d, tr):
    """Moving mask, moving seconds so far (the latch's count), |pitch err| <= 1 sigma, |roll err| <= 1 sigma."""
    T = d.truth
    dt = np.asarray(d.egomotion.delta_t, dtype=float)
    moving = T["evaluate"].to_numpy(bool) & np.asarray(tr.valid, dtype=bool)
    counted = np.asarray(tr.valid, bool) & ~np.asarray(d.egomotion.stationary, bool) & (np.abs(tr.speed) >= SLOW_SPEED)
    mt = np.cumsum(np.where(counted, dt, 0.0))
    cp = np.abs(tr.pitch - T["pitch"].to_numpy(float)) <= tr.pitch_std
    cr = np.abs(tr.roll - T["roll"].to_numpy(float)) <= tr.roll_std
    return moving, mt, cp, cr, dt


def _first_ok(d, tr):
    """The first :data:`FIRST_OK_SECONDS` of moving frames the track's status calls ``ok``."""
    moving, _, cp, cr, dt = _scores(d, tr)
    sel = (tr.status == OK) & moving
    return sel & (np.cumsum(np.where(sel, dt, 0.0)) <= FIRST_OK_SECONDS), cp, cr


def rows() -> list[dict]:
    """Both tables of the module docstring (column ``table``)."""
    out = []
    suites = {label: [d for s in seeds for d in _suite(s)] for label, seeds in (("fit", FIT_SEEDS),
                                                                                ("held out", HELD_OUT_SEEDS))}
    for with_speed in (True, False):
        mode = "speed" if with_speed else "IMU only"
        for label, drives in suites.items():
            for grade in ("nav", "mems"):
                g = [d for d in drives if d.grade == grade]
                scored = [_scores(d, _track(d, with_speed, 0.0)) for d in g]
                for lo, hi in zip(BINS[:-1], BINS[1:], strict=True):
                    n = cp = cr = 0
                    for moving, mt, p, r, _ in scored:
                        k = moving & (mt >= lo) & (mt < hi)
                        n, cp, cr = n + k.sum(), cp + p[k].sum(), cr + r[k].sum()
                    out.append({"table": "by moving time", "speed": mode, "suites": label, "grade": grade,
                                "moving_s": f"{lo:g}-{hi:g}", "frames": int(n),
                                "pitch_within_pct": 100.0 * cp / n if n else np.nan,
                                "roll_within_pct": 100.0 * cr / n if n else np.nan})
                for wait in CANDIDATES:
                    n = cp = cr = 0
                    for d in g:
                        k, p, r = _first_ok(d, _track(d, with_speed, wait))
                        n, cp, cr = n + k.sum(), cp + p[k].sum(), cr + r[k].sum()
                    out.append({"table": "first ok frames", "speed": mode, "suites": label, "grade": grade,
                                "wait_s": wait, "frames": int(n),
                                "pitch_within_pct": 100.0 * cp / n if n else np.nan,
                                "roll_within_pct": 100.0 * cr / n if n else np.nan,
                                "shipped": wait == CONVERGED_MOVING_SECONDS})
    return out


def chosen_wait(table: list[dict]) -> float:
    """The shortest candidate whose fit-suite first-ok share is at least :data:`MIN_SHARE` everywhere."""
    for wait in CANDIDATES:
        fit = [r for r in table if r["table"] == "first ok frames" and r["suites"] == "fit" and r["wait_s"] == wait]
        if all(min(r["pitch_within_pct"], r["roll_within_pct"]) >= 100 * MIN_SHARE for r in fit):
            return wait
    return float("nan")


def main() -> None:
    table = rows()
    for r in table:
        print("; ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in r.items()))
    print(f"chosen wait: {chosen_wait(table):g} s (shipped {CONVERGED_MOVING_SECONDS:g} s)")


if __name__ == "__main__":
    sys.exit(main())
