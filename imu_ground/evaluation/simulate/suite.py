"""Suites of varied synthetic drives: random roads, vehicles, driving styles and mounts."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from imu_ground.evaluation.simulate.drive import (
    SimResult,
    as_extrinsic,
    check_rates,
    clean_drive,
    finish_drive,
)
from imu_ground.evaluation.simulate.imu_errors import ImuErrorModel, imu_error_model
from imu_ground.evaluation.simulate.road import RoadParams
from imu_ground.evaluation.simulate.vehicle import SpeedParams, VehicleParams
from imu_ground.so3 import rotx, roty, rotz
from imu_ground.units import DEG

__all__ = ["random_drive", "simulate_suite"]


def random_drive(rng: np.random.Generator, duration_range, roughness_classes, styles) -> dict:
    """One random drive configuration: duration, road, vehicle, speed style and mount.

    Returns
    -------
    dict
        ``duration`` (s), ``road``, ``vehicle``, ``speed`` (parameter objects),
        ``R_gs`` (body <- sensor, 1.5 deg per axis) and ``t_gs`` (lever arm, m).
    """
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
    ang = rng.normal(0.0, 1.5 * DEG, 3)
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
    oversample = check_rates(max(duration_range), imu_rate, frame_rate, None)
    models = [imu_error_model(g) for g in grades]
    results: list[SimResult] = []
    for i in range(n):
        drive_seed = int(np.random.SeedSequence([int(seed), i]).generate_state(1)[0])
        cfg = random_drive(np.random.default_rng([int(seed), i, 1]), duration_range,
                           roughness_classes, styles)
        r, t = as_extrinsic(cfg["R_gs"], cfg["t_gs"])
        clean = clean_drive(cfg["duration"], drive_seed, float(imu_rate), cfg["road"], cfg["vehicle"],
                            cfg["speed"], r, t, oversample)
        for model in models:
            name = f"drive{i:03d}_{model.name}"
            params = dict(duration=cfg["duration"], seed=drive_seed, imu=model,
                          imu_rate=float(imu_rate), frame_rate=float(frame_rate),
                          road=replace(cfg["road"]), vehicle=replace(cfg["vehicle"]),
                          speed=replace(cfg["speed"]), R_gs=r.tolist(), t_gs=t.tolist(),
                          oversample=oversample, name=name)
            results.append(finish_drive(clean, model, drive_seed, float(imu_rate), float(frame_rate),
                                        r, t, params, name))
    return results
