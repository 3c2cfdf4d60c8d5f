"""``imu-ground calibrate LOG... -o CAR.txt``: static extrinsic and suspension gains of one platform."""
from __future__ import annotations

import argparse

from imu_ground.cli import _common as common
from imu_ground.datasets import read_imu
from imu_ground.errors import ImuGroundError
from imu_ground.filters import calibrate
from imu_ground.filters.calibration import TooLittleDataError
from imu_ground.pipeline.estimate import require_imu_log
from imu_ground.pipeline.output import atomic_path, check_output_path, check_run_paths

__all__ = ["register", "run"]


def register(sub) -> None:
    """Add the ``calibrate`` sub-command."""
    c = common.add_logs_command(
        sub, "calibrate", help="static extrinsic and suspension gains from drives of one platform",
        description="Estimate the sensor-to-ground extrinsic ('up' and 'forward' of the vehicle in the IMU's axes) "
                    "and, with --lever-arm, the suspension gains, from IMU logs of one mounting.",
        logs_metavar="LOG", logs_help="one or more IMU logs of the same mounting (several drives, e.g. a closed loop "
                                      "or both directions of a road, average out the grade)",
        output_metavar="FILE",
        output_help="calibration file to write (calib/ text format; pass it to 'estimate --extrinsic')")
    c.add_argument("--tilt", default="auto", choices=("auto", "cruise", "standstill", "all"),
                   help="frames that define 'up': straight constant-speed driving (auto, if there is enough), "
                        "standstills, or all")
    c.add_argument("--lever-arm", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="sensor position relative to the body's pitch/roll centre, m (ground frame); "
                        "needed to estimate the suspension gains")
    c.add_argument("--translation", type=float, nargs=3, metavar=("X", "Y", "Z"),
                   help="sensor origin in the ground frame, m (stored; not observable from an IMU)")
    common.add_reader_flags(c)
    c.set_defaults(func=run)


def run(a: argparse.Namespace) -> int:
    """Read every log (IMU logs only), calibrate, write the file atomically."""
    opts = common.reader_options(a)
    fmt = opts.pop("format", None)
    check_output_path(a.output, a.logs, kind="txt")
    check_run_paths([("-o", a.output)], common.input_paths(a, "logs"))
    imus = []
    for log in a.logs:
        require_imu_log(log, fmt, "'imu-ground calibrate'")
        with common.warnings_as_lines(log):
            imus.append(read_imu(log, format=fmt, **opts))
    with_gains = a.lever_arm is not None
    with common.warnings_as_lines(", ".join(a.logs)):
        try:
            cal = calibrate(imus if len(imus) > 1 else imus[0], tilt=a.tilt, gains=with_gains,
                            lever_arm=a.lever_arm, translation=a.translation)
        except TooLittleDataError as e:
            advice = {"gains": "calibrate on a longer drive (or several logs), or leave out --lever-arm to "
                               "calibrate the tilt alone",
                      "tilt": "calibrate on a longer drive (or several logs), or pass --tilt all"}[e.part]
            raise ImuGroundError(f"{', '.join(a.logs)}: {e.base}; {advice}") from None
        except ImuGroundError as e:                 # e.g. too short a log, no gravity: name the logs
            if hasattr(e, "cli_message"):
                raise
            raise ImuGroundError(f"{', '.join(a.logs)}: {e}") from None
    with atomic_path(a.output) as tmp:
        cal.save(tmp)
    common.say(str(cal))
    if not with_gains:
        common.say("suspension gains not estimated: they need the sensor's position relative to the body's pitch/roll "
            "centre (--lever-arm X Y Z, metres, ground frame); the filter keeps its defaults")
    common.say(f"wrote {a.output}")
    return 0
