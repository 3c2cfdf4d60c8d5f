"""Drives with ground truth for the evaluation (:class:`Drive`: ego-motion, static extrinsic, truth at the frames).

- Real ``kitti_imu100`` drives (:func:`load_real_drive`): pitch only (the INS reference and its
  verdict, :mod:`~imu_ground.evaluation.reference`), moving frames valid in the ego-motion, means
  removed per drive, the reference's 1-sigma per frame; faulty drives reported, not averaged.
- Synthetic drives (:func:`synthetic_drive`): exact truth, pitch and roll, nothing removed; every
  method gets the true static extrinsic.
"""
from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from imu_ground.datasets import read_kitti_imu100
from imu_ground.datasets.kitti_imu100 import drive_name
from imu_ground.evaluation.conditions import frame_signals, reference_sigma
from imu_ground.evaluation.reference import MIN_SPEED, check_reference, pitch_reference
from imu_ground.evaluation.simulate import simulate_suite
from imu_ground.filters import Extrinsic
from imu_ground.imu import EgoMotion, ImuData, imu_to_egomotion
from imu_ground.units import DEFAULT_FRAME_RATE

__all__ = ["Drive", "drive_name", "load_real_drive", "load_real_drives", "synthetic_drive",
           "synthetic_drives"]


@dataclass
class Drive:
    """One drive for evaluation.

    Attributes
    ----------
    name : str
    kind : {"real", "synthetic"}
    grade : str
        IMU grade (``"oxts"`` for KITTI, ``"nav"`` or ``"mems"``).
    egomotion, extrinsic : EgoMotion, Extrinsic
        Frames in the IMU (sensor) frame; the static extrinsic (ground <- sensor) every method gets.
    truth : pandas.DataFrame
        Per frame: ``t`` (s), ``pitch``, ``roll`` (rad), ``normal_x/y/z`` (sensor frame; NaN when
        unknown), ``speed`` (m/s), ``evaluate`` (the frames that count), ``ref_sigma`` (rad) and the
        condition signals (:func:`~imu_ground.evaluation.conditions.frame_signals`).
    remove_mean : bool
        Centre estimate and truth per drive before the errors (real protocol).
    valid : bool
        False when the truth is unusable; ``reason`` says why.
    reason : str
    imu, sim, check : optional
        The raw log, the simulation (synthetic) or the reference's verdict (real).
    """
    name: str
    kind: str
    grade: str
    egomotion: EgoMotion
    extrinsic: Extrinsic
    truth: Any
    remove_mean: bool
    valid: bool = True
    reason: str = "ok"
    imu: ImuData | None = field(default=None, repr=False)
    sim: object | None = field(default=None, repr=False)
    check: object | None = field(default=None, repr=False)

    @property
    def has_roll(self) -> bool:
        """Whether the truth has roll (synthetic drives)."""
        return bool(np.isfinite(self.truth["roll"]).any())


def _truth_frame(em: EgoMotion, ext: Extrinsic, columns: dict):
    """The truth table of a drive: the given columns plus the condition signals."""
    import pandas as pd
    truth = pd.DataFrame({"t": em.t, **columns})
    for key, value in frame_signals(em, ext.rotation, truth["speed"].to_numpy(float)).items():
        if key != "speed":
            truth[key] = value
    return truth


def load_real_drive(path: Path, rate: float = DEFAULT_FRAME_RATE) -> Drive:
    """A ``kitti_imu100`` drive with its pitch-relative-to-road reference.

    Parameters
    ----------
    path : Path
        ``.../kitti_imu100/<drive>.csv.gz``.
    rate : float
        Frame rate, Hz.

    Returns
    -------
    Drive
        ``valid``, ``reason`` and ``check`` from the signals alone; the reader's warnings in
        ``egomotion.meta["reader_warnings"]``.
    """
    path = Path(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        imu = read_kitti_imu100(path)
    em = imu_to_egomotion(imu, rate=rate)
    df = imu.to_dataframe()
    ref = pitch_reference(df, times=em.t)
    check = check_reference(df, ref)
    n = len(em)
    ext = Extrinsic()
    truth = _truth_frame(em, ext, {
        "pitch": ref.pitch_rel_road, "roll": np.full(n, np.nan), "normal_x": np.nan, "normal_y": np.nan,
        "normal_z": np.nan, "speed": ref.speed, "evaluate": ref.valid & em.valid,
        "ref_sigma": reference_sigma(ref.speed)})
    drive = Drive(drive_name(path), "real", "oxts", em, ext, truth, True, check.valid, check.reason, imu,
                  check=check)
    drive.egomotion.meta["reader_warnings"] = [str(w.message) for w in caught]
    return drive


def load_real_drives(folder: Path, names: Sequence[str] | None = None, progress: bool = True,
                     rate: float = DEFAULT_FRAME_RATE, valid_only: bool = False) -> list[Drive]:
    """All ``*.csv.gz`` drives of a ``kitti_imu100`` folder (or the named ones), sorted by name.

    Parameters
    ----------
    folder : Path
    names : sequence of str, optional
        Drive names (e.g. ``2011_09_26_drive_0001``); every one must exist.
    progress : bool
    rate : float
        Frame rate, Hz.
    valid_only : bool
        Keep only the drives whose reference passes the checks.
    """
    from tqdm.auto import tqdm
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"real-data folder not found: {folder}")
    paths = sorted(folder.glob("*.csv.gz"))
    if names:
        wanted = set(names)
        paths = [p for p in paths if drive_name(p) in wanted]
        missing = wanted - {drive_name(p) for p in paths}
        if missing:
            raise FileNotFoundError(f"drives not found in {folder}: {', '.join(sorted(missing))}")
    if not paths:
        raise FileNotFoundError(f"no *.csv.gz drives in {folder}")
    drives = [load_real_drive(p, rate) for p in tqdm(paths, desc="loading drives", unit="drive",
                                                     disable=not progress)]
    return [d for d in drives if d.valid] if valid_only else drives


def synthetic_drive(sim, rate: float = DEFAULT_FRAME_RATE) -> Drive:
    """A :class:`Drive` from a :class:`~imu_ground.evaluation.simulate.SimResult` (exact truth)."""
    em = imu_to_egomotion(sim.imu, rate=rate)
    tr = sim.truth
    idx = np.clip(np.searchsorted(tr["t"].to_numpy(), em.t - 1e-6), 0, len(tr) - 1)
    if np.abs(tr["t"].to_numpy()[idx] - em.t).max() > 1e-6:
        raise ValueError(f"{sim.name}: truth frames do not line up with the IMU frames")
    sel = tr.iloc[idx].reset_index(drop=True)
    ext = Extrinsic(sim.R_gs, sim.t_gs, {"source": "simulation truth"})
    truth = _truth_frame(em, ext, {
        **{k: sel[k].to_numpy() for k in ("pitch", "roll", "normal_x", "normal_y", "normal_z", "speed")},
        "evaluate": (sel["speed"] > MIN_SPEED).to_numpy() & em.valid, "ref_sigma": np.zeros(len(em))})
    return Drive(sim.name, "synthetic", sim.imu_model.name, em, ext, truth, False, True, "ok", sim.imu, sim)


def synthetic_drives(n: int = 10, seed: int = 0, grades: Sequence[str] = ("nav", "mems"),
                     progress: bool = True, **kw) -> list[Drive]:
    """A synthetic suite: ``n`` drives per IMU grade (see :func:`imu_ground.evaluation.simulate.simulate_suite`)."""
    from tqdm.auto import tqdm

    sims = simulate_suite(n, seed=seed, grades=tuple(grades), **kw)
    return [synthetic_drive(s) for s in tqdm(sims, desc="simulating", unit="drive", disable=not progress)]
