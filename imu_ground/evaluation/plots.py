"""Plots for evaluations and simulations (PNG, matplotlib: ``pip install imu-ground[plot]``).

- :func:`plot_pitch_over_time`: estimated pitch (and roll) of each method against the reference, the
  :data:`HIGHLIGHTED` methods apart from the others, the default's 1-sigma band.
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
from imu_ground.evaluation.reference import MIN_SPEED
from imu_ground.filters.methods import default_method, reference_methods

__all__ = ["HIGHLIGHTED", "SAME_RMS_DEG", "error_distribution_figure", "evaluation_plots", "pitch_over_time_figure",
           "plot_error_distribution", "plot_pitch_over_time", "plot_simulation"]


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


#: Methods drawn bold in the pitch and roll panels, the first that is there being the default with its 1-sigma
#: band (``estimate``'s default for an IMU log, the paper's method, the static extrinsic alone); the others
#: have a panel of their own.
HIGHLIGHTED = (default_method(True), *reference_methods())
_LINESTYLES = ("-", "--", "-.", ":")


def _method_styles(methods: Sequence[str]) -> dict[str, dict]:
    """A colour and line style per method, the same in every picture of a run (highlighted: bold, solid)."""
    from imu_ground.evaluation.runner import METHODS
    order = list(dict.fromkeys([*METHODS, *methods]))
    styles = {}
    for name in methods:
        k = order.index(name)
        bold = name in HIGHLIGHTED
        styles[name] = {"color": f"C{k % 10}", "ls": "-" if bold else _LINESTYLES[k % len(_LINESTYLES)],
                        "lw": 1.5 if bold else 1.0}
    return styles


def _split_methods(methods: Sequence[str]) -> tuple[list[str], list[str]]:
    """``(highlighted, others)`` of ``methods``, the highlighted in :data:`HIGHLIGHTED` order."""
    bold = [m for m in HIGHLIGHTED if m in methods]
    return bold, [m for m in methods if m not in bold]


#: Two methods whose pitch differs by less than this RMS (deg, scored frames) lie on each other in a picture:
#: the later one's legend says so.
SAME_RMS_DEG = 0.01


def _overlap_labels(tracks: dict, names: Sequence[str], centred, m: np.ndarray) -> dict[str, str]:
    """Legend label per method: its name, and the earlier method it lies on (pitch within :data:`SAME_RMS_DEG`)."""
    labels: dict[str, str] = {}
    drawn: list[tuple[str, np.ndarray]] = []
    for name in names:
        p = np.degrees(centred(np.asarray(tracks[name].pitch, dtype=float)))[m]
        labels[name] = name
        for other, q in drawn:
            ok = np.isfinite(p) & np.isfinite(q)
            if ok.any() and (rms := float(np.sqrt(np.mean((p[ok] - q[ok]) ** 2)))) < SAME_RMS_DEG:
                labels[name] = f"{name} (on {other}: {rms:.3f} deg RMS apart)"
                break
        drawn.append((name, p))
    return labels


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    _plt().close(fig)
    return Path(path)


def plot_pitch_over_time(drive, tracks: dict, path: Path, methods: Optional[Sequence[str]] = None) -> Path:
    """Write :func:`pitch_over_time_figure` as a PNG to ``path``; returns ``path``."""
    return _save(pitch_over_time_figure(drive, tracks, methods), path)


def pitch_over_time_figure(drive, tracks: dict, methods: Optional[Sequence[str]] = None):
    """Pitch (and roll, where the truth has it) relative to the road over time: reference and estimates.

    The :data:`HIGHLIGHTED` methods (the default with its 1-sigma band) apart from the others;
    real drives less their means over the scored frames. Deg, pitch + nose down, roll + left up.

    Parameters
    ----------
    drive : imu_ground.evaluation.runner.Drive
    tracks : dict
        ``{method: GroundTrack}`` for this drive.
    methods : sequence of str, optional
        The methods to draw, in order (default: every key of ``tracks``).

    Returns
    -------
    matplotlib.figure.Figure
        Its axes, top to bottom: pitch, roll (with a roll truth), other methods (when there are), speed.
    """
    plt = _plt()
    names = [m for m in (methods or list(tracks)) if m in tracks]
    bold, others = _split_methods(names)
    styles = _method_styles(names)
    t = drive.egomotion.t
    m = drive.truth["evaluate"].to_numpy()
    angles = ["pitch", *(["roll"] if drive.has_roll else [])]
    panels = [*angles, *(["others"] if others else []), "speed"]
    ratios = {"pitch": 3, "roll": 3, "others": 3, "speed": 1.3}
    fig, axes = plt.subplots(len(panels), 1, figsize=(13, 2.4 * sum(ratios[p] for p in panels) / 3 + 0.8),
                             sharex=True, gridspec_kw={"height_ratios": [ratios[p] for p in panels]})
    ax_of = dict(zip(panels, axes, strict=True))

    def centred(x: np.ndarray) -> np.ndarray:
        return x - (np.nanmean(x[m]) if drive.remove_mean and m.any() else 0.0)

    label = _overlap_labels(tracks, [*bold, *others], centred, m)
    sign = {"pitch": "+ nose down", "roll": "+ left side up"}
    for p in panels[:-1]:                       # the reference in every angle panel (other methods: the pitch)
        ref = drive.truth["pitch" if p == "others" else p].to_numpy()
        ax_of[p].plot(t, np.degrees(np.where(m, centred(ref), np.nan)), color="k", lw=2.0, label="reference")
    for what in angles:
        ax = ax_of[what]
        for k, name in enumerate(bold):
            est = centred(np.asarray(getattr(tracks[name], what), dtype=float))
            std = getattr(tracks[name], f"{what}_std", None)
            if k == 0 and std is not None and np.isfinite(std).any():
                ax.fill_between(t, np.degrees(est - std), np.degrees(est + std), color=styles[name]["color"],
                                alpha=0.2, lw=0, label=f"{name} 1-sigma")
            ax.plot(t, np.degrees(est), label=label[name] + (" (default)" if k == 0 and name == HIGHLIGHTED[0] else ""),
                    **styles[name])
        ax.set_ylabel(f"{what} rel. road\n(deg, {sign[what]})")
    if others:
        ax = ax_of["others"]
        for name in others:
            ax.plot(t, np.degrees(centred(np.asarray(tracks[name].pitch, dtype=float))), label=label[name],
                    **styles[name])
        ax.set_ylabel("pitch rel. road\n(deg, other methods)")
    ax = ax_of["speed"]
    ax.plot(t, drive.truth["speed"].to_numpy(), color="tab:gray", label="speed")
    ax.axhline(MIN_SPEED, color="tab:red", lw=0.8, ls="--",
               label=f"{MIN_SPEED:g} m/s: slower frames\nnot scored")
    ax.set(ylabel="speed (m/s)", xlabel="time (s)")
    for p in panels:
        ax_of[p].legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, frameon=False)
        ax_of[p].grid(alpha=0.3)
    axes[0].set_title(f"{drive.name} ({drive.kind}, {drive.grade})" +
                      (": estimates and reference less their means" if drive.remove_mean else ""))
    fig.tight_layout()
    return fig


def plot_error_distribution(errors: dict, path: Path, title: str = "") -> Path:
    """Write :func:`error_distribution_figure` as a PNG to ``path``; returns ``path``."""
    return _save(error_distribution_figure(errors, title), path)


def error_distribution_figure(errors: dict, title: str = ""):
    """Histogram (density, 1/deg; the :data:`HIGHLIGHTED` methods) and CDF (every method) of per-frame absolute
    errors (deg), ``errors`` by method (a Figure)."""
    plt = _plt()
    styles = _method_styles(list(errors))
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(13, 4.5))
    allv = np.concatenate([v for v in errors.values() if len(v)]) if errors else np.zeros(1)
    hi = np.percentile(allv, 99) if allv.size else 1.0
    bins = np.linspace(0.0, max(hi, 1e-3), 60)
    bold = _split_methods(list(errors))[0] or list(errors)
    for name, e in errors.items():
        e = np.asarray(e)
        if not len(e):
            continue
        if name in bold:
            a1.hist(np.clip(e, 0, bins[-1]), bins=bins, histtype="step", density=True, color=styles[name]["color"],
                    lw=styles[name]["lw"] + 0.3, label=name)
        s = np.sort(e)
        a2.plot(s, np.arange(1, len(s) + 1) / len(s), label=f"{name} (mean {e.mean():.3f} deg)", **styles[name])
    a1.set(xlabel="absolute error (deg; the last bin holds the top 1%)", ylabel="density (1/deg)")
    a1.set_title("histogram: " + ", ".join(bold) + ("; every method in the CDF" if len(bold) < len(errors) else ""),
                 fontsize=9)
    a1.legend(fontsize=8, loc="upper right")
    a1.grid(alpha=0.3)
    a2.set(xlabel="absolute error (deg)", ylabel="fraction of frames", xlim=(0, bins[-1]))
    a2.grid(alpha=0.3)
    a2.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_simulation(sim, path: Path) -> Path:
    """The synthetic road (top view, grade, bank, roughness) and the body motion of a ``SimResult``, as a PNG."""
    plt = _plt()
    tr = sim.truth
    fig = plt.figure(figsize=(12, 9))
    gs = fig.add_gridspec(3, 2)
    ax = fig.add_subplot(gs[:2, 0])
    sc = ax.scatter(tr["x"], tr["y"], c=tr["speed"], s=4, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="speed (m/s)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set(xlabel="east (m)", ylabel="north (m)", title=f"{sim.name or 'synthetic drive'}: path")
    ax = a_grade = fig.add_subplot(gs[0, 1])
    ax.plot(tr["s"], np.degrees(tr["road_grade"]), label="grade (+ uphill)")
    ax.plot(tr["s"], np.degrees(tr["road_bank"]), label="bank (+ left edge up)")
    ax.set(xlabel="distance (m)", ylabel="deg")
    ax = fig.add_subplot(gs[1, 1])
    road = sim.road
    x = np.asarray(road["x"])
    sel = (x >= 0) & (x <= min(tr["s"].max(), 200.0))
    ax.plot(x[sel], 1e3 * np.asarray(road["h_left"])[sel], lw=0.7, label="left track")
    ax.plot(x[sel], 1e3 * np.asarray(road["h_right"])[sel], lw=0.7, label="right track")
    ax.set(xlabel="distance (m)", ylabel="roughness (mm)")
    for a in (a_grade, ax):
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    ax = fig.add_subplot(gs[2, :])
    ax.plot(tr["t"], np.degrees(tr["pitch"]), label="body pitch rel. road (deg)")
    ax.plot(tr["t"], np.degrees(tr["roll"]), label="body roll rel. road (deg)")
    ax2 = ax.twinx()
    ax2.plot(tr["t"], tr["acc_long"], color="tab:gray", lw=0.8, alpha=0.7, label="long. accel (m/s²)")
    ax2.plot(tr["t"], tr["acc_lat"], color="tab:olive", lw=0.8, alpha=0.7, label="lat. accel (m/s²)")
    ax.set(xlabel="time (s)", ylabel="deg")
    ax2.set_ylabel("m/s²")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, ncol=4, loc="upper right")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def evaluation_plots(drives: Iterable, results: pd.DataFrame, tracks: dict, folder: Path,
                     max_drives: int = 6) -> list[Path]:
    """PNG plots of an evaluation run: pitch over time (a few drives), error distributions per drive set.

    Parameters
    ----------
    drives, results, tracks
        The drives evaluated, :func:`~imu_ground.evaluation.runner.evaluate`'s table and tracks (``keep_tracks``).
    folder : Path
        Output folder (created).
    max_drives : int
        Pitch-over-time plots for at most this many drives per kind.

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
