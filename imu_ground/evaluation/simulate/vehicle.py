r"""The simulated vehicle: speed profile in time, and the body on its suspension.

Speed
    Smooth-step phases of the longitudinal acceleration (:func:`speed_profile`);
    speed and distance are closed-form integrals, stops exact.

Suspension
    ``x'' + 2 zeta w x' + w^2 x = w^2 (r(t) + l(t)) + 2 zeta w r'(t)`` for pitch, roll
    and heave (unit static gain): ``r`` the road input through springs and dampers
    (the base-excited quarter car; ``VehicleParams.damper_road_input=False`` drops
    the damper term), ``l`` the load: pitch ``-K_pitch * f_x``, roll ``+K_roll * f_y``
    (``f`` the specific force of the reference point in the road frame; with
    ``gravity_load_transfer`` also gravity along the grade and cross-slope): braking
    pitches the nose down, a left turn raises the left side. Road inputs: pitch
    ``-(h_front - h_rear) / wheelbase``, roll ``(h_left - h_right) / track``, heave the
    wheel plane under the reference point. Discretised exactly for a first-order-hold
    input (:func:`suspension_response`, :func:`imu_ground.filters.design.foh_filter`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from imu_ground.evaluation.simulate.smooth import Piecewise
from imu_ground.filters.design import foh_filter
from imu_ground.units import DEG, GRAVITY

__all__ = [
    "STOP_BRAKE", "STYLES", "SpeedParams", "VehicleParams", "body_motion", "speed_profile", "suspension_response"
]


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
    damper_road_input: bool = True       # the dampers transmit the road's velocity (False: springs only)


#: Driving styles: speed range (m/s), probability of a stop at each change,
#: cruise duration (s) between changes, acceleration and braking magnitudes (m/s^2)
#: and the largest speed change of one manoeuvre (m/s); calibrated to the shared real KITTI drives
#: (``benchmarks/studies/sim_vs_real.py``).
STYLES: dict[str, dict[str, Any]] = {
    "urban": dict(speed=(4.0, 14.0), stop_p=0.08, cruise=(0.3, 3.0), accel=(0.35, 1.6), brake=(0.35, 1.9), step=5.0),
    "rural": dict(speed=(10.0, 18.0), stop_p=0.02, cruise=(0.5, 6.0), accel=(0.3, 1.3), brake=(0.3, 1.5), step=5.0),
    "highway": dict(speed=(18.0, 28.0), stop_p=0.0, cruise=(2.0, 12.0), accel=(0.2, 0.9), brake=(0.2, 1.1), step=5.0),
    "mixed": dict(speed=(4.0, 16.0), stop_p=0.05, cruise=(0.3, 4.0), accel=(0.35, 1.6), brake=(0.35, 1.9), step=6.0),
}
#: Braking magnitude (m/s^2) of a stop: drivers brake harder to a standstill than in traffic.
STOP_BRAKE = (0.8, 2.2)


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
    step: float | None = None                     # m/s, largest speed change of one manoeuvre
    ramp_time: tuple[float, float] = (0.6, 1.6)   # s of jerk at each end of a speed change
    stop_duration: tuple[float, float] = (2.0, 25.0)
    start_at_rest: bool = True
    initial_rest: tuple[float, float] = (3.0, 6.0)
    plan: Sequence[tuple[float, float, float]] | None = None
    v_start: float = 0.0


# --------------------------------------------------------------------------- speed
def _speed_change(phases: list, v_from: float, v_to: float, a_mag: float, ramp: float) -> float:
    """Append the phases of one speed change (jerk ramp, constant acceleration, ramp); its seconds."""
    dv = v_to - v_from
    if dv == 0.0 or a_mag <= 0.0:
        return 0.0
    hold = abs(dv) / a_mag - ramp
    if hold < 0.0:
        hold, a_mag = 0.0, abs(dv) / ramp
    a_p = math.copysign(a_mag, dv)
    phases.extend([(ramp, a_p), (hold, 0.0), (ramp, -a_p)])
    return 2.0 * ramp + hold


def _random_speed(p: SpeedParams, duration: float, rng: np.random.Generator) -> Piecewise:
    style = STYLES.get(p.style)
    if style is None:
        raise ValueError(f"unknown speed style {p.style!r}; choose one of {sorted(STYLES)}")
    vr = p.speed_range or style["speed"]
    stop_p = style["stop_p"] if p.stop_probability is None else p.stop_probability
    cruise = p.cruise_duration or style["cruise"]
    acc = p.accel or style["accel"]
    brk = p.brake or style["brake"]
    step = style["step"] if p.step is None else float(p.step)
    phases: list[tuple[float, float]] = []
    t = 0.0
    if p.start_at_rest:
        v = 0.0
        rest = rng.uniform(*p.initial_rest)
        phases.append((rest, 0.0))
        t += rest
    else:
        v = rng.uniform(*vr)
    v0 = v
    while t < duration:
        stop = v > 0.0 and rng.random() < stop_p
        if stop:
            target = 0.0
        elif v == 0.0:              # moving off: to a speed of the style's lower part
            target = rng.uniform(vr[0], min(vr[1], vr[0] + step))
        else:
            target = rng.uniform(max(vr[0], v - step), min(vr[1], v + step))
            if abs(target - v) < 0.5:
                target = min(vr[1], v + 1.0) if v < 0.5 * (vr[0] + vr[1]) else max(vr[0], v - 1.0)
        a_mag = rng.uniform(*(acc if target > v else STOP_BRAKE if stop else brk))
        t += _speed_change(phases, v, target, a_mag, rng.uniform(*p.ramp_time))
        v = target
        hold = rng.uniform(*(p.stop_duration if v == 0.0 else cruise))
        phases.append((hold, 0.0))
        t += hold
    return Piecewise(0.0, 0.0, phases, i1_0=v0, snap=True)


def speed_profile(p: SpeedParams, duration: float, rng: np.random.Generator) -> Piecewise:
    """Longitudinal acceleration (m/s^2; its integrals the speed and distance) in time (s).

    ``p.plan`` if given, otherwise drawn from ``rng`` by ``p.style`` until ``duration`` s are covered.
    """
    if p.plan is None:
        return _random_speed(p, duration, rng)
    phases: list[tuple[float, float]] = []
    v = float(p.v_start)
    ramp = float(np.mean(p.ramp_time))
    for target, accel, hold in p.plan:
        if target < 0:
            raise ValueError("speeds in the plan must be >= 0")
        _speed_change(phases, v, float(target), float(accel), ramp)
        v = float(target)
        if hold > 0:
            phases.append((float(hold), 0.0))
    return Piecewise(0.0, 0.0, phases, i1_0=float(p.v_start), snap=True)


# --------------------------------------------------------------------------- suspension
def suspension_response(u, dt: float, freq: float, damping: float, gain: float = 1.0):
    """Exact response of ``x'' + 2 zeta w x' + w^2 x = w^2 gain u(t)``, ``w = 2 pi freq``.

    ``u`` linear between samples (first-order hold), starting at rest in equilibrium with ``u[0]``.

    Parameters
    ----------
    u : array_like (N,)
    dt, freq, damping, gain : float
        Sample interval (s), undamped natural frequency (Hz), damping ratio, static gain.

    Returns
    -------
    x, xdot, xddot : ndarray (N,)
    """
    from scipy.signal import lfilter, lfilter_zi
    u = gain * np.asarray(u, dtype=float)
    num_x, num_v, den = foh_filter(freq, damping, dt)
    x = lfilter(num_x, den, u, zi=lfilter_zi(num_x, den) * u[0])[0]
    v = lfilter(num_v, den, u, zi=lfilter_zi(num_v, den) * u[0])[0]
    w = 2.0 * math.pi * freq
    acc = w * w * (u - x) - 2.0 * damping * w * v
    return x, v, acc


def _profile_at(x_rough, h, pos):
    """Height (m) of a uniformly sampled profile, linear between samples, and its slope dh/ds there."""
    dx = x_rough[1] - x_rough[0]
    i = np.clip(np.floor((pos - x_rough[0]) / dx).astype(int), 0, len(x_rough) - 2)
    slope = (h[i + 1] - h[i]) / dx
    return h[i] + slope * (pos - x_rough[i]), slope


def _road_inputs(vehicle: VehicleParams, s_f, v_f, rough):
    """Pitch, roll and heave inputs of the roughness under the four wheels at distances ``s_f``,
    and their exact time derivatives (the profile's slope under each wheel times the speed ``v_f``)."""
    x_rough, h_l, h_r = rough
    l_r = vehicle.rear_axle_to_ref
    l_f = vehicle.wheelbase - l_r
    front, rear = s_f + l_f, s_f - l_r
    heights, slopes = zip(*(_profile_at(x_rough, h, pos) for pos in (front, rear) for h in (h_l, h_r)), strict=True)

    def inputs(fl, fr, rl, rr):
        h_front, h_rear = 0.5 * (fl + fr), 0.5 * (rl + rr)
        return (-(h_front - h_rear) / vehicle.wheelbase, (0.5 * (fl + rl) - 0.5 * (fr + rr)) / vehicle.track,
                (l_r * h_front + l_f * h_rear) / vehicle.wheelbase)

    return inputs(*heights), tuple(d * v_f for d in inputs(*slopes))          # wheels fl, fr, rl, rr


def _base_excited(road, road_rate, load, dt_f: float, freq: float, damping: float, damper: bool = True):
    """One suspension mode (module docstring): by linearity ``x = y + (2 zeta / w) y' + x_load``, ``y`` the
    plain response to the road (``damper=False``: without the ``y'`` term)."""
    y, yd, ydd = suspension_response(road, dt_f, freq, damping)
    x_l, xd_l, xdd_l = suspension_response(load, dt_f, freq, damping)
    w = 2.0 * math.pi * freq
    c = 2.0 * damping / w if damper else 0.0
    yddd = w * w * (road_rate - yd) - 2.0 * damping * w * ydd
    return y + c * yd + x_l, yd + c * ydd + xd_l, ydd + c * yddd + xdd_l


def _load_transfer(vehicle: VehicleParams, a_f, v_f, s_f, layout):
    """Road-frame specific force ``(f_x, f_y)`` of the reference point (m/s^2) at the fine grid."""
    kappa_pw, grade_pw, bank_pw = layout
    al, al_s, _, _, _ = grade_pw(s_f)
    bk = bank_pw(s_f)[0]
    kap = kappa_pw(s_f)[0]
    th_r = -al
    psi_d, th_d = kap * v_f, -al_s * v_f          # the yaw rate about the road's z holds no roll rate
    w_rz = -np.sin(bk) * th_d + np.cos(bk) * np.cos(th_r) * psi_d
    f_x = a_f.copy()
    f_y = v_f * w_rz
    if vehicle.gravity_load_transfer:
        f_x += GRAVITY * np.sin(al)
        f_y += GRAVITY * np.cos(th_r) * np.sin(bk)
    return f_x, f_y


def body_motion(vehicle: VehicleParams, a_f, v_f, s_f, dt_f: float, layout, rough):
    """Body pitch, roll and heave relative to the road on a fine time grid.

    Parameters
    ----------
    vehicle : VehicleParams
    a_f, v_f, s_f : ndarray (N,)
        Longitudinal acceleration (m/s^2), speed (m/s), distance (m) on the fine grid of step ``dt_f`` (s).
    layout, rough
        The road profiles and the roughness (:mod:`~imu_ground.evaluation.simulate.road`).

    Returns
    -------
    pitch, roll, heave : tuple of three ndarrays (N,)
        Each ``(value, rate, acceleration)``: rad, rad/s, rad/s^2 (heave m, m/s, m/s^2).
    """
    (u_pitch, u_roll, u_heave), (du_pitch, du_roll, du_heave) = _road_inputs(vehicle, s_f, v_f, rough)
    load_pitch = load_roll = np.zeros_like(s_f)
    if vehicle.pitch_gain_deg or vehicle.roll_gain_deg:
        f_x, f_y = _load_transfer(vehicle, a_f, v_f, s_f, layout)
        load_pitch = -vehicle.pitch_gain_deg * DEG * f_x
        load_roll = vehicle.roll_gain_deg * DEG * f_y
    modes = (("pitch", u_pitch, du_pitch, load_pitch), ("roll", u_roll, du_roll, load_roll),
             ("heave", u_heave, du_heave, np.zeros_like(s_f)))
    return tuple(_base_excited(u, du, load, dt_f, getattr(vehicle, f"{mode}_freq"),
                               getattr(vehicle, f"{mode}_damping"), vehicle.damper_road_input)
                 for mode, u, du, load in modes)
