"""``python -m imu_ground``: the ``imu-ground`` command."""
from imu_ground.cli import main

if __name__ == "__main__":          # guarded: Dask's worker processes re-import the main module
    raise SystemExit(main())
