"""The live front end, in the order a raw sample passes it: clock, standstill and gyro bias, preintegration, speed.

- :mod:`~imu_ground.imu.live.sample_clock` (:class:`SampleClock`): raw stamps to a strictly increasing clock,
  bad samples, dropouts and restarts told apart;
- :mod:`~imu_ground.imu.live.causal_standstill`: standstills and the gyro bias from the past alone;
- :mod:`~imu_ground.imu.live.preint_stream` (:class:`StreamingPreintegrator`): samples to frames, one compiled
  step a sample, the same body the batch preintegration's deltas run;
- :mod:`~imu_ground.imu.live.speed_buffer` (:class:`SpeedBuffer`): the measured speed over each frame.

:class:`~imu_ground.pipeline.streaming.StreamingEstimator` drives them, sample by sample, and its whole-log run
(``estimate --causal``) drives the same objects over a log.
"""
from imu_ground._lazy import lazy_exports

_EXPORTS = {
    ".sample_clock": "SampleClock",
    ".causal_standstill": "CausalGyroBias StandstillBlocks",
    ".preint_stream": "StreamingPreintegrator",
    ".speed_buffer": "SpeedBuffer",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
