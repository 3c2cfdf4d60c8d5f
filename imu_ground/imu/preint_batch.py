"""The batch preintegration's old import path: :func:`~imu_ground.imu.preint_frames.preintegrate` lives with the frames."""
from imu_ground.imu.preint_frames import preintegrate as preintegrate
