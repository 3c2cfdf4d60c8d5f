"""Tune the process noise of the heading-following GroundNormalFilter on the real KITTI drives.

Only the ratio Q/R matters for the estimate (P0 = R), so R = 1 and Q is searched on a
log grid. The score is the evaluation's: mean absolute pitch error relative to the
road over moving frames, means removed, averaged over the valid drives. A split-half
check (tune on one half, test on the other, 20 random splits) shows whether the
choice carries over to drives it was not tuned on.

Run: ``python benchmarks/studies/tune_paper.py [--data ../shared/data/kitti_imu100]``;
``rows()`` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from imu_ground.evaluation.metrics import evaluate_drive
from imu_ground.evaluation.runner import load_real_drives
from imu_ground.filters import GroundNormalFilter

GRID = [1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0, 3.0]
DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "kitti_imu100"


def score(drive, Q):
    tr = GroundNormalFilter(Q=Q, R=1.0, P=1.0, extrinsic=drive.extrinsic).run(drive.egomotion)
    res = evaluate_drive(tr.pitch, drive.truth["pitch"], mask=drive.truth["evaluate"].to_numpy(), remove_mean=True)
    return res["pitch"]["mean"]


def valid_drives(data: Path = DEFAULT_DATA, drives: int = 0) -> list:
    """The valid real drives of ``data`` (the first ``drives`` only; 0: all), reader warnings silenced."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = [d for d in load_real_drives(Path(data), progress=False) if d.valid]
    return ds[:drives] if drives else ds


def parse_args(doc: str, argv=None) -> argparse.Namespace:
    """``--data`` and ``--drives``, the options of the tuning scripts."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    ap.add_argument("--drives", type=int, default=0, help="first N valid drives only (0: all)")
    return ap.parse_args(argv)


def rows(data: Path = DEFAULT_DATA, drives: int = 0) -> list[dict]:
    """Mean error per Q and the split-half check as rows (``drives``: first N only, 0 = all)."""
    ds = valid_drives(data, drives)
    table = np.array([[score(d, q) for q in GRID] for d in ds])      # drives x grid
    mean = table.mean(axis=0)
    out = [dict(Q=q, R=1.0, drives=len(ds), mean_deg=float(m)) for q, m in zip(GRID, mean, strict=True)]
    rng = np.random.default_rng(0)
    picks, tests, papers = [], [], []
    i_paper = GRID.index(1e-2)
    for _ in range(20):
        idx = rng.permutation(len(ds))
        tr_i, te_i = idx[: len(idx) // 2], idx[len(idx) // 2:]
        j = int(np.argmin(table[tr_i].mean(axis=0)))
        picks.append(GRID[j])
        tests.append(table[te_i, j].mean())
        papers.append(table[te_i, i_paper].mean())
    out.append(dict(Q=f"split-half choice {sorted(set(picks))}", R=1.0, drives=len(ds),
                    mean_deg=float(np.mean(tests)), paper_Q_same_halves_deg=float(np.mean(papers))))
    return out


def main(argv=None) -> None:
    a = parse_args(__doc__, argv)
    out = rows(Path(a.data), a.drives)
    print(f"{out[0]['drives']} valid drives; mean |pitch error| (deg) by Q (R = 1):")
    for r in out[:-1]:
        print(f"  Q = {r['Q']:<6g} {r['mean_deg']:.4f}")
    best = min(out[:-1], key=lambda r: r["mean_deg"])
    print(f"best on all drives: Q = {best['Q']:g}")
    last = out[-1]
    print(f"split-half (20 splits): {last['Q']}, held-out error {last['mean_deg']:.4f} "
          f"(Q = 1e-2 on the same halves: {last['paper_Q_same_halves_deg']:.4f})")


if __name__ == "__main__":
    main()
