"""The walks of issue 37: which of the package's files and functions one offline run and one live IMU sample pass through.

    python benchmarks/studies/walks.py

``estimate_log:speed``: ``estimate_log`` of a shared KITTI drive (the first of ``kitti_imu100/drives.csv``; its
INS speed, ``speed="auto"``), every package function called at least once, grouped by file. ``one live sample``: a
:class:`~imu_ground.StreamingEstimator` fed that log's first 30 s (samples and speed), then the next ``push_imu``
that completes a frame and the one after it (within a frame), the functions each calls. Counted with :func:`sys.setprofile` (Python-level calls; a compiled body counts as the one call into it).
"""
from __future__ import annotations

import sys
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data" / "kitti_imu100"


def _package_file(path: str) -> str | None:
    p = Path(path)
    for root in ("imu_ground", "datasets", "calib"):
        if root in p.parts:
            parts = p.parts[p.parts.index(root):]
            return "/".join(parts)
    return None


def _trace(run) -> dict[str, set[str]]:
    """``file -> {function}`` of the package's Python calls while ``run()`` runs."""
    seen: dict[str, set[str]] = defaultdict(set)

    def prof(frame, event, arg):
        if event == "call":
            f = _package_file(frame.f_code.co_filename)
            if f is not None:
                seen[f].add(frame.f_code.co_name)
    sys.setprofile(prof)
    try:
        run()
    finally:
        sys.setprofile(None)
    return seen


def _rows(walk: str, seen: dict[str, set[str]]) -> list[dict]:
    out = [dict(table="walks", walk=walk, file=f, functions=len(fn), names=", ".join(sorted(fn))[:160])
           for f, fn in sorted(seen.items())]
    out.append(dict(table="walks", walk=walk, file=f"total: {len(seen)} files",
                    functions=sum(len(v) for v in seen.values())))
    return out


def rows() -> list[dict]:
    """The walks as rows (``table = walks``)."""
    import pandas as pd

    from imu_ground import StreamingEstimator
    from imu_ground.pipeline import estimate_log
    index = DATA / "drives.csv"
    if not index.is_file():
        return [dict(table="walks", walk=f"skipped: {index} not found")]
    log_path = DATA / f"{pd.read_csv(index)['drive'].iloc[0]}.csv.gz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        estimate_log(log_path)                             # imports and compilations out of the walk
        out = _rows("estimate_log:speed", _trace(lambda: estimate_log(log_path)))
        log = pd.read_csv(log_path)
        t = log["t"].to_numpy(float)
        gyro = log[["wx", "wy", "wz"]].to_numpy(float)
        acc = log[["ax", "ay", "az"]].to_numpy(float)
        speed = np.hypot(log["ve"].to_numpy(float), log["vn"].to_numpy(float))
        est = StreamingEstimator()
        k = 0

        def push() -> list:
            est.push_speed(t[k], speed[k])
            return est.push_imu(t[k], gyro[k], acc[k])
        while t[k] < t[0] + 30.0:
            push()
            k += 1
        frames: list = []
        while not frames:                                  # the walk of the first push that completes a frame
            seen = _trace(lambda: frames.extend(push()))
            k += 1
        out += _rows("one live sample (completes a frame)", seen)
        out += _rows("one live sample (within a frame)", _trace(push))
    return out


def main() -> int:
    import pandas as pd
    print(pd.DataFrame(rows()).drop(columns="table").to_string(index=False, max_colwidth=100))
    return 0


if __name__ == "__main__":
    sys.exit(main())
