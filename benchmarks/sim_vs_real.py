"""Do synthetic drives behave like the real ones? Spectra of the body motion and the ranking of the methods.

Compares the simulator's suite (:func:`imu_ground.evaluation.simulate.simulate_suite`) with the
shared real KITTI drives (``../shared/data/kitti_imu100``) on what issue 10 point 5 asks:

1. **Power in frequency bands** (0.01-0.1, 0.1-0.5, 0.5-2, 2-5 Hz) of

   - the body pitch relative to the road: real, the INS reference ``pitch + grade`` at 100 Hz
     (:func:`imu_ground.evaluation.reference.pitch_reference`); synthetic, the truth ``pitch``;
   - the gyro pitch rate (``wy``, rad/s, 100 Hz): real, the OXTS IMU; synthetic, the simulated IMU;

   each from Welch's method over the longest stretch of each drive above 3 m/s (segments of up to
   100 s; a band whose lower edge needs a longer stretch than the drive has is left out for that
   drive), the band power being the integral of the one-sided PSD over the band (rad^2, or
   (rad/s)^2). Printed: the median over drives, real and synthetic, and their ratio; the target is
   a ratio within 1/1.5 .. 1.5 in every band.
2. **Ranking of the methods**: mean absolute error per method on real drives (pitch, means removed
   per drive) and on synthetic drives (normal angle, and pitch with the means removed as on real
   drives), the ranks side by side and Spearman's rank correlation.

``--reference-error`` scores the synthetic drives against their truth plus a simulated error
of the INS reference (:func:`reference_error`: a slow vertical-velocity error over the speed,
as :mod:`imu_ground.evaluation.conditions` models the real reference's uncertainty), so that
both sides carry the same kind of reference. :class:`~imu_ground.evaluation.simulate.suite.SuiteRanges`
sets what the synthetic drives are drawn from (for calibration experiments).

Run: ``python benchmarks/sim_vs_real.py [--drives 10] [--data ../shared/data/kitti_imu100]``
(``--no-ranking`` for the spectra only). The figures go to ``benchmarks/RESULTS.md`` only through
``make_results.py``; this script prints them.
"""
from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

BANDS = ((0.01, 0.1), (0.1, 0.5), (0.5, 2.0), (2.0, 5.0))
RATE = 100.0
MIN_SPEED = 3.0
SEGMENT_S = 100.0
DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "kitti_imu100"

#: Correlation time of the simulated INS vertical-velocity error, s (``--reference-error``).
VU_ERROR_TAU = 20.0

__all__ = ["reference_error", "band_powers", "real_spectra", "synthetic_spectra", "compare_spectra", "ranking", "main"]


def _longest_run(mask: np.ndarray) -> slice:
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    if edges.size == 0:
        return slice(0, 0)
    lengths = edges[1::2] - edges[::2]
    k = int(np.argmax(lengths))
    return slice(int(edges[2 * k]), int(edges[2 * k + 1]))


def reference_error(t: np.ndarray, speed: np.ndarray, seed: int, tau: float = VU_ERROR_TAU) -> np.ndarray:
    """A simulated error of the INS reference, rad: a slow vertical-velocity error over the speed.

    The error ``e_vu`` is a first-order Gauss-Markov process (std
    :data:`~imu_ground.evaluation.conditions.INS_VU_NOISE`, correlation time ``tau`` s); the
    reference's grade error is ``e_vu / v`` (NaN at or below 0.5 m/s).
    """
    from imu_ground.evaluation.conditions import INS_VU_NOISE
    rng = np.random.default_rng(seed)
    dt = np.diff(t, prepend=t[0])
    a = np.exp(-dt / tau)
    w = rng.standard_normal(len(t)) * INS_VU_NOISE * np.sqrt(1.0 - a * a)
    e = np.empty(len(t))
    e[0] = INS_VU_NOISE * rng.standard_normal()
    for k in range(1, len(t)):          # a loop over frames of a benchmark script
        e[k] = a[k] * e[k - 1] + w[k]
    v = np.asarray(speed, dtype=float)
    return np.where(v > 0.5, e / np.maximum(v, 0.5), np.nan)


def band_powers(x: np.ndarray, fs: float = RATE) -> dict[str, float]:
    """Power of ``x`` in each band of :data:`BANDS` (integral of the one-sided Welch PSD), NaN where too short."""
    from scipy.signal import welch
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    out = {}
    nper = int(min(len(x), SEGMENT_S * fs))
    f, p = welch(x - x.mean(), fs=fs, nperseg=nper, detrend="linear") if nper >= 16 else (None, None)
    for lo, hi in BANDS:
        key = f"{lo:g}-{hi:g} Hz"
        if f is None or nper / fs < 1.0 / lo:
            out[key] = np.nan
            continue
        sel = (f >= lo) & (f < hi)
        out[key] = float(np.trapezoid(p[sel], f[sel])) if sel.sum() > 1 else np.nan
    return out


def real_spectra(data: Path, limit: int | None = None) -> pd.DataFrame:
    """Band powers of the real drives: one row per drive and signal."""
    from imu_ground.evaluation.drives import load_real_drives
    from imu_ground.evaluation.reference import pitch_reference
    rows = []
    drives = [d for d in load_real_drives(data, progress=False) if d.valid][:limit]
    for d in drives:
        df = d.imu.to_dataframe()
        ref = pitch_reference(df, times=df["t"].to_numpy())
        run = _longest_run(ref.valid)
        rows.append({"drive": d.name, "signal": "pitch rel. road", **band_powers(ref.pitch_rel_road[run])})
        rows.append({"drive": d.name, "signal": "gyro pitch rate", **band_powers(d.imu.gyro[run, 1])})
    return pd.DataFrame(rows)


def synthetic_spectra(n: int, seed: int = 0, with_reference_error: bool = False, **suite_kw) -> pd.DataFrame:
    """Band powers of the synthetic suite (nav grade; truth at the IMU rate, optionally plus a reference error)."""
    from imu_ground.evaluation.simulate import simulate_suite
    rows = []
    for i, sim in enumerate(simulate_suite(n, seed=seed, grades=("nav",), frame_rate=RATE, **suite_kw)):
        tr = sim.truth
        run = _longest_run(tr["speed"].to_numpy() > MIN_SPEED)
        pitch = tr["pitch"].to_numpy()
        if with_reference_error:
            pitch = pitch + reference_error(tr["t"].to_numpy(), tr["speed"].to_numpy(), seed=1000 + i)
        rows.append({"drive": sim.name, "signal": "pitch rel. road", **band_powers(pitch[run])})
        rows.append({"drive": sim.name, "signal": "gyro pitch rate", **band_powers(sim.imu.gyro[run, 1])})
    return pd.DataFrame(rows)


def compare_spectra(real: pd.DataFrame, synthetic: pd.DataFrame) -> pd.DataFrame:
    """Median band power per signal, real and synthetic, their ratio and whether it is within 1.5x."""
    cols = [f"{lo:g}-{hi:g} Hz" for lo, hi in BANDS]
    rows = []
    for signal in real["signal"].unique():
        r = real[real["signal"] == signal][cols].median()
        s = synthetic[synthetic["signal"] == signal][cols].median()
        for c in cols:
            ratio = s[c] / r[c]
            rows.append({"signal": signal, "band": c, "real_median": r[c], "synthetic_median": s[c],
                         "ratio": ratio, "within_1.5x": bool(1 / 1.5 <= ratio <= 1.5)})
    return pd.DataFrame(rows)


def ranking(data: Path, n_synthetic: int, limit: int | None = None, methods=None,
            with_reference_error: bool = False, **suite_kw) -> pd.DataFrame:
    """Mean error per method on real and synthetic drives, with ranks (1 = best).

    With ``with_reference_error`` the synthetic truth pitch gets :func:`reference_error` added,
    so that synthetic drives are scored against a reference as imperfect as the real one.
    """
    from imu_ground.evaluation.runner import evaluate, load_real_drives, synthetic_drives
    real = [d for d in load_real_drives(data, progress=False) if d.valid][:limit]
    syn = synthetic_drives(n_synthetic, seed=0, grades=("nav", "mems"), progress=False, **suite_kw)
    for i, d in enumerate(syn):         # pitch with the means removed, as on real drives
        d.remove_mean = True
        if with_reference_error:
            err = reference_error(d.truth["t"].to_numpy(), d.truth["speed"].to_numpy(), seed=1000 + i // 2)
            d.truth["pitch"] = d.truth["pitch"] + np.nan_to_num(err)
            d.truth["roll"] = np.nan          # the angle is then meaningless: pitch only
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res_r = evaluate(real, methods, progress=False)
        res_s = evaluate(syn, methods, progress=False)
    out = pd.DataFrame({"real_pitch": res_r.groupby("method", sort=False)["pitch_mean"].mean()})
    for grade in ("nav", "mems"):
        g = res_s[res_s["grade"] == grade].groupby("method", sort=False)
        out[f"{grade}_pitch_centred"] = g["pitch_mean"].mean()
        if "angle_mean" in res_s:
            out[f"{grade}_angle_centred"] = g["angle_mean"].mean()
    for c in list(out.columns):
        out[f"rank_{c}"] = out[c].rank().astype(int)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--drives", type=int, default=10, help="synthetic drives (default 10)")
    ap.add_argument("--real-limit", type=int, default=None, help="use only the first N valid real drives")
    ap.add_argument("--no-ranking", action="store_true")
    ap.add_argument("--reference-error", action="store_true",
                    help="add a simulated INS reference error to the synthetic pitch (spectra and ranking)")
    a = ap.parse_args(argv)
    pd.set_option("display.width", 200)
    real = real_spectra(a.data, a.real_limit)
    syn = synthetic_spectra(a.drives, with_reference_error=a.reference_error)
    cmp = compare_spectra(real, syn)
    print(f"band power, median over drives ({real['drive'].nunique()} real, {syn['drive'].nunique()} synthetic): "
          "pitch rel. road in rad^2, gyro pitch rate in (rad/s)^2")
    print(cmp.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(f"within 1.5x: {int(cmp['within_1.5x'].sum())} of {len(cmp)} bands")
    if not a.no_ranking:
        rk = ranking(a.data, a.drives, a.real_limit, with_reference_error=a.reference_error)
        print("\nmean absolute error per method, deg (synthetic 'centred': means removed per drive as on real):")
        print(rk.to_string(float_format=lambda v: f"{v:.3f}"))
        for c in [c for c in rk.columns if not c.startswith("rank_") and c != "real_pitch"]:
            rho = rk["real_pitch"].rank().corr(rk[c].rank())
            print(f"Spearman rank correlation real_pitch vs {c}: {rho:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
