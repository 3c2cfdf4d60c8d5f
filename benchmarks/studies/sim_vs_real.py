"""Do synthetic drives behave like the real ones? Spectra of the body motion and the ranking of the methods.

Compares the simulator's suite (:func:`imu_ground.evaluation.simulate.simulate_suite`) with the
shared real KITTI drives (``../shared/data/kitti_imu100``) on two criteria:

1. **Power in frequency bands** (0.01-0.1, 0.1-0.5, 0.5-2, 2-5 Hz) of

   - the body pitch relative to the road: real, the INS reference ``pitch + grade`` at 100 Hz
     (:func:`imu_ground.evaluation.reference.pitch_reference`); synthetic, the truth ``pitch``;
   - the gyro pitch rate (``wy``, rad/s, 100 Hz): real, the OXTS IMU; synthetic, the simulated IMU
     through the OXTS's rate-output low-pass (:data:`GYRO_OUTPUT_CORNER`, :func:`oxts_rate_output`);

   each from Welch's method over the longest stretch of each drive above 3 m/s (segments of up to
   100 s; a band is left out for a drive whose stretch is shorter than :data:`MIN_CYCLES` periods of
   the band's lower edge: 19 real drives resolve 0.01-0.1 Hz), the band power being the integral of the
   interpolated one-sided PSD over the band (rad^2, or (rad/s)^2). Printed: the median over drives,
   real and synthetic, their ratio and ``within_1.5x`` yes/no; the target is every band within.
2. **Ranking of the methods**: mean absolute error per method on real drives (pitch, means removed
   per drive) and on synthetic drives (normal angle, and pitch with the means removed as on real
   drives; roll, which only synthetic drives have), the ranks side by side, Spearman's rank
   correlation and ``ranking equal`` yes/no (:func:`order_agreement`: pairs of methods more than
   5 % apart on real drives in the same order on synthetic ones). :func:`rows` gives the criteria
   as table rows for ``make_results.py``.

The real "pitch relative to the road" is the INS reference, which carries its own slow error: on
the real drives the slow part left after the body's pitch from the acceleration scales as one over
the speed (a vertical-velocity error of ~0.02 m/s, :data:`VU_ERROR_STD`), which no body motion
does. So by default the synthetic side is scored and compared as truth plus a simulated error of
that reference (:func:`reference_error`), the pitch only (roll is exact: the real drives have no roll
reference to mimic); ``--exact-truth`` compares the exact truth instead.
:class:`~imu_ground.evaluation.simulate.suite.SuiteRanges` sets what the synthetic drives are drawn
from (for calibration experiments).

Run: ``python benchmarks/studies/sim_vs_real.py [--drives 12] [--spectra-drives 40]
[--data ../shared/data/kitti_imu100]``
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
#: Shortest stretch for a band, in periods of its lower edge (see :func:`band_powers`).
MIN_CYCLES = 0.3
DEFAULT_DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "kitti_imu100"

#: Methods whose real errors are closer than this (relative) count as tied in the ranking.
ORDER_TOL = 0.05
#: The methods the ranking criterion compares (the project's own; the paper's published code and
#: the retuned paper filter are printed and checked too, as information).
RANKED_METHODS = ("suspension", "suspension-offline", "filter", "paper", "ekf", "naive")

#: The real reference's own slow error, as a vertical-velocity error of the INS (``--reference-error``,
#: the default): std (m/s) and correlation time (s) of a first-order Gauss-Markov process. Measured
#: on the real drives: after the body pitch from the acceleration (0.265 deg per m/s^2) is removed,
#: the slow (< 0.1 Hz) rest of ``pitch + grade`` times the speed is the same at every speed
#: (0.018-0.029 m/s rms in bins from 3 to 30 m/s, i.e. an error over the speed, not a body motion),
#: with a spectrum (0.025-0.1 Hz) that a 0.02 m/s, 10 s process fits.
VU_ERROR_STD = 0.02
VU_ERROR_TAU = 10.0
#: Corner (Hz) of the first-order low-pass through which the real OXTS angular rates come out: on the
#: real drives the power of d(pitch)/dt over that of ``wy`` is ``1 + (f / 2.57)^2`` (1.14 at 1 Hz,
#: 1.6 at 2, 2.3 at 3, 4.75 at 5, 10.4 at 8 Hz: medians over the drives), so the rate output is
#: filtered relative to the attitude. The synthetic gyro is compared through the same filter.
GYRO_OUTPUT_CORNER = 2.57

__all__ = [
    "band_powers",
    "compare_spectra",
    "main",
    "order_agreement",
    "ranking",
    "real_spectra",
    "reference_error",
    "rows",
    "synthetic_spectra",
]


def _longest_run(mask: np.ndarray) -> slice:
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(m))
    if edges.size == 0:
        return slice(0, 0)
    lengths = edges[1::2] - edges[::2]
    k = int(np.argmax(lengths))
    return slice(int(edges[2 * k]), int(edges[2 * k + 1]))


def reference_error(t: np.ndarray, speed: np.ndarray, seed: int, tau: float = VU_ERROR_TAU,
                    std: float = VU_ERROR_STD) -> np.ndarray:
    """A simulated error of the INS reference, rad: a slow vertical-velocity error over the speed.

    The error ``e_vu`` is a first-order Gauss-Markov process (``std`` m/s, correlation time
    ``tau`` s; defaults :data:`VU_ERROR_STD`, :data:`VU_ERROR_TAU`, measured on the real drives);
    the reference's grade error is ``e_vu / v`` (NaN at or below 0.5 m/s).
    """
    rng = np.random.default_rng(seed)
    dt = np.diff(t, prepend=t[0])
    a = np.exp(-dt / tau)
    w = rng.standard_normal(len(t)) * std * np.sqrt(1.0 - a * a)
    e = np.empty(len(t))
    e[0] = std * rng.standard_normal()
    for k in range(1, len(t)):          # a loop over frames of a benchmark script
        e[k] = a[k] * e[k - 1] + w[k]
    v = np.asarray(speed, dtype=float)
    return np.where(v > 0.5, e / np.maximum(v, 0.5), np.nan)


def oxts_rate_output(w: np.ndarray, fs: float = RATE, corner: float = GYRO_OUTPUT_CORNER) -> np.ndarray:
    """An angular rate as the real OXTS outputs it: through a causal first-order low-pass at ``corner`` Hz."""
    from scipy.signal import lfilter
    a = float(np.exp(-2.0 * np.pi * corner / fs))
    w = np.asarray(w, dtype=float)
    return lfilter([1.0 - a], [1.0, -a], w, zi=[a * w[0]])[0]


def band_powers(x: np.ndarray, fs: float = RATE) -> dict[str, float]:
    """Power of ``x`` in each band of :data:`BANDS`, NaN where the stretch is too short.

    The one-sided Welch PSD (Hann segments of up to :data:`SEGMENT_S` s, linear
    detrend) interpolated linearly between its bins and integrated over the exact band
    (flat below the first bin). A band counts when the stretch lasts at least
    :data:`MIN_CYCLES` periods of its lower edge (30 s for 0.01 Hz; the PSD is then
    held flat from its first bin, 0.033 Hz, down to the edge), so the slow band rests on
    19 of the 31 real drives (a 100 s stretch: 2 drives, whose median is their mean;
    50 s: 6, a few long hilly or turning drives), the same rule on both sides.
    """
    from scipy.signal import welch
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    out = {}
    nper = int(min(len(x), SEGMENT_S * fs))
    f, p = welch(x - x.mean(), fs=fs, nperseg=nper, detrend="linear") if nper >= 16 else (None, None)
    for lo, hi in BANDS:
        key = f"{lo:g}-{hi:g} Hz"
        if f is None or nper / fs < MIN_CYCLES / lo:
            out[key] = np.nan
            continue
        fine = np.linspace(lo, hi, 400)
        out[key] = float(np.trapezoid(np.interp(fine, f, p), fine))
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


def synthetic_spectra(n: int, seed: int = 0, with_reference_error: bool = True, **suite_kw) -> pd.DataFrame:
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
        rows.append({"drive": sim.name, "signal": "gyro pitch rate",
                     **band_powers(oxts_rate_output(sim.imu.gyro[:, 1])[run])})
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
                         "ratio": ratio, "within_15": bool(1 / 1.5 <= ratio <= 1.5)})
    return pd.DataFrame(rows)


def ranking(data: Path, n_synthetic: int, limit: int | None = None, methods=None,
            with_reference_error: bool = True, **suite_kw) -> pd.DataFrame:
    """Mean error per method on real and synthetic drives, with ranks (1 = best).

    With ``with_reference_error`` the synthetic truth pitch gets :func:`reference_error` added,
    so that synthetic drives are scored against a reference as imperfect as the real one.
    """
    from imu_ground.evaluation.runner import (
        evaluate,
        load_real_drives,
        synthetic_drives,
    )
    real = [d for d in load_real_drives(data, progress=False) if d.valid][:limit]
    syn = synthetic_drives(n_synthetic, seed=0, grades=("nav", "mems"), progress=False, **suite_kw)
    for i, d in enumerate(syn):         # pitch with the means removed, as on real drives
        d.remove_mean = True
        if with_reference_error:
            err = reference_error(d.truth["t"].to_numpy(), d.truth["speed"].to_numpy(), seed=1000 + i // 2)
            d.truth["pitch"] = d.truth["pitch"] + np.nan_to_num(err)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res_r = evaluate(real, methods, progress=False)
        res_s = evaluate(syn, methods, progress=False)
    out = pd.DataFrame({"real_pitch": res_r.groupby("method", sort=False)["pitch_mean"].mean()})
    for grade in ("nav", "mems"):
        g = res_s[res_s["grade"] == grade].groupby("method", sort=False)
        out[f"{grade}_pitch_centred"] = g["pitch_mean"].mean()
        if "angle_mean" in res_s and not with_reference_error:   # the angle would mix in the pitch's error
            out[f"{grade}_angle_centred"] = g["angle_mean"].mean()
        if "roll_mean" in res_s:                 # exact: real drives have no roll reference to mimic
            out[f"{grade}_roll_centred"] = g["roll_mean"].mean()
    for c in list(out.columns):
        out[f"rank_{c}"] = out[c].rank().astype(int)
    return out


def order_agreement(real: pd.Series, synthetic: pd.Series, tol: float = ORDER_TOL) -> tuple[bool, list[str]]:
    """Do the methods rank the same? Every pair of methods whose real errors differ by more than
    ``tol`` (relative to the larger) must be in the same order on synthetic drives; closer pairs
    are ties (0.218 against 0.219 deg is not a ranking). Returns (agree, the pairs out of order)."""
    bad = []
    names = [m for m in real.index if m in synthetic.index and np.isfinite(synthetic[m])]
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            ra, rb = real[a], real[b]
            if abs(ra - rb) <= tol * max(ra, rb):
                continue
            if (ra < rb) != (synthetic[a] < synthetic[b]):
                lo, hi = (a, b) if ra < rb else (b, a)
                bad.append(f"{lo} < {hi} on real, not on synthetic")
    return not bad, bad


def rows(drives: int = 12, real_limit: int | None = None, reference_error: bool = True,
         data: Path = DEFAULT_DATA, spectra_drives: int = 40) -> list[dict[str, object]]:
    """The two criteria as table rows (``benchmark``, ``target``, ``figure``, ``unit``,
    ``passed``): each band's synthetic/real ratio within 1.5x, and the ranking on nav-grade
    synthetic drives (pitch, means removed) against the real drives."""
    real = real_spectra(data, real_limit)
    syn = synthetic_spectra(max(spectra_drives, drives), with_reference_error=reference_error)
    out: list[dict[str, object]] = []
    for r in compare_spectra(real, syn).itertuples():
        out.append({"benchmark": f"sim vs real: {r.signal} power {r.band}",
                    "target": "synthetic/real median within 1/1.5..1.5",
                    "figure": float(r.ratio), "unit": "ratio", "passed": bool(r.within_15)})
    rk = ranking(data, drives, real_limit, with_reference_error=reference_error)
    sub = rk.loc[[m for m in RANKED_METHODS if m in rk.index]]
    for grade in ("nav", "mems"):
        col = f"{grade}_pitch_centred"
        agree, bad = order_agreement(sub["real_pitch"], sub[col])
        order = " < ".join(f"{m} {v:.3f}" for m, v in sub[col].sort_values().items())
        real_order = " < ".join(f"{m} {v:.3f}" for m, v in sub["real_pitch"].sort_values().items())
        out.append({"benchmark": f"sim vs real: methods ranked the same (pitch, {grade})",
                    "target": f"same order for pairs > {ORDER_TOL:.0%} apart on real",
                    "figure": f"real: {real_order}; synthetic: {order}", "unit": "order", "passed": agree})
    for m, v in rk.get("nav_roll_centred", pd.Series(dtype=float)).items():
        out.append({"benchmark": f"sim: roll error, {m} (nav, synthetic only)", "target": "informative",
                    "figure": float(v), "unit": "deg", "passed": None})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--drives", type=int, default=12, help="synthetic drives for the ranking (default 12)")
    ap.add_argument("--spectra-drives", type=int, default=40,
                    help="synthetic drives for the spectra (default 40: their medians settle)")
    ap.add_argument("--real-limit", type=int, default=None, help="use only the first N valid real drives")
    ap.add_argument("--no-ranking", action="store_true")
    ap.add_argument("--exact-truth", action="store_true",
                    help="compare the synthetic drives' exact truth, without the simulated error of the real "
                         "reference (default: truth plus that error, like the real drives' reference)")
    a = ap.parse_args(argv)
    pd.set_option("display.width", 200)
    real = real_spectra(a.data, a.real_limit)
    syn = synthetic_spectra(a.spectra_drives, with_reference_error=not a.exact_truth)
    cmp = compare_spectra(real, syn)
    counts = real.groupby("signal").count()
    print(f"band power, median over drives ({real['drive'].nunique()} real, {syn['drive'].nunique()} synthetic): "
          "pitch rel. road in rad^2, gyro pitch rate in (rad/s)^2; real drives long enough per band: "
          + ", ".join(f"{c} {int(counts[c].min())}" for c in counts.columns if c != "drive"))
    show = cmp.assign(**{"within_1.5x": cmp["within_15"].map({True: "yes", False: "no"})}).drop(columns="within_15")
    print(show.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(f"within 1.5x: {int(cmp['within_15'].sum())} of {len(cmp)} bands")
    if not a.no_ranking:
        rk = ranking(a.data, a.drives, a.real_limit, with_reference_error=not a.exact_truth)
        print("\nmean absolute error per method, deg (synthetic 'centred': means removed per drive as on real;"
              " roll: synthetic only):")
        print(rk.to_string(float_format=lambda v: f"{v:.3f}"))
        sub = rk.loc[[m for m in RANKED_METHODS if m in rk.index]]
        for c in [c for c in rk.columns if not c.startswith("rank_") and c != "real_pitch" and "roll" not in c]:
            rho = rk["real_pitch"].rank().corr(rk[c].rank())
            agree, bad = order_agreement(sub["real_pitch"], sub[c])
            agree_all, bad_all = order_agreement(rk["real_pitch"], rk[c])
            print(f"{c}: Spearman {rho:.2f} (all methods); ranking equal ({', '.join(sub.index)}; pairs > "
                  f"{ORDER_TOL:.0%} apart on real): {'yes' if agree else 'no'}"
                  + (f" ({'; '.join(bad)})" if bad else "")
                  + f"; all methods: {'yes' if agree_all else 'no'}" + (f" ({'; '.join(bad_all)})" if bad_all else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
