"""Parameters of IMU preintegration (:class:`PreintegrationParams`): one value type for the noise, the bias the
deltas are integrated with, gravity and the interval rules, as GTSAM's ``PreintegrationParams`` plus
``imuBias::ConstantBias``; the batch, the streaming preintegrator and the measurement all take one.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from imu_ground.units import GRAVITY

__all__ = ["Hold", "OnGap", "ParamsView", "PreintegrationParams", "gap_message"]

Hold = Literal["midpoint", "left"]
OnGap = Literal["raise", "flag"]


def _vec3(x: Any, name: str) -> tuple[float, float, float]:
    try:
        vals = [float(v) for v in (x.tolist() if hasattr(x, "tolist") else x)]
    except TypeError:
        vals = []
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"{name} must be 3 finite numbers, got {x!r}")
    return vals[0], vals[1], vals[2]


@dataclass(frozen=True)
class PreintegrationParams:
    """Noise, bias, gravity and interval rules of a preintegration (immutable).

    Parameters
    ----------
    bias_gyro, bias_accel : sequence of 3 floats
        Biases subtracted from every rate (rad/s) and specific force (m/s^2), body frame: the linearisation
        point of the bias Jacobians.
    gyro_noise_density, accel_noise_density : float
        White noise, rad/s/sqrt(Hz) and m/s^2/sqrt(Hz), the same on all axes
        (:mod:`imu_ground.imu.preintegration`).
    gravity : float
        Magnitude of gravity, m/s^2, for :meth:`PreintegratedImu.predict` and dead reckoning
        (``g_world = [0, 0, -gravity]``); the deltas never contain gravity.
    hold : {"midpoint", "left"}
        How a sample is held over its interval (:mod:`imu_ground.imu.preintegration`).
    max_gap : float
        Sample intervals longer than this, s, are timestamp gaps.
    on_gap : {"raise", "flag"}
        A gap inside a frame raises ValueError, or is integrated through and the frame flagged invalid.
    snap_tol : float
        A frame boundary within this of a sample, s, is placed on the sample.
    uncertainty : bool
        Propagate the 9x9 covariance and the bias Jacobians (default); False: the deltas only.
    """

    bias_gyro: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bias_accel: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_noise_density: float = 0.0
    accel_noise_density: float = 0.0
    gravity: float = GRAVITY
    hold: Hold = "midpoint"
    max_gap: float = 0.1
    on_gap: OnGap = "raise"
    snap_tol: float = 1e-9
    uncertainty: bool = True

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "bias_gyro", _vec3(self.bias_gyro, "bias_gyro"))
        set_(self, "bias_accel", _vec3(self.bias_accel, "bias_accel"))
        for name in ("gyro_noise_density", "accel_noise_density", "gravity", "max_gap", "snap_tol"):
            value = float(getattr(self, name))
            if not value >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
            set_(self, name, value)
        if self.hold not in ("midpoint", "left"):
            raise ValueError(f"hold must be 'midpoint' or 'left', got {self.hold!r}")
        if self.on_gap not in ("raise", "flag"):
            raise ValueError(f"on_gap must be 'raise' or 'flag', got {self.on_gap!r}")
        set_(self, "uncertainty", bool(self.uncertainty))

    @classmethod
    def coerce(cls, params: PreintegrationParams | None = None, **options: Any) -> PreintegrationParams:
        """``params`` (default: the defaults) with the given fields (``None`` ignored) replaced.

        Raises
        ------
        TypeError
            An option that is not a field (the message lists the fields).
        """
        base = cls() if params is None else params
        if not isinstance(base, cls):
            raise TypeError(f"params must be a PreintegrationParams, got {type(params).__name__}")
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(options) - fields)
        if unknown:
            raise TypeError(f"unknown preintegration option(s) {unknown}; the options are {sorted(fields)}")
        changes = {k: v for k, v in options.items() if v is not None}
        return dataclasses.replace(base, **changes) if changes else base

    @property
    def bias(self) -> tuple[float, ...]:
        """``(bg_x, bg_y, bg_z, ba_x, ba_y, ba_z)``: rad/s and m/s^2, body frame."""
        return self.bias_gyro + self.bias_accel

    @property
    def noise(self) -> tuple[float, float]:
        """``(q_g, q_a)``: the squared noise densities, for the scalar kernel."""
        return self.gyro_noise_density ** 2, self.accel_noise_density ** 2

    def same_model(self, other: PreintegrationParams) -> bool:
        """Equal biases and noise densities (what composing two measurements needs)."""
        return (self.bias_gyro == other.bias_gyro and self.bias_accel == other.bias_accel
                and self.gyro_noise_density == other.gyro_noise_density
                and self.accel_noise_density == other.accel_noise_density)


class ParamsView:
    """Read-only views of ``self.params`` under their old attribute names (a mixin)."""

    __slots__ = ()
    params: PreintegrationParams

    bias_gyro = property(lambda self: np.array(self.params.bias_gyro),
                         doc="Gyro bias the deltas were integrated with, rad/s, body frame, shape (3,).")
    bias_accel = property(lambda self: np.array(self.params.bias_accel),
                          doc="Accelerometer bias the deltas were integrated with, m/s^2, body frame, shape (3,).")
    gyro_noise_density = property(lambda self: self.params.gyro_noise_density,
                                  doc="Gyro white noise used for the covariance, rad/s/sqrt(Hz).")
    accel_noise_density = property(lambda self: self.params.accel_noise_density,
                                   doc="Accelerometer white noise used for the covariance, m/s^2/sqrt(Hz).")
    hold = property(lambda self: self.params.hold, doc="``'midpoint'`` or ``'left'`` (:mod:`imu_ground.imu.preintegration`).")


def gap_message(t0: float, length: float, max_gap: float) -> str:
    """The ValueError text for a timestamp gap of ``length`` s starting at ``t0`` s."""
    return (f"IMU timestamp gap of {length:.6g} s at t = {t0:.6f} s (from {t0:.6f} s to "
            f"{t0 + length:.6f} s) exceeds max_gap = {max_gap:g} s; refusing to preintegrate "
            f"across it (pass on_gap='flag' to mark the affected frames invalid instead)")
