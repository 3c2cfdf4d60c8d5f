"""The batch preintegration's old import path: :func:`~imu_ground.imu.preintegration.preintegrate`."""
from imu_ground.imu.preintegration import preintegrate as preintegrate
