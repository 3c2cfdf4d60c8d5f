"""What the per-frame ground plane does for a camera: ground-point range and lane-width errors on the synthetic suite.

For every drive of ``simulate_suite(n, seed=0, grades=('nav', 'mems'))`` (the suite of
the accuracy tables), a camera with KITTI's camera 2 intrinsics, height and mount
looks ahead; the true plane comes from the simulator's body pitch and roll relative to
the road, the static one from the extrinsic alone, the dynamic one from the default
method's estimate (:func:`imu_ground.filters.methods.default_method`). For the road
point straight ahead at 20, 40 and 60 m and the lane lines 1.75 m either side, the
point is projected into the image through the true plane and back through each
believed plane (:func:`imu_ground.evaluation.ground_effect.drive_ground_errors`);
the table gives the mean over drives of the per-drive mean absolute error over the
moving frames (above 3 m/s), m. The truth rows are the check (zero).

Run ``python benchmarks/bench_ground_effect.py`` (or through ``make_results.py``).
"""
from __future__ import annotations

import sys
import warnings

import numpy as np

DISTANCES = (20.0, 40.0, 60.0)


def rows(n: int = 10) -> list[dict]:
    """One row per IMU grade and plane (static, dynamic, truth), plus the dynamic plane's cut at 40 m."""
    from imu_ground.evaluation.ground_effect import drive_ground_errors
    from imu_ground.evaluation.runner import run_method
    from imu_ground.evaluation.runner import synthetic_drives
    from imu_ground.filters.methods import default_method
    from imu_ground.perception import load_camera
    camera = load_camera("kitti_cam2")
    method = default_method(True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        drives = synthetic_drives(n, seed=0, grades=("nav", "mems"), progress=False)
    per: dict[tuple[str, str], list[dict]] = {}
    for d in drives:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            track, _ = run_method(method, d)
        use = d.truth["evaluate"].to_numpy(bool) & np.isfinite(track.pitch)
        errs = drive_ground_errors(camera, track.pitch[use], track.roll[use], d.truth["pitch"].to_numpy()[use],
                                   d.truth["roll"].to_numpy()[use], DISTANCES)
        for plane, e in errs.items():
            row = {}
            for j, x in enumerate(DISTANCES):
                row[f"range_{x:.0f}m"] = float(np.nanmean(np.abs(e["range"][:, j])))
                row[f"lane_{x:.0f}m"] = float(np.nanmean(np.abs(e["lane_width"][:, j])))
            per.setdefault((d.grade, plane), []).append(row)
    out = []
    for (grade, plane), rs in per.items():
        row = {"grade": grade, "plane": plane if plane != "dynamic" else f"dynamic ({method})", "drives": len(rs)}
        for key in rs[0]:
            row[key + "_m"] = float(np.mean([r[key] for r in rs]))
        out.append(row)
    for grade in dict.fromkeys(g for g, _ in per):
        static = np.mean([r["range_40m"] for r in per[(grade, "static")]])
        dynamic = np.mean([r["range_40m"] for r in per[(grade, "dynamic")]])
        out.append({"grade": grade, "plane": "dynamic cut of the static range error at 40 m",
                    "cut_percent": float(100.0 * (1.0 - dynamic / static)),
                    "target_met": bool(dynamic <= 0.5 * static)})
    return out


if __name__ == "__main__":
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))
    from make_results import markdown
    print(markdown(rows(int(sys.argv[1]) if len(sys.argv) > 1 else 10)))
