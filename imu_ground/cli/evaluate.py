"""``imu-ground evaluate``: compare the methods on real (KITTI) and/or synthetic drives."""
from __future__ import annotations

from pathlib import Path

import argparse
import numpy as np

from imu_ground.cli._common import (LazyHelp, add_progress_flag, first_given, input_paths, no_warnings, nonnegative_int,
                                    progress_enabled, say, write_said)
from imu_ground.cli._lidar import add_lidar_flags, run_lidar
from imu_ground.datasets.storage import is_url, join, local_input, local_name, staged_folder
from imu_ground.errors import ImuGroundError
from imu_ground.evaluation.plots import evaluation_plots
from imu_ground.evaluation.runner import (
    METHODS, conditions_table, evaluate, format_table, load_real_drives, methods_from_list, sigma_table, summary_table,
    synthetic_drives
)
from imu_ground.evaluation.revisit import revisit_table
from imu_ground.evaluation.simulate.suite import MAX_SUITE_DRIVES, check_suite_size
from imu_ground.pipeline.input_checks import check_creatable
from imu_ground.pipeline.output import check_output_path, check_run_paths

__all__ = ["register", "run"]


class _WholeWordsHelp(argparse.HelpFormatter):
    """Help lines wrapped between words only: method names such as ``suspension-offline`` stay whole."""

    def _split_lines(self, text: str, width: int) -> list:
        import textwrap
        return textwrap.wrap(" ".join(text.split()), width, break_on_hyphens=False)


def _methods_help() -> str:
    lines = [f"{name}: {getattr(m, 'description', '')}" for name, m in METHODS.items()]
    return "comma-separated methods to compare (default all): " + "; ".join(lines)


def register(sub) -> None:
    """Add the ``evaluate`` sub-command."""
    v = sub.add_parser("evaluate", help="compare methods on real and/or synthetic drives",
                       formatter_class=_WholeWordsHelp,
                       description="Error of every method against the reference (real KITTI drives: pitch relative "
                                   "to the road from the INS; synthetic drives: exact truth), like the paper's "
                                   "Table 2; on real drives also the pitch error by the reference's own uncertainty "
                                   "and, on drives that pass the same place twice, the revisit consistency of "
                                   "pitch and roll (no grade reference). Give --real, --synthetic or both; or "
                                   "--lidar DRIVE_DIR ... (KITTI raw sync "
                                   "folders) or --lidar LOG SCANS: the methods against road planes fitted to LiDAR "
                                   "scans.")
    v.add_argument("--real", metavar="DIR", help="folder of kitti_imu100 drives (*.csv.gz), e.g. ../shared/data/kitti_imu100")
    v.add_argument("--synthetic", type=nonnegative_int, default=0, metavar="N",
                   help=f"number of synthetic drives per IMU grade (default 0, at most {MAX_SUITE_DRIVES})")
    v.add_argument("--grades", default="nav,mems", metavar="LIST",
                   help="comma-separated IMU grades of the synthetic drives: nav, mems, perfect (default nav,mems)")
    v.add_argument("--seed", type=nonnegative_int, default=0,
                   help="random seed of the synthetic drives, a whole number >= 0 (default 0)")
    v.add_argument("--methods", metavar="LIST", help=LazyHelp(_methods_help))
    v.add_argument("--per-drive", action="store_true", help="also print the per-drive error table")
    v.add_argument("--csv", metavar="FILE", help="write the per-drive results as CSV")
    v.add_argument("--markdown", metavar="FILE", help="write the summary table as Markdown")
    v.add_argument("--plots", metavar="DIR", help="write PNG plots into this folder (needs matplotlib)")
    add_lidar_flags(v)
    add_progress_flag(v)
    v.set_defaults(func=run)


def _check(a: argparse.Namespace) -> list:
    lidar_only = first_given(("--times", a.times), ("--lidar-extrinsic", a.lidar_extrinsic),
                             ("--lidar-planes", a.lidar_planes), ("--lidar-region", a.lidar_region),
                             ("--extrinsic", a.extrinsic), ("-o", a.plot), ("--log", a.log), ("--json", a.json),
                             ("--lidar-scans", a.lidar_scans), ("--lidar-min-speed", a.lidar_min_speed),
                             ("--lidar-fit", a.lidar_fit != "auto"))
    if lidar_only:
        raise ImuGroundError(f"{lidar_only} goes with --lidar (DRIVE_DIR ..., or LOG SCANS)")
    if a.real is None and not a.synthetic:
        raise ImuGroundError("nothing to evaluate: give --real DIR (kitti_imu100 drives) and/or --synthetic N, or "
                             "--lidar LOG SCANS (LiDAR road planes)")
    methods = methods_from_list(a.methods)
    if a.real is not None and not is_url(a.real) and not Path(local_name(a.real)).is_dir():
        raise ImuGroundError(f"--real {a.real}: {'is a file' if Path(a.real).exists() else 'no such folder'}; give "
                             "--real the folder of kitti_imu100 drives (*.csv.gz)")
    if a.plots and not is_url(a.plots):
        plots = Path(local_name(a.plots))
        if plots.exists() and not plots.is_dir():
            raise ImuGroundError(f"{plots}: is a file; give --plots a folder (created if missing)")
        check_creatable(plots, "--plots")
    grades = a.grades.split(",")
    bad = [g for g in grades if g not in ("nav", "mems", "perfect")]
    if bad:
        raise ImuGroundError(f"--grades: unknown {', '.join(bad)}; choose from nav, mems, perfect")
    twice = sorted({g for g in grades if grades.count(g) > 1})
    if twice:
        raise ImuGroundError(f"--grades: {', '.join(twice)} given twice; each grade once (its drives would count "
                             "twice in the summary)")
    check_suite_size(a.synthetic)
    for option, path in (("--csv", a.csv), ("--markdown", a.markdown)):
        if path:
            check_output_path(path, option=option, kind="text")
    check_run_paths([("--csv", a.csv), ("--markdown", a.markdown), ("--plots", a.plots)], input_paths(a))
    return methods


def run(a: argparse.Namespace) -> int:
    """Load the drives, run the methods, print the summary (and per-drive) tables, write the files asked for."""
    if a.lidar:
        return run_lidar(a)
    methods = _check(a)
    progress = progress_enabled(a)
    drives = []
    if a.real is not None:
        with local_input(a.real) as real:          # a URL: the folder copied here first
            drives += load_real_drives(Path(real), progress=progress)
    if a.synthetic:
        drives += synthetic_drives(a.synthetic, seed=a.seed, grades=a.grades.split(","), progress=progress)
    with no_warnings():
        out = evaluate(drives, methods, progress=progress, keep_tracks=bool(a.plots))
    res, tracks = out if isinstance(out, tuple) else (out, {})
    if not res["valid"].any():
        reasons = "; ".join(f"{r['drive']}: {r['reason']}" for _, r in res.drop_duplicates("drive").iterrows())
        raise ImuGroundError(f"{a.real}: no drive with a usable reference ({reasons})")
    table = summary_table(res)
    cols = [c for c in ("drives", "mean_deg", "median_deg", "worst_deg", "worst_ratio_to_paper", "worst_ratio_drive",
                        "seg_pitch_deg", "ref_floor_deg", "ref_share", "us_per_frame") if c in table.columns]
    say(format_table(table[cols], "text"))
    say("(mean_deg: per-drive mean absolute error averaged over drives; seg_pitch_deg: the same with the mean "
        "removed per moving segment; ref_floor_deg: what a perfect estimator would score against the reference's "
        "own uncertainty, each drive at most the method's own error; ref_share: the share of the squared error the "
        "reference alone can explain, each drive at most all of its own)")
    say("\nby condition (mean absolute pitch error, deg, pooled over frames):")
    say(format_table(conditions_table(res), "text"))
    sig, rev = sigma_table(res), revisit_table(res)
    for title, tab in (("real drives, pitch error by the reference's own uncertainty (ref_sigma bins, deg; "
                        "ref_floor_deg: what a perfect estimator would score there, so the reference can judge 0.1 "
                        "deg only where it is well below 0.1)", sig),
                       ("revisit consistency (real drives that pass the same place twice in the same direction: "
                        "the road's attitude, INS minus estimate, must repeat; mean |difference| / sqrt(2), deg, "
                        "over the pairs; no grade reference involved)", rev)):
        if len(tab):
            say(f"\n{title}:")
            say(format_table(tab, "text"))
    if not len(rev) and a.real is not None:
        say("\nrevisit consistency: no drive passes the same place twice in the same direction")
    excluded = res[~res["valid"]].drop_duplicates("drive")
    if len(excluded):
        say("\nexcluded drives (reference not usable):")
        for _, row in excluded.iterrows():
            say(f"  {row['drive']}: {row['reason']}")
    if a.per_drive:
        q = np.where(res["kind"] == "real", res.get("pitch_mean"), res.get("angle_mean", np.nan))
        per = res.assign(error_deg=q).pivot_table(index="drive", columns="method", values="error_deg")
        say("\nper drive (mean absolute error, deg: pitch for real drives, normal angle for synthetic):")
        say(format_table(per[[m for m in methods if m in per.columns]], "text"))
    if a.csv:
        write_said(a.csv, res.to_csv(index=False, float_format="%.5f"))
    if a.markdown:
        md = format_table(table[cols], "markdown") + "\n"
        for title, tab in (("Pitch error by the reference's own uncertainty (deg)", sig),
                           ("Revisit consistency (mean |difference| / sqrt(2), deg)", rev)):
            if len(tab):
                md += f"\n{title}:\n\n" + format_table(tab, "markdown") + "\n"
        write_said(a.markdown, md)
    if a.plots:
        with staged_folder(a.plots) as folder:     # a URL: written here, then uploaded
            written = list(evaluation_plots(drives, res, tracks, Path(folder)))
        for p in written:
            say(f"wrote {join(a.plots, Path(p).name) if is_url(a.plots) else p}")
    return 0
