"""Write benchmarks/RESULTS.md: every accuracy and speed table of the project, measured in one run.

Regenerate with::

    python benchmarks/make_results.py            # full: the valid real drives of drives.csv, 10 synthetic drives a grade, all benchmarks
    python benchmarks/make_results.py --quick    # fast subset (a few drives, small benchmark sizes)
    python benchmarks/make_results.py --only bench_readers   # rewrite that script's section only
    python benchmarks/make_results.py --only accuracy        # rewrite the accuracy part only

Accuracy: the evaluation (:mod:`imu_ground.evaluation`) of every method on the
shared real KITTI drives (``../shared/data/kitti_imu100``; pitch relative to the
road, per drive means removed; by condition; per moving segment; the
reference's own uncertainty) and on the synthetic suite (navigation-grade and
MEMS IMUs; exact truth, normal angle, pitch and roll), and the simulator's
checks against the real drives (``sim_vs_real.rows()``: band powers of body pitch
and gyro pitch rate, and the methods' ranking, synthetic against real), and the
real-drive error by speed, slow and fast, shared between methods and against the
reference's own error (``error_budget.rows()``), and the timestamp policies
``drop`` against ``retime`` on the shared drives (``retime_table.rows()``: samples
dropped, frames invalid, pitch error), and the revisit consistency of pitch and roll on the
drives that pass the same place twice, every method, the suspension filter before and after
the revisit work, the settings held out (``revisit_table.rows()``), and what the per-frame plane
does for a camera on the synthetic suite (``bench_ground_effect.rows()``: ground-point range and
lane-width errors at 20, 40, 60 m with the static extrinsic, the default method and the truth), and every method
against road planes fitted to the shared KITTI LiDAR scans with the fit's repeatability
(``lidar_table.rows()``); these studies live in
``benchmarks/studies/``.
Speed: the tables of the benchmark scripts in ``benchmarks/``, each of which exposes
``rows()`` returning its rows
(``bench_filter``, ``bench_suspension``, ``bench_preintegration``, ``bench_ekf``,
``bench_gravity``, ``bench_readers``, ``bench_batch``, ``bench_job``; ``bench_preview``: the preview's peak memory;
``bench_streaming``: the live estimator; ``bench_first_run``: a new install's cold first run and a fresh
process's first live estimate); a script that is missing
or has no ``rows()`` is listed with a note instead. Figures are measured on
whatever machine runs this (shared, 2 cores while others work: speed figures are
medians but noisy).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import platform
import subprocess
import sys
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
DEFAULT_DATA = REPO.parent / "shared" / "data" / "kitti_imu100"
OUT = HERE / "RESULTS.md"
BENCHMARKS = ("bench_filter", "bench_suspension", "bench_preintegration", "bench_ekf", "bench_gravity",
              "bench_readers", "bench_batch", "bench_preview", "bench_streaming", "bench_job", "bench_first_run")
#: Folder of the studies (accuracy, tuning and simulator checks; not speed targets).
STUDIES = HERE / "studies"
#: Studies whose rows check the simulator against the real drives (band powers, method ranking), not speeds.
SIMULATOR_CHECKS = ("sim_vs_real",)
#: Studies whose rows break the real-drive error down: the estimator's share, or the reference's own.
ERROR_BUDGET = ("error_budget",)
#: Studies whose rows compare the readers' timestamp policies on the real drives (drop against retime).
READER_CHECKS = ("retime_table",)
#: Script whose rows are the revisit consistency (pitch and roll with no grade reference) and its checks.
REVISIT = "revisit_table"
#: ``--only accuracy`` rewrites the accuracy part (real and synthetic drives, every method).
ACCURACY = "accuracy"
#: Captions of the revisit script's tables, by its rows' ``table``.
REVISIT_CAPTIONS = {
    "revisit": "Road attitude (INS minus estimate) repeated between two passes over the same place, same "
               "direction: mean |difference| / sqrt(2), deg, pitch / roll, per drive with revisit pairs and "
               "pooled (pairs in the header). `suspension` is the evaluation's IMU-only default; `before` is the "
               "suspension filter's configuration before this table existed, `now` today's; `+ speed` uses "
               "the INS horizontal speed as the measured speed (`--speed auto`, the CLI default); `live (--causal)` "
               "is the live estimator's (`StreamingEstimator`, `estimate --causal`: causal clock, standstills and gyro "
               "bias) with the speed. The other methods do not use what changed (gravity filter, suspension model): "
               "the same before and now.",
    "INS-grade": "The same suspension variants against the INS-grade pitch reference on every valid drive: "
                 "mean over drives of the per-drive mean absolute pitch error (deg), the worst drive's ratio "
                 "to the paper's method (at most 1.1 allowed), and the error pooled over frames by the "
                 "reference's own 1-sigma uncertainty (below 0.15 deg it can judge about 0.1 deg; above 0.25 "
                 "it cannot).",
    "held out": "Each changed setting chosen on one revisit drive (lowest pitch + roll there, all else at "
                "today's defaults, with the speed) and scored on the other, and chosen on the first half (in "
                "time) of every drive's pairs and scored on the second; the last column scores every value of "
                "the grid on the held-out pairs.",
    "synthetic": "The suspension filter before and now on the synthetic suite: mean absolute pitch and roll "
                 "error, deg, exact truth, moving frames.",
}
#: Scripts whose rows check the 1-sigma, the status and the road's grade and bank.
CONFIDENCE_CHECKS = ("confidence", "calibrate_std", "drive_offset", "synthetic_revisit", "convergence_time", "real_coverage")
CONFIDENCE_TITLE = "How sure, and what the road does"
#: Scripts whose rows measure what the per-frame ground plane does for a camera (range and lane-width errors).
PERCEPTION_CHECKS = ("bench_ground_effect",)
#: Scripts whose rows compare the methods with road planes fitted to LiDAR scans (the paper's protocol).
LIDAR_CHECKS = ("lidar_table", "lidar_default")
#: A paragraph printed above a script's table (what it measures), by script name.
INTROS = {"bench_streaming": (
    "Live (`imu_ground.StreamingEstimator`, `imu-ground stream`, `estimate --causal`): `push_imu` per IMU sample "
    "(the log's speed pushed too, at its 100 Hz or every tenth sample; the time of those `push_speed` calls alone "
    "taken out and given in rows of its own, per speed sample) against the offline pipeline's cost per sample "
    "(`estimate_log` of the same log, reading included, same process), the pure-Python kernels beside, the load "
    "average during the run in each row; the frame-completing call's 99th percentile "
    "(CPU time; wall time beside); the INS-grade score and the revisit consistency of the live estimate against "
    "the default (both with the log's speed); and per shared drive the largest and 99th-percentile |difference| "
    "of pitch and roll, deg, between the default (whole-log gyro bias and standstills) and the live estimate, "
    "over the whole drive and after its first 60 s (empty on drives shorter than that)."),
    "bench_job": (
    "The whole `imu-ground estimate` on issue 30's 10 h log (shared `2011_10_03_drive_0042` tiled to 36,000 s, "
    "written with gzip level 1, and the same log as plain CSV; its INS speed used) against `pandas.read_csv` of the "
    "same file (`benchmarks/bench_job.py`): whole fresh processes, the cases and the competitor interleaved in each "
    "round, medians. `before` is the code before issue 30 (commit b669bd8, a second checkout given by "
    "`IMU_GROUND_BENCH_BEFORE`), timed in the same rounds as `after` (this commit). The machine is shared: the load "
    "average is in each row, CPU times beside the wall times. The stage rows split one run of each into read, "
    "standstill masks, preintegration, filter and each of its outputs, table and writer."),
    "lidar_table": (
    "LiDAR drives: `imu-ground evaluate --lidar DRIVE_DIR --lidar-fit all` (the product's own code, "
    "`lidar_drives_report`) on every KITTI raw sync folder under `kitti_raw` with `velodyne_points` and `oxts` "
    "(found from the folders), each from its own 10 Hz `oxts/` and, where `kitti_imu100` has the drive, from that "
    "100 Hz CSV too (`--log`, the same scans on its clock); per fit (RANSAC or Patchwork++ ground points, in the box "
    "x 5..30 m, |y| < 4 m, or along the driven path: within 1.5 m of the future OXTS track, 3-32 m ahead) each "
    "method's `pitch / roll` spread (deg, standard deviation of estimate minus LiDAR, each method's offset removed; "
    "`default` is what `imu-ground estimate` runs with its defaults on that input, `suspension` the same filter "
    "IMU only), the fit's frame-to-frame noise, and pooled over the 10 Hz drives (each drive's offset removed). "
    "Scans outside the log's frames or below 0.5 m/s are left out (`scans` counts those compared). LiDAR ranking: "
    "the order of `naive`, `paper` and `default` per fit, and whether it (and that of every method) is the same "
    "under every fit. The tables after: the earlier protocol on drive 0009 (the CSV with the older scan-time "
    "estimate), the object frames and the fit's repeatability. "
    "The paper's protocol on real data (`benchmarks/studies/lidar_table.py`; `imu-ground evaluate --lidar`): road "
    "planes fitted to KITTI Velodyne scans (RANSAC, then least squares on the inliers, region x 5..30 m, |y| < 4 m) "
    "against every method, deg, estimate minus LiDAR. Drive 0009 (31 scans, 3.1 s): the angle between the normals "
    "with the constant offset and centred, the pitch spread (standard deviation of the difference) with its "
    "moving-block bootstrap 95 % interval, `p_best` (share of the draws in which the method ranks first among the "
    "methods) and `vs_best` (the interval of its spread minus the best method's, same draws), roll as changes only. "
    "What 31 frames can say: a method is behind only where `vs_best` excludes 0; the methods that differ by a "
    "hundredth of a degree cannot be ranked here, and the INS reference's own spread against the LiDAR (the scans' "
    "times are known to +-0.05 s) is the floor. The absolute roll offset is no crown alone: the INS's own roll "
    "against gravity is as large over these frames (the IMU, taken as level in the car, is rolled relative to the "
    "road). Object frames: the fit against the AVOD planes (`far_fit`: the fit in x 10..40 m, where a road that "
    "changes slope ahead is not one plane), and each method with drive 0009's offset removed (frame times assumed "
    "`0.35 + 0.1036 k` s; `timing_deg`: the default estimate's pitch range over +-0.3 s). Fit repeatability: over "
    "RANSAC seeds, frame to frame (second differences), by region and threshold (|y| < 6 m: the fit's roll flips "
    "between the crown's sides from seed to seed)."
), "bench_ground_effect": (
    "What the per-frame plane does for a camera with KITTI camera 2's intrinsics, height and mount "
    "(`benchmarks/bench_ground_effect.py`): mean over drives of the per-drive mean absolute ground-point range "
    "error and lane-width error (m) over the moving frames, at 20, 40 and 60 m ahead, with the static extrinsic, "
    "the default method's plane and the truth (a check: zero). Target: the dynamic plane cuts the static one's "
    "range error at 40 m by at least 50 %. The cut follows the method's pitch error (Synthetic drives above: "
    "suspension against naive)."
), "calibrate_std": (
    "The 1-sigma constants of `imu_ground/filters/status.py` and how they were fitted "
    "(`benchmarks/studies/calibrate_std.py`), on synthetic drives with exact truth only: 8 drives a grade (navigation "
    "and MEMS) of 300-600 s per seed, fitted on seeds 2-4 (Gaussian likelihood; each grade's pooled share within "
    "1 sigma held in 64-72 %, around the aim, and each quarter of the frames by their 1-sigma in 58-80 %) and scored on the held-out "
    "seeds 5-7 (targets: pooled 55-80 %, aim 68 %; every drive 50-85 %). Two drive terms (running, from the IMU "
    "alone) carry what the per-frame inputs do not see: the road's roughness (RMS body rate so far) and the mean "
    "load so far (a drive's errors carry an offset, the accelerometer's bias through the gains: next table); the fit "
    "holds each fit drive in 55-82 % too. The per-drive target is still not met on every held-out drive: MEMS "
    "drives whose roll offset the mean load does not predict (the bias and the road's crown are one number in the "
    "data) under- or over-cover, which the estimate, not its 1-sigma, would have to change (drive_offset, part 3), "
    "and a navigation-grade drive sits on the band's top. The rows 'without "
    "the drive terms (before)' are the model before them. The yaw-rate term ships only where it makes "
    "the fit suites' likelihood better (by more than 0.001): for roll it does not; for pitch the fit with it ships, "
    "its term negligible (the two pitch fits differ by their local optimum). The revisit "
    "z RMS of the real revisit drives is a diagnostic, no longer a target: it measures how differently the two passes "
    "were driven as much as the 1-sigma (next table); 2011_10_03_drive_0034's roll differences sit where one pass "
    "turns, which the synthetic errors do not show."
), "drive_offset": (
    "Where a synthetic drive's error offset and error scale come from (`benchmarks/studies/drive_offset.py`; the "
    "held-out suites of `calibrate_std`, the default method, IMU only), and how much of a MEMS drive's roll offset "
    "the data cannot tell. Part 1, per grade and angle over the drives: the share of the offsets' variance explained by "
    "each simulated cause (a line through the drives) and by what the estimator sees (the drive's mean load), and "
    "the correlation of the spread about the offset with the road's roughness and the RMS body rate seen. Part 2: "
    "one MEMS drive simulated on the two ends of the suites' crown range, the second with the lateral accelerometer "
    "bias that gives it the first one's mean lateral specific force: the logs and the estimates are the same to "
    "within the noise, the true roll is not (the body rolls on the crown by the car's gain); the last column gives "
    "the scale factors on one common 1-sigma that keep both drives within 50-85 %: some, for an ambiguity of this "
    "size alone. The held-out drives outside 50-85 % (`calibrate_std`) combine it with the part of the offset "
    "neither the accelerometer bias nor the mean load explains (the MEMS pitch offsets: a third explained) and with "
    "drives whose spread is small. Part 3, a what-if (nothing shipped): the held-out drives outside 50-85 % if "
    "each estimate had the offset its drive's causal mean load predicts taken out (a gain per grade and angle fitted "
    "on the fit suites), with the shipped 1-sigma and with the 1-sigma refitted on the corrected fit suites, beside the drives "
    "outside as shipped: whether keeping the estimates fixed, rather than the 1-sigma model, leaves drives outside. "
    "Part 4: the shipped 1-sigma (and scaled by a common factor) on three sets of three suites, the fit's, the "
    "held-out and a third seen by neither: how much the count of drives outside moves with the suites alone."
), "convergence_time": (
    "How long the suspension filter's status stays `converging` (`benchmarks/studies/convergence_time.py`): its "
    "1-sigma's drive terms grow in over the first tens of seconds of moving frames, and before that the 1-sigma is "
    "too small. Synthetic drives with exact truth (4 drives a grade of 120-300 s per seed), with the true speed and "
    "IMU only. `by moving time`: the share of moving frames within 1 sigma by the moving seconds seen so far "
    "(no wait). `first ok frames`: for each candidate wait (the latch closes only after that many seconds of "
    "moving frames), the share within 1 sigma of the first 30 s of frames the status calls `ok`; the shipped wait "
    "(`CONVERGED_MOVING_SECONDS`) is the shortest whose fit-suite (seeds 2-3) share is at least 50 % (the per-drive "
    "target's floor) for each grade, angle and speed mode; seeds 5-6 are held out. MEMS-grade IMU-only pitch stays "
    "below 55 % for every wait up to 45 s: the 1-sigma of that case is too small all drive long, not only at the "
    "start."
), "lidar_default": (
    "The default against the paper's method on LiDAR truth, and the measures it must keep (issue 36, part 2; "
    "`benchmarks/studies/lidar_default.py`, whose docstring defines each table): per LiDAR case the pitch and roll "
    "spreads of the methods and suspension variants with `pitch/paper` (target <= 0.9) and its paired bootstrap "
    "interval; how much of the LiDAR's pitch excursions each follows; how far ahead the LiDAR's road lies; the "
    "default with the grade change ahead added (from the INS, an exact trajectory, or from its own road grade), "
    "where the log goes on that far; the kept measures (revisit, INS-grade, live); the load's pitch gain on both."
), "real_coverage": (
    "The 1-sigma on real truth (`benchmarks/studies/real_coverage.py`): the default estimate's pitch error against "
    "the INS-grade reference on every valid shared drive, within its 1-sigma alone and within the 1-sigma and the "
    "reference's own (`reference_sigma`) together, per drive and pooled; the LiDAR rows, where present, against road "
    "planes with the fit's frame-to-frame noise added. The two INS columns bracket what a calibrated 1-sigma would "
    "show: the reference's error is as large as the estimate's. `sigma_scale` (pooled rows): the factor on the "
    "1-sigma that maximises the Gaussian likelihood of the pooled errors with the truth's own noise added, and the "
    "share within the 1-sigma so scaled: the INS asks for about 1 (the shipped constants), the LiDAR scans (all in "
    "their drives' first seconds, `converging`, and of the road ahead) for several times more."
), "synthetic_revisit": (
    "The revisit check of the 1-sigma with exact truth (`benchmarks/studies/synthetic_revisit.py`): each drive of "
    "the synthetic suite of seed 1 driven a second time on the same road by the same sensor "
    "(`imu_ground.evaluation.simulate.second_pass`), with the same speed profile, faster at every place, or a new "
    "profile; the default method's errors against the truth at the evaluation's revisit pairs. With the 1-sigma "
    "that covers 55-80 % of the errors, the check's z RMS follows how differently the second pass is driven, not "
    "the 1-sigma: the errors repeat at the same place. The last rows: the real revisit drives, IMU only."
)}
#: Smaller sizes for ``--quick``, passed to a benchmark's ``rows()`` where it has the parameter.
QUICK_KWARGS = {"frames": 20_000, "stream_frames": 5_000, "repeat": 2, "steps": 5_000, "samples": 60_000,
                "stream_samples": 5_000, "hours": (0.1,), "n": 2, "drives": 4}
QUICK_REAL_DRIVES = 6
SYNTHETIC_DRIVES, QUICK_SYNTHETIC_DRIVES = 10, 2

__all__ = ["accuracy_sections", "revisit_sections", "speed_sections", "main"]


# ----------------------------------------------------------------------------- formatting
def _cell(v) -> str:
    if isinstance(v, bool) or v is None:
        return "" if v is None else ("yes" if v else "no")
    if isinstance(v, float):
        if not math.isfinite(v):
            return ""
        return f"{v:.3f}" if abs(v) < 1000 else f"{v:,.0f}"
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):
        return _cell(v.item())
    return str(v).replace("|", "\\|")


def markdown(rows: list[dict]) -> str:
    """A list of dicts as a Markdown table (columns: the union of the keys, first seen first)."""
    if not rows:
        return "(no rows)"
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(_cell(r.get(c)) for c in cols) + " |" for r in rows]
    return "\n".join(lines)


def _frame_rows(df) -> list[dict]:
    return df.reset_index().to_dict("records")


# ----------------------------------------------------------------------------- accuracy
def _real_section(data: Path, quick: bool) -> list[str]:
    from imu_ground.evaluation import conditions as cond
    from imu_ground.evaluation.runner import conditions_table, evaluate, load_real_drives, summary_table
    if not data.is_dir():
        return ["## Real drives", "", f"Skipped: {data} not found (the shared recordings are not on this machine)."]
    drives = load_real_drives(data, progress=False)
    excluded = [d for d in drives if not d.valid]
    valid = [d for d in drives if d.valid]
    if quick:
        valid = valid[:QUICK_REAL_DRIVES]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = evaluate(valid, progress=False)
    summary = summary_table(res)[["drives", "mean_deg", "median_deg", "worst_deg", "worst_drive",
                                  "worst_ratio_to_paper", "seg_pitch_deg", "ref_floor_deg", "ref_share",
                                  "us_per_frame"]]
    out = ["## Real drives (shared KITTI, IMU only)", "",
           f"{len(valid)} valid drives of `{data.name}`" + (" (quick subset)" if quick else "")
           + "; excluded from their signals: "
           + ("; ".join(f"{d.name} ({d.reason})" for d in excluded) or "none") + ".", "",
           "Mean absolute pitch error relative to the road, deg, over the valid frames above 3 m/s, means "
           "removed per drive (`mean_deg`: mean over drives; `worst_ratio_to_paper`: worst drive's error over "
           "the paper's method's on the same drive). `seg_pitch_deg`: the same with the means removed per moving "
           "segment (between stops). `ref_floor_deg`: what a perfect estimator would score against this "
           f"reference (INS vertical-velocity noise {cond.INS_VU_NOISE} m/s over the speed, pitch noise "
           f"{math.degrees(cond.INS_PITCH_NOISE):.2f} deg), each drive at most the method's own error; `ref_share`: share of the method's mean squared "
           "error the reference's own uncertainty can explain, each drive at most all of its own (on most drives "
           "the suspension method's error is below what this reference model allows for). `us_per_frame`: batch "
           "run time.", "",
           markdown(_frame_rows(summary)), "",
           "### By condition (real drives)", "",
           "Mean absolute pitch error, deg, pooled over the frames of each condition "
           "(definitions in `imu_ground.evaluation.conditions`: speed bins; turning |yaw rate| > "
           f"{cond.TURN_YAW_RATE} rad/s; braking deceleration > {cond.BRAKE_DECEL} m/s^2; within "
           f"{cond.NEAR_STOP_S:g} s of a stop (< {cond.STOP_SPEED} m/s); rough road: high-passed pitch rate RMS > "
           f"{math.degrees(cond.ROUGH_PITCH_RATE):.1f} deg/s).", "",
           markdown(_frame_rows(conditions_table(res))), "",
           "Frames per condition:", "",
           markdown(_frame_rows(conditions_table(res, counts=True).groupby(level=0).first())), ""]
    return out


def _synthetic_section(quick: bool) -> list[str]:
    from imu_ground.evaluation.runner import conditions_table, evaluate, summary_table, synthetic_drives
    n = QUICK_SYNTHETIC_DRIVES if quick else SYNTHETIC_DRIVES
    drives = synthetic_drives(n, seed=0, grades=("nav", "mems"), progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = evaluate(drives, progress=False)
    ok = res[res["valid"]]
    by = ok.groupby(["grade", "method"], sort=False)[["angle_mean", "pitch_mean", "roll_mean", "seg_pitch_mean"]]
    table = by.mean().rename(columns=lambda c: c.replace("_mean", "_deg"))
    summary = summary_table(res)[["drives", "mean_deg", "median_deg", "worst_deg", "worst_ratio_to_paper",
                                  "us_per_frame"]]
    return ["## Synthetic drives", "",
            f"`simulate_suite({n}, seed=0, grades=('nav', 'mems'))` (the CLI's `evaluate --synthetic {n}`): "
            "exact truth, nothing removed, valid frames above 3 m/s. Mean over drives of the per-drive mean "
            "absolute error, deg: normal angle, pitch, roll, pitch per moving segment.", "",
            markdown(_frame_rows(table)), "",
            "Normal angle error per IMU grade (`worst_ratio_to_paper` as for the real drives):", "",
            markdown(_frame_rows(summary)), "",
            "By condition (pitch, deg):", "",
            markdown(_frame_rows(conditions_table(res))), ""]


def _revisit_pivot(rows: list[dict]) -> list[dict]:
    """The long revisit rows (drive, method) as one row a method: ``pitch / roll`` per drive."""
    out: dict[str, dict] = {}
    for r in rows:
        key = f"{r['drive']} ({r['pairs']} pairs)"
        out.setdefault(r["method"], {"method": r["method"]})[key] = f"{_cell(r['pitch_deg'])} / {_cell(r['roll_deg'])}"
    return list(out.values())


def revisit_sections(quick: bool) -> list[str]:
    """The revisit part of RESULTS.md: ``revisit_table.rows()`` as one table per kind of row."""
    out = ["# Revisit consistency on the real drives", ""]
    res = _run_benchmark(REVISIT, quick)
    if res["status"] != "ok":
        return out + [f"Skipped: `benchmarks/{REVISIT}.py` rows(): {res.get('error', res['status'])}", ""]
    out += [f"`{REVISIT}.rows({_args(res['kwargs'])})`, {res['seconds']:.0f} s.", ""]
    tables: dict[str, list[dict]] = {}
    for r in res["rows"]:
        tables.setdefault(r["table"], []).append({k: v for k, v in r.items() if k != "table"})
    for name, rows in tables.items():
        out += [f"## {name}", "", REVISIT_CAPTIONS.get(name, ""), "",
                markdown(_revisit_pivot(rows) if name == "revisit" else rows), ""]
    return out


def accuracy_sections(data: Path, quick: bool) -> list[str]:
    """The accuracy part of RESULTS.md as Markdown lines."""
    return ["# Accuracy", ""] + _real_section(data, quick) + _synthetic_section(quick)


# ----------------------------------------------------------------------------- speed
#: Seconds a benchmark's ``rows()`` may take before it is stopped and noted.
BENCH_TIMEOUT = 1800.0

_CHILD = """
import inspect, json, sys, time
sys.path.insert(0, {here!r})
name, quick, quick_kwargs = {name!r}, {quick!r}, {quick_kwargs!r}
module = __import__(name)
rows = getattr(module, "rows", None)
if rows is None:
    print(json.dumps({{"status": "norows"}}))
    raise SystemExit(0)
params = inspect.signature(rows).parameters
kwargs = {{k: v for k, v in quick_kwargs.items() if k in params}} if quick else {{}}
t0 = time.perf_counter()
table = [dict(r) for r in rows(**kwargs)]
print(json.dumps({{"status": "ok", "kwargs": kwargs, "seconds": time.perf_counter() - t0, "rows": table}},
                 default=lambda o: o.item() if hasattr(o, "item") else str(o)))
"""


def _script(name: str) -> Path:
    """``benchmarks/<name>.py`` or, for a study, ``benchmarks/studies/<name>.py``."""
    return HERE / f"{name}.py" if (HERE / f"{name}.py").is_file() else STUDIES / f"{name}.py"


def _run_benchmark(name: str, quick: bool) -> dict:
    """The script's ``rows()`` in a child process (imported by name from its folder, so that its own
    worker processes can import it too); its result as a dict with ``status``."""
    script = _script(name)
    if not script.is_file():
        return {"status": "missing"}
    code = _CHILD.format(here=str(script.parent), name=name, quick=quick, quick_kwargs=QUICK_KWARGS)
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO,
                              timeout=BENCH_TIMEOUT)
    except subprocess.TimeoutExpired:
        return {"status": "error", "error": f"stopped after {BENCH_TIMEOUT:.0f} s"}
    if proc.returncode != 0:
        lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
        return {"status": "error", "error": lines[-1] if lines else f"exit code {proc.returncode}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def speed_sections(quick: bool, only: tuple[str, ...] = BENCHMARKS, title: str = "Speed") -> list[str]:
    """A part of RESULTS.md (by default the speed part): each script's ``rows()`` as a table, or a note."""
    out = [f"# {title}", ""]
    for name in only:
        res = _run_benchmark(name, quick)
        path = _script(name).relative_to(REPO).as_posix()
        out += [f"## {name}", ""] + ([INTROS[name], ""] if name in INTROS else [])
        if res["status"] == "missing":
            out += [f"Skipped: `{path}` does not exist yet.", ""]
        elif res["status"] == "norows":
            out += [f"Skipped: `{path}` has no `rows()` function (run it by hand: "
                    f"`python {path}`).", ""]
        elif res["status"] == "error":
            out += [f"Failed: `{path}` rows(): {res['error']}", ""]
        elif res["rows"] and all("table" in r for r in res["rows"]):
            out += [f"`{name}.rows({_args(res['kwargs'])})`, {res['seconds']:.0f} s:", ""]
            tables: dict[str, list[dict]] = {}
            for r in res["rows"]:
                tables.setdefault(r["table"], []).append({k: v for k, v in r.items() if k != "table"})
            for table, rows in tables.items():
                out += [f"### {table}", "", markdown(rows), ""]
        else:
            out += [f"`{name}.rows({_args(res['kwargs'])})`, {res['seconds']:.0f} s:", "",
                    markdown(res["rows"]), ""]
    return out


def _args(kwargs: dict) -> str:
    return ", ".join(f"{k}={v!r}" for k, v in kwargs.items())


# ----------------------------------------------------------------------------- main
def _header(argv: list[str], quick: bool) -> list[str]:
    try:
        commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit, dirty = "unknown", ""
    command = " ".join(["python benchmarks/make_results.py"] + argv)
    return ["# imu-ground results", "",
            f"Regenerate: `{command}`" + ("" if quick else " (add `--quick` for a fast subset)"), "",
            f"Written {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M} UTC at commit {commit}"
            + (" (with uncommitted changes in the tree)" if dirty else "")
            + f", Python {platform.python_version()}, {platform.machine()}."
            + (" QUICK SUBSET: not the reference figures." if quick else ""), "",
            "Every measured figure of the project lives here (docstrings and the README point to this file).", ""]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a fast subset: few drives, small benchmark sizes")
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of the kitti_imu100 drives")
    ap.add_argument("--out", type=Path, default=OUT, help="output file (default %(default)s)")
    ap.add_argument("--no-speed", action="store_true", help="accuracy tables only")
    ap.add_argument("--no-accuracy", action="store_true", help="speed tables only")
    ap.add_argument("--only", nargs="+", metavar="SCRIPT",
                    help="rerun these benchmark scripts and replace their sections of the existing file "
                         f"({ACCURACY!r}: the accuracy part)")
    a = ap.parse_args(argv)
    if a.only:
        return _rewrite_sections(a.out, a.only, a.quick, argv, a.data)
    lines = _header(argv, a.quick)
    if not a.no_accuracy:
        lines += accuracy_sections(a.data, a.quick)
        lines += speed_sections(a.quick, ERROR_BUDGET, "Where the real-drive error is")
        lines += speed_sections(a.quick, SIMULATOR_CHECKS, "Simulator against the real drives")
        lines += speed_sections(a.quick, READER_CHECKS, "Timestamp policies on the real drives")
        lines += revisit_sections(a.quick)
        lines += speed_sections(a.quick, CONFIDENCE_CHECKS, CONFIDENCE_TITLE)
        lines += speed_sections(a.quick, PERCEPTION_CHECKS, "Ground plane for a camera (synthetic suite)")
        lines += speed_sections(a.quick, LIDAR_CHECKS, "LiDAR ground truth (real scans)")
    if not a.no_speed:
        lines += speed_sections(a.quick)
    tmp = a.out.with_suffix(a.out.suffix + ".tmp")
    tmp.write_text("\n".join(lines).rstrip() + "\n")
    tmp.replace(a.out)
    print(f"wrote {a.out}")
    return 0


def _rewrite_sections(out: Path, names: list[str], quick: bool, argv: list[str], data: Path = DEFAULT_DATA) -> int:
    """Replace the ``## NAME`` sections of ``out`` by a fresh run of those scripts (the rest is kept);
    ``accuracy`` (:data:`ACCURACY`) and :data:`REVISIT` rewrite their whole parts."""
    text = out.read_text().splitlines()
    commit = _header(argv, quick)[4]
    for name in names:
        if name in (REVISIT, ACCURACY):                     # a part of its own, several "## " tables
            fresh = revisit_sections(quick) if name == REVISIT else accuracy_sections(data, quick)
            fresh.insert(2, f"Part rewritten alone (`python benchmarks/make_results.py {' '.join(argv)}`): "
                            f"{commit[0].lower()}{commit[1:]}")
            fresh.insert(3, "")
            start = text.index(fresh[0]) if fresh[0] in text else None
            if start is None:
                text += [""] + fresh
                continue
            stop = next((i for i in range(start + 1, len(text)) if text[i].startswith("# ")), len(text))
            text[start:stop] = fresh
            continue
        fresh = speed_sections(quick, (name,))[2:]          # "## name" and its table, without the part title
        fresh.insert(2, f"Section rewritten alone (`python benchmarks/make_results.py {' '.join(argv)}`): "
                        f"{commit[0].lower()}{commit[1:]}")
        fresh.insert(3, "")
        start = text.index(f"## {name}") if f"## {name}" in text else None
        if start is None:
            text += [""] + fresh
            continue
        stop = next((i for i in range(start + 1, len(text)) if text[i].startswith(("## ", "# "))), len(text))
        text[start:stop] = fresh
    tmp = out.with_suffix(out.suffix + ".tmp")
    tmp.write_text("\n".join(text).rstrip() + "\n")
    tmp.replace(out)
    print(f"rewrote {', '.join(names)} in {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
