"""Plots for evaluations and simulations (PNG, matplotlib: ``pip install imu-ground[plot]``).

- :func:`plot_pitch_over_time`: estimated pitch of each method against the reference.
- :func:`plot_error_distribution`: per-frame error histogram and CDF per method.
- :func:`plot_simulation`: the synthetic road (top view, grade and bank) and the body motion.
- :func:`evaluation_plots`: all of the above for an evaluation run.

Angles are shown in degrees; pitch positive nose down, roll positive left side up.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Optional, Sequence

import numpy as np
import pandas as pd

from imu_ground.errors import require_extra
from imu_ground.evaluation.metrics import normal_angle

__all__ = ["plot_pitch_over_time", "plot_error_distribution", "plot_simulation", "evaluation_plots"]


def _plt():
    matplotlib = require_extra("matplotlib", "plot", "plots")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _frame_errors(drive, track) -> np.ndarray:
    """Per-frame error (deg) as evaluated: pitch for real drives (means removed), normal angle otherwise."""
    m = drive.truth["evaluate"].to_numpy()
    if drive.has_roll:
        return normal_angle(track.normal, drive.truth[["normal_x", "normal_y", "normal_z"]].to_numpy())[m]
    est, ref = track.pitch[m], drive.truth["pitch"].to_numpy()[m]
    if drive.remove_mean:
        est, ref = est - est.mean(), ref - ref.mean()
    return np.abs(np.degrees(est - ref))


def plot_pitch_over_time(drive, tracks: dict, path: Path, methods: Optional[Sequence[str]] = None) -> Path:
    """Pitch relative to the road over time: reference and each method's estimate.

    Parameters
    ----------
    drive : imu_ground.evaluation.runner.Drive
    tracks : dict
        ``{method: GroundTrack}`` for this drive.
    path : Path
        PNG to write.
    """
    plt = _plt()
    t = drive.egomotion.t
    m = drive.truth["evaluate"].to_numpy()
    ref = drive.truth["pitch"].to_numpy()
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    ax = axes[0]
    off = ref[m].mean() if drive.remove_mean and m.any() else 0.0
    ax.plot(t, np.degrees(np.where(m, ref - off, np.nan)), color="k", lw=2.0, label="reference")
    for name in methods or list(tracks):
        tr = tracks[name]
        est = tr.pitch - (tr.pitch[m].mean() if drive.remove_mean and m.any() else 0.0)
        ax.plot(t, np.degrees(est), lw=1.0, label=name)
    ax.set_ylabel("pitch rel. road (deg, + nose down)")
    ax.set_title(f"{drive.name} ({drive.kind}, {drive.grade})" +
                 (": estimate and reference mean-removed" if drive.remove_mean else ""))
    ax.legend(loc="upper right", ncol=3, fontsize=8)
    ax.grid(alpha=0.3)
    axes[1].plot(t, drive.truth["speed"].to_numpy(), color="tab:gray")
    axes[1].axhline(3.0, color="tab:red", lw=0.8, ls="--")
    axes[1].set_ylabel("speed (m/s)")
    axes[1].set_xlabel("time (s)")
    axes[1].grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_error_distribution(errors: dict, path: Path, title: str = "") -> Path:
    """Histogram and empirical CDF of per-frame absolute errors (deg), one curve per method."""
    plt = _plt()
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
    allv = np.concatenate([v for v in errors.values() if len(v)]) if errors else np.zeros(1)
    hi = np.percentile(allv, 99) if allv.size else 1.0
    bins = np.linspace(0.0, max(hi, 1e-3), 60)
    for name, e in errors.items():
        e = np.asarray(e)
        if not len(e):
            continue
        a1.hist(np.clip(e, 0, bins[-1]), bins=bins, histtype="step", lw=1.3, density=True,
                label=f"{name} (mean {e.mean():.3f})")
        s = np.sort(e)
        a2.plot(s, np.arange(1, len(s) + 1) / len(s), lw=1.3, label=name)
    a1.set_xlabel("absolute error (deg; the last bin holds the top 1%)")
    a1.set_ylabel("density")
    a1.legend(fontsize=8)
    a2.set_xlabel("absolute error (deg)")
    a2.set_ylabel("fraction of frames")
    a2.set_xlim(0, bins[-1])
    a2.grid(alpha=0.3)
    a2.legend(fontsize=8, loc="lower right")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_simulation(sim, path: Path) -> Path:
    """The synthetic road and the body motion of a :class:`~imu_ground.evaluation.simulate.SimResult`.

    Panels: top view of the path coloured by speed; road grade and bank along
    the path; roughness profile (left and right tracks); body pitch and roll
    relative to the road with the longitudinal and lateral acceleration.
    """
    plt = _plt()
    tr = sim.truth
    fig = plt.figure(figsize=(12, 9))
    gs = fig.add_gridspec(3, 2)
    ax = fig.add_subplot(gs[:2, 0])
    sc = ax.scatter(tr["x"], tr["y"], c=tr["speed"], s=4, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="speed (m/s)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title(f"{sim.name or 'synthetic drive'}: path")
    ax = fig.add_subplot(gs[0, 1])
    ax.plot(tr["s"], np.degrees(tr["road_grade"]), label="grade (+ uphill)")
    ax.plot(tr["s"], np.degrees(tr["road_bank"]), label="bank (+ left edge up)")
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("deg")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = fig.add_subplot(gs[1, 1])
    road = sim.road
    x = np.asarray(road["x"])
    sel = (x >= 0) & (x <= min(tr["s"].max(), 200.0))
    ax.plot(x[sel], 1e3 * np.asarray(road["h_left"])[sel], lw=0.7, label="left track")
    ax.plot(x[sel], 1e3 * np.asarray(road["h_right"])[sel], lw=0.7, label="right track")
    ax.set_xlabel("distance (m)")
    ax.set_ylabel("roughness (mm)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = fig.add_subplot(gs[2, :])
    ax.plot(tr["t"], np.degrees(tr["pitch"]), label="body pitch rel. road (deg)")
    ax.plot(tr["t"], np.degrees(tr["roll"]), label="body roll rel. road (deg)")
    ax2 = ax.twinx()
    ax2.plot(tr["t"], tr["acc_long"], color="tab:gray", lw=0.8, alpha=0.7, label="long. accel (m/s²)")
    ax2.plot(tr["t"], tr["acc_lat"], color="tab:olive", lw=0.8, alpha=0.7, label="lat. accel (m/s²)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("deg")
    ax2.set_ylabel("m/s²")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, ncol=4, loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def evaluation_plots(drives: Iterable, results: pd.DataFrame, tracks: dict, folder: Path,
                     max_drives: int = 6) -> list[Path]:
    """PNG plots of an evaluation run: pitch over time (a few drives), error distributions per drive set.

    Parameters
    ----------
    drives : the drives evaluated.
    results : DataFrame from :func:`imu_ground.evaluation.runner.evaluate`.
    tracks : ``{(drive, method): GroundTrack}`` from the same call (``keep_tracks=True``).
    folder : output folder (created).
    max_drives : pitch-over-time plots for at most this many drives per kind.

    Returns
    -------
    list of Path
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    drives = [d for d in drives if d.valid]
    methods = list(dict.fromkeys(results["method"]))
    per_set: dict = {}
    shown: dict = {}
    for d in drives:
        key = "real" if d.kind == "real" else f"synthetic-{d.grade}"
        dtracks = {m: tracks[(d.name, m)] for m in methods if (d.name, m) in tracks}
        for m, tr in dtracks.items():
            per_set.setdefault(key, {}).setdefault(m, []).append(_frame_errors(d, tr))
        if shown.get(key, 0) < max_drives:
            shown[key] = shown.get(key, 0) + 1
            out.append(plot_pitch_over_time(d, dtracks, folder / f"pitch_{d.name}.png"))
    for key, errs in per_set.items():
        what = "pitch error, means removed" if key == "real" else "normal angle error"
        merged = {m: np.concatenate(v) for m, v in errs.items()}
        out.append(plot_error_distribution(merged, folder / f"errors_{key}.png", f"{key}: {what}"))
    sims = [d for d in drives if d.kind == "synthetic"]
    if sims and sims[0].sim is not None:
        out.append(plot_simulation(sims[0].sim, folder / f"road_{sims[0].name}.png"))
    return out
