"""The shipped synthetic example drive in ``datasets/fixtures/``, made by the simulator, and the script that regenerates it.

The files are a pure function of the seed below, so running this again gives the
same numbers (and, on the same platform and library versions, the same bytes)::

    python -m imu_ground.evaluation.simulate.fixtures            # into the readers' fixtures folder
    python -m imu_ground.evaluation.simulate.fixtures --out /tmp/check

Files
-----
``example_drive.csv``
    60 s of a navigation-grade IMU (``"nav"``) at 100 Hz: ``t,wx,wy,wz,ax,ay,az`` (s, rad/s,
    m/s^2), sensor aligned with the body (FLU), ``t_gs = (0.3, 0, 0.9)`` m.
``example_drive_truth.csv``
    Ground truth at 10 Hz (:meth:`~imu_ground.evaluation.simulate.SimResult.truth_table`).
``example_drive_meta.json``
    Seed, IMU error model, extrinsic and every simulation parameter.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

import imu_ground.datasets
from imu_ground.evaluation.simulate import RoadParams, SimResult, SpeedParams, simulate

__all__ = ["EXAMPLE_NAME", "EXAMPLE_SEED", "FIXTURES", "FLOAT_FORMAT", "example_drive", "main", "write_example"]

#: The readers' fixtures folder (``datasets/fixtures`` in a checkout), where the example drive ships.
FIXTURES = Path(imu_ground.datasets.__file__).resolve().parent / "fixtures"
#: The example drive's file names (``NAME.csv``, ``NAME_truth.csv``, ``NAME_meta.json``) and its seed.
EXAMPLE_NAME = "example_drive"
EXAMPLE_SEED = 2024
#: How the CSV files write a number.
FLOAT_FORMAT = "%.10g"


def example_drive() -> SimResult:
    """The example drive (deterministic)."""
    return simulate(60.0, seed=EXAMPLE_SEED, imu="nav", imu_rate=100.0, frame_rate=10.0,
                    road=RoadParams(roughness="B"), speed=SpeedParams(style="mixed"),
                    R_gs=None, t_gs=(0.3, 0.0, 0.9), name=EXAMPLE_NAME)


def _meta(result: SimResult) -> dict:
    p = result.params
    return {
        "name": result.name,
        "generator": "python -m imu_ground.evaluation.simulate.fixtures",
        "seed": result.seed,
        "duration_s": p["duration"],
        "imu_rate_hz": p["imu_rate"],
        "frame_rate_hz": p["frame_rate"],
        "imu_frame": result.imu.frame,
        "imu_columns": {"t": "s", "wx,wy,wz": "rad/s, sensor frame",
                        "ax,ay,az": "m/s^2, specific force, sensor frame"},
        "imu_model": asdict(result.imu_model),
        "R_gs": result.R_gs.tolist(),
        "t_gs": result.t_gs.tolist(),
        "road": asdict(p["road"]),
        "vehicle": asdict(p["vehicle"]),
        "speed": asdict(p["speed"]),
        "conventions": "see imu_ground.evaluation.simulate: world z up, body FLU, R = Rz(yaw) Ry(pitch) Rx(roll), "
                       "pitch > 0 nose down, roll > 0 left side up; pitch/roll are body relative to road; "
                       "normal_* in the sensor frame; q* is world <- sensor (w, x, y, z)",
    }


def write_example(out_dir: str | Path = FIXTURES) -> dict[str, Path]:
    """Write the three example files into ``out_dir``; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = example_drive()
    paths = {"imu": out / f"{EXAMPLE_NAME}.csv",
             "truth": out / f"{EXAMPLE_NAME}_truth.csv",
             "meta": out / f"{EXAMPLE_NAME}_meta.json"}
    result.to_csv(paths["imu"], paths["truth"], float_format=FLOAT_FORMAT)
    paths["meta"].write_text(json.dumps(_meta(result), indent=2) + "\n")
    return paths


def main(argv: list[str] | None = None) -> int:
    """Write the example drive (``--out DIR``, default :data:`FIXTURES`) and print its files; returns 0."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(FIXTURES), help="output folder (default: %(default)s)")
    args = parser.parse_args(argv)
    for kind, path in write_example(args.out).items():
        print(f"{kind:5s} {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
