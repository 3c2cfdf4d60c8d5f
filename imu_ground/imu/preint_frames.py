"""The batch preintegration's old import path: it lives in :mod:`imu_ground.imu.preintegration`."""
from imu_ground.imu.preintegration import (FrameDeltas as FrameDeltas, first_rate_boundary as first_rate_boundary,
                                           make_frame_times as make_frame_times, preintegrate as preintegrate,
                                           segment_frame_times as segment_frame_times)
