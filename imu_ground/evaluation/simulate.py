r"""Synthetic drives with exact ground truth: a vehicle on a rough road, and its IMU.

A drive is built in three layers, every one vectorised over the samples:

1. **Road** (a function of the distance travelled ``s``): horizontal curvature
   (straights, curves with smooth transitions; the heading follows), grade
   (vertical curves between constant grades), cross-slope (crown on straights,
   superelevation in curves), and a random roughness profile per wheel track
   after ISO 8608.
2. **Vehicle**: a speed profile in time (cruising, accelerating, braking,
   stops), and the body's pitch, roll and heave on its suspension: three
   second-order systems driven by the road under the wheels and by the
   longitudinal and lateral specific force (nose dive under braking, roll out
   of a turn).
3. **Sensor**: rigidly mounted on the body with a static extrinsic; its exact
   angular rate and specific force, then the IMU errors (white noise, bias
   random walk, turn-on bias) of an :class:`ImuErrorModel`.

Conventions
-----------
- **World** ``w``: local level, z up (ENU-like), treated as inertial (the Earth's
  rotation, 7.3e-5 rad/s, is not simulated); gravity ``g_w = (0, 0, -9.80665)``.
- **Body / ground frame** ``b`` (FLU): x forward, y left, z up, fixed to the
  vehicle body; its origin is on the road surface below the vehicle reference
  point (by default mid-wheelbase), displaced vertically by the body's heave.
- **Attitude** of a frame ``a`` relative to a frame ``c`` as ``R (c <- a) =
  Rz(yaw) @ Ry(pitch) @ Rx(roll)``; pitch positive = nose DOWN (right-handed
  about y-left), roll positive = left side UP (right-handed about x-forward),
  the KITTI OXTS convention.
- **Road frame** ``r`` at the vehicle: x along the road tangent in the heading
  direction (the velocity of the reference point), z the road-surface normal
  of the *macro* road (grade and cross-slope; the roughness is not part of the
  plane, it is what shakes the body, so the truth pitch and roll include the
  quasi-static tilt of the wheels' contact plane over the wheelbase). ``R_wr = Rz(heading) @ Ry(-grade) @
  Rx(bank)``: ``road_grade`` (rad) is the inclination of the tangent, positive
  uphill; ``road_bank`` (rad) the roll of the road frame, positive when the
  left edge is higher.
- **Body relative to road**: ``E = R_rb = Ry(pitch) @ Rx(roll)`` (the body never
  yaws relative to the road: no side-slip). The ground normal in the body frame
  is ``n_b = E^T e_z = [-sin(pitch), sin(roll) cos(pitch), cos(pitch) cos(roll)]``.
- **Sensor** ``s``: ``R_gs`` (body/ground <- sensor) and ``t_gs`` (sensor origin in
  the body frame, m). ``R_ws = R_wr @ E @ R_gs``; ``p_ws = p_wb + R_wb @ t_gs``. The
  normal in the sensor frame is ``n_s = R_gs^T n_b``. The IMU measures, in the
  sensor frame, the angular rate of the sensor frame (``w_s = R_gs^T w_b``) and
  the specific force ``f_s = R_ws^T (a_w - g_w)`` (about ``+9.81`` up at rest).

Exactness
---------
Every rotation and its first two time derivatives are closed-form: the speed
profile, curvature, grade and bank are made of septic (C^3) smooth steps (with their
integrals: speed, distance, heading), and the three suspension systems are
discretised exactly for a first-order-hold input on a fine time grid (default
1 kHz), which gives their state (angle and rate) exactly at the grid points and
the angular acceleration from the differential equation. The angular rate is
then assembled from the Euler-angle rates through the kinematic chain, and the
specific force from the analytic acceleration of the sensor (road path, heave
and the lever arm ``t_gs`` with the body's angular rate and acceleration). The
positions are the Gauss-Legendre (3-point) integral of the analytic velocity.
So noise-free samples are the exact derivatives of the truth trajectory, and
integrating them reproduces it to the accuracy of the integration scheme.

Road roughness
--------------
ISO 8608: displacement PSD ``G_d(n) = G_d(n0) (n / n0)^-2``, ``n0 = 0.1``
cycles/m, class A ``16e-6``, B ``64e-6``, C ``256e-6``, D ``1024e-6`` m^3 (the
geometric means of the classes), on the band ``0.011 <= n <= 2.83`` cycles/m
(wavelengths 0.35 m to 90 m; the upper edge stands in for the tyre's
enveloping of shorter wavelengths). The left and right wheel tracks are two
Gaussian profiles with that PSD and the coherence ``c(n) = exp(-k n B)`` (``B``
the track width, ``k = coherence_decay``, default 4: 0.77 at 25 m wavelength,
0.08 at 2 m), so long waves lift both wheels together and short ones roll the
body. Pitch input: ``-(h_front - h_rear) / wheelbase`` (track-averaged); roll
input ``(h_left - h_right) / track`` (axle-averaged); heave input: the height
of the wheel plane under the reference point.

Suspension
----------
``x'' + 2 zeta w x' + w^2 x = w^2 u(t)`` for pitch, roll and heave (unit static
gain), with ``u`` the road input plus, for pitch, ``-K_pitch * f_x`` and, for
roll, ``+K_roll * f_y`` (``f`` the specific force of the reference point in the
road frame: acceleration and, with ``gravity_load_transfer``, the components
of gravity along the grade and the cross-slope). Braking (``f_x < 0``) thus
pitches the nose down, ``pitch = K_pitch * deceleration`` once the transient
has died out; a left turn (``f_y > 0``) rolls the body to the right, i.e. raises
its left side relative to the road (positive roll).

IMU error presets (one sigma, per axis; white noise std at rate ``fs`` is
``density * sqrt(fs)``)
-----------------------------------------------------------------------------
``"nav"`` (navigation-grade GPS/INS like KITTI's OXTS RT3003):
    gyro noise 0.0025 deg/s/sqrt(Hz) (0.15 deg/sqrt(h); OXTS RT3000-series
    datasheets quote an ARW of 0.2 deg/sqrt(h); KITTI raw 100 Hz OXTS data at standstill,
    engine running, shows 0.021-0.031 deg/s per sample, i.e. 0.002-0.003
    deg/s/sqrt(Hz)), gyro in-run bias instability 2 deg/h (datasheet) as a
    random walk of 2 deg/h per 100 s, turn-on gyro bias 10 deg/h (stationary
    KITTI means are 5-40 deg/h, Earth rate included); accelerometer noise
    0.0008 m/s^2/sqrt(Hz) (~80 ug/sqrt(Hz); KITTI standstill 0.006-0.010 m/s^2 per
    sample at 100 Hz), bias random walk 1e-5 m/s^3/sqrt(Hz) (10 ug per 100 s),
    turn-on 0.005 m/s^2 (0.5 mg).
``"mems"`` (phone / consumer MEMS, Bosch BMI160 / InvenSense MPU-6500 class):
    gyro noise 0.007 deg/s/sqrt(Hz) (BMI160 datasheet typ.; MPU-6500 0.01), bias
    random walk 1 deg/h per sqrt(s) (10 deg/h of wander over 100 s, the order of
    consumer-MEMS in-run bias instability), turn-on gyro bias 1 deg/s (BMI160 zero-rate offset +-3 deg/s typ. before offset
    compensation; phones' bias calibration leaves ~0.1-1 deg/s); accelerometer
    noise 180 ug/sqrt(Hz) (BMI160 typ.; MPU-6500 300 ug/sqrt(Hz)), bias random
    walk 1e-4 m/s^3/sqrt(Hz) (0.1 mg per 100 s), turn-on 0.2 m/s^2 (~20 mg;
    BMI160 zero-g offset +-40 mg typ.).
Both are the sensor's own errors: vibration of a phone holder or an engine
above the body's own motion is not in them (pass a model with larger
densities to emulate it).

Public API: :func:`simulate`, :func:`simulate_suite`, :class:`SimResult`,
:class:`ImuErrorModel` with :data:`IMU_PRESETS`, :func:`imu_error_model`,
:class:`VehicleParams`, :class:`RoadParams`, :class:`SpeedParams`,
:func:`road_profile`, :func:`suspension_response`, :func:`iso8608_psd`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
import pandas as pd
from scipy.linalg import expm
from scipy.signal import lfilter, lfilter_zi
from scipy.spatial.transform import Rotation

from imu_ground import so3
from imu_ground.imu.data import ImuData
from imu_ground.so3 import rotx, roty, rotz

__all__ = [
    "GRAVITY", "ISO8608_N0", "ISO8608_CLASSES", "ImuErrorModel", "IMU_PRESETS",
    "imu_error_model", "VehicleParams", "RoadParams", "SpeedParams", "SimResult",
    "simulate", "simulate_suite", "road_profile", "suspension_response",
    "iso8608_psd", "TRUTH_COLUMNS",
]

GRAVITY = 9.80665
_G_W = np.array([0.0, 0.0, -GRAVITY])
ISO8608_N0 = 0.1                       # cycles/m
ISO8608_CLASSES = {"A": 16e-6, "B": 64e-6, "C": 256e-6, "D": 1024e-6}   # G_d(n0), m^3
_DEG = math.pi / 180.0
_DEG_H = _DEG / 3600.0                 # 1 deg/h in rad/s

TRUTH_COLUMNS = (
    "t", "s", "speed", "acc_long", "acc_lat", "curvature", "heading",
    "normal_x", "normal_y", "normal_z", "normal_body_x", "normal_body_y", "normal_body_z",
    "pitch", "roll", "pitch_rate", "roll_rate", "heave", "road_grade", "road_bank",
    "qw", "qx", "qy", "qz", "x", "y", "z", "vx", "vy", "vz", "stationary",
)


# --------------------------------------------------------------------------- IMU errors
@dataclass(frozen=True)
class ImuErrorModel:
    """Stochastic errors of a 6-axis IMU (same numbers on every axis, one sigma).

    Measurement ``y_k = true_k + b_k + n_k``: ``n_k`` white, std
    ``density * sqrt(rate)``; ``b_k = b_0 + random walk`` with increments of std
    ``bias_rw * sqrt(dt)``; ``b_0`` drawn once per drive, std ``turn_on``.

    Parameters
    ----------
    name : str
    gyro_noise_density : float
        Angular random walk, rad/s/sqrt(Hz).
    gyro_bias_rw : float
        Rate random walk, rad/s^2/sqrt(Hz) (rad/s per sqrt(s)).
    gyro_bias_turn_on : float
        Constant gyro bias, rad/s.
    accel_noise_density : float
        Velocity random walk, m/s^2/sqrt(Hz).
    accel_bias_rw : float
        Accelerometer bias random walk, m/s^3/sqrt(Hz).
    accel_bias_turn_on : float
        Constant accelerometer bias, m/s^2.
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

    def scaled(self, factor: float, name: str | None = None) -> "ImuErrorModel":
        """The same model with every error multiplied by ``factor``."""
        return ImuErrorModel(name or f"{self.name}x{factor:g}",
                             *(factor * v for v in (self.gyro_noise_density, self.gyro_bias_rw,
                                                    self.gyro_bias_turn_on, self.accel_noise_density,
                                                    self.accel_bias_rw, self.accel_bias_turn_on)))


IMU_PRESETS: dict[str, ImuErrorModel] = {
    # Sources and reasoning in the module docstring.
    "nav": ImuErrorModel(
        name="nav",
        gyro_noise_density=0.0025 * _DEG,            # 0.15 deg/sqrt(h)
        gyro_bias_rw=2.0 * _DEG_H / 10.0,            # 2 deg/h wander over 100 s
        gyro_bias_turn_on=10.0 * _DEG_H,
        accel_noise_density=8e-4,                    # ~80 ug/sqrt(Hz)
        accel_bias_rw=1e-5,                          # 1e-4 m/s^2 over 100 s
        accel_bias_turn_on=5e-3,
    ),
    "mems": ImuErrorModel(
        name="mems",
        gyro_noise_density=0.007 * _DEG,             # BMI160 typ.
        gyro_bias_rw=10.0 * _DEG_H / 10.0,           # ~10 deg/h wander over 100 s
        gyro_bias_turn_on=1.0 * _DEG,
        accel_noise_density=180e-6 * GRAVITY,        # 180 ug/sqrt(Hz)
        accel_bias_rw=1e-4,                          # 1e-3 m/s^2 over 100 s
        accel_bias_turn_on=0.2,                      # ~20 mg
    ),
    "perfect": ImuErrorModel("perfect", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
}


def imu_error_model(model: str | ImuErrorModel | None) -> ImuErrorModel:
    """An :class:`ImuErrorModel` from a preset name (``"nav"``, ``"mems"``,
    ``"perfect"``; ``None`` means ``"perfect"``) or a model (returned as is)."""
    if model is None:
        return IMU_PRESETS["perfect"]
    if isinstance(model, ImuErrorModel):
        return model
    try:
        return IMU_PRESETS[str(model).lower()]
    except KeyError:
        raise ValueError(f"unknown IMU preset {model!r}; choose one of {sorted(IMU_PRESETS)}"
                         " or pass an ImuErrorModel") from None


# --------------------------------------------------------------------------- parameters
@dataclass
class VehicleParams:
    """Geometry and suspension of the vehicle.

    Frequencies in Hz, damping ratios dimensionless, gains in degrees per m/s^2
    of specific force (static: ``pitch = pitch_gain_deg * deceleration``).
    """

    wheelbase: float = 2.7               # m
    rear_axle_to_ref: float = 1.35       # m, reference point ahead of the rear axle
    track: float = 1.6                   # m
    pitch_freq: float = 1.4
    pitch_damping: float = 0.35
    roll_freq: float = 1.2
    roll_damping: float = 0.4
    heave_freq: float = 1.2
    heave_damping: float = 0.3
    pitch_gain_deg: float = 0.25         # nose down per m/s^2 of deceleration
    roll_gain_deg: float = 0.4           # outward roll per m/s^2 of lateral acceleration
    gravity_load_transfer: bool = True   # grade and cross-slope load the suspension too


@dataclass
class RoadParams:
    """The road: roughness, grades, cross-slope, curves.

    ``roughness``: ISO 8608 class letter (``"A"``-``"D"``), a level ``G_d(n0)`` in m^3,
    or ``None`` for a smooth road. Grades and cross-slopes are rise over run.
    Explicit plans replace the random layout:

    - ``curve_plan``: ``[(s_start, transition, arc, curvature), ...]`` (m, m, m, 1/m;
      curvature > 0 turns left); curvature ramps up over ``transition`` from
      ``s_start``, holds over ``arc``, ramps down over ``transition``.
    - ``grade_plan``: ``[(s_start, transition, grade), ...]``: the grade moves to
      ``grade`` over ``transition`` metres from ``s_start``.
    """

    roughness: str | float | None = "B"
    band: tuple[float, float] = (0.011, 2.83)     # cycles/m
    coherence_decay: float = 4.0
    dx: float = 0.05                              # m, roughness sampling
    grade0: float | None = None                   # grade at s = 0; None: random (0 if grade_std == 0)
    grade_std: float = 0.03
    grade_max: float = 0.08
    grade_segment: tuple[float, float] = (150.0, 800.0)      # m at constant grade
    grade_transition: tuple[float, float] = (60.0, 250.0)    # m of vertical curve
    crown: float = 0.02                           # cross-slope on straights, > 0: left edge higher
    superelevation_max: float = 0.06
    superelevation_factor: float = 0.4            # share of v^2 kappa / g taken by the bank
    curves: bool = True
    straight_length: tuple[float, float] = (60.0, 400.0)     # m
    turn_angle_deg: tuple[float, float] = (15.0, 100.0)
    lat_accel: tuple[float, float] = (1.0, 3.0)   # m/s^2 at the highest speed in the curve
    radius_range: tuple[float, float] = (12.0, 1500.0)       # m
    transition_time: tuple[float, float] = (1.5, 3.0)        # s of driving over a transition
    heading0: float | None = None                 # rad, None: random
    curve_plan: Sequence[tuple[float, float, float, float]] | None = None
    grade_plan: Sequence[tuple[float, float, float]] | None = None


_STYLES = {
    "urban": dict(speed=(5.0, 14.0), stop_p=0.35, cruise=(4.0, 15.0), accel=(0.8, 2.0), brake=(1.0, 3.0)),
    "rural": dict(speed=(12.0, 24.0), stop_p=0.1, cruise=(6.0, 25.0), accel=(0.6, 1.8), brake=(0.8, 2.5)),
    "highway": dict(speed=(22.0, 33.0), stop_p=0.0, cruise=(10.0, 40.0), accel=(0.4, 1.2), brake=(0.5, 2.0)),
    "mixed": dict(speed=(5.0, 25.0), stop_p=0.2, cruise=(4.0, 20.0), accel=(0.6, 2.2), brake=(0.8, 3.0)),
}


@dataclass
class SpeedParams:
    """The speed profile: random by ``style`` or an explicit ``plan``.

    ``style``: ``"urban"``, ``"rural"``, ``"highway"`` or ``"mixed"`` (speed range,
    stop probability, accelerations); any of the ``None`` fields overrides the
    style's value. ``plan``: ``[(target_speed, accel, hold), ...]``: reach
    ``target_speed`` (m/s) with a peak acceleration of magnitude ``accel`` (m/s^2;
    smooth jerk ramps of ``ramp_time`` s), then hold it ``hold`` s; starts at
    ``v_start`` (m/s) and the last speed holds to the end of the drive.
    """

    style: str = "mixed"
    speed_range: tuple[float, float] | None = None
    stop_probability: float | None = None
    cruise_duration: tuple[float, float] | None = None
    accel: tuple[float, float] | None = None
    brake: tuple[float, float] | None = None
    ramp_time: tuple[float, float] = (0.5, 1.2)   # s of jerk at each end of a speed change
    stop_duration: tuple[float, float] = (3.0, 15.0)
    start_at_rest: bool = True
    initial_rest: tuple[float, float] = (3.0, 6.0)
    plan: Sequence[tuple[float, float, float]] | None = None
    v_start: float = 0.0


# --------------------------------------------------------------------------- smooth steps
def _smoothstep(u):
    """Septic smooth step S(u) on [0, 1] (C^3: value, slope, curvature and jerk
    continuous at both ends), its first two derivatives, and its integrals from 0."""
    u2 = u * u
    u3 = u2 * u
    w = 1.0 - u
    s = u2 * u2 * (35.0 - 84.0 * u + 70.0 * u2 - 20.0 * u3)
    d1 = 140.0 * u3 * w * w * w
    d2 = 420.0 * u2 * w * w * (1.0 - 2.0 * u)
    i1 = u * u2 * u2 * (7.0 - 14.0 * u + 10.0 * u2 - 2.5 * u3)
    i2 = u3 * u3 * (7.0 / 6.0 - 2.0 * u + 1.25 * u2 - 2.5 / 9.0 * u3)
    return s, d1, d2, i1, i2


_S2_AT_1 = 7.0 / 6.0 - 2.0 + 1.25 - 2.5 / 9.0      # = 5/36; S1(1) = 1/2


class _Piecewise:
    """``y(x)``: contiguous phases, ``y = A_j + D_j S((x - x_j) / d_j)`` on phase ``j``.

    ``I1 = V_j + A_j tau + D_j d_j S1(u)`` (integral of y, ``V_0 = y1_0``) and
    ``I2 = P_j + V_j tau + A_j tau^2/2 + D_j d_j^2 S2(u)`` (integral of I1), all in
    closed form. The last phase holds forever; before ``x_0`` the first level holds.
    ``snap`` sets an integral level of magnitude below 1e-9 to exactly 0 at the
    start of a constant phase whose level is 0 (exact stops for a speed profile).
    """

    def __init__(self, x0: float, y0: float, phases: Sequence[tuple[float, float]],
                 i1_0: float = 0.0, i2_0: float = 0.0, snap: bool = False) -> None:
        phases = list(phases) + [(math.inf, 0.0)]
        n = len(phases)
        self.start = np.empty(n)
        self.dur = np.empty(n)
        self.a = np.empty(n)
        self.d = np.empty(n)
        self.v = np.empty(n)
        self.p = np.empty(n)
        x, level, v, p = float(x0), float(y0), float(i1_0), float(i2_0)
        for j, (dur, delta) in enumerate(phases):
            if snap and delta == 0.0 and level == 0.0 and abs(v) < 1e-9:
                v = 0.0
            self.start[j], self.dur[j], self.a[j], self.d[j] = x, dur, level, delta
            self.v[j], self.p[j] = v, p
            if math.isinf(dur):
                break
            p = p + v * dur + level * dur * dur / 2.0 + delta * dur * dur * _S2_AT_1
            v = v + level * dur + delta * dur / 2.0
            level = level + delta
            x = x + dur
        self.end_level = level

    @property
    def end(self) -> float:
        """Start of the final (infinite) phase."""
        return float(self.start[-1])

    def __call__(self, x, derivatives: bool = True):
        """Value, first and second derivative, first and second integral at ``x``."""
        x = np.asarray(x, dtype=float)
        j = np.clip(np.searchsorted(self.start, x, side="right") - 1, 0, len(self.start) - 1)
        tau = x - self.start[j]
        dur = self.dur[j]
        finite = np.isfinite(dur)
        dsafe = np.where(finite, dur, 1.0)
        u = np.where(finite, np.clip(tau / dsafe, 0.0, 1.0), 0.0)
        s, d1, d2, i1, i2 = _smoothstep(u)
        a, dd = self.a[j], self.d[j]
        y = a + dd * s
        y1 = dd * d1 / dsafe
        y2 = dd * d2 / (dsafe * dsafe)
        # before x0, tau < 0 and u = 0: the first level extends linearly in the integrals
        big1 = self.v[j] + a * tau + dd * dsafe * i1
        big2 = self.p[j] + self.v[j] * tau + a * tau * tau / 2.0 + dd * dsafe * dsafe * i2
        return y, y1, y2, big1, big2


# --------------------------------------------------------------------------- road roughness
def _roughness_level(roughness: str | float | None) -> float:
    if roughness is None:
        return 0.0
    if isinstance(roughness, str):
        try:
            return ISO8608_CLASSES[roughness.upper()]
        except KeyError:
            raise ValueError(f"unknown ISO 8608 class {roughness!r}; use one of "
                             f"{sorted(ISO8608_CLASSES)} or G_d(n0) in m^3") from None
    value = float(roughness)
    if value < 0:
        raise ValueError("roughness level must be >= 0")
    return value


def iso8608_psd(n, roughness: str | float = "B") -> np.ndarray:
    """ISO 8608 displacement PSD ``G_d(n) = G_d(n0) (n / n0)^-2``, m^3 (one-sided).

    Parameters
    ----------
    n : array_like
        Spatial frequency, cycles/m (> 0).
    roughness : str or float
        Class letter or ``G_d(n0)`` in m^3.
    """
    n = np.asarray(n, dtype=float)
    return _roughness_level(roughness) * (n / ISO8608_N0) ** -2.0


def road_profile(length: float, roughness: str | float | None = "B", *, dx: float = 0.05,
                 band: tuple[float, float] = (0.011, 2.83), track: float = 1.6,
                 coherence_decay: float = 4.0, x0: float = 0.0,
                 rng: np.random.Generator | int | None = None):
    """Random left and right wheel-track heights with the ISO 8608 PSD.

    Parameters
    ----------
    length : float
        Metres of road to generate.
    roughness : str, float or None
        ISO 8608 class letter, ``G_d(n0)`` in m^3, or ``None`` (zero heights).
    dx : float
        Sample spacing, m.
    band : (float, float)
        Spatial-frequency band with the ISO PSD, cycles/m; zero outside.
    track : float
        Track width, m (sets the coherence).
    coherence_decay : float
        ``k`` in the left/right coherence ``exp(-k n track)``.
    x0 : float
        Position of the first sample, m.
    rng : numpy Generator, seed or None

    Returns
    -------
    x, h_left, h_right : ndarray, shape (N,)
        Positions and heights (m); Gaussian, zero mean, one-sided PSD
        ``iso8608_psd(n)`` in the band for each track.
    """
    rng = np.random.default_rng(rng)
    n_pts = max(int(math.ceil(length / dx)) + 1, 16)
    x = x0 + dx * np.arange(n_pts)
    level = _roughness_level(roughness)
    if level == 0.0:
        return x, np.zeros(n_pts), np.zeros(n_pts)
    n_fft = n_pts + (n_pts % 2)
    freqs = np.fft.rfftfreq(n_fft, dx)
    dn = 1.0 / (n_fft * dx)
    inband = (freqs >= band[0]) & (freqs <= band[1]) & (freqs > 0)
    psd = np.zeros_like(freqs)
    psd[inband] = level * (freqs[inband] / ISO8608_N0) ** -2.0
    amp = 0.5 * n_fft * np.sqrt(psd * dn)
    shape = (2, freqs.size)
    z = amp * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))
    coh = np.exp(-coherence_decay * freqs * track)
    zl = z[0]
    zr = coh * z[0] + np.sqrt(1.0 - coh * coh) * z[1]
    h_left = np.fft.irfft(zl, n_fft)[:n_pts]
    h_right = np.fft.irfft(zr, n_fft)[:n_pts]
    return x, h_left, h_right


# --------------------------------------------------------------------------- suspension
def _foh_filter(freq: float, damping: float, dt: float):
    """Transfer functions (num_x, num_xdot, den) of ``x'' + 2 z w x' + w^2 x = w^2 u``
    discretised exactly for a first-order-hold (piecewise-linear) input."""
    w = 2.0 * math.pi * freq
    a = np.array([[0.0, 1.0], [-w * w, -2.0 * damping * w]])
    b = np.array([0.0, w * w])
    m = np.zeros((4, 4))
    m[:2, :2] = a
    m[:2, 2] = b
    m[2, 3] = 1.0
    e = expm(m * dt)
    phi, g1, g2 = e[:2, :2], e[:2, 2], e[:2, 3]
    # x[k+1] = phi x[k] + g1 u[k] + g2 (u[k+1] - u[k]) / dt
    b0 = g1 - g2 / dt
    b1 = g2 / dt
    k = np.array([[-phi[1, 1], phi[0, 1]], [phi[1, 0], -phi[0, 0]]])   # adj(zI - phi) = zI + k
    num = np.stack([b1, b0 + k @ b1, k @ b0], axis=1)                   # rows: x, xdot
    den = np.array([1.0, -np.trace(phi), np.linalg.det(phi)])
    return num[0], num[1], den


def suspension_response(u, dt: float, freq: float, damping: float, gain: float = 1.0):
    """Exact response of ``x'' + 2 zeta w x' + w^2 x = w^2 gain u(t)``, ``w = 2 pi freq``.

    ``u`` is sampled every ``dt`` and linear in between (first-order hold); the
    system starts at rest in equilibrium with ``u[0]``. The states are exact at the
    samples (no discretisation error), the acceleration follows from the equation.

    Parameters
    ----------
    u : array_like, shape (N,)
    dt : float
        Sample interval, s.
    freq : float
        Undamped natural frequency, Hz.
    damping : float
        Damping ratio.
    gain : float
        Static gain.

    Returns
    -------
    x, xdot, xddot : ndarray, shape (N,)
    """
    u = gain * np.asarray(u, dtype=float)
    num_x, num_v, den = _foh_filter(freq, damping, dt)
    x = lfilter(num_x, den, u, zi=lfilter_zi(num_x, den) * u[0])[0]
    v = lfilter(num_v, den, u, zi=lfilter_zi(num_v, den) * u[0])[0]
    w = 2.0 * math.pi * freq
    acc = w * w * (u - x) - 2.0 * damping * w * v
    return x, v, acc


# --------------------------------------------------------------------------- profiles
def _speed_profile(p: SpeedParams, duration: float, rng: np.random.Generator) -> _Piecewise:
    """Longitudinal acceleration as smooth-step phases (speed and distance integrate it)."""
    phases: list[tuple[float, float]] = []

    def change(v_from: float, v_to: float, a_mag: float, ramp: float) -> float:
        dv = v_to - v_from
        if dv == 0.0 or a_mag <= 0.0:
            return 0.0
        hold = abs(dv) / a_mag - ramp
        if hold < 0.0:
            hold, a_mag = 0.0, abs(dv) / ramp
        a_p = math.copysign(a_mag, dv)
        phases.extend([(ramp, a_p), (hold, 0.0), (ramp, -a_p)])
        return 2.0 * ramp + hold

    t = 0.0
    if p.plan is not None:
        v = float(p.v_start)
        ramp = float(np.mean(p.ramp_time))
        for target, accel, hold in p.plan:
            if target < 0:
                raise ValueError("speeds in the plan must be >= 0")
            t += change(v, float(target), float(accel), ramp)
            v = float(target)
            if hold > 0:
                phases.append((float(hold), 0.0))
                t += float(hold)
        return _Piecewise(0.0, 0.0, phases, i1_0=float(p.v_start), snap=True)

    style = _STYLES.get(p.style)
    if style is None:
        raise ValueError(f"unknown speed style {p.style!r}; choose one of {sorted(_STYLES)}")
    vr = p.speed_range or style["speed"]
    stop_p = style["stop_p"] if p.stop_probability is None else p.stop_probability
    cruise = p.cruise_duration or style["cruise"]
    acc = p.accel or style["accel"]
    brk = p.brake or style["brake"]
    if p.start_at_rest:
        v = 0.0
        rest = rng.uniform(*p.initial_rest)
        phases.append((rest, 0.0))
        t += rest
    else:
        v = rng.uniform(*vr)
    v0 = v
    while t < duration:
        if v > 0.0 and rng.random() < stop_p:
            target = 0.0
        else:
            target = rng.uniform(*vr)
            if abs(target - v) < 1.0:
                target = min(vr[1], v + 2.0) if v < 0.5 * (vr[0] + vr[1]) else max(vr[0], v - 2.0)
        a_mag = rng.uniform(*(acc if target > v else brk))
        t += change(v, target, a_mag, rng.uniform(*p.ramp_time))
        v = target
        hold = rng.uniform(*(p.stop_duration if v == 0.0 else cruise))
        phases.append((hold, 0.0))
        t += hold
    return _Piecewise(0.0, 0.0, phases, i1_0=v0, snap=True)


def _max_speed_between(s_grid, v_grid, s_a, s_b):
    i0 = np.searchsorted(s_grid, s_a, side="left")
    i1 = np.searchsorted(s_grid, s_b, side="right")
    lo, hi = max(i0 - 1, 0), min(i1 + 1, len(s_grid))
    return float(v_grid[lo:hi].max()) if hi > lo else float(np.interp(s_a, s_grid, v_grid))


def _road_layout(p: RoadParams, length: float, s_grid, v_grid, rng: np.random.Generator):
    """Curvature, grade and bank profiles along s, and the list of curves."""
    # curves: (s_start, transition, arc, curvature)
    curves: list[tuple[float, float, float, float]] = []
    if p.curve_plan is not None:
        curves = [tuple(map(float, c)) for c in p.curve_plan]
    elif p.curves:
        s = rng.uniform(*p.straight_length) * rng.uniform(0.2, 1.0)
        while s < length:
            turn = rng.uniform(*p.turn_angle_deg) * _DEG
            # first guess of the extent, then the speed there sets the radius
            vmax = max(_max_speed_between(s_grid, v_grid, s, s + 150.0), 1.0)
            kappa = rng.uniform(*p.lat_accel) / (vmax * vmax)
            kappa = float(np.clip(kappa, 1.0 / p.radius_range[1], 1.0 / p.radius_range[0]))
            w = float(np.clip(vmax * rng.uniform(*p.transition_time), 5.0, 120.0))
            w = min(w, 0.5 * turn / kappa)
            arc = turn / kappa - w
            vmax2 = max(_max_speed_between(s_grid, v_grid, s, s + 2 * w + arc), 1.0)
            if vmax2 > vmax:     # a faster stretch inside the curve: open the radius
                kappa = max(kappa * (vmax / vmax2) ** 2, 1.0 / p.radius_range[1])
                w = min(w, 0.5 * turn / kappa)
                arc = turn / kappa - w
            curves.append((s, w, arc, float(kappa * rng.choice([-1.0, 1.0]))))
            s += 2 * w + arc + rng.uniform(*p.straight_length)
    kappa_phases, bank_phases = [], []
    crown = math.atan(p.crown)
    s_prev = 0.0
    for s0, w, arc, kappa in curves:
        if s0 < s_prev - 1e-9 or w <= 0 or arc < 0:
            raise ValueError("curves must be sorted, non-overlapping, with transition > 0, arc >= 0")
        vmax = max(_max_speed_between(s_grid, v_grid, s0, s0 + 2 * w + arc), 0.0)
        e = min(p.superelevation_max, p.superelevation_factor * abs(kappa) * vmax * vmax / GRAVITY)
        bank = -math.copysign(math.atan(e), kappa)          # inside of the curve lower
        gap = s0 - s_prev
        kappa_phases += [(gap, 0.0), (w, kappa), (arc, 0.0), (w, -kappa)]
        bank_phases += [(gap, 0.0), (w, bank - crown), (arc, 0.0), (w, crown - bank)]
        s_prev = s0 + 2 * w + arc
    heading0 = rng.uniform(-math.pi, math.pi) if p.heading0 is None else float(p.heading0)
    curvature = _Piecewise(0.0, 0.0, kappa_phases, i1_0=heading0)
    bank = _Piecewise(0.0, crown, bank_phases)

    grades: list[tuple[float, float, float]] = []
    g_rand = float(np.clip(rng.normal(0.0, p.grade_std), -p.grade_max, p.grade_max)) if p.grade_std > 0 else 0.0
    g0 = g_rand if p.grade0 is None else float(p.grade0)
    if p.grade_plan is not None:
        grades = [tuple(map(float, g)) for g in p.grade_plan]
    elif p.grade_std > 0:
        s = rng.uniform(*p.grade_segment) * rng.uniform(0.1, 1.0)
        while s < length:
            w = rng.uniform(*p.grade_transition)
            g = float(np.clip(rng.normal(0.0, p.grade_std), -p.grade_max, p.grade_max))
            grades.append((s, w, g))
            s += w + rng.uniform(*p.grade_segment)
    grade_phases = []
    s_prev, level = 0.0, math.atan(g0)
    for s0, w, g in grades:
        if s0 < s_prev - 1e-9 or w <= 0:
            raise ValueError("grade changes must be sorted, non-overlapping, transition > 0")
        target = math.atan(g)
        grade_phases += [(s0 - s_prev, 0.0), (w, target - level)]
        level = target
        s_prev = s0 + w
    grade = _Piecewise(0.0, math.atan(g0), grade_phases)
    return curvature, grade, bank, curves


# --------------------------------------------------------------------------- kinematics
_AXES = {"x": rotx, "y": roty, "z": rotz}
_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def _chain(axes: str, q, qd, qdd):
    """Rotation ``R = R_1(q_1) ... R_n(q_n)`` with its body-frame angular velocity and
    acceleration, from the angles and their first two time derivatives.

    ``w = sum_i u_i q_i'`` with ``u_i = (R_{i+1} ... R_n)^T a_i``, and
    ``w' = sum_i u_i q_i'' + sum_i q_i' u_i x w_(i)`` with ``w_(i) = sum_{j > i} u_j q_j'``.
    """
    n = q[0].shape[0]
    c = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    w = np.zeros((n, 3))
    wd = np.zeros((n, 3))
    for ax, qi, qdi, qddi in reversed(list(zip(axes, q, qd, qdd))):
        ui = c[:, _AXIS_INDEX[ax], :]                 # (C^T a)_k = C[a, k]
        wd += ui * qddi[:, None] + qdi[:, None] * np.cross(ui, w)
        w += ui * qdi[:, None]
        c = _AXES[ax](qi) @ c
    return c, w, wd


def _quat_wxyz(r: np.ndarray) -> np.ndarray:
    q = Rotation.from_matrix(r).as_quat()            # x, y, z, w
    q = q[:, [3, 0, 1, 2]]
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


# --------------------------------------------------------------------------- result
@dataclass
class SimResult:
    """One simulated drive.

    Attributes
    ----------
    imu : ImuData
        Noisy samples in the sensor frame (``t``, ``gyro`` rad/s, ``accel`` m/s^2).
    imu_clean : ImuData
        The same without any error (exact angular rate and specific force).
    truth : pandas.DataFrame
        One row per frame (``frame_rate``), columns :data:`TRUTH_COLUMNS`:
        ``t`` s; ``s`` distance travelled m; ``speed`` m/s; ``acc_long`` dv/dt and
        ``acc_lat`` (lateral acceleration of the reference point in the road
        frame, ~ v^2 curvature, > 0 to the left) m/s^2; ``curvature`` 1/m (> 0 left);
        ``heading`` rad (yaw of the road frame); ``normal_x/y/z`` the ground normal
        in the sensor frame; ``normal_body_x/y/z`` in the body frame; ``pitch``,
        ``roll`` body relative to road (rad, nose down / left up positive) and their
        rates rad/s; ``heave`` m; ``road_grade`` rad (uphill positive), ``road_bank``
        rad (left edge higher positive); ``qw, qx, qy, qz`` world <- sensor (``qw >= 0``);
        ``x, y, z`` sensor position and ``vx, vy, vz`` its velocity in the world
        frame (m, m/s); ``stationary`` (speed exactly 0).
    R_gs, t_gs : ndarray
        The extrinsic (body/ground <- sensor rotation, sensor origin in the body frame).
    imu_model : ImuErrorModel
    bias_gyro, bias_accel : ndarray, shape (N, 3)
        The true biases at every IMU sample.
    R_ws, p_ws, v_ws : ndarray
        World <- sensor attitude (N, 3, 3), position and velocity (N, 3) at every IMU sample.
    params : dict
        Everything needed to rerun: ``simulate(**params)`` gives this drive again.
    seed : int
    name : str
    curves : list of (s_start, transition, arc, curvature)
    road : dict
        The roughness profile: ``x``, ``h_left``, ``h_right`` (m).
    """

    imu: ImuData
    imu_clean: ImuData
    truth: pd.DataFrame
    R_gs: np.ndarray
    t_gs: np.ndarray
    imu_model: ImuErrorModel
    bias_gyro: np.ndarray
    bias_accel: np.ndarray
    R_ws: np.ndarray
    p_ws: np.ndarray
    v_ws: np.ndarray
    params: dict[str, Any]
    seed: int
    name: str = ""
    curves: list = field(default_factory=list)
    road: dict = field(default_factory=dict, repr=False)

    def __repr__(self) -> str:
        return (f"SimResult(name={self.name!r}, seed={self.seed}, imu={self.imu_model.name!r}, "
                f"duration={self.imu.duration:.1f} s, samples={len(self.imu)}, frames={len(self.truth)})")

    def to_csv(self, imu_path, truth_path=None, float_format: str = "%.10g") -> None:
        """Write the noisy IMU (columns t,wx,wy,wz,ax,ay,az) and, if given, the truth."""
        df = self.imu.to_dataframe()[["t", "wx", "wy", "wz", "ax", "ay", "az"]]
        df.to_csv(imu_path, index=False, float_format=float_format, lineterminator="\n")
        if truth_path is not None:
            truth = self.truth.copy()
            truth["stationary"] = truth["stationary"].astype(int)
            truth.to_csv(truth_path, index=False, float_format=float_format, lineterminator="\n")


# --------------------------------------------------------------------------- simulate
def _as_extrinsic(R_gs, t_gs):
    r = np.eye(3) if R_gs is None else np.array(R_gs, dtype=float)
    t = np.array([0.3, 0.0, 0.9]) if t_gs is None else np.array(t_gs, dtype=float)
    if r.shape != (3, 3) or t.shape != (3,):
        raise ValueError("R_gs must be 3x3 and t_gs of length 3")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
        raise ValueError("R_gs must be a rotation matrix")
    return r, t


#: Length of the centred window (m) over which the roughness counts as part of
#: the road plane in the truth (a triangular kernel: two boxcars of half this).
ROAD_PLANE_WINDOW = 10.0


def _rough_plane(x, h_l, h_r, s, track, dx):
    """Grade and cross-slope (rad) of the roughness smoothed over ROAD_PLANE_WINDOW, at distances ``s``."""
    if not np.any(h_l) and not np.any(h_r):
        return np.zeros_like(s), np.zeros_like(s)
    half = max(int(round(0.5 * ROAD_PLANE_WINDOW / dx)), 1)

    def box(h):                       # centred moving average, edges padded with edge values
        hp = np.pad(h, (half, half), mode="edge")
        c = np.concatenate([[0.0], np.cumsum(hp)])
        lo = np.arange(len(h)) + half - half // 2
        return (c[lo + half] - c[lo]) / half

    hl, hr = box(box(h_l)), box(box(h_r))
    hc = 0.5 * (hl + hr)
    slope = np.gradient(hc, x)
    grade = np.arctan(np.interp(s, x, slope))
    bank = np.arctan(np.interp(s, x, (hl - hr) / track))
    return grade, bank


def _clean_drive(duration: float, seed: int, imu_rate: float, frame_rate: float,
                 road: RoadParams, vehicle: VehicleParams, speed: SpeedParams,
                 R_gs: np.ndarray, t_gs: np.ndarray, oversample: int):
    """The exact trajectory and noise-free IMU samples."""
    ss = np.random.SeedSequence(seed)
    rng_speed, rng_road, rng_rough, _ = (np.random.default_rng(s) for s in ss.spawn(4))

    n_imu = int(math.floor(duration * imu_rate + 1e-9)) + 1
    dt = 1.0 / imu_rate
    t_imu = dt * np.arange(n_imu)
    dt_f = dt / oversample
    t_f = dt_f * np.arange((n_imu - 1) * oversample + 1)

    # speed profile and distance
    acc_pw = _speed_profile(speed, duration, rng_speed)
    t_coarse = np.linspace(0.0, duration, int(duration * 10) + 2)
    _, _, _, v_c, s_c = acc_pw(t_coarse)
    v_c = np.maximum(v_c, 0.0)
    s_end = float(s_c[-1])
    length = s_end + vehicle.wheelbase + 50.0

    kappa_pw, grade_pw, bank_pw, curves = _road_layout(road, length, s_c, v_c, rng_road)

    # roughness under the four wheels
    l_r = vehicle.rear_axle_to_ref
    l_f = vehicle.wheelbase - l_r
    x_rough, h_l, h_r = road_profile(length + l_r + 20.0, road.roughness, dx=road.dx, band=road.band,
                                 track=vehicle.track, coherence_decay=road.coherence_decay,
                                 x0=-l_r - 10.0, rng=rng_rough)

    def motion(t):
        a, _, _, v, s = acc_pw(t)
        return a, np.maximum(v, 0.0), s

    # ---- fine grid: suspension inputs
    a_f, v_f, s_f = motion(t_f)
    front, rear = s_f + l_f, s_f - l_r
    hfl, hfr = np.interp(front, x_rough, h_l), np.interp(front, x_rough, h_r)
    hrl, hrr = np.interp(rear, x_rough, h_l), np.interp(rear, x_rough, h_r)
    h_front, h_rear = 0.5 * (hfl + hfr), 0.5 * (hrl + hrr)
    u_pitch = -(h_front - h_rear) / vehicle.wheelbase
    u_roll = (0.5 * (hfl + hrl) - 0.5 * (hfr + hrr)) / vehicle.track
    u_heave = (l_r * h_front + l_f * h_rear) / vehicle.wheelbase
    if vehicle.pitch_gain_deg or vehicle.roll_gain_deg:
        al, al_s, _, _, _ = grade_pw(s_f)
        bk, bk_s, _, _, _ = bank_pw(s_f)
        kap = kappa_pw(s_f)[0]
        th_r = -al
        psi_d, th_d, ph_d = kap * v_f, -al_s * v_f, bk_s * v_f
        w_rz = -np.sin(bk) * th_d + np.cos(bk) * np.cos(th_r) * psi_d
        f_x = a_f.copy()
        f_y = v_f * w_rz
        if vehicle.gravity_load_transfer:
            f_x += GRAVITY * np.sin(al)
            f_y += GRAVITY * np.cos(th_r) * np.sin(bk)
        u_pitch = u_pitch - vehicle.pitch_gain_deg * _DEG * f_x
        u_roll = u_roll + vehicle.roll_gain_deg * _DEG * f_y
    th, th_d1, th_d2 = suspension_response(u_pitch, dt_f, vehicle.pitch_freq, vehicle.pitch_damping)
    ph, ph_d1, ph_d2 = suspension_response(u_roll, dt_f, vehicle.roll_freq, vehicle.roll_damping)
    zh, zh_d1, zh_d2 = suspension_response(u_heave, dt_f, vehicle.heave_freq, vehicle.heave_damping)
    sub = slice(None, None, oversample)
    th, th_d1, th_d2 = th[sub], th_d1[sub], th_d2[sub]
    ph, ph_d1, ph_d2 = ph[sub], ph_d1[sub], ph_d2[sub]
    zh, zh_d1, zh_d2 = zh[sub], zh_d1[sub], zh_d2[sub]

    # ---- IMU grid: exact kinematics
    a, v, s = a_f[sub], v_f[sub], s_f[sub]
    kap, kap_s, _, psi, _ = kappa_pw(s)
    al, al_s, al_ss, _, _ = grade_pw(s)
    bk, bk_s, bk_ss, _, _ = bank_pw(s)
    v2 = v * v
    q = [psi, -al, bk, th, ph]
    qd = [kap * v, -al_s * v, bk_s * v, th_d1, ph_d1]
    qdd = [kap_s * v2 + kap * a, -(al_ss * v2 + al_s * a), bk_ss * v2 + bk_s * a, th_d2, ph_d2]
    r_wb, w_b, wd_b = _chain("zyxyx", q, qd, qdd)
    r_ws = r_wb @ R_gs
    r_wr = _chain("zyx", q[:3], qd[:3], qdd[:3])[0]

    ca, sa, cp, sp = np.cos(al), np.sin(al), np.cos(psi), np.sin(psi)
    x_r = np.stack([ca * cp, ca * sp, sa], axis=1)
    ald, psd = al_s * v, kap * v
    xd_r = np.stack([-sa * ald * cp - ca * sp * psd, -sa * ald * sp + ca * cp * psd, ca * ald], axis=1)
    ez = np.array([0.0, 0.0, 1.0])
    lever_b = np.broadcast_to(t_gs, w_b.shape)
    w_x_t = np.cross(w_b, lever_b)
    acc_w = (a[:, None] * x_r + v[:, None] * xd_r + zh_d2[:, None] * ez
             + np.einsum("nij,nj->ni", r_wb, np.cross(wd_b, lever_b) + np.cross(w_b, w_x_t)))
    vel_w = v[:, None] * x_r + zh_d1[:, None] * ez + np.einsum("nij,nj->ni", r_wb, w_x_t)
    f_s = np.einsum("nji,nj->ni", r_ws, acc_w - _G_W)
    w_s = w_b @ R_gs

    # ---- positions: Gauss-Legendre (3 nodes) integral of the road-point velocity
    gl = 0.5 * np.array([1.0 - math.sqrt(0.6), 1.0, 1.0 + math.sqrt(0.6)])
    glw = np.array([5.0, 8.0, 5.0]) / 18.0
    tn = (t_imu[:-1, None] + dt * gl[None, :]).ravel()
    _, vn, sn = motion(tn)
    psi_n = kappa_pw(sn)[3]
    al_n = grade_pw(sn)[0]
    vel_n = vn[:, None] * np.stack([np.cos(al_n) * np.cos(psi_n), np.cos(al_n) * np.sin(psi_n),
                                   np.sin(al_n)], axis=1)
    steps = dt * np.einsum("k,nkj->nj", glw, vel_n.reshape(-1, 3, 3))
    p_road = np.vstack([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
    p_wb = p_road + zh[:, None] * ez
    p_ws = p_wb + np.einsum("nij,j->ni", r_wb, t_gs)

    # ---- per-sample truth (subsampled to frames later)
    # The road plane the truth refers to is the macro road (grade, cross-slope)
    # plus the roughness smoothed over a centred window of ROAD_PLANE_WINDOW
    # metres: undulations longer than that are road geometry (what a camera
    # sees and what the real-data reference keeps in its 10 m grade), shorter
    # ones shake the body. The IMU signals do not depend on this choice.
    d_grade, d_bank = _rough_plane(x_rough, h_l, h_r, s, vehicle.track, road.dx)
    al_t, bk_t = al + d_grade, bk + d_bank
    r_wr_t = so3.rotz(psi) @ so3.roty(-al_t) @ so3.rotx(bk_t)
    n_b = np.einsum("nji,nj->ni", r_wb, r_wr_t[:, :, 2])      # E^T e_z, E = R_wr^T R_wb
    th_t = np.arctan2(-n_b[:, 0], np.hypot(n_b[:, 1], n_b[:, 2]))
    ph_t = np.arctan2(n_b[:, 1], n_b[:, 2])
    n_s = n_b @ R_gs
    w_rz = -np.sin(bk) * qd[1] + np.cos(bk) * np.cos(q[1]) * qd[0]
    truth = {
        "t": t_imu, "s": s, "speed": v, "acc_long": a, "acc_lat": v * w_rz,
        "curvature": kap, "heading": psi,
        "normal_x": n_s[:, 0], "normal_y": n_s[:, 1], "normal_z": n_s[:, 2],
        "normal_body_x": n_b[:, 0], "normal_body_y": n_b[:, 1], "normal_body_z": n_b[:, 2],
        "pitch": th_t, "roll": ph_t, "pitch_rate": th_d1, "roll_rate": ph_d1, "heave": zh,
        "road_grade": al_t, "road_bank": bk_t,
    }
    return dict(t=t_imu, gyro=w_s, accel=f_s, R_ws=r_ws, R_wr=r_wr, p_ws=p_ws, v_ws=vel_w,
                truth=truth, curves=curves, road=dict(x=x_rough, h_left=h_l, h_right=h_r))


def _imu_errors(model: ImuErrorModel, n: int, rate: float, seed: int):
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
    return out   # bias_g, noise_g, bias_a, noise_a


def _finish(clean: dict, model: ImuErrorModel, seed: int, imu_rate: float, frame_rate: float,
            R_gs, t_gs, params: dict, name: str) -> SimResult:
    n = clean["t"].shape[0]
    bias_g, noise_g, bias_a, noise_a = _imu_errors(model, n, imu_rate, seed)
    frame = "FLU" if np.allclose(R_gs, np.eye(3), atol=1e-12) else "sensor"
    meta = {"seed": seed, "imu_model": model.name, "R_gs": R_gs.tolist(), "t_gs": t_gs.tolist(),
            "simulated": True, "name": name}
    imu_clean = ImuData(clean["t"], clean["gyro"], clean["accel"], frame=frame,
                        source="simulated (noise-free)", meta=dict(meta))
    imu = ImuData(clean["t"], clean["gyro"] + bias_g + noise_g, clean["accel"] + bias_a + noise_a,
                  frame=frame, source="simulated", meta=dict(meta))
    step = int(round(imu_rate / frame_rate))
    idx = np.arange(0, n, step)
    truth = pd.DataFrame({k: np.asarray(v)[idx] for k, v in clean["truth"].items()})
    q = _quat_wxyz(clean["R_ws"][idx])
    for i, c in enumerate("wxyz"):
        truth[f"q{c}"] = q[:, i]
    for i, c in enumerate("xyz"):
        truth[c] = clean["p_ws"][idx, i]
        truth[f"v{c}"] = clean["v_ws"][idx, i]
    truth["stationary"] = truth["speed"].to_numpy() == 0.0
    truth = truth[list(TRUTH_COLUMNS)]
    return SimResult(imu=imu, imu_clean=imu_clean, truth=truth, R_gs=R_gs.copy(), t_gs=t_gs.copy(),
                     imu_model=model, bias_gyro=bias_g, bias_accel=bias_a, R_ws=clean["R_ws"],
                     p_ws=clean["p_ws"], v_ws=clean["v_ws"], params=params, seed=seed, name=name,
                     curves=clean["curves"], road=clean["road"])


def _check_rates(duration, imu_rate, frame_rate, oversample):
    if duration <= 0:
        raise ValueError("duration must be > 0")
    if imu_rate <= 0 or frame_rate <= 0:
        raise ValueError("rates must be > 0")
    ratio = imu_rate / frame_rate
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise ValueError(f"imu_rate / frame_rate must be a whole number, got {ratio}")
    if oversample is None:
        oversample = max(1, int(math.ceil(1000.0 / imu_rate - 1e-9)))
    if int(oversample) < 1:
        raise ValueError("oversample must be >= 1")
    return int(oversample)


def simulate(duration: float = 120.0, seed: int = 0, imu: str | ImuErrorModel | None = "nav", *,
             imu_rate: float = 100.0, frame_rate: float = 10.0,
             road: RoadParams | None = None, vehicle: VehicleParams | None = None,
             speed: SpeedParams | None = None, R_gs=None, t_gs=None,
             oversample: int | None = None, name: str = "") -> SimResult:
    """Simulate one drive with exact ground truth.

    Parameters
    ----------
    duration : float
        Seconds; the IMU has ``floor(duration * imu_rate) + 1`` samples from t = 0.
    seed : int
        Everything random (speed profile, road layout, roughness, IMU errors) follows
        from it; the IMU errors use their own stream, so the same seed with another
        ``imu`` gives the same trajectory.
    imu : str or ImuErrorModel or None
        ``"nav"``, ``"mems"``, ``"perfect"`` (no error), or a model.
    imu_rate, frame_rate : float
        Hz; ``imu_rate / frame_rate`` must be a whole number (truth frames fall on
        IMU samples, the first at t = 0).
    road, vehicle, speed : RoadParams, VehicleParams, SpeedParams
        Defaults when ``None``.
    R_gs, t_gs : array_like
        Extrinsic, body/ground <- sensor; default identity and ``(0.3, 0, 0.9)`` m.
    oversample : int, optional
        Fine-grid factor for the suspension (default: the smallest giving >= 1 kHz).
    name : str

    Returns
    -------
    SimResult
    """
    oversample = _check_rates(duration, imu_rate, frame_rate, oversample)
    road = road or RoadParams()
    vehicle = vehicle or VehicleParams()
    speed = speed or SpeedParams()
    r, t = _as_extrinsic(R_gs, t_gs)
    model = imu_error_model(imu)
    seed = int(seed)
    clean = _clean_drive(float(duration), seed, float(imu_rate), float(frame_rate), road, vehicle,
                         speed, r, t, oversample)
    params = dict(duration=float(duration), seed=seed, imu=model, imu_rate=float(imu_rate),
                  frame_rate=float(frame_rate), road=road, vehicle=vehicle, speed=speed,
                  R_gs=r.tolist(), t_gs=t.tolist(), oversample=oversample, name=name)
    return _finish(clean, model, seed, float(imu_rate), float(frame_rate), r, t, params, name)


def _random_drive(rng: np.random.Generator, duration_range, roughness_classes, styles):
    duration = float(rng.uniform(*duration_range))
    style = str(rng.choice(list(styles)))
    road = RoadParams(roughness=str(rng.choice(list(roughness_classes))),
                      grade_std=float(rng.uniform(0.0, 0.05)),
                      crown=float(rng.uniform(0.0, 0.025)))
    vehicle = VehicleParams(
        wheelbase=float(rng.uniform(2.5, 3.0)), track=float(rng.uniform(1.5, 1.7)),
        pitch_freq=float(rng.uniform(1.1, 1.5)), pitch_damping=float(rng.uniform(0.3, 0.5)),
        roll_freq=float(rng.uniform(1.0, 1.4)), roll_damping=float(rng.uniform(0.3, 0.5)),
        heave_freq=float(rng.uniform(1.0, 1.5)), heave_damping=float(rng.uniform(0.25, 0.4)),
        pitch_gain_deg=float(rng.uniform(0.2, 0.35)), roll_gain_deg=float(rng.uniform(0.3, 0.5)))
    vehicle.rear_axle_to_ref = float(rng.uniform(0.4, 0.6)) * vehicle.wheelbase
    speed = SpeedParams(style=style, start_at_rest=bool(rng.random() < 0.7))
    ang = rng.normal(0.0, 1.5 * _DEG, 3)
    r_gs = rotz(ang[2]) @ roty(ang[1]) @ rotx(ang[0])
    t_gs = np.array([rng.uniform(-1.0, 1.0), rng.uniform(-0.4, 0.4), rng.uniform(0.6, 1.5)])
    return dict(duration=duration, road=road, vehicle=vehicle, speed=speed, R_gs=r_gs, t_gs=t_gs)


def simulate_suite(n: int, seed: int = 0, grades: Sequence[str | ImuErrorModel] = ("nav", "mems"), *,
                   duration_range: tuple[float, float] = (60.0, 180.0),
                   roughness_classes: Sequence[str] = ("A", "B", "C"),
                   styles: Sequence[str] = ("urban", "rural", "highway", "mixed"),
                   imu_rate: float = 100.0, frame_rate: float = 10.0) -> list[SimResult]:
    """``n`` varied drives, each simulated once per IMU grade.

    Every drive draws its duration, roughness class, driving style, grades and
    cross-slope, vehicle geometry and suspension (frequencies 1.0-1.5 Hz, damping
    0.3-0.5, gains 0.2-0.35 / 0.3-0.5 deg per m/s^2) and a slightly misaligned
    mount (1.5 deg per axis) with its lever arm; the grades of one drive share its
    trajectory and extrinsic. Returns ``n * len(grades)`` results, drive-major,
    named ``"drive{i:03d}_{grade}"``; ``simulate(**result.params)`` reproduces any one.
    """
    if n < 0:
        raise ValueError("n must be >= 0")
    oversample = _check_rates(max(duration_range), imu_rate, frame_rate, None)
    models = [imu_error_model(g) for g in grades]
    results: list[SimResult] = []
    for i in range(n):
        drive_seed = int(np.random.SeedSequence([int(seed), i]).generate_state(1)[0])
        cfg = _random_drive(np.random.default_rng([int(seed), i, 1]), duration_range,
                            roughness_classes, styles)
        r, t = _as_extrinsic(cfg["R_gs"], cfg["t_gs"])
        clean = _clean_drive(cfg["duration"], drive_seed, float(imu_rate), float(frame_rate),
                             cfg["road"], cfg["vehicle"], cfg["speed"], r, t, oversample)
        for model in models:
            name = f"drive{i:03d}_{model.name}"
            params = dict(duration=cfg["duration"], seed=drive_seed, imu=model,
                          imu_rate=float(imu_rate), frame_rate=float(frame_rate),
                          road=replace(cfg["road"]), vehicle=replace(cfg["vehicle"]),
                          speed=replace(cfg["speed"]), R_gs=r.tolist(), t_gs=t.tolist(),
                          oversample=oversample, name=name)
            results.append(_finish(clean, model, drive_seed, float(imu_rate), float(frame_rate),
                                   r, t, params, name))
    return results
