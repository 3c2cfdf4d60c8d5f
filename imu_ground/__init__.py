"""imu-ground: ground plane normal estimation from ego-motion and raw IMU logs."""
__version__ = "0.1.0"
__all__ = ["__version__"]
