r"""IMU errors of the simulator: white noise, bias random walk and turn-on bias per axis.

Presets (:data:`IMU_PRESETS`, one sigma per axis; white noise std at rate ``fs`` is
``density * sqrt(fs)``): ``"nav"``, a navigation-grade GPS/INS like KITTI's OXTS RT3003
(its datasheet); ``"mems"``, a consumer MEMS IMU of the Bosch BMI160 / InvenSense
MPU-6500 class (their datasheets); ``"perfect"``, no error. They are the sensor's own
errors: vibration of a holder or an engine is not in them (:meth:`ImuErrorModel.scaled`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from imu_ground.units import DEG, GRAVITY

__all__ = ["IMU_PRESETS", "ImuErrorModel", "imu_error_model", "imu_errors"]

_DEG_H = DEG / 3600.0                  # 1 deg/h in rad/s


@dataclass(frozen=True)
class ImuErrorModel:
    """Stochastic errors of a 6-axis IMU (same numbers on every axis, one sigma).

    Measurement ``y_k = true_k + b_k + n_k``: ``n_k`` white, std
    ``density * sqrt(rate)``; ``b_k = b_0 + random walk`` with increments of std
    ``bias_rw * sqrt(dt)``; ``b_0`` drawn once per drive, std ``turn_on``.

    Parameters
    ----------
    name : str
    gyro_noise_density, gyro_bias_rw, gyro_bias_turn_on : float
        rad/s/sqrt(Hz), rad/s^2/sqrt(Hz), rad/s.
    accel_noise_density, accel_bias_rw, accel_bias_turn_on : float
        m/s^2/sqrt(Hz), m/s^3/sqrt(Hz), m/s^2.
    """

    name: str
    gyro_noise_density: float
    gyro_bias_rw: float
    gyro_bias_turn_on: float
    accel_noise_density: float
    accel_bias_rw: float
    accel_bias_turn_on: float

    def gyro_noise_std(self, rate: float) -> float:
        """Std of the gyro white noise per sample at ``rate`` Hz, rad/s."""
        return self.gyro_noise_density * math.sqrt(rate)

    def accel_noise_std(self, rate: float) -> float:
        """Std of the accelerometer white noise per sample at ``rate`` Hz, m/s^2."""
        return self.accel_noise_density * math.sqrt(rate)

    def scaled(self, factor: float, name: str | None = None) -> ImuErrorModel:
        """The same model with every error multiplied by ``factor``."""
        errors = (factor * getattr(self, f.name) for f in fields(self)[1:])
        return ImuErrorModel(name or f"{self.name}x{factor:g}", *errors)


IMU_PRESETS: dict[str, ImuErrorModel] = {
    "nav": ImuErrorModel(
        name="nav",
        gyro_noise_density=0.0025 * DEG,             # 0.15 deg/sqrt(h)
        gyro_bias_rw=2.0 * _DEG_H / 10.0,            # 2 deg/h wander over 100 s
        gyro_bias_turn_on=10.0 * _DEG_H,
        accel_noise_density=8e-4,                    # ~80 ug/sqrt(Hz)
        accel_bias_rw=1e-5,                          # 1e-4 m/s^2 over 100 s
        accel_bias_turn_on=5e-3,
    ),
    "mems": ImuErrorModel(
        name="mems",
        gyro_noise_density=0.007 * DEG,              # BMI160 typ.
        gyro_bias_rw=10.0 * _DEG_H / 10.0,           # ~10 deg/h wander over 100 s
        gyro_bias_turn_on=1.0 * DEG,
        accel_noise_density=180e-6 * GRAVITY,        # 180 ug/sqrt(Hz)
        accel_bias_rw=1e-4,                          # 1e-3 m/s^2 over 100 s
        accel_bias_turn_on=0.2,                      # ~20 mg
    ),
    "perfect": ImuErrorModel("perfect", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
}


def imu_error_model(model: str | ImuErrorModel | None) -> ImuErrorModel:
    """An :class:`ImuErrorModel` from a preset name (:data:`IMU_PRESETS`; ``None``: ``"perfect"``) or a model."""
    if model is None:
        return IMU_PRESETS["perfect"]
    if isinstance(model, ImuErrorModel):
        return model
    try:
        return IMU_PRESETS[str(model).lower()]
    except KeyError:
        raise ValueError(f"unknown IMU preset {model!r}; choose one of {sorted(IMU_PRESETS)}"
                         " or pass an ImuErrorModel") from None


def imu_errors(model: ImuErrorModel, n: int, rate: float, seed: int):
    """One draw of the errors of ``n`` samples at ``rate`` Hz, from the fourth child of ``SeedSequence(seed)``.

    Returns
    -------
    bias_gyro, noise_gyro, bias_accel, noise_accel : ndarray (n, 3)
        rad/s and m/s^2, sensor frame.
    """
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[3])
    dt = 1.0 / rate
    out = []
    for dens, rw, on in ((model.gyro_noise_density, model.gyro_bias_rw, model.gyro_bias_turn_on),
                         (model.accel_noise_density, model.accel_bias_rw, model.accel_bias_turn_on)):
        b0 = on * rng.standard_normal(3)
        steps = rw * math.sqrt(dt) * rng.standard_normal((n, 3))
        steps[0] = 0.0
        bias = b0 + np.cumsum(steps, axis=0)
        noise = dens * math.sqrt(rate) * rng.standard_normal((n, 3))
        out += [bias, noise]
    return out
