"""Tune the process noise of the heading-following GroundNormalFilter on the real KITTI drives.

Only the ratio Q/R matters for the estimate (P0 = R), so R = 1 and Q is searched on a
log grid. The score is the evaluation's: mean absolute pitch error relative to the
road over moving frames, means removed, averaged over the valid drives. A split-half
check (tune on one half, test on the other, 20 random splits) shows whether the
choice carries over to drives it was not tuned on.

Run: ``python benchmarks/tune_paper.py [--data ../shared/data/kitti_imu100]``
"""
from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from imu_ground.evaluation.runner import load_real_drives
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.evaluation.metrics import evaluate_drive

GRID = [1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0, 3.0]


def score(drive, Q):
    tr = GroundNormalFilter(Q=Q, R=1.0, P=1.0, extrinsic=drive.extrinsic).run(drive.egomotion.delta_R)
    res = evaluate_drive(tr.pitch, drive.truth["pitch"], mask=drive.truth["evaluate"].to_numpy(), remove_mean=True)
    return res["pitch"]["mean"]


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data" / "kitti_imu100"))
    a = ap.parse_args(argv)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        drives = [d for d in load_real_drives(Path(a.data), progress=False) if d.valid]
    table = np.array([[score(d, q) for q in GRID] for d in drives])      # drives x grid
    mean = table.mean(axis=0)
    print(f"{len(drives)} valid drives; mean |pitch error| (deg) by Q (R = 1):")
    for q, m in zip(GRID, mean):
        print(f"  Q = {q:<6g} {m:.4f}")
    best = GRID[int(np.argmin(mean))]
    print(f"best on all drives: Q = {best:g}")
    rng = np.random.default_rng(0)
    picks, tests, papers = [], [], []
    i_paper = GRID.index(1e-2)
    for _ in range(20):
        idx = rng.permutation(len(drives))
        tr_i, te_i = idx[: len(idx) // 2], idx[len(idx) // 2:]
        j = int(np.argmin(table[tr_i].mean(axis=0)))
        picks.append(GRID[j])
        tests.append(table[te_i, j].mean())
        papers.append(table[te_i, i_paper].mean())
    print(f"split-half (20 splits): chosen Q {sorted(set(picks))}, held-out error {np.mean(tests):.4f} "
          f"(Q = 1e-2 on the same halves: {np.mean(papers):.4f})")


if __name__ == "__main__":
    main()
