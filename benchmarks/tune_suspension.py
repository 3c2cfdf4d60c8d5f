"""The suspension-aware filter's configuration on the real KITTI drives: load share and configurations.

The load that tilts the body is the gravity-compensated acceleration plus a share
of gravity's road-plane component (``SuspensionAwareFilter(load=share)``). For each
share on a grid this reports the real-data score (mean absolute pitch error relative
to the road, moving frames, means removed, averaged over the valid drives) and the
worst per-drive ratio to the paper's method, checks the selection rule (lowest mean
error with every drive within 10 % of the paper) on held-out halves, and scores the
filter's configurations (streaming, online gains, offline blend, pure RTS smoother):
the figures the module docstrings point to ``benchmarks/RESULTS.md`` for.

Run: ``python benchmarks/tune_suspension.py [--data ../shared/data/kitti_imu100]``;
``rows()`` returns the tables for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from imu_ground.evaluation.metrics import evaluate_drive
from imu_ground.filters import GroundNormalFilter, SuspensionAwareFilter

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tune_paper import DEFAULT_DATA, parse_args, valid_drives  # noqa: E402

SHARES = [0.0, 0.25, 0.5, 0.6, 0.75, 1.0]
#: label -> (constructor keywords, smooth)
CONFIGURATIONS = {
    "streaming (default)": ({}, False),
    "online gains": (dict(online_gains=True), False),
    "offline (smoother_weight 0.25)": ({}, True),
    "offline, pure RTS smoother": (dict(smoother_weight=1.0), True),
}


def score(drive, track) -> float:
    res = evaluate_drive(track.pitch, drive.truth["pitch"], mask=drive.truth["evaluate"].to_numpy(),
                         remove_mean=True)
    return res["pitch"]["mean"]


def pick(err: np.ndarray, paper: np.ndarray, idx: np.ndarray) -> int:
    """Grid index with the lowest mean over ``idx`` whose worst ratio to the paper is <= 1.1."""
    ok = [(err[idx, j].mean(), j) for j in range(err.shape[1]) if (err[idx, j] / paper[idx]).max() <= 1.1]
    return min(ok)[1] if ok else int(np.argmin(err[idx].mean(axis=0)))


def rows(data: Path = DEFAULT_DATA, drives: int = 0) -> list[dict]:
    """Load-share grid, split-half check and configurations as rows (``drives``: first N only, 0 = all)."""
    ds = valid_drives(data, drives)
    paper = np.array([score(d, GroundNormalFilter.paper(extrinsic=d.extrinsic).run(d.egomotion)) for d in ds])
    err = np.array([[score(d, SuspensionAwareFilter(extrinsic=d.extrinsic, load=s).run(d.egomotion))
                     for s in SHARES] for d in ds])
    out = [dict(table="load share", setting=f"load={s:g}", drives=len(ds), mean_deg=float(err[:, j].mean()),
                worst_ratio_to_paper=float((err[:, j] / paper).max()),
                worst_drive=ds[int((err[:, j] / paper).argmax())].name) for j, s in enumerate(SHARES)]
    j = pick(err, paper, np.arange(len(ds)))
    rng = np.random.default_rng(0)
    held, chosen = [], []
    for _ in range(20):
        idx = rng.permutation(len(ds))
        tr, te = idx[: len(idx) // 2], idx[len(idx) // 2:]
        k = pick(err, paper, tr)
        chosen.append(SHARES[k])
        held.append(err[te, k].mean())
    out.append(dict(table="load share", setting=f"rule on all drives: load={SHARES[j]:g}; split-half (20 splits) "
                    f"chose {sorted(set(chosen))}", drives=len(ds), mean_deg=float(np.mean(held))))
    out.append(dict(table="configurations", setting="paper's method", drives=len(ds), mean_deg=float(paper.mean())))
    for label, (kw, smooth) in CONFIGURATIONS.items():
        e = np.array([score(d, SuspensionAwareFilter(extrinsic=d.extrinsic, **kw).run(d.egomotion, smooth=smooth))
                      for d in ds])
        out.append(dict(table="configurations", setting=label, drives=len(ds), mean_deg=float(e.mean()),
                        worst_ratio_to_paper=float((e / paper).max()), worst_drive=ds[int((e / paper).argmax())].name))
    return out


def main(argv=None) -> None:
    a = parse_args(__doc__, argv)
    for r in rows(Path(a.data), a.drives):
        extra = f", worst ratio to the paper {r['worst_ratio_to_paper']:.3f} ({r['worst_drive']})" \
            if "worst_ratio_to_paper" in r else ""
        print(f"[{r['table']}] {r['setting']}: {r['mean_deg']:.4f} deg over {r['drives']} drives{extra}")


if __name__ == "__main__":
    main()
