"""Pipeline: a log in, a ground-normal table out; one log (:func:`estimate_log`) or a fleet (:func:`run_batch`).

- :mod:`imu_ground.pipeline.estimate`: :func:`estimate_log`, the library form of
  ``imu-ground estimate`` (read, preintegrate, run the method, summarise).
- :mod:`imu_ground.pipeline.output`: the one output table and its writers
  (``.csv``, ``.parquet``, ``.tum``, ``.bag``/``.mcap``), all atomic.
- :mod:`imu_ground.pipeline.batch`: :func:`run_batch`, many logs on Dask.

Names are imported lazily (numpy only at package import).
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    "EstimateResult": "imu_ground.pipeline.estimate",
    "OptionError": "imu_ground.pipeline.estimate",
    "estimate_log": "imu_ground.pipeline.estimate",
    "POSE_FORMATS": "imu_ground.pipeline.estimate",
    "OUTPUT_SUFFIXES": "imu_ground.pipeline.output",
    "check_output_path": "imu_ground.pipeline.output",
    "default_output_name": "imu_ground.pipeline.output",
    "result_table": "imu_ground.pipeline.output",
    "summarize_table": "imu_ground.pipeline.output",
    "write_output": "imu_ground.pipeline.output",
    "write_outputs": "imu_ground.pipeline.output",
    "atomic_path": "imu_ground.pipeline.output",
    "run_batch": "imu_ground.pipeline.batch",
    "expand_logs": "imu_ground.pipeline.batch",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
