"""Compare ground-normal methods on drives with ground truth: real KITTI and synthetic.

:data:`METHODS`: the registry's :class:`~imu_ground.filters.methods.MethodSpec` then the research
baselines, each built with the drive's extrinsic and run over its ego-motion. :func:`evaluate` reports
per drive and method the error statistics, the per-segment metric, the error by condition
(:mod:`~imu_ground.evaluation.conditions`), what the reference's own uncertainty explains
(``ref_floor``, ``ref_share``, :func:`sigma_table`) and the revisit consistency
(:mod:`imu_ground.evaluation.revisit`).
"""
from __future__ import annotations

import math
import time
from types import MappingProxyType
from collections import ChainMap
from collections.abc import Iterable, Mapping, Sequence, ValuesView
from functools import partial

import numpy as np

from imu_ground.evaluation.baselines import EulerEKF
from imu_ground.evaluation.conditions import CONDITIONS, condition_masks, moving_segments, segment_centred
from imu_ground.evaluation.drives import Drive, load_real_drive, load_real_drives, synthetic_drive, synthetic_drives
from imu_ground.evaluation.metrics import evaluate_drive
from imu_ground.evaluation.revisit import drive_revisit_pairs, revisit_differences
from imu_ground.filters import GroundNormalFilter
from imu_ground.errors import OptionError
from imu_ground.filters.methods import METHODS as REGISTRY, MethodSpec

__all__ = [
    "EVALUATION_METHODS", "METHODS", "TUNED", "Drive", "Method", "check_methods", "methods_from_list",
    "conditions_table", "evaluate", "format_table", "load_real_drive", "load_real_drives", "SIGMA_BINS", "run_method",
    "sigma_table", "summary_table", "synthetic_drive", "synthetic_drives"
]

#: Tuned parameters of the paper's method, chosen on the real drives (``benchmarks/studies/tune_paper.py``).
TUNED = dict(Q=0.1, R=1.0, P=1.0)
#: Edges (deg) of the bins of the reference's own 1-sigma uncertainty in :func:`sigma_table`.
SIGMA_BINS = (0.0, 0.075, 0.1, 0.15, 0.25, 0.5, math.inf)


#: One method of the evaluation: the registry's :class:`~imu_ground.filters.methods.MethodSpec`
#: (name, description, ``factory(extrinsic=...)``, needs_accel, smooth).
Method = MethodSpec


#: The methods the evaluation adds to the registry: research baselines, not offered by ``estimate``.
_BASELINES: tuple[MethodSpec, ...] = (
    MethodSpec("ekf", "standard EKF, Euler-angle state, the paper's Q and R, random walk",
               partial(EulerEKF, Q=1e-2, R=1.0, P=1.0, follow_heading=False), False, False),
    MethodSpec("paper-code", "the reference code's variant: forward axis observed only",
               GroundNormalFilter.reference_code, False, False),
    MethodSpec("paper-tuned", "invariant EKF, heading-following, Q tuned on the real drives",
               partial(GroundNormalFilter, **TUNED), False, False),
)


#: Every method of the evaluation by name, in report order: the registry's (as it is now), then the research baselines
#: (a live, read-only view: a ChainMap lists its last mapping's keys first).
METHODS: Mapping[str, MethodSpec] = MappingProxyType(ChainMap({m.name: m for m in _BASELINES}, REGISTRY))
#: The same methods (a view of :data:`METHODS`).
EVALUATION_METHODS: ValuesView[MethodSpec] = METHODS.values()


def run_method(name: str, drive: Drive):
    """Run one method on one drive; returns the track and the seconds it took."""
    if name not in METHODS:
        raise OptionError(f"unknown method {name!r}; choose from {', '.join(METHODS)}", "methods")
    m = METHODS[name]
    t0 = time.perf_counter()
    track = m.factory(extrinsic=drive.extrinsic).run(drive.egomotion, smooth=m.smooth)
    return track, time.perf_counter() - t0


# ----------------------------------------------------------------------------- per drive
_STATS = ("mean", "median", "rms", "p95", "bias")


def _drive_metrics(d: Drive, track) -> dict[str, float]:
    """All per-drive numbers of one track (see the module docstring); angles in deg."""
    tr = d.truth
    mask = tr["evaluate"].to_numpy(bool) & np.asarray(track.valid, dtype=bool)
    true_pitch = tr["pitch"].to_numpy(float)
    est_roll, true_roll = (track.roll, tr["roll"].to_numpy(float)) if d.has_roll else (None, None)
    res = evaluate_drive(track.pitch, true_pitch, est_roll, true_roll, mask=mask, remove_mean=d.remove_mean)
    row: dict[str, float] = {"n": res["pitch"]["n"]}
    for q, s in res.items():
        for stat in _STATS:
            row[f"{q}_{stat}"] = s[stat]
    use = mask & np.isfinite(track.pitch) & np.isfinite(true_pitch)
    est_c, ref_c = track.pitch, true_pitch
    if d.remove_mean and np.any(use):
        est_c, ref_c = est_c - est_c[use].mean(), ref_c - ref_c[use].mean()
    err = np.degrees(est_c - ref_c)
    seg = np.degrees(segment_centred(track.pitch, true_pitch, use, moving_segments(tr["speed"].to_numpy(float))))
    row["seg_n"] = int(np.count_nonzero(np.isfinite(seg)))
    row["seg_pitch_mean"] = float(np.nanmean(np.abs(seg))) if row["seg_n"] else math.nan
    masks = condition_masks({k: tr[k].to_numpy(float) for k in ("speed", "acc_long", "yaw_rate", "pitch_rate_hf")},
                            tr["t"].to_numpy(float))
    for key, m in masks.items():
        sel = use & m
        row[f"cond_{key}_n"] = int(np.count_nonzero(sel))
        row[f"cond_{key}_sum"] = float(np.abs(err[sel]).sum())
    sigma = np.degrees(tr["ref_sigma"].to_numpy(float))[use]
    row["ref_floor"] = (float(min(math.sqrt(2.0 / math.pi) * sigma.mean(), np.abs(err[use]).mean()))   # deg, capped
                        if sigma.size else math.nan)
    row["ref_var_sum"] = float(np.sum(sigma * sigma))
    row["err_sq_sum"] = float(np.sum(err[use] ** 2))
    row["ref_share"] = min(row["ref_var_sum"] / row["err_sq_sum"], 1.0) if row["err_sq_sum"] > 0 else math.nan
    bins = np.digitize(sigma, SIGMA_BINS[1:-1])
    for b in range(len(SIGMA_BINS) - 1):
        sel = bins == b
        row[f"sigma{b}_n"] = int(np.count_nonzero(sel))
        row[f"sigma{b}_sum"] = float(np.abs(err[use][sel]).sum())
        row[f"sigma{b}_ref_sum"] = float(sigma[sel].sum())
    return row


def check_methods(methods: Iterable[str]) -> list[str]:
    """The method names of an evaluation, checked: each a key of :data:`METHODS`, each once.

    Raises
    ------
    OptionError
        No name, an unknown name, or one given twice (naming ``--methods``).
    """
    methods = list(methods)
    if not methods:
        raise OptionError(f"{{opt}}: names no method; choose from {', '.join(METHODS)} (comma-separated), or leave "
                          "it out for all", "methods")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise OptionError(f"{{opt}}: unknown {', '.join(map(str, unknown))}; choose from {', '.join(METHODS)}",
                          "methods")
    twice = sorted({m for m in methods if methods.count(m) > 1})
    if twice:
        raise OptionError(f"{{opt}}: {', '.join(twice)} given twice; each method once (its rows would count twice)",
                          "methods")
    return methods


def methods_from_list(text: str | None) -> list[str]:
    """The methods a comma-separated list names (``--methods``; blanks ignored), checked; None: all of them."""
    if text is None:
        return list(METHODS)
    return check_methods([m.strip() for m in text.split(",") if m.strip()])


def evaluate(drives: Iterable[Drive], methods: Sequence[str] | None = None,
             progress: bool = True, keep_tracks: bool = False):
    """Run methods over drives and summarise the errors per drive (valid frames where the truth is defined).

    Parameters
    ----------
    drives : iterable of Drive
    methods : sequence of str, optional
        Names from :data:`METHODS` (default all).
    progress : bool
        Progress bar over drive x method runs.
    keep_tracks : bool
        Also return the tracks (for plots): ``{(drive, method): GroundTrack}``.

    Returns
    -------
    pandas.DataFrame
        One row per drive and method: drive, kind, grade, method, valid, reason, frames, n;
        ``{pitch,roll,angle}_{mean,median,rms,p95,bias}`` (deg, absolute errors; roll and angle on
        synthetic drives); ``seg_pitch_mean`` (deg), ``seg_n``; ``cond_<key>_n``, ``cond_<key>_sum``
        (frames and summed absolute pitch error, deg, per condition); ``ref_floor`` (deg), ``ref_share``,
        ``ref_var_sum``, ``err_sq_sum`` (deg^2); ``us_per_frame``; ``sigma<b>_n``, ``sigma<b>_sum``,
        ``sigma<b>_ref_sum`` per bin of :data:`SIGMA_BINS`; on real drives with a raw log ``revisit_n``,
        ``revisit_pitch_sum``, ``revisit_roll_sum`` (deg).
    dict, only with ``keep_tracks``
    """
    import pandas as pd
    from tqdm.auto import tqdm
    drives = list(drives)
    methods = list(METHODS) if methods is None else check_methods(methods)
    rows, tracks = [], {}
    bar = tqdm(total=len(drives) * len(methods), desc="evaluating", unit="run", disable=not progress)
    for d in drives:
        pairs = drive_revisit_pairs(d) if d.valid and d.kind == "real" and d.imu is not None else None
        for m in methods:
            bar.set_postfix_str(f"{d.name} {m}", refresh=False)
            row = {"drive": d.name, "kind": d.kind, "grade": d.grade, "method": m,
                   "valid": d.valid, "reason": d.reason, "frames": len(d.egomotion)}
            if d.valid:
                track, sec = run_method(m, d)
                row["us_per_frame"] = sec / max(len(d.egomotion), 1) * 1e6
                row.update(_drive_metrics(d, track))
                if pairs is not None:
                    dp, dr = revisit_differences(pairs, track.pitch, track.roll, track.valid)
                    row.update(revisit_n=int(len(dp)), revisit_pitch_sum=float(np.degrees(np.abs(dp)).sum()),
                               revisit_roll_sum=float(np.degrees(np.abs(dr)).sum()))
                if keep_tracks:
                    tracks[(d.name, m)] = track
            rows.append(row)
            bar.update()
    bar.close()
    df = pd.DataFrame(rows)
    return (df, tracks) if keep_tracks else df


# ----------------------------------------------------------------------------- tables
def _sets(results):
    ok = results[results["valid"]].copy()
    ok["set"] = np.where(ok["kind"] == "real", "real", "synthetic-" + ok["grade"].astype(str))
    return ok


def _pooled_ref_share(g) -> float:
    """The share of the drives' pooled squared pitch error the reference can explain (each drive's capped), 0..1."""
    err = g["err_sq_sum"].to_numpy(float)
    total = float(err.sum())
    return float(np.minimum(g["ref_var_sum"].to_numpy(float), err).sum() / total) if total > 0 else math.nan


def summary_table(results, quantity: str | None = None):
    """Overall table like the paper's Table 2: per drive set and method.

    Parameters
    ----------
    results : DataFrame from :func:`evaluate`.
    quantity : {"pitch", "angle"}, optional
        Error to summarise; default ``"angle"`` on synthetic drives, ``"pitch"`` on real ones.

    Returns
    -------
    pandas.DataFrame
        Index (set, method); columns drives, mean_deg (over drives of the mean absolute error),
        median_deg, worst_deg / worst_drive, the worst ratio to the paper's method, seg_pitch_deg,
        ref_floor_deg, ref_share (pooled over frames, 0..1), us_per_frame.
    """
    import pandas as pd
    ok = _sets(results)
    out = []
    for (s, m), g in ok.groupby(["set", "method"], sort=False):
        q = quantity or ("pitch" if s == "real" else "angle")
        col = f"{q}_mean"
        paper = ok[(ok["set"] == s) & (ok["method"] == "paper")].set_index("drive")[col]
        ratio = (g.set_index("drive")[col] / paper).dropna() if len(paper) else pd.Series(dtype=float)
        out.append({"set": s, "method": m, "error": q, "drives": len(g), "mean_deg": g[col].mean(),
                    "median_deg": g[col].median(), "worst_deg": g[col].max(),
                    "worst_drive": g.loc[g[col].idxmax(), "drive"] if len(g) else "",
                    "worst_ratio_to_paper": ratio.max() if len(ratio) else np.nan,
                    "worst_ratio_drive": ratio.idxmax() if len(ratio) else "",
                    "seg_pitch_deg": g["seg_pitch_mean"].mean(),
                    "ref_floor_deg": g["ref_floor"].mean(),
                    "ref_share": _pooled_ref_share(g),
                    "us_per_frame": g["us_per_frame"].mean()})
    return pd.DataFrame(out).set_index(["set", "method"])


def conditions_table(results, counts: bool = False):
    """Mean absolute pitch error (deg) per drive set, method and condition, pooled over frames.

    Parameters
    ----------
    results : DataFrame from :func:`evaluate`.
    counts : bool
        Return the numbers of frames instead of the errors.

    Returns
    -------
    pandas.DataFrame
        Index (set, method); a column per label of :data:`~imu_ground.evaluation.conditions.CONDITIONS`, and ``all``.
    """
    ok = _sets(results).assign(pitch_sum=lambda f: f["pitch_mean"] * f["n"])
    by = ok.groupby(["set", "method"], sort=False)
    n = by[[*(f"cond_{key}_n" for key in CONDITIONS), "n"]].sum().astype(int)
    sums = by[[*(f"cond_{key}_sum" for key in CONDITIONS), "pitch_sum"]].sum()
    n.columns = sums.columns = [*CONDITIONS.values(), "all"]
    return n if counts else sums / n.where(n > 0)


def sigma_table(results):
    """Mean absolute pitch error on real drives by the reference's own uncertainty, per method.

    Parameters
    ----------
    results : DataFrame from :func:`evaluate`.

    Returns
    -------
    pandas.DataFrame
        Index: the ``ref_sigma`` bin, deg (:data:`SIGMA_BINS`, bins with frames); ``frames``, ``ref_floor_deg``
        (``sqrt(2/pi)`` times the bin's mean sigma: a perfect estimator's score) and per method its mean
        absolute pitch error, deg, pooled over the bin's frames.
    """
    import pandas as pd
    ok = results[results["valid"] & (results["kind"] == "real")]
    if "sigma0_n" not in ok.columns or not len(ok):
        return pd.DataFrame(columns=["frames", "ref_floor_deg"])
    out = []
    first = ok[ok["method"] == ok["method"].iloc[0]]
    by = ok.groupby("method", sort=False)[[c for c in ok.columns if c.startswith("sigma")]].sum()
    for b in range(len(SIGMA_BINS) - 1):
        n = int(first[f"sigma{b}_n"].sum())
        if not n:
            continue
        lo, hi = SIGMA_BINS[b], SIGMA_BINS[b + 1]
        row = {"ref_sigma_deg": f"{lo:g}-{hi:g}" if math.isfinite(hi) else f">{lo:g}", "frames": n,
               "ref_floor_deg": math.sqrt(2.0 / math.pi) * first[f"sigma{b}_ref_sum"].sum() / n}
        k = by[f"sigma{b}_n"]
        row.update(by[f"sigma{b}_sum"] / k.where(k > 0))            # per method
        out.append(row)
    return pd.DataFrame(out).set_index("ref_sigma_deg")


def format_table(table, fmt: str = "text") -> str:
    """A summary or per-drive table as plain text, Markdown or CSV."""
    t = table.copy()
    if fmt == "csv":
        return t.to_csv(float_format="%.4f")
    t = t.reset_index()
    for c in t.columns:
        if t[c].dtype.kind == "f":
            t[c] = t[c].map(lambda v: "" if not np.isfinite(v) else f"{v:.3f}")
    if fmt == "markdown":
        cols = list(t.columns)
        lines = ["| " + " | ".join(map(str, cols)) + " |", "|" + "|".join("---" for _ in cols) + "|"]
        lines += ["| " + " | ".join(str(v) for v in row) + " |" for row in t.itertuples(index=False)]
        return "\n".join(lines)
    if fmt == "text":
        return t.to_string(index=False)
    raise ValueError(f"unknown table format {fmt!r}: use text, markdown or csv")
