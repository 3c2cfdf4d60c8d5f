"""The live front end, in the order a raw sample passes it: :class:`SampleClock` (raw stamps to a strictly
increasing clock), :mod:`~imu_ground.imu.live.causal_standstill` (standstills and gyro bias from the past alone),
:class:`StreamingPreintegrator` (samples to frames) and :class:`SpeedBuffer` (the measured speed over each
frame), driven by :class:`~imu_ground.pipeline.streaming.StreamingEstimator`.
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    ".sample_clock": "SampleClock",
    ".causal_standstill": "CausalGyroBias StandstillBlocks",
    ".preint_stream": "StreamingPreintegrator",
    ".speed_buffer": "SpeedBuffer",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
