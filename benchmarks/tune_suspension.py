"""The suspension-aware filter's configuration on the real KITTI drives: load share and configurations.

The load that tilts the body is the gravity-compensated acceleration plus a share
of gravity's road-plane component (``SuspensionAwareFilter(load=share)``). For each
share on a grid this reports the real-data score (mean absolute pitch error relative
to the road, moving frames, means removed, averaged over the valid drives) and the
worst per-drive ratio to the paper's method, checks the selection rule (lowest mean
error with every drive within 10 % of the paper) on held-out halves, and scores the
filter's configurations (streaming, online gains, offline blend, pure RTS smoother).
The pitch from the lateral load (``cross_gain``) is chosen the same way on its grid,
and the speed-aided mode (the KITTI INS horizontal speed ``hypot(ve, vn)`` as the
wheel speed, :mod:`imu_ground.datasets.speed`) is scored beside IMU only, with the
per-moving-segment metric: the figures the module docstrings point to
``benchmarks/RESULTS.md`` for.

Run: ``python benchmarks/tune_suspension.py [--data ../shared/data/kitti_imu100]``;
``rows()`` returns the tables for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from imu_ground.datasets.speed import frame_speed, log_speed
from imu_ground.evaluation.conditions import moving_segments, segment_centred
from imu_ground.evaluation.metrics import evaluate_drive
from imu_ground.filters import GroundNormalFilter, SuspensionAwareFilter
from imu_ground.units import DEG

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tune_paper import DEFAULT_DATA, parse_args, valid_drives  # noqa: E402

SHARES = [0.0, 0.25, 0.5, 0.6, 0.75, 1.0]
#: cross_gain grid, deg (pitch) per m/s^2 (lateral load).
CROSS_GAINS = [0.0, -0.025, -0.05, -0.075, -0.1]
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


def segment_score(drive, track) -> float:
    """Mean absolute pitch error, deg, with the means removed per moving segment (between stops)."""
    tr = drive.truth
    use = tr["evaluate"].to_numpy(bool) & np.asarray(track.valid, dtype=bool)
    e = segment_centred(track.pitch, tr["pitch"].to_numpy(float), use, moving_segments(tr["speed"].to_numpy(float)))
    return float(np.degrees(np.nanmean(np.abs(e))))


def drive_speed(drive) -> np.ndarray:
    """The drive's INS horizontal speed averaged over each frame, m/s."""
    t, v = log_speed(drive.egomotion.meta.get("source", ""), "kitti_imu100", drive.imu)
    return frame_speed(t, v, drive.egomotion.t, drive.egomotion.delta_t)


def split_half(err: np.ndarray, paper: np.ndarray, labels: list, n: int = 20, base: int = 0):
    """Held-out mean error over ``n`` random half splits (chosen on one half, scored on the other),
    the choices, and column ``base``'s mean over the same held-out halves."""
    rng = np.random.default_rng(0)
    held, chosen, held_base = [], [], []
    for _ in range(n):
        idx = rng.permutation(len(err))
        tr, te = idx[: len(idx) // 2], idx[len(idx) // 2:]
        k = pick(err, paper, tr)
        chosen.append(labels[k])
        held.append(err[te, k].mean())
        held_base.append(err[te, base].mean())
    return float(np.mean(held)), sorted(set(chosen)), float(np.mean(held_base))


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
    held, chosen, _ = split_half(err, paper, SHARES)
    out.append(dict(table="load share", setting=f"rule on all drives: load={SHARES[j]:g}; split-half (20 splits) "
                    f"chose {chosen}", drives=len(ds), mean_deg=held))
    out += _cross_and_speed(ds, paper)
    out.append(dict(table="configurations", setting="paper's method", drives=len(ds), mean_deg=float(paper.mean())))
    for label, (kw, smooth) in CONFIGURATIONS.items():
        e = np.array([score(d, SuspensionAwareFilter(extrinsic=d.extrinsic, **kw).run(d.egomotion, smooth=smooth))
                      for d in ds])
        out.append(dict(table="configurations", setting=label, drives=len(ds), mean_deg=float(e.mean()),
                        worst_ratio_to_paper=float((e / paper).max()), worst_drive=ds[int((e / paper).argmax())].name))
    return out


def _cross_and_speed(ds, paper) -> list[dict]:
    """cross_gain grid (split-half) and IMU only against IMU + speed, streaming, with the per-segment metric."""
    out = []
    err = np.array([[score(d, SuspensionAwareFilter(extrinsic=d.extrinsic, cross_gain=c * DEG).run(d.egomotion))
                     for c in CROSS_GAINS] for d in ds])
    for j, c in enumerate(CROSS_GAINS):
        r = err[:, j] / paper
        out.append(dict(table="cross gain", setting=f"cross_gain={c:g} deg/(m/s^2)", drives=len(ds),
                        mean_deg=float(err[:, j].mean()), worst_ratio_to_paper=float(r.max()),
                        worst_drive=ds[int(r.argmax())].name))
    held, chosen, held0 = split_half(err, paper, CROSS_GAINS)
    out.append(dict(table="cross gain", setting=f"split-half (20 splits) chose {chosen} deg/(m/s^2); held out "
                    f"(cross_gain 0 on the same halves: {held0:.4f})", drives=len(ds), mean_deg=held))
    modes = {"IMU only": lambda d: None, "IMU + speed": drive_speed}
    errs = {}
    for label, speed in modes.items():
        tracks = [SuspensionAwareFilter(extrinsic=d.extrinsic).run(d.egomotion, speed=speed(d)) for d in ds]
        e = np.array([score(d, t) for d, t in zip(ds, tracks)])
        seg = np.array([segment_score(d, t) for d, t in zip(ds, tracks)])
        errs[label] = e
        out.append(dict(table="speed-aided", setting=f"{label}, streaming", drives=len(ds), mean_deg=float(e.mean()),
                        segment_mean_deg=float(seg.mean()), worst_ratio_to_paper=float((e / paper).max()),
                        worst_drive=ds[int((e / paper).argmax())].name))
    both = np.column_stack([errs["IMU only"], errs["IMU + speed"]])
    better = int(np.sum(both[:, 1] <= both[:, 0]))
    out.append(dict(table="speed-aided", setting=f"IMU + speed no worse than IMU only on {better} of {len(ds)} drives "
                    f"(largest increase {float(np.max(both[:, 1] - both[:, 0])):+.4f} deg)", drives=len(ds),
                    mean_deg=float(both[:, 1].mean())))
    return out


def main(argv=None) -> None:
    a = parse_args(__doc__, argv)
    for r in rows(Path(a.data), a.drives):
        extra = f", worst ratio to the paper {r['worst_ratio_to_paper']:.3f} ({r['worst_drive']})" \
            if "worst_ratio_to_paper" in r else ""
        seg = f", per segment {r['segment_mean_deg']:.4f}" if "segment_mean_deg" in r else ""
        print(f"[{r['table']}] {r['setting']}: {r['mean_deg']:.4f} deg over {r['drives']} drives{seg}{extra}")


if __name__ == "__main__":
    main()
