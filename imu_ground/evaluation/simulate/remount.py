"""A drive whose sensor is turned on its mount part-way: the case the mount monitor must flag.

After the instant the sensor frame ``s'`` relates to the old one by ``R = R_{s<-s'}``:
``w_s' = R^T w_s``, ``f_s' = R^T f_s``, ``R_ws' = R_ws R``, ``n_s' = R^T n_s`` (the gyro does
not see the turn itself); the body's truth is unchanged and ``R_gs`` stays the extrinsic known
before the change.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from imu_ground.evaluation.simulate.drive import SimResult

__all__ = ["remounted"]


def remounted(sim: SimResult, at: float, rotation) -> SimResult:
    """The drive with its sensor turned by ``rotation`` (``R_{s<-s'}``, 3x3) from time ``at`` (s) on.

    Returns
    -------
    SimResult
        A copy: ``imu`` and ``imu_clean`` samples at or after ``at`` in the turned frame, ``R_ws``
        and the truth's ``normal_x/y/z`` (sensor frame) of the turned sensor; named ``NAME_remounted``.
    """
    R = np.asarray(rotation, dtype=float).reshape(3, 3)
    after = sim.imu.t >= at

    def turned(imu):
        g, a = imu.gyro.copy(), imu.accel.copy()
        g[after], a[after] = g[after] @ R, a[after] @ R          # rows: (R^T x)^T = x^T R
        return replace(imu, gyro=g, accel=a)
    truth = sim.truth.copy()
    late = truth["t"].to_numpy() >= at
    n = truth[["normal_x", "normal_y", "normal_z"]].to_numpy().copy()
    n[late] = n[late] @ R
    truth[["normal_x", "normal_y", "normal_z"]] = n
    R_ws = sim.R_ws.copy()
    R_ws[after] = R_ws[after] @ R
    return replace(sim, imu=turned(sim.imu), imu_clean=turned(sim.imu_clean), truth=truth, R_ws=R_ws,
                   params=dict(sim.params, remount=dict(at=float(at), rotation=R.tolist())),
                   name=f"{sim.name}_remounted" if sim.name else "remounted")
