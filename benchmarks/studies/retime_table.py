"""Timestamp policy ``drop`` (before) against ``retime`` (after) on the shared real drives.

Run: ``python benchmarks/studies/retime_table.py [--data ../shared/data]``.

For each of the 33 shared kitti_imu100 drives and the KITTI raw OXTS folder,
read with each policy, as the evaluation loads a real drive
(:func:`imu_ground.evaluation.drives.load_real_drive`: ego-motion at the default
frame rate, the pitch-relative-to-road reference and its check), and run the
suspension-aware filter (the ``suspension`` method, streaming). Printed per drive
and policy: samples dropped, frames flagged invalid, the retiming's max and RMS
shift and the dropouts kept as gaps, and the mean absolute pitch error (deg)
against the reference (drive mean removed) where the reference is valid: over
each policy's own valid frames, and over the frames valid under both.
:func:`rows` returns the table for ``benchmarks/make_results.py``.
"""
from __future__ import annotations

import argparse
import os
import warnings
from pathlib import Path

import numpy as np

__all__ = ["POLICIES", "drive_paths", "main", "measure", "rows"]

REPO = Path(__file__).resolve().parents[2]
SHARED = Path(os.environ.get("IMU_GROUND_SHARED_DATA", REPO.parent / "shared" / "data"))
POLICIES = ("drop", "retime")


def drive_paths(data: Path) -> list[Path]:
    """The kitti_imu100 drives and the complete KITTI raw OXTS drive folders under ``data``."""
    def complete(p: Path) -> bool:
        ts = p / "oxts" / "timestamps.txt"
        return ts.is_file() and len(ts.read_text().split()) // 2 == len(list((p / "oxts" / "data").glob("*.txt")))
    raw = sorted(p for p in (data / "kitti_raw").glob("*/*_sync") if complete(p))
    return sorted((data / "kitti_imu100").glob("*.csv.gz")) + raw


def measure(path: Path, policy: str) -> dict[str, object]:
    """One drive read with ``policy``: dropped, invalid frames, shifts, gaps, pitch error."""
    from imu_ground.datasets import read_imu

    from imu_ground.evaluation.metrics import evaluate_drive
    from imu_ground.evaluation.reference import check_reference, pitch_reference
    from imu_ground.filters import Extrinsic
    from imu_ground.filters.methods import METHODS
    from imu_ground.imu import imu_to_egomotion

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        imu = read_imu(path, policy=policy)
        rep = imu.meta["validation"]
        em = imu_to_egomotion(imu)
        out: dict[str, object] = {
            "drive": path.name.split(".")[0], "policy": policy, "samples": rep.n_in, "dropped": rep.n_dropped,
            "frames": len(em), "invalid": int(np.count_nonzero(~np.asarray(em.valid))),
            "shift_max": rep.retime_shift_max, "shift_rms": rep.retime_shift_rms,
            "gaps": rep.n_gaps, "pitch_err": float("nan"), "ref_valid": False}
        try:
            df = imu.to_dataframe()
            ref = pitch_reference(df, times=em.t)
            check = check_reference(df, ref)
        except (KeyError, ValueError) as e:  # a folder without the reference's signals
            out["ref_note"] = str(e)
            return out
        track = METHODS["suspension"].factory(extrinsic=Extrinsic()).run(em)
        mask = ref.valid & np.asarray(em.valid)
        res = evaluate_drive(track.pitch, ref.pitch_rel_road, mask=mask, remove_mean=True)
    out["ref_valid"] = bool(check.valid)
    out["pitch_err"] = float(res["pitch"]["mean"]) if check.valid else float("nan")  # deg
    out["arrays"] = (np.asarray(track.pitch), np.asarray(ref.pitch_rel_road), mask)
    return out


def _common_error(before: dict, after: dict) -> tuple[float, float]:
    """Pitch errors (deg) of both policies on the frames evaluated under both."""
    from imu_ground.evaluation.metrics import evaluate_drive
    if "arrays" not in before or "arrays" not in after or not before["ref_valid"]:
        return float("nan"), float("nan")
    n = min(len(before["arrays"][0]), len(after["arrays"][0]))
    both = before["arrays"][2][:n] & after["arrays"][2][:n]
    return tuple(float(evaluate_drive(m["arrays"][0][:n], m["arrays"][1][:n], mask=both,
                                      remove_mean=True)["pitch"]["mean"]) for m in (before, after))


def rows(data: Path = SHARED) -> list[dict[str, object]]:
    """Per drive: the ``drop`` and ``retime`` figures side by side."""
    table = []
    for path in drive_paths(data):
        before, after = (measure(path, p) for p in POLICIES)
        common = _common_error(before, after)
        table.append({"drive": before["drive"], "samples": before["samples"],
                      "common drop": common[0], "common retime": common[1],
                      **{f"{k} {p}": m[k] for p, m in zip(POLICIES, (before, after), strict=True)
                         for k in ("dropped", "invalid", "gaps", "pitch_err")},
                      "shift_max": after["shift_max"], "shift_rms": after["shift_rms"],
                      "ref_valid": before["ref_valid"]})
    return table


def main(argv: list[str] | None = None) -> None:
    """Print the before/after table and the totals."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=SHARED)
    args = ap.parse_args(argv)
    table = rows(args.data)
    head = ("| drive | samples | dropped drop / retime | invalid frames drop / retime | gaps drop / retime "
            "| max / RMS shift (s) | pitch error (deg) drop / retime | same frames drop / retime |")
    print(head)
    print("|" + "---|" * 8)
    for r in table:
        err = ("n/a (reference not valid) | n/a" if not r["ref_valid"] else
               f"{r['pitch_err drop']:.4f} / {r['pitch_err retime']:.4f} | "
               f"{r['common drop']:.4f} / {r['common retime']:.4f}")
        print(f"| {r['drive']} | {r['samples']} | {r['dropped drop']} / {r['dropped retime']} | "
              f"{r['invalid drop']} / {r['invalid retime']} | {r['gaps drop']} / {r['gaps retime']} | "
              f"{r['shift_max']:.3f} / {r['shift_rms']:.4f} | {err} |")
    ok = [r for r in table if r["ref_valid"]]
    tot = {k: sum(int(r[k]) for r in table) for k in ("dropped drop", "dropped retime", "invalid drop",
                                                     "invalid retime")}
    e_b = np.mean([r["pitch_err drop"] for r in ok]) if ok else float("nan")
    e_a = np.mean([r["pitch_err retime"] for r in ok]) if ok else float("nan")
    worse = max((r["pitch_err retime"] - r["pitch_err drop"] for r in ok), default=float("nan"))
    c_b = np.mean([r["common drop"] for r in ok]) if ok else float("nan")
    c_a = np.mean([r["common retime"] for r in ok]) if ok else float("nan")
    worse_c = max((r["common retime"] - r["common drop"] for r in ok), default=float("nan"))
    print(f"| mean ({len(table)} logs, {len(ok)} with a valid reference) | | {tot['dropped drop']} / "
          f"{tot['dropped retime']} | {tot['invalid drop']} / {tot['invalid retime']} | | | "
          f"{e_b:.4f} / {e_a:.4f} (worst drive {worse:+.4f}) | {c_b:.4f} / {c_a:.4f} (worst drive {worse_c:+.4f}) |")


if __name__ == "__main__":
    main()
