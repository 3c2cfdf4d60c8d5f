"""The package version: its one owner (``pyproject.toml`` reads it from here, ``imu-ground --version`` prints it)."""
__version__ = "0.2.0"
