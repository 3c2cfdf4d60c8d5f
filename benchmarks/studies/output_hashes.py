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

A change that may move outputs in the last bits (a loop compiled instead of interpreted) keeps the
arrays too and compares them with a tolerance::

    python benchmarks/studies/output_hashes.py --arrays before.npz          # on the old code
    python benchmarks/studies/output_hashes.py --compare-arrays before.npz  # largest |difference| per field
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


def track_arrays(track, prefix: str) -> dict:
    """The numeric fields of a track as float arrays, keyed ``prefix/field`` (text fields left out)."""
    out = {}
    for f in dataclasses.fields(track):
        a = np.asarray(getattr(track, f.name))
        if a.dtype.kind in "fiub":
            out[f"{prefix}/{f.name}"] = a.astype(np.float64)
    return out


def compare_arrays(old: dict, new: dict) -> list[tuple[str, float]]:
    """``(key, largest |new - old|)`` per array of either side (inf: missing, other shape or NaN placement)."""
    rows = []
    for k in sorted(set(old) | set(new)):
        a, b = old.get(k), new.get(k)
        if a is None or b is None or a.shape != b.shape or not np.array_equal(np.isnan(a), np.isnan(b)):
            rows.append((k, float("inf")))
            continue
        ok = ~np.isnan(a)
        rows.append((k, float(np.max(np.abs(a[ok] - b[ok]), initial=0.0))))
    return rows


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
    p.add_argument("--arrays", help="write the numeric fields of every track to this .npz file")
    p.add_argument("--compare-arrays", help="a .npz file of --arrays to compare with (largest |difference| per field)")
    p.add_argument("--tolerance", type=float, default=1e-9,
                   help="--compare-arrays: largest difference allowed (the fields' own units; angles in deg)")
    p.add_argument("--configs", default=",".join(CONFIGS), help="comma-separated subset of " + ",".join(CONFIGS))
    a = p.parse_args(argv)
    hashes: dict = {"warm_start": _stream_hashes()}
    arrays: dict = {}
    for log in _logs():
        for cfg in a.configs.split(","):
            try:
                track = estimate_log(log, **CONFIGS[cfg]).track
                hashes[f"{log.name}:{cfg}"] = track_hashes(track)
                arrays.update(track_arrays(track, f"{log.name}:{cfg}"))
            except Exception as exc:        # an error is an output too
                hashes[f"{log.name}:{cfg}"] = {"error": f"{type(exc).__name__}: {exc}"}
        print(log.name, file=sys.stderr)
    if a.output:
        Path(a.output).write_text(json.dumps(hashes, indent=1, sort_keys=True))
    if a.arrays:
        np.savez_compressed(a.arrays, **arrays)
    if a.compare_arrays:
        with np.load(a.compare_arrays) as z:
            old_arrays = {k: z[k] for k in z.files}
        rows = compare_arrays(old_arrays, arrays)
        worst: dict = {}
        for k, d in rows:
            field = k.split("/")[-1]
            worst[field] = max(worst.get(field, 0.0), d)
        for field, d in sorted(worst.items()):
            print(f"{field:28s} {d:.3g}")
        bad = [(k, d) for k, d in rows if not d <= a.tolerance]
        for k, d in bad:
            print(f"beyond {a.tolerance:g}: {k} {d:.3g}")
        print(f"{len(rows)} arrays compared, {len(bad)} beyond {a.tolerance:g}")
        if bad:
            return 1
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
