"""estimate_log frees the IMU samples before the filter runs: the whole job's peak memory is then the read's, not
the read's plus the filter's (benchmarks/bench_job.py)."""
import gc
import weakref
from pathlib import Path

import imu_ground.pipeline.estimate as estimate_mod

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


def test_the_samples_are_freed_before_the_filter(monkeypatch):
    """Failed before: estimate_log held the ImuData (every sample and its columns) while the filter ran."""
    seen: dict = {}
    read, run = estimate_mod._read_log, estimate_mod._run_method

    def read_log(*a, **k):
        imu, info = read(*a, **k)
        seen["imu"] = weakref.ref(imu)
        return imu, info

    def run_method(*a, **k):
        gc.collect()
        seen["alive"] = seen["imu"]() is not None
        return run(*a, **k)

    monkeypatch.setattr(estimate_mod, "_read_log", read_log)
    monkeypatch.setattr(estimate_mod, "_run_method", run_method)
    track = estimate_mod.estimate_log(EXAMPLE).track
    assert seen["alive"] is False
    assert len(track) > 0
