"""Revisit consistency on the real drives that pass the same place twice, every method, before and after.

Where a drive passes the same place twice in the same direction the road's own attitude
repeats, so ``INS attitude - estimated attitude relative to the road`` must repeat between
the passes (:mod:`imu_ground.evaluation.revisit`; metric ``mean |difference| / sqrt(2)``, deg).
This script reports:

- ``revisit``: pitch and roll per drive with revisit pairs (and pooled), for every method of
  the evaluation and for the suspension filter in the configuration before the revisit work
  (``BEFORE``: load share 0.6, roll gain 0.5 deg/(m/s^2), accelerometer lateral load, no gravity
  noise through gaps, no road noise per heading change) and now, IMU only and with the INS
  horizontal speed as the measured speed (``--speed auto`` on KITTI); and now without the road noise
  per heading change (``q_turn=0``), the one change that trades INS-grade pitch for revisit roll;
  and the live estimate (``estimate --causal``, the numbers of ``StreamingEstimator``) with the speed;
- ``INS-grade``: the same suspension variants on the INS-grade pitch reference of every valid
  drive (mean over drives, worst ratio to the paper's method: the guard rail, at most 1.1);
- ``held out``: each changed setting chosen on one revisit drive and scored on the other (both
  ways), and chosen on the first half of every drive's pairs and scored on the second half;
- ``synthetic``: the suspension filter before and now on the synthetic suite (exact truth).

Run: ``python benchmarks/studies/revisit_table.py [--data ../shared/data/kitti_imu100]``; ``rows()``
returns the tables for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import math
import sys
import warnings
from pathlib import Path

import numpy as np

from imu_ground.evaluation.drives import load_real_drives, synthetic_drives
from imu_ground.evaluation.metrics import evaluate_drive
from imu_ground.evaluation.revisit import drive_revisit_pairs, revisit_consistency, revisit_differences
from imu_ground.evaluation.runner import METHODS, run_method
from imu_ground.datasets.speed import log_speed
from imu_ground.filters import GroundNormalFilter, SuspensionAwareFilter
from imu_ground.pipeline.streaming import causal_track
from imu_ground.units import DEG

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tune_paper import DEFAULT_DATA, parse_args
from tune_suspension import drive_speed, score

#: The suspension filter's configuration before the revisit work.
BEFORE = dict(gains=(-0.25 * DEG, 0.5 * DEG), load=0.6, lateral="accelerometer", q_turn=0.0,
              gravity=dict(q_gap_g=0.0))
#: label -> (constructor keywords, speed-aided)
VARIANTS = {
    "suspension before, IMU only": (BEFORE, False),
    "suspension before, + speed": (BEFORE, True),
    "suspension now without q_turn, IMU only": (dict(q_turn=0.0), False),
    "suspension now without q_turn, + speed": (dict(q_turn=0.0), True),
    "suspension now, IMU only": ({}, False),
    "suspension now, + speed (default)": ({}, True),
    "suspension now, + speed, live (--causal)": (None, True),
}
#: Settings checked out of sample: name -> (grid, keywords of a value).
GRIDS = {
    "roll gain, deg/(m/s^2)": ([0.3, 0.35, 0.4, 0.45, 0.5], lambda x: dict(gains=(-0.25 * DEG, x * DEG))),
    "load share": ([0.6, 0.8, 1.0], lambda x: dict(load=x)),
    "q_turn, sigma_e^2/rad": ([0.0, 3.0, 10.0, 30.0, 100.0], lambda x: dict(q_turn=x)),
    "q_gap_g, m/s^2/sqrt(s)": ([0.0, 0.1, 1.0], lambda x: dict(gravity=dict(q_gap_g=x))),
}
SYNTHETIC_DRIVES = 5


def _revisit(pairs, track) -> tuple[np.ndarray, np.ndarray]:
    """Pitch and roll differences (rad) of the road attitude over a drive's pairs."""
    return revisit_differences(pairs, track.pitch, track.roll, track.valid)


def _row(table: str, drive: str, method: str, dp: np.ndarray, dr: np.ndarray) -> dict:
    m = revisit_consistency(dp, dr)
    return dict(table=table, drive=drive, method=method, pairs=m["n"], pitch_deg=m["pitch_deg"],
                roll_deg=m["roll_deg"])


def _suspension(d, kw: dict | None, with_speed: bool, speeds: dict):
    if kw is None:                     # live: the streaming estimator's choices over the drive (estimate --causal)
        return _live(d)
    return SuspensionAwareFilter(extrinsic=d.extrinsic, **kw).run(d.egomotion,
                                                                    speed=speeds[d.name] if with_speed else None)


def _live(d):
    """The drive as ``estimate --causal`` (equal to ``StreamingEstimator`` fed it sample by sample) estimates it,
    with the INS speed; on the drive's own frames (the causal clock gives the same frames on these drives)."""
    t, v = log_speed(d.egomotion.meta.get("source", ""), "kitti_imu100", d.imu)
    track, _ = causal_track(d.imu.t, d.imu.gyro, d.imu.accel, extrinsic=d.extrinsic, speed=(t, v))
    if len(track) != len(d.egomotion) or np.max(np.abs(track.t - d.egomotion.t)) > 0.05:
        raise ValueError(f"{d.name}: the live frames are not the drive's ({len(track)} against {len(d.egomotion)})")
    return track


def revisit_rows(rev: list, pairs: dict, speeds: dict) -> list[dict]:
    """Per drive and pooled: every evaluation method and the suspension variants."""
    out, pooled = [], {}
    tracks = {}
    for d in rev:
        for name in METHODS:
            tracks[(d.name, name)] = run_method(name, d)[0]
        for label, (kw, sp) in VARIANTS.items():
            tracks[(d.name, label)] = _suspension(d, kw, sp, speeds)
    labels = list(METHODS) + list(VARIANTS)
    for label in labels:
        for d in rev:
            dp, dr = _revisit(pairs[d.name], tracks[(d.name, label)])
            out.append(_row("revisit", d.name, label, dp, dr))
            acc = pooled.setdefault(label, ([], []))
            acc[0].append(dp)
            acc[1].append(dr)
    for label in labels:
        dp, dr = (np.concatenate(x) for x in pooled[label])
        out.append(_row("revisit", "pooled", label, dp, dr))
    return out


#: Bins (deg) of the INS-grade reference's own 1-sigma uncertainty: below 0.15 deg it can judge about 0.1 deg.
SIGMA_EDGES = (0.0, 0.1, 0.15, 0.25, math.inf)


def _frame_errors(d, track) -> tuple[np.ndarray, np.ndarray]:
    """|pitch error| (deg, means removed) and the reference's sigma (deg) on the evaluated frames."""
    tr = d.truth
    m = tr["evaluate"].to_numpy(bool) & np.asarray(track.valid, dtype=bool)
    est, ref = track.pitch, tr["pitch"].to_numpy(float)
    e = (est - est[m].mean()) - (ref - ref[m].mean())
    return np.degrees(np.abs(e[m])), np.degrees(tr["ref_sigma"].to_numpy(float)[m])


def ins_grade_rows(ds: list, speeds: dict) -> list[dict]:
    """Mean over drives, worst ratio to the paper's method, and the pooled error by the reference's sigma."""
    def binned(pairs) -> dict:
        e = np.concatenate([p[0] for p in pairs])
        s = np.concatenate([p[1] for p in pairs])
        b = np.digitize(s, SIGMA_EDGES[1:-1])
        return {(f"sigma {lo:g}-{hi:g} deg" if math.isfinite(hi) else f"sigma > {lo:g} deg"):
                float(e[b == k].mean()) for k, (lo, hi) in enumerate(zip(SIGMA_EDGES[:-1], SIGMA_EDGES[1:], strict=True))}

    tracks = [GroundNormalFilter.paper(extrinsic=d.extrinsic).run(d.egomotion) for d in ds]
    paper = np.array([score(d, t) for d, t in zip(ds, tracks, strict=True)])
    out = [dict(table="INS-grade", method="paper", drives=len(ds), mean_deg=float(paper.mean()),
                **binned([_frame_errors(d, t) for d, t in zip(ds, tracks, strict=True)]))]
    for label, (kw, sp) in VARIANTS.items():
        tracks = [_suspension(d, kw, sp, speeds) for d in ds]
        e = np.array([score(d, t) for d, t in zip(ds, tracks, strict=True)])
        r = e / paper
        out.append(dict(table="INS-grade", method=label, drives=len(ds), mean_deg=float(e.mean()),
                        worst_ratio_to_paper=float(r.max()), worst_drive=ds[int(r.argmax())].name,
                        **binned([_frame_errors(d, t) for d, t in zip(ds, tracks, strict=True)])))
    return out


def held_out_rows(rev: list, pairs: dict, speeds: dict) -> list[dict]:
    """Each setting of ``GRIDS`` (all else at today's defaults, with the speed): chosen on one revisit drive
    by the sum of pitch and roll there, scored on the other; and chosen on the first half of every drive's
    pairs (in time), scored on the second half."""
    out = []
    for name, (grid, kw_of) in GRIDS.items():
        res = {}                                    # (drive, value) -> (dp, dr)
        for d in rev:
            for x in grid:
                res[(d.name, x)] = _revisit(pairs[d.name], _suspension(d, kw_of(x), True, speeds))

        def metric(sel):
            dp = np.concatenate([s[0] for s in sel])
            dr = np.concatenate([s[1] for s in sel])
            m = revisit_consistency(dp, dr)
            return m["pitch_deg"], m["roll_deg"]

        schemes = [(f"chosen on {a.name}, scored on {b.name}", lambda x, a=a: [res[(a.name, x)]],  # noqa: B023 (used in this iteration)
                    lambda x, b=b: [res[(b.name, x)]]) for a in rev for b in rev if a is not b]  # noqa: B023 (used in this iteration)
        def half(v, first):
            return (v[0][: len(v[0]) // 2], v[1][: len(v[1]) // 2]) if first else \
                (v[0][len(v[0]) // 2:], v[1][len(v[1]) // 2:])
        schemes.append(("chosen on the first half of each drive's pairs, scored on the second",
                        lambda x: [half(res[(d.name, x)], True) for d in rev],  # noqa: B023 (used in this iteration)
                        lambda x: [half(res[(d.name, x)], False) for d in rev]))  # noqa: B023 (used in this iteration)
        for label, train, test in schemes:
            tr = {x: metric(train(x)) for x in grid}
            best = min(grid, key=lambda x: sum(tr[x]))
            te = metric(test(best))
            row = dict(table="held out", setting=name, scheme=label, chosen=best,
                       pitch_deg=te[0], roll_deg=te[1])
            row["grid (pitch/roll held out)"] = "; ".join(f"{x:g}: {metric(test(x))[0]:.3f}/{metric(test(x))[1]:.3f}"
                                                           for x in grid)
            out.append(row)
    return out


def synthetic_rows(n: int = SYNTHETIC_DRIVES) -> list[dict]:
    """Mean absolute pitch and roll error (deg, exact truth) of the suspension filter before and now."""
    ds = synthetic_drives(n, seed=0, progress=False)
    out = []
    for grade in ("nav", "mems"):
        for label, kw in (("suspension before", BEFORE), ("suspension now without q_turn", dict(q_turn=0.0)),
                          ("suspension now", {})):
            for smooth in (False, True):
                p, r = [], []
                for d in ds:
                    if d.grade != grade:
                        continue
                    tr = SuspensionAwareFilter(extrinsic=d.extrinsic, **kw).run(d.egomotion, smooth=smooth)
                    m = d.truth["evaluate"].to_numpy(bool) & tr.valid
                    e = evaluate_drive(tr.pitch, d.truth["pitch"].to_numpy(), tr.roll, d.truth["roll"].to_numpy(),
                                       mask=m, remove_mean=False)
                    p.append(e["pitch"]["mean"])
                    r.append(e["roll"]["mean"])
                out.append(dict(table="synthetic", grade=grade, method=label + (", offline" if smooth else ""),
                                drives=len(p), pitch_deg=float(np.mean(p)), roll_deg=float(np.mean(r))))
    return out


def rows(data: Path = DEFAULT_DATA, drives: int = 0, n: int = SYNTHETIC_DRIVES) -> list[dict]:
    """All four tables (``drives``: the INS-grade table on the first N valid drives only, 0 = all;
    ``n``: synthetic drives per grade)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = [d for d in load_real_drives(Path(data), progress=False) if d.valid]
        pairs = {d.name: drive_revisit_pairs(d) for d in ds}
        rev = [d for d in ds if len(pairs[d.name])]
        grade_drives = ds[:drives] if drives else ds
        speeds = {d.name: drive_speed(d) for d in {id(d): d for d in rev + grade_drives}.values()}
        return (revisit_rows(rev, pairs, speeds) + ins_grade_rows(grade_drives, speeds)
                + held_out_rows(rev, pairs, speeds) + synthetic_rows(n))


def main(argv=None) -> int:
    a = parse_args(__doc__, argv)
    import pandas as pd
    out = pd.DataFrame(rows(Path(a.data), a.drives))
    for name, g in out.groupby("table", sort=False):
        print(f"\n{name}")
        table = g.dropna(axis=1, how="all").drop(columns="table")
        print(table.to_string(index=False, float_format=lambda v: f"{v:.3f}"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
