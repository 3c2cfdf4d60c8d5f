"""Suites of varied synthetic drives: random roads, vehicles, driving styles and mounts."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from imu_ground.evaluation.simulate.drive import (
    SimResult, as_extrinsic, check_rates, check_seed, clean_drive, finish_drive
)
from imu_ground.errors import OptionError
from imu_ground.evaluation.simulate.imu_errors import ImuErrorModel, imu_error_model
from imu_ground.evaluation.simulate.road import ISO8608_CLASSES, RoadParams
from imu_ground.evaluation.simulate.vehicle import SpeedParams, VehicleParams
from imu_ground.so3 import rotx, roty, rotz
from imu_ground.units import DEG

__all__ = ["MAX_SUITE_DRIVES", "STYLE_MIX", "SuiteRanges", "check_suite_size", "random_drive", "simulate_suite"]

#: Share of each driving style in a suite, like the shared real KITTI drives.
STYLE_MIX = {"urban": 0.4, "mixed": 0.3, "rural": 0.2, "highway": 0.1}


@dataclass(frozen=True)
class SuiteRanges:
    """The ranges a suite draws each drive's road, vehicle and mount from (uniform unless said).

    Road: ``roughness_level`` (``G_d(n0)``, m^3, log-uniform; without ``roughness_classes``) and the
    fields of :class:`~imu_ground.evaluation.simulate.road.RoadParams`. Vehicle: those of
    :class:`~imu_ground.evaluation.simulate.vehicle.VehicleParams`, the reference point as a share of
    the wheelbase. Mount: misalignment std per axis (rad), lever-arm box (m). ``start_at_rest``: a
    probability. Calibrated to the shared real KITTI drives (``benchmarks/studies/sim_vs_real.py``).
    """

    roughness_level: tuple[float, float] = (ISO8608_CLASSES["B"], ISO8608_CLASSES["C"])
    grade_std: tuple[float, float] = (0.002, 0.008)
    crown: tuple[float, float] = (0.015, 0.03)
    grade_segment: tuple[float, float] = (30.0, 200.0)
    grade_transition: tuple[float, float] = (20.0, 80.0)
    wheelbase: tuple[float, float] = (2.5, 3.0)
    track: tuple[float, float] = (1.5, 1.7)
    pitch_freq: tuple[float, float] = (1.2, 1.6)
    pitch_damping: tuple[float, float] = (0.35, 0.55)
    roll_freq: tuple[float, float] = (1.0, 1.4)
    roll_damping: tuple[float, float] = (0.3, 0.5)
    heave_freq: tuple[float, float] = (1.0, 1.5)
    heave_damping: tuple[float, float] = (0.25, 0.4)
    pitch_gain_deg: tuple[float, float] = (0.2, 0.35)
    roll_gain_deg: tuple[float, float] = (0.3, 0.5)
    ref_share: tuple[float, float] = (0.4, 0.6)
    mount_std: float = 1.5 * DEG
    lever_arm: tuple[tuple[float, float], ...] = ((-1.0, 1.0), (-0.4, 0.4), (0.6, 1.5))
    start_at_rest: float = 0.7


def random_drive(rng: np.random.Generator, duration_range, roughness_classes, styles,
                 ranges: SuiteRanges = SuiteRanges()) -> dict:
    """One random drive configuration: duration, road, vehicle, speed style and mount, from ``ranges``.

    Returns
    -------
    dict
        ``duration`` (s), ``road``, ``vehicle``, ``speed``, ``R_gs`` (body <- sensor) and ``t_gs`` (m).
    """
    r = ranges
    u = lambda lim: float(rng.uniform(*lim))           # noqa: E731  (one draw, in this order)
    duration = u(duration_range)
    if isinstance(styles, Mapping):
        names, weights = list(styles), np.array(list(styles.values()), dtype=float)
        style = str(rng.choice(names, p=weights / weights.sum()))
    else:
        style = str(rng.choice(list(styles)))
    if roughness_classes is None:       # a level between the ends, log-uniform
        roughness: str | float = float(np.exp(rng.uniform(*np.log(r.roughness_level))))
    else:
        roughness = str(rng.choice(list(roughness_classes)))
    road = RoadParams(roughness=roughness, grade_std=u(r.grade_std),
                      crown=u(r.crown), grade_segment=r.grade_segment, grade_transition=r.grade_transition)
    vehicle = VehicleParams(
        wheelbase=u(r.wheelbase), track=u(r.track), pitch_freq=u(r.pitch_freq), pitch_damping=u(r.pitch_damping),
        roll_freq=u(r.roll_freq), roll_damping=u(r.roll_damping), heave_freq=u(r.heave_freq),
        heave_damping=u(r.heave_damping), pitch_gain_deg=u(r.pitch_gain_deg), roll_gain_deg=u(r.roll_gain_deg))
    vehicle.rear_axle_to_ref = u(r.ref_share) * vehicle.wheelbase
    speed = SpeedParams(style=style, start_at_rest=bool(rng.random() < r.start_at_rest))
    ang = rng.normal(0.0, r.mount_std, 3)
    r_gs = rotz(ang[2]) @ roty(ang[1]) @ rotx(ang[0])
    t_gs = np.array([u(lim) for lim in r.lever_arm])
    return dict(duration=duration, road=road, vehicle=vehicle, speed=speed, R_gs=r_gs, t_gs=t_gs)


#: Most drives of a suite per IMU grade (every drive is held in memory, with its truth, until the suite returns).
MAX_SUITE_DRIVES = 100


def check_suite_size(n) -> int:
    """The number of drives of a suite per grade, checked: a whole number from 0 to :data:`MAX_SUITE_DRIVES`.

    Raises
    ------
    OptionError
        Otherwise (naming ``--synthetic``).
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n <= MAX_SUITE_DRIVES:
        raise OptionError(f"{{opt}} {n}: a suite has 0 to {MAX_SUITE_DRIVES} drives per IMU grade (all are held "
                          "in memory); for more, run several suites with other seeds", "n", flag="--synthetic")
    return int(n)


def simulate_suite(n: int, seed: int = 0, grades: Sequence[str | ImuErrorModel] = ("nav", "mems"), *,
                   duration_range: tuple[float, float] = (60.0, 180.0),
                   roughness_classes: Sequence[str] | None = None,
                   styles: Sequence[str] | Mapping[str, float] = STYLE_MIX,
                   imu_rate: float = 100.0, frame_rate: float = 10.0,
                   ranges: SuiteRanges = SuiteRanges()) -> list[SimResult]:
    """``n`` varied drives, each simulated once per IMU grade.

    Every drive draws its duration, roughness (``ranges.roughness_level``, or one of
    ``roughness_classes``), style (``styles``: a mapping of style to share, or a sequence drawn
    uniformly), road, vehicle and mount from ``ranges`` (:class:`SuiteRanges`); the grades of one
    drive share its trajectory and extrinsic.

    Returns
    -------
    list of SimResult
        ``n * len(grades)``, drive-major, named ``"drive{i:03d}_{grade}"``; ``simulate(**result.params)``
        reproduces any one.
    """
    check_suite_size(n)
    seed = check_seed(seed)
    oversample = check_rates(max(duration_range), imu_rate, frame_rate, None)
    models = [imu_error_model(g) for g in grades]
    results: list[SimResult] = []
    for i in range(n):
        drive_seed = int(np.random.SeedSequence([int(seed), i]).generate_state(1)[0])
        cfg = random_drive(np.random.default_rng([int(seed), i, 1]), duration_range,
                           roughness_classes, styles, ranges)
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
