"""The same road driven a second time: what a revisit check sees when the truth is exact.

The road is a function of the distance ``s``, so frames of both passes with the same ``s``
are on the same place, heading the same way. The sensor keeps the first pass's bias path
sample by sample (held past its end), with its own white noise.
"""
from __future__ import annotations

import numpy as np

from imu_ground.evaluation.simulate.drive import (SimResult, as_extrinsic, drive_on_road, drive_road, finish_drive,
                                                  motion_of)
from imu_ground.evaluation.simulate.imu_errors import imu_errors
from imu_ground.evaluation.simulate.vehicle import speed_profile

__all__ = ["second_pass"]

#: ``SimResult.params`` keys of a drive :func:`second_pass` can drive again (as :func:`~.drive.simulate` takes them).
_PARAMS = ("duration", "seed", "imu", "imu_rate", "frame_rate", "road", "vehicle", "speed", "R_gs", "t_gs",
           "oversample")


def _held(path: np.ndarray, n: int) -> np.ndarray:
    """The first ``n`` rows of ``path`` (N, 3), its last row repeated past its end."""
    if n <= len(path):
        return path[:n].copy()
    return np.concatenate([path, np.repeat(path[-1:], n - len(path), axis=0)])


def second_pass(sim: SimResult, *, speed_scale: float = 1.0, speed_seed: int | None = None,
                noise_seed: int | None = None) -> SimResult:
    """The road of ``sim`` driven again from its start (module docstring).

    Parameters
    ----------
    sim : SimResult
        A drive from ``simulate`` or ``simulate_suite`` (its ``params`` rebuild the road).
    speed_scale : float
        ``k > 0``: ``v_2(s) = k v_1(s)`` at every place (``k = 1``: only the noise differs).
    speed_seed : int, optional
        Instead, a new random speed profile of the drive's style from this seed.
    noise_seed : int, optional
        Seed of the second pass's white noise (default ``sim.seed + 1``).

    Returns
    -------
    SimResult
        Named ``NAME_second_pass``, its time from 0, ``params`` the first pass's plus ``second_pass``
        (the three arguments); its truth's ``s`` the distance along the same road.

    Raises
    ------
    ValueError
        ``sim`` has no simulation parameters (e.g. a remounted drive), or ``speed_scale <= 0``.
    """
    p = sim.params
    if any(k not in p for k in _PARAMS) or set(p) - set(_PARAMS) - {"name"}:
        raise ValueError(f"{sim.name or 'drive'}: second_pass needs a drive from simulate() or simulate_suite() "
                         "(its params rebuild the road)")
    if not speed_scale > 0.0:
        raise ValueError(f"speed_scale must be > 0, got {speed_scale}")
    R_gs, t_gs = as_extrinsic(p["R_gs"], p["t_gs"])
    rate, duration = float(p["imu_rate"]), float(p["duration"])
    acc1, layout, curves, rough = drive_road(duration, int(p["seed"]), p["road"], p["vehicle"], p["speed"])
    first_motion = motion_of(acc1)
    s_end = float(first_motion(np.array([duration]))[2][0])
    if speed_seed is None:
        k = float(speed_scale)

        def motion(t):                              # at time t the second pass is where the first was at k t
            a, v, s = first_motion(k * np.asarray(t, dtype=float))
            return k * k * a, k * v, s
        duration2 = duration / k
    else:
        motion = motion_of(speed_profile(p["speed"], duration, np.random.default_rng(int(speed_seed))))
        tc = np.arange(0.0, duration, 0.1)
        past = np.flatnonzero(motion(tc)[2] >= s_end)
        duration2 = float(tc[past[0]]) if len(past) else duration
    clean = drive_on_road(motion, duration2, rate, layout, rough, p["road"], p["vehicle"], R_gs, t_gs,
                          int(p["oversample"]))
    clean["curves"] = curves
    n = len(clean["t"])
    nseed = int(sim.seed) + 1 if noise_seed is None else int(noise_seed)
    _, noise_g, _, noise_a = imu_errors(sim.imu_model, n, rate, nseed)
    errors = (_held(sim.bias_gyro, n), noise_g, _held(sim.bias_accel, n), noise_a)
    name = f"{sim.name}_second_pass" if sim.name else "second_pass"
    params = dict(p, name=name, second_pass=dict(speed_scale=float(speed_scale), speed_seed=speed_seed, noise_seed=nseed))
    return finish_drive(clean, sim.imu_model, int(sim.seed), rate, float(p["frame_rate"]), R_gs, t_gs, params, name,
                        errors=errors)
