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

Run: ``python benchmarks/studies/tune_suspension.py [--data ../shared/data/kitti_imu100]``;
``rows()`` returns the tables for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
from imu_ground.datasets.speed import frame_speed, log_speed

from imu_ground.evaluation.conditions import moving_segments, segment_centred
from imu_ground.evaluation.metrics import evaluate_drive
from imu_ground.filters import GroundNormalFilter, SuspensionAwareFilter
from imu_ground.units import DEG

sys.path.insert(0, str(Path(__file__).resolve().parent))
from tune_paper import DEFAULT_DATA, parse_args, valid_drives

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
    out += _cross_and_speed(ds, paper) + other_logs(data)
    out.append(dict(table="configurations", setting="paper's method", drives=len(ds), mean_deg=float(paper.mean())))
    for label, (kw, smooth) in CONFIGURATIONS.items():
        e = np.array([score(d, SuspensionAwareFilter(extrinsic=d.extrinsic, **kw).run(d.egomotion, smooth=smooth))
                      for d in ds])
        out.append(dict(table="configurations", setting=label, drives=len(ds), mean_deg=float(e.mean()),
                        worst_ratio_to_paper=float((e / paper).max()), worst_drive=ds[int((e / paper).argmax())].name))
    return out


def _grid(ds, speeds) -> tuple[np.ndarray, np.ndarray]:
    """Per-drive scores (drives x CROSS_GAINS): drive-mean removed and per moving segment."""
    err, seg = np.zeros((len(ds), len(CROSS_GAINS))), np.zeros((len(ds), len(CROSS_GAINS)))
    for i, (d, v) in enumerate(zip(ds, speeds, strict=True)):
        for j, c in enumerate(CROSS_GAINS):
            tr = SuspensionAwareFilter(extrinsic=d.extrinsic, cross_gain=c * DEG).run(d.egomotion, speed=v)
            err[i, j], seg[i, j] = score(d, tr), segment_score(d, tr)
    return err, seg


def _cross_and_speed(ds, paper) -> list[dict]:
    """cross_gain grid with split-half, IMU only and IMU + speed (streaming), per drive and per segment."""
    out = []
    jd = CROSS_GAINS.index(-0.05)
    grids = {"IMU only": _grid(ds, [None] * len(ds)), "IMU + speed": _grid(ds, [drive_speed(d) for d in ds])}
    err = grids["IMU only"][0]
    for j, c in enumerate(CROSS_GAINS):
        r = err[:, j] / paper
        out.append(dict(table="cross gain", setting=f"cross_gain={c:g} deg/(m/s^2)", drives=len(ds),
                        mean_deg=float(err[:, j].mean()), worst_ratio_to_paper=float(r.max()),
                        worst_drive=ds[int(r.argmax())].name))
    for label, (e, seg) in grids.items():
        held, chosen, held0 = split_half(e, paper, CROSS_GAINS)
        out.append(dict(table="speed-aided", setting=f"{label}, streaming, cross_gain -0.05 (default)", drives=len(ds),
                        mean_deg=float(e[:, jd].mean()), segment_mean_deg=float(seg[:, jd].mean()),
                        worst_ratio_to_paper=float((e[:, jd] / paper).max()),
                        worst_drive=ds[int((e[:, jd] / paper).argmax())].name))
        out.append(dict(table="speed-aided", setting=f"{label}: cross_gain by split-half (20 splits, chose {chosen}), "
                        f"held out (cross_gain 0 on the same halves {held0:.4f})", drives=len(ds), mean_deg=held))
    imu, spd = grids["IMU only"][0][:, jd], grids["IMU + speed"][0][:, jd]
    out.append(dict(table="speed-aided", setting=f"IMU + speed no worse than IMU only on {int(np.sum(spd <= imu))} "
                    f"of {len(ds)} drives (largest increase {float(np.max(spd - imu)):+.4f} deg, "
                    f"{ds[int(np.argmax(spd - imu))].name})", drives=len(ds), mean_deg=float(spd.mean())))
    return out


def other_logs(data: Path = DEFAULT_DATA) -> list[dict]:
    """Sanity runs on the shared nuScenes and comma2k19 logs (no truth): IMU only and with the log's speed."""
    from imu_ground.pipeline import estimate_log
    out = []
    for name in ("nuscenes_can_bus", "comma2k19_example"):
        path = Path(data).parent / name
        if not path.exists():
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            a, b = (estimate_log(path, speed=sp) for sp in ("none", "auto"))
        ok = a.track.valid & b.track.valid
        diff = np.degrees(b.track.pitch[ok] - a.track.pitch[ok])
        sa, sb = (float(np.degrees(np.std(r.track.pitch[ok]))) for r in (a, b))
        out.append(dict(table="other logs", setting=f"{name}: {ok.sum()} frames, speed {b.meta['speed']}; pitch std "
                        f"{sa:.3f} (IMU) / {sb:.3f} (speed) deg; RMS difference", drives=1,
                        mean_deg=float(np.sqrt(np.mean(diff ** 2)))))
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
