"""``python -m imu_ground``: the ``imu-ground`` command."""
from imu_ground.cli import main

raise SystemExit(main())
