"""Command-line interface: ``imu-ground estimate | evaluate | simulate | calibrate``.

Run ``imu-ground COMMAND --help`` for the options of each command.
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

__all__ = ["main", "estimate_log", "ESTIMATE_METHODS"]

#: Methods of ``imu-ground estimate``.
ESTIMATE_METHODS = ("filter", "paper", "suspension", "suspension-offline")


def _progress(enabled: bool, total: int, desc: str):
    from tqdm.auto import tqdm
    return tqdm(total=total, desc=desc, disable=not enabled, leave=False,
                unit="frame" if total > 10 else "step")


def estimate_log(path, fmt: Optional[str] = None, method: str = "filter", extrinsic=None,
                 rate: float = 10.0, policy: str = "drop", progress: bool = False, Q=None, R=None):
    """Raw IMU log in, per-frame ground normals out (what ``imu-ground estimate`` does).

    Parameters
    ----------
    path : str or Path
        Log file or folder (any format of :func:`imu_ground.datasets.read_imu`).
    fmt : str, optional
        Format name; detected from the path when None.
    method : {"filter", "paper", "suspension", "suspension-offline"}
        ``filter``: :class:`~imu_ground.filters.ground.GroundNormalFilter` (heading-following
        invariant EKF); ``paper``: the paper's random-walk filter with its
        published parameters; ``suspension`` / ``suspension-offline``: the
        suspension-aware filter, streaming or smoothed.
    extrinsic : str, Path or Extrinsic, optional
        Static sensor-to-ground extrinsic (shipped name or file); identity by default.
    rate : float
        Frame rate, Hz.
    policy : {"drop", "sort", "strict"}
        What to do with out-of-order timestamps (see :func:`imu_ground.datasets.validation.validate`).
    progress : bool
        Progress bars.
    Q, R : float, optional
        Process and measurement noise of the ``filter`` method.

    Returns
    -------
    track : GroundTrack
        Frames as documented in :class:`~imu_ground.filters.ground.GroundTrack` (normal in
        the sensor frame; pitch/roll of the body relative to the road).
    egomotion : EgoMotion
        The frames (times, validity) the track belongs to.
    """
    from imu_ground.datasets import read_imu
    from imu_ground.imu.egomotion import imu_to_egomotion
    from imu_ground.filters.extrinsics import Extrinsic, load_extrinsic
    from imu_ground.filters.ground import GroundNormalFilter

    if method not in ESTIMATE_METHODS:
        raise ValueError(f"unknown method {method!r}; choose from {', '.join(ESTIMATE_METHODS)}")
    if extrinsic is None:
        ext = Extrinsic()
    elif isinstance(extrinsic, Extrinsic):
        ext = extrinsic
    else:
        ext = load_extrinsic(extrinsic)
    steps = _progress(progress, 3, "estimate")
    steps.set_postfix_str("reading")
    imu = read_imu(path, format=fmt, policy=policy)
    if imu.frame != "FLU" and extrinsic is None:
        warnings.warn(f"{path}: the IMU's body frame is {imu.frame!r}, not FLU (x forward, y left, z up), and no "
                      "extrinsic was given: pitch and roll refer to the sensor's own axes. Run "
                      "'imu-ground calibrate' once and pass the result with --extrinsic.", stacklevel=2)
    steps.update()
    steps.set_postfix_str("preintegrating")
    em = imu_to_egomotion(imu, rate=rate)
    steps.update()
    steps.set_postfix_str(method)
    if method in ("filter", "paper"):
        kw = {} if method == "filter" else dict(Q=1e-2, R=1.0, P=1.0, follow_heading=False)
        if Q is not None:
            kw["Q"] = Q
        if R is not None:
            kw["R"] = R
        f = GroundNormalFilter(extrinsic=ext, **kw)
        # chunked so that a long log shows progress; run() continues exactly
        chunk = 20_000
        parts = []
        bar = _progress(progress and len(em) > chunk, len(em), "filter")
        for i in range(0, len(em), chunk):
            parts.append(f.run(em.delta_R[i:i + chunk]))
            bar.update(len(parts[-1]))
        bar.close()
        track = _concat(parts)
    else:
        from imu_ground.filters.suspension import estimate_suspension_aware
        track = estimate_suspension_aware(em, extrinsic=ext, smooth=(method == "suspension-offline"))
    steps.update()
    steps.close()
    return track, em


def _concat(parts):
    from imu_ground.filters.ground import GroundTrack
    if len(parts) == 1:
        return parts[0]
    fields = ("normal", "pitch", "roll", "residual", "extrinsic", "P", "x", "cumulative")
    return GroundTrack(*[np.concatenate([getattr(p, f) for p in parts]) for f in fields],
                       translation=parts[0].translation)


def _write_estimate(track, em, out: Path) -> None:
    from scipy.spatial.transform import Rotation
    import pandas as pd
    q = Rotation.from_matrix(track.residual).as_quat()        # x, y, z, w
    df = pd.DataFrame({"t": em.t, "normal_x": track.normal[:, 0], "normal_y": track.normal[:, 1],
                       "normal_z": track.normal[:, 2], "pitch_deg": np.degrees(track.pitch),
                       "roll_deg": np.degrees(track.roll), "qw": q[:, 3], "qx": q[:, 0], "qy": q[:, 1],
                       "qz": q[:, 2], "valid": em.valid, "stationary": em.stationary})
    with open(out, "w") as fh:
        fh.write("# imu-ground estimate: t (s), unit ground normal in the sensor frame, pitch (deg, +nose down) and\n"
                 "# roll (deg, +left side up) of the body relative to the road, residual rotation road <- body as a\n"
                 "# unit quaternion (qw, qx, qy, qz); valid = 0 where the frame spans a timestamp gap\n")
        df.to_csv(fh, index=False, float_format="%.9g")


def _cmd_estimate(a) -> int:
    t0 = time.perf_counter()
    track, em = estimate_log(a.log, a.format, a.method, a.extrinsic, a.rate, a.policy,
                             progress=not a.no_progress, Q=a.Q, R=a.R)
    out = Path(a.output) if a.output else Path(Path(a.log).name.split(".")[0] + "_ground.csv")
    _write_estimate(track, em, out)
    if a.tum:
        from imu_ground.datasets.poses import write_tum_poses
        write_tum_poses(a.tum, em.t, track.extrinsic, track.translation)
    dt = time.perf_counter() - t0
    p = np.degrees(track.pitch)
    r = np.degrees(track.roll)
    print(f"{len(em)} frames at {a.rate:g} Hz from {a.log} ({em.meta.get('invalid_frames', 0)} across gaps, "
          f"{int(em.stationary.sum())} stationary) in {dt:.2f} s")
    print(f"pitch {p.mean():+.3f} +- {p.std():.3f} deg (range {p.min():+.2f} .. {p.max():+.2f}), "
          f"roll {r.mean():+.3f} +- {r.std():.3f} deg")
    print(f"wrote {out}" + (f" and {a.tum}" if a.tum else ""))
    return 0


def _cmd_evaluate(a) -> int:
    from imu_ground.evaluation.runner import METHODS, evaluate, format_table, load_real_drives, summary_table, synthetic_drives
    if a.real is None and not a.synthetic:
        raise SystemExit("imu-ground evaluate: give --real DIR and/or --synthetic N")
    methods = a.methods.split(",") if a.methods else list(METHODS)
    drives = []
    if a.real is not None:
        drives += load_real_drives(Path(a.real), progress=not a.no_progress)
    if a.synthetic:
        drives += synthetic_drives(a.synthetic, seed=a.seed, grades=a.grades.split(","),
                                   progress=not a.no_progress)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res, tracks = evaluate(drives, methods, progress=not a.no_progress, keep_tracks=bool(a.plots))
    excluded = res[~res["valid"]].drop_duplicates("drive")
    table = summary_table(res)
    cols = ["drives", "mean_deg", "median_deg", "worst_deg", "worst_ratio_to_paper", "worst_ratio_drive",
            "us_per_frame"]
    print(format_table(table[cols], "text"))
    if len(excluded):
        print("\nexcluded drives (reference not usable):")
        for _, row in excluded.iterrows():
            print(f"  {row['drive']}: {row['reason']}")
    if a.per_drive:
        q = np.where(res["kind"] == "real", res.get("pitch_mean"), res.get("angle_mean", np.nan))
        per = res.assign(error_deg=q).pivot_table(index="drive", columns="method", values="error_deg")
        print("\nper drive (mean absolute error, deg: pitch for real drives, normal angle for synthetic):")
        print(format_table(per[[m for m in methods if m in per.columns]], "text"))
    if a.csv:
        res.to_csv(a.csv, index=False, float_format="%.5f")
        print(f"wrote {a.csv}")
    if a.markdown:
        Path(a.markdown).write_text(format_table(table[cols], "markdown") + "\n")
        print(f"wrote {a.markdown}")
    if a.plots:
        from imu_ground.evaluation.plots import evaluation_plots
        for p in evaluation_plots(drives, res, tracks, Path(a.plots)):
            print(f"wrote {p}")
    return 0


def _cmd_simulate(a) -> int:
    from imu_ground.evaluation.simulate import simulate
    sim = simulate(a.duration, seed=a.seed, imu=a.imu)
    out = Path(a.output)
    truth = Path(a.truth) if a.truth else out.with_name(out.name.replace(".csv", "") + "_truth.csv")
    sim.to_csv(out, truth)
    print(f"simulated {a.duration:g} s ({a.imu} IMU, seed {a.seed}): wrote {out} and {truth}")
    if a.plot:
        from imu_ground.evaluation.plots import plot_simulation
        print(f"wrote {plot_simulation(sim, Path(a.plot))}")
    return 0


def _cmd_calibrate(a) -> int:
    from imu_ground.filters.calibration import calibrate
    from imu_ground.datasets import read_imu
    imus = [read_imu(p, format=a.format, policy=a.policy) for p in a.logs]
    with_gains = a.lever_arm is not None
    cal = calibrate(imus if len(imus) > 1 else imus[0], tilt=a.tilt, gains=with_gains,
                    lever_arm=a.lever_arm, translation=a.translation)
    cal.save(a.output)
    print(cal)
    if not with_gains:
        print("suspension gains not estimated: they need the sensor's position relative to the body's "
              "pitch/roll centre (--lever-arm X Y Z, metres, ground frame); the filter keeps its defaults")
    print(f"wrote {a.output}")
    return 0


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="imu-ground", description="Ground plane normal (pitch and roll relative "
                                 "to the road) of a moving vehicle from raw IMU logs.")
    sub = ap.add_subparsers(dest="command", required=True)

    e = sub.add_parser("estimate", help="raw IMU log -> per-frame ground normals (CSV)")
    e.add_argument("log", help="IMU log: KITTI OXTS folder, kitti_imu100 CSV, CSV table, nuScenes "
                               "*_ms_imu.json, comma2k19 segment")
    e.add_argument("--format", help="log format (detected when omitted): kitti_oxts, kitti_imu100, table, "
                                    "nuscenes, comma2k19")
    e.add_argument("--method", default="filter", choices=ESTIMATE_METHODS)
    e.add_argument("--extrinsic", help="static sensor-to-ground extrinsic: shipped name (e.g. kitti_imu) or file")
    e.add_argument("--rate", type=float, default=10.0, help="frame rate, Hz (default 10)")
    e.add_argument("--policy", default="drop", choices=("drop", "sort", "strict"),
                   help="out-of-order timestamps: drop them (default), sort them, or fail")
    e.add_argument("--Q", type=float, help="process noise of the filter method, rad^2 per frame")
    e.add_argument("--R", type=float, help="measurement noise of the filter method")
    e.add_argument("-o", "--output", help="output CSV (default: <log>_ground.csv)")
    e.add_argument("--tum", help="also write the dynamic extrinsic as TUM poses (t x y z qx qy qz qw)")
    e.add_argument("--no-progress", action="store_true")
    e.set_defaults(func=_cmd_estimate)

    v = sub.add_parser("evaluate", help="compare methods on real and/or synthetic drives")
    v.add_argument("--real", help="folder of kitti_imu100 drives (*.csv.gz)")
    v.add_argument("--synthetic", type=int, default=0, help="number of synthetic drives per IMU grade")
    v.add_argument("--grades", default="nav,mems", help="IMU grades of the synthetic drives")
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--methods", help="comma-separated subset of the methods (default all)")
    v.add_argument("--per-drive", action="store_true", help="also print the per-drive table")
    v.add_argument("--csv", help="write per-drive results as CSV")
    v.add_argument("--markdown", help="write the summary table as Markdown")
    v.add_argument("--plots", help="write PNG plots into this folder")
    v.add_argument("--no-progress", action="store_true")
    v.set_defaults(func=_cmd_evaluate)

    s = sub.add_parser("simulate", help="write a synthetic drive (IMU CSV + truth CSV)")
    s.add_argument("-o", "--output", required=True, help="IMU CSV (t, wx, wy, wz, ax, ay, az)")
    s.add_argument("--truth", help="truth CSV (default: <output>_truth.csv)")
    s.add_argument("--duration", type=float, default=120.0, help="seconds")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--imu", default="nav", choices=("nav", "mems", "perfect"))
    s.add_argument("--plot", help="also write a picture of the road and body motion (PNG)")
    s.set_defaults(func=_cmd_simulate)

    c = sub.add_parser("calibrate", help="static extrinsic and suspension gains from drives of one platform")
    c.add_argument("logs", nargs="+", help="one or more IMU logs of the same mounting (several drives, e.g. a "
                                           "closed loop or both directions of a road, average out the grade)")
    c.add_argument("--format")
    c.add_argument("--policy", default="drop", choices=("drop", "sort", "strict"))
    c.add_argument("--tilt", default="auto", choices=("auto", "cruise", "standstill", "all"),
                   help="frames that define 'up': straight constant-speed driving (auto, if there is enough), "
                        "standstills, or all")
    c.add_argument("--lever-arm", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="sensor position relative to the body's pitch/roll centre, m (ground frame); "
                        "needed to estimate the suspension gains")
    c.add_argument("--translation", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="sensor origin in the ground frame, m (stored; not observable from an IMU)")
    c.add_argument("-o", "--output", required=True, help="calibration file (calib/ text format)")
    c.set_defaults(func=_cmd_calibrate)
    return ap


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of the ``imu-ground`` console script."""
    args = _parser().parse_args(argv)
    try:
        return args.func(args)
    except (FileNotFoundError, ValueError) as e:
        print(f"imu-ground {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
