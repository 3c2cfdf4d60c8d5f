"""Fingerprints of the estimates on every shared drive: a refactor that should change no output checks it here.

For every drive of ``../shared/data/kitti_imu100/drives.csv`` and the example fixture, and for
several configurations (the default, IMU only, online mount re-estimation, the invariant filter
and the paper's method), :func:`imu_ground.pipeline.estimate_log` runs and every field of its
track (all arrays, the 1-sigma, the status codes and reasons, the road) is hashed bit for bit,
one hash per field. A streaming pass over the fixture with a warm start at its middle (the state
through JSON into a new filter) is hashed beside the uninterrupted pass (the two hashes are equal: the warm
start continues bit for bit).

Usage::

    python benchmarks/studies/output_hashes.py -o before.json        # on the old code
    python benchmarks/studies/output_hashes.py --compare before.json # on the new: lists what differs
"""
from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
DATA = REPO.parent / "shared" / "data" / "kitti_imu100"
FIXTURE = REPO / "datasets" / "fixtures" / "example_drive.csv"
CONFIGS = {"auto": {}, "imu_only": {"speed": "none"}, "recal": {"recalibrate_online": True},
           "filter": {"method": "filter"}, "paper": {"method": "paper"}}


def _digest(value) -> str:
    a = np.asarray(value)
    h = hashlib.sha256(str((a.dtype, a.shape)).encode())
    if a.dtype == object:
        h.update("\x1f".join(map(str, a.ravel().tolist())).encode())
    else:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def track_hashes(track) -> dict:
    """One hash per field of a track (arrays bit for bit, strings as text)."""
    return {f.name: _digest(getattr(track, f.name)) for f in dataclasses.fields(track)}


def _logs() -> list[Path]:
    logs = [FIXTURE]
    index = DATA / "drives.csv"
    if index.exists():
        import pandas as pd
        logs += [DATA / f"{name}.csv.gz" for name in pd.read_csv(index)["drive"]]
    return logs


def _stream_hashes() -> dict:
    """The fixture frame by frame, uninterrupted and with a JSON warm start at the middle."""
    from imu_ground import SuspensionAwareFilter, imu_to_egomotion
    from imu_ground.datasets import read_imu
    frames = list(imu_to_egomotion(read_imu(FIXTURE), rate=10.0).frames())
    out = {}
    for name, kw, warm in (("stream", {}, True), ("stream_recal", {"recalibrate_online": True}, True),
                           ("stream_uninterrupted", {}, False)):
        f = SuspensionAwareFilter(**kw)
        rows = []
        for k, fr in enumerate(frames):
            if warm and k == len(frames) // 2:
                state = json.loads(json.dumps(f.state_dict()))
                f = SuspensionAwareFilter(**kw)
                f.load_state_dict(state)
            e = f.step(fr)
            rows.append([e.pitch, e.roll, e.pitch_std, e.roll_std, e.status_code, e.road_grade, e.road_bank,
                         e.road_grade_std, e.road_bank_std, *e.normal])
        out[name] = _digest(np.array(rows))
    return out


def main(argv=None) -> int:
    from imu_ground.pipeline import estimate_log
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-o", "--output", help="write the hashes to this JSON file")
    p.add_argument("--compare", help="a JSON file of hashes to compare with")
    p.add_argument("--configs", default=",".join(CONFIGS), help="comma-separated subset of " + ",".join(CONFIGS))
    a = p.parse_args(argv)
    hashes: dict = {"warm_start": _stream_hashes()}
    for log in _logs():
        for cfg in a.configs.split(","):
            try:
                track = estimate_log(log, **CONFIGS[cfg]).track
                hashes[f"{log.name}:{cfg}"] = track_hashes(track)
            except Exception as exc:        # an error is an output too
                hashes[f"{log.name}:{cfg}"] = {"error": f"{type(exc).__name__}: {exc}"}
        print(log.name, file=sys.stderr)
    if a.output:
        Path(a.output).write_text(json.dumps(hashes, indent=1, sort_keys=True))
    if a.compare:
        old = json.loads(Path(a.compare).read_text())
        diff = [(k, f) for k in sorted(set(old) | set(hashes)) for f in sorted(set(old.get(k, {})) | set(hashes.get(k, {})))
                if old.get(k, {}).get(f) != hashes.get(k, {}).get(f)]
        for k, f in diff:
            print(f"differs: {k} {f}")
        print(f"{len(hashes)} runs compared, {len(diff)} fields differ")
        return 1 if diff else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
