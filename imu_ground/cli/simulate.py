"""``imu-ground simulate -o DRIVE.csv``: a synthetic drive (IMU CSV) and its exact truth (CSV)."""
from __future__ import annotations

from pathlib import Path

import argparse

from imu_ground.cli._common import nonnegative_int, positive_float, say
from imu_ground.evaluation.plots import plot_simulation
from imu_ground.evaluation.simulate import simulate
from imu_ground.evaluation.simulate.drive import MAX_DURATION_S, MAX_IMU_RATE_HZ, MAX_IMU_SAMPLES
from imu_ground.pipeline.output import atomic_path, check_output_path, check_run_paths

__all__ = ["FRAME_RATE", "register", "run"]

#: Frame rate of the truth file, Hz (the IMU rate is a whole multiple of it).
FRAME_RATE = 10.0


def register(sub) -> None:
    """Add the ``simulate`` sub-command."""
    s = sub.add_parser("simulate", help="write a synthetic drive (IMU CSV + truth CSV)",
                       description="Simulate a drive on a random road (ISO 8608 roughness, grades, curves, stops) "
                                   "with suspension and IMU errors; write the IMU log and the exact truth.")
    s.add_argument("-o", "--output", required=True, metavar="FILE",
                   help="IMU CSV to write (columns t s, wx wy wz rad/s, ax ay az m/s^2)")
    s.add_argument("--truth", metavar="FILE",
                   help="truth CSV (default <output>_truth.csv); angles in degrees, named *_deg (pitch_deg, "
                        "roll_deg: body relative to road, same signs as 'estimate'), rates *_deg_s")
    s.add_argument("--duration", type=positive_float, default=120.0, metavar="S",
                   help=f"seconds (default 120), {1 / FRAME_RATE:g} to {MAX_DURATION_S:g}; with --rate at most "
                        f"{MAX_IMU_SAMPLES} IMU samples (an hour at 100 Hz)")
    s.add_argument("--rate", type=positive_float, default=100.0, metavar="HZ",
                   help=f"IMU sample rate, Hz (default 100, at most {MAX_IMU_RATE_HZ:g}); a whole multiple of the "
                        "truth's 10 Hz frame rate, e.g. 400")
    s.add_argument("--seed", type=nonnegative_int, default=0, help="random seed, a whole number >= 0 (default 0)")
    s.add_argument("--imu", default="nav", choices=("nav", "mems", "perfect"),
                   help="IMU error grade: nav (navigation grade, default), mems, perfect (no errors)")
    s.add_argument("--plot", metavar="PNG", help="also write a picture of the road and body motion (needs matplotlib)")
    s.set_defaults(func=run)


def run(a: argparse.Namespace) -> int:
    """Simulate and write both files atomically (both or neither)."""
    out = Path(a.output)
    truth = Path(a.truth) if a.truth else out.with_name(out.name.split(".")[0] + "_truth.csv")
    check_output_path(out, option="-o", kind="csv")
    check_output_path(truth, option="--truth", kind="csv")
    if a.plot:
        check_output_path(a.plot, option="--plot", kind="png")
    check_run_paths([("-o", out), ("--truth" if a.truth else "-o (its _truth.csv)", truth), ("--plot", a.plot)])
    sim = simulate(a.duration, seed=a.seed, imu=a.imu, imu_rate=a.rate, frame_rate=FRAME_RATE)
    with atomic_path(out) as tmp_imu, atomic_path(truth) as tmp_truth:
        sim.to_csv(tmp_imu, tmp_truth)
    say(f"simulated {a.duration:g} s at {a.rate:g} Hz ({a.imu} IMU, seed {a.seed}): wrote {out} and {truth}")
    if a.plot:
        say(f"wrote {plot_simulation(sim, Path(a.plot))}")
    return 0
