"""Pipeline: a log in, a ground-normal table out; one log (:func:`estimate_log`) or a fleet (:func:`run_batch`).

- :mod:`imu_ground.pipeline.estimate`: :func:`estimate_log`, the library form of
  ``imu-ground estimate`` (read, preintegrate, run the method, summarise).
- :mod:`imu_ground.pipeline.output`: the one output table and its writers
  (``.csv``, ``.parquet``, ``.tum``, ``.bag``/``.mcap``), all atomic.
- :mod:`imu_ground.pipeline.batch`: :func:`run_batch`, many logs on Dask.
- :mod:`imu_ground.pipeline.input_checks`: option errors, the gravity-direction check of
  a log against its extrinsic, the options record an output keeps.
- :mod:`imu_ground.pipeline.streaming`: :class:`StreamingEstimator`, live: raw samples and speed in,
  per-frame estimates out, causal; :func:`causal_track`, the same object fed a whole log (``causal=True``).
- :mod:`imu_ground.pipeline.plot`: :func:`plot_estimate`, the picture of one estimate
  (``estimate --plot``): pitch and roll with their 1-sigma, the status, the speed.
- :mod:`imu_ground.pipeline.planes`: with a camera, the plane columns and the KITTI
  object ``planes`` files (:func:`write_kitti_planes`).

Names are imported lazily (numpy only at package import).
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    ".estimate": "EstimateResult OptionError estimate_log POSE_FORMATS",
    ".output": ("OUTPUT_SUFFIXES check_output_path default_output_name result_table "
                "track_table summarize_table write_output write_outputs atomic_path"),
    ".batch": "run_batch expand_logs",
    ".planes": "write_kitti_planes read_kitti_planes",
    ".plot": "PLOT_SUFFIXES estimate_figure plot_estimate",
    ".streaming": "StreamingEstimator FrameEstimate causal_track replay",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
