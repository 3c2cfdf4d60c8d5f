r"""One simulated drive with exact truth: :func:`clean_drive` (the road and speed, :func:`drive_road`; the body on
a fine grid and the sensor's kinematics, :func:`drive_on_road`), then the IMU errors and frames (:func:`finish_drive`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from imu_ground import so3
from imu_ground.errors import OptionError
from imu_ground.evaluation.simulate.imu_errors import ImuErrorModel, imu_error_model, imu_errors
from imu_ground.evaluation.simulate.kinematics import quat_wxyz, road_positions, sensor_kinematics
from imu_ground.evaluation.simulate.road import RoadParams, road_layout, road_profile, rough_plane
from imu_ground.evaluation.simulate.vehicle import SpeedParams, VehicleParams, body_motion, speed_profile
from imu_ground.filters.estimator import pitch_roll_from_normal
from imu_ground.imu.data import ImuData

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "MAX_DURATION_S", "MAX_IMU_RATE_HZ", "MAX_IMU_SAMPLES", "TRUTH_ANGLES", "TRUTH_COLUMNS", "SimResult",
    "as_extrinsic", "check_rates", "check_seed", "clean_drive", "drive_on_road", "drive_road", "finish_drive",
    "motion_of", "simulate"
]

TRUTH_COLUMNS = (
    "t", "s", "speed", "acc_long", "acc_lat", "curvature", "heading",
    "normal_x", "normal_y", "normal_z", "normal_body_x", "normal_body_y", "normal_body_z",
    "pitch", "roll", "pitch_rate", "roll_rate", "heave", "road_grade", "road_bank",
    "qw", "qx", "qy", "qz", "x", "y", "z", "vx", "vy", "vz", "stationary",
)
#: Truth columns in radians (or rad/s) -> their name in the written truth file, in degrees (or deg/s).
TRUTH_ANGLES = {"heading": "heading_deg", "pitch": "pitch_deg", "roll": "roll_deg", "pitch_rate": "pitch_rate_deg_s",
                "roll_rate": "roll_rate_deg_s", "road_grade": "road_grade_deg", "road_bank": "road_bank_deg"}


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
        One row a frame, columns :data:`TRUTH_COLUMNS`: ``t`` s; ``s`` distance m; ``speed`` m/s;
        ``acc_long``, ``acc_lat`` (road frame, > 0 left) m/s^2; ``curvature`` 1/m (> 0 left); ``heading``
        rad; the ground normal in the sensor (``normal_x/y/z``) and body (``normal_body_*``) frames;
        body ``pitch``, ``roll`` relative to the road (rad, nose down / left up positive) and their rates
        rad/s; ``heave`` m; ``road_grade`` (uphill +), ``road_bank`` (left edge higher +) rad; ``qw qx qy
        qz`` world <- sensor (``qw >= 0``); sensor position ``x y z`` and velocity ``vx vy vz`` in the
        world frame (m, m/s); ``stationary`` (speed exactly 0).
    R_gs, t_gs : ndarray
        The extrinsic (body/ground <- sensor rotation, sensor origin in the body frame).
    imu_model : ImuErrorModel
    bias_gyro, bias_accel : ndarray (N, 3)
        The true biases at every IMU sample.
    R_ws, p_ws, v_ws : ndarray
        World <- sensor attitude (N, 3, 3), position and velocity (N, 3) at every IMU sample.
    params : dict
        ``simulate(**params)`` gives this drive again.
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

    def truth_table(self) -> pd.DataFrame:
        """The truth as written to a file: :data:`TRUTH_ANGLES` in degrees and renamed, ``stationary`` as 0/1."""
        truth = self.truth.copy()
        truth["stationary"] = truth["stationary"].astype(int)
        for col in TRUTH_ANGLES:
            truth[col] = np.degrees(truth[col].to_numpy(dtype=float))
        return truth.rename(columns=TRUTH_ANGLES)

    def to_csv(self, imu_path, truth_path=None, float_format: str = "%.10g") -> None:
        """Write the noisy IMU (columns t,wx,wy,wz,ax,ay,az; s, rad/s, m/s^2) and, if given,
        the truth (:meth:`truth_table`: angles in degrees, e.g. ``pitch_deg``, ``roll_deg``)."""
        df = self.imu.to_dataframe()[["t", "wx", "wy", "wz", "ax", "ay", "az"]]
        df.to_csv(imu_path, index=False, float_format=float_format, lineterminator="\n")
        if truth_path is not None:
            self.truth_table().to_csv(truth_path, index=False, float_format=float_format, lineterminator="\n")


def as_extrinsic(R_gs, t_gs):
    """The checked extrinsic: ``R_gs`` (default identity) and ``t_gs`` (default ``(0.3, 0, 0.9)`` m)."""
    r = np.eye(3) if R_gs is None else np.array(R_gs, dtype=float)
    t = np.array([0.3, 0.0, 0.9]) if t_gs is None else np.array(t_gs, dtype=float)
    if r.shape != (3, 3) or t.shape != (3,):
        raise ValueError("R_gs must be 3x3 and t_gs of length 3")
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
        raise ValueError("R_gs must be a rotation matrix")
    return r, t


#: Longest simulated drive, s (one hour).
MAX_DURATION_S = 3600.0
#: Highest simulated IMU rate, Hz.
MAX_IMU_RATE_HZ = 1000.0
#: Most IMU samples of one simulated drive, ``duration * imu_rate``: an hour at 100 Hz. Time and memory grow in
#: proportion to the samples (and to the suspension's fine grid of at least 1 kHz), so the bound keeps one drive
#: within an ordinary machine's memory; longer studies simulate several drives (seeds).
MAX_IMU_SAMPLES = 360_000


def check_rates(duration, imu_rate, frame_rate, oversample) -> int:
    """Check a drive's duration and rates; the fine-grid factor (default: the smallest giving >= 1 kHz).

    Raises
    ------
    OptionError
        Not a finite number > 0, shorter than one frame, a rate not a whole multiple of the frame
        rate, or over :data:`MAX_DURATION_S`, :data:`MAX_IMU_RATE_HZ` or :data:`MAX_IMU_SAMPLES`.
    """
    for value, name, flag in ((imu_rate, "imu_rate", "--rate"), (frame_rate, "frame_rate", None),
                              (duration, "duration", None)):
        try:
            ok = math.isfinite(value) and value > 0
        except TypeError:
            ok = False
        if not ok:
            raise OptionError(f"{{opt}} {value}: must be a finite number > 0", name, flag=flag)
    ratio = imu_rate / frame_rate
    if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
        raise OptionError(f"{{opt}} {imu_rate:g}: the IMU rate must be a whole multiple of the truth's "
                          f"{frame_rate:g} Hz frame rate (e.g. 100, 200, 400)", "imu_rate", flag="--rate")
    if imu_rate > MAX_IMU_RATE_HZ:
        raise OptionError(f"{{opt}} {imu_rate:g}: over the simulator's highest IMU rate, {MAX_IMU_RATE_HZ:g} Hz",
                          "imu_rate", flag="--rate")
    if duration < 1.0 / frame_rate:
        raise OptionError(f"{{opt}} {duration:g}: shorter than one frame of the truth ({1.0 / frame_rate:g} s at "
                          f"{frame_rate:g} Hz)", "duration")
    if duration > MAX_DURATION_S:
        raise OptionError(f"{{opt}} {duration:g}: over the simulator's longest drive, {MAX_DURATION_S:g} s (one "
                          "hour); for more, simulate several drives (other seeds)", "duration")
    if duration * imu_rate > MAX_IMU_SAMPLES:
        raise OptionError(f"{{opt}} {duration:g} at {imu_rate:g} Hz: {duration * imu_rate:.0f} IMU samples, over the "
                          f"simulator's {MAX_IMU_SAMPLES} (an hour at 100 Hz); shorten the drive or lower the rate "
                          f"(at {imu_rate:g} Hz at most {MAX_IMU_SAMPLES / imu_rate:g} s)", "duration")
    if oversample is None:
        oversample = max(1, int(math.ceil(1000.0 / imu_rate - 1e-9)))
    if int(oversample) < 1:
        raise OptionError(f"{{opt}} {oversample}: must be >= 1", "oversample")
    return int(oversample)


def _truth_samples(kin, body, rough, s, vehicle: VehicleParams, road: RoadParams, t_imu, a, v, R_gs):
    """Per-sample truth columns against the macro road plus the smoothed roughness (``rough_plane``)."""
    (th, th_d1, _), (ph, ph_d1, _), (zh, _, _) = body
    d_grade, d_bank = rough_plane(rough[0], rough[1], rough[2], s, vehicle.track, road.dx)
    al_t, bk_t = kin["grade"] + d_grade, kin["bank"] + d_bank
    r_wr_t = so3.rotz(kin["heading"]) @ so3.roty(-al_t) @ so3.rotx(bk_t)
    n_b = np.einsum("nji,nj->ni", kin["R_wb"], r_wr_t[:, :, 2])      # E^T e_z, E = R_wr^T R_wb
    th_t, ph_t = pitch_roll_from_normal(n_b)
    n_s = n_b @ R_gs
    return {
        "t": t_imu, "s": s, "speed": v, "acc_long": a, "acc_lat": kin["acc_lat"],
        "curvature": kin["curvature"], "heading": kin["heading"],
        "normal_x": n_s[:, 0], "normal_y": n_s[:, 1], "normal_z": n_s[:, 2],
        "normal_body_x": n_b[:, 0], "normal_body_y": n_b[:, 1], "normal_body_z": n_b[:, 2],
        "pitch": th_t, "roll": ph_t, "pitch_rate": th_d1, "roll_rate": ph_d1, "heave": zh,
        "road_grade": al_t, "road_bank": bk_t,
    }


def check_seed(seed) -> int:
    """A random seed as an int; a seed that is not a whole number >= 0 (NumPy's seeds are) is an
    :class:`OptionError` naming ``seed``."""
    try:
        value = int(seed)
    except (TypeError, ValueError):
        value = -1
    if value < 0 or value != seed:
        raise OptionError(f"{{opt}} {seed}: a seed is a whole number >= 0", "seed")
    return value


def clean_drive(duration: float, seed: int, imu_rate: float, road: RoadParams, vehicle: VehicleParams,
                speed: SpeedParams, R_gs: np.ndarray, t_gs: np.ndarray, oversample: int) -> dict:
    """The exact trajectory and noise-free IMU samples of one drive.

    Returns
    -------
    dict
        ``t``, ``gyro``, ``accel``, ``R_ws``, ``R_wr``, ``p_ws``, ``v_ws``, ``truth`` (per-sample columns),
        ``curves``, ``road`` (roughness profile).
    """
    acc_pw, layout, curves, rough = drive_road(duration, seed, road, vehicle, speed)
    out = drive_on_road(motion_of(acc_pw), duration, imu_rate, layout, rough, road, vehicle, R_gs, t_gs, oversample)
    out["curves"] = curves
    return out


def drive_road(duration: float, seed: int, road: RoadParams, vehicle: VehicleParams, speed: SpeedParams) -> tuple:
    """The speed profile of a drive and the road it is driven on (the first three children of
    ``SeedSequence(seed)``; the IMU errors use the fourth).

    Returns
    -------
    acc_pw, layout, curves, rough
        Acceleration in time (``speed_profile``), ``(curvature, grade, bank)`` along the distance and
        curves (``road_layout``), ``(x, h_left, h_right)`` per wheel track, m (``road_profile``).
    """
    rng_speed, rng_road, rng_rough, _ = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4))
    acc_pw = speed_profile(speed, duration, rng_speed)
    t_coarse = np.linspace(0.0, duration, int(duration * 10) + 2)
    _, _, _, v_c, s_c = acc_pw(t_coarse)
    v_c = np.maximum(v_c, 0.0)
    length = float(s_c[-1]) + vehicle.wheelbase + 50.0
    kappa_pw, grade_pw, bank_pw, curves = road_layout(road, length, s_c, v_c, rng_road)
    l_r = vehicle.rear_axle_to_ref
    rough = road_profile(length + l_r + 20.0, road.roughness, dx=road.dx, band=road.band,
                         track=vehicle.track, coherence_decay=road.coherence_decay,
                         x0=-l_r - 10.0, rng=rng_rough, waviness=road.waviness)
    return acc_pw, (kappa_pw, grade_pw, bank_pw), curves, rough


def motion_of(acc_pw):
    """``t -> (acceleration, speed, distance)`` (m/s^2, m/s, m) of a speed profile
    (:func:`~imu_ground.evaluation.simulate.vehicle.speed_profile`), the speed held at or above 0."""
    def motion(t):
        a, _, _, v, s = acc_pw(t)
        return a, np.maximum(v, 0.0), s
    return motion


def drive_on_road(motion, duration: float, imu_rate: float, layout: tuple, rough: tuple, road: RoadParams,
                  vehicle: VehicleParams, R_gs: np.ndarray, t_gs: np.ndarray, oversample: int) -> dict:
    """The exact trajectory and noise-free IMU samples of a vehicle driven along a given road.

    Parameters
    ----------
    motion : callable
        ``t -> (a, v, s)``: m/s^2, m/s (>= 0), m at ``t`` (s) (:func:`motion_of`).
    duration, imu_rate : float
        s, Hz: samples at ``k / imu_rate`` up to ``duration``.
    layout, rough
        As :func:`drive_road` returns them; the rest as :func:`clean_drive`.

    Returns
    -------
    dict
        As :func:`clean_drive` (``curves`` empty).
    """
    n_imu = int(math.floor(duration * imu_rate + 1e-9)) + 1
    dt = 1.0 / imu_rate
    t_imu = dt * np.arange(n_imu)
    dt_f = dt / oversample
    t_f = dt_f * np.arange((n_imu - 1) * oversample + 1)
    a_f, v_f, s_f = motion(t_f)
    body_f = body_motion(vehicle, a_f, v_f, s_f, dt_f, layout, rough)
    sub = slice(None, None, oversample)
    body = tuple(tuple(x[sub] for x in axis) for axis in body_f)
    a, v, s = a_f[sub], v_f[sub], s_f[sub]
    kin = sensor_kinematics(a, v, s, layout, body, R_gs, t_gs)
    p_wb = road_positions(t_imu, dt, motion, layout) + body[2][0][:, None] * np.array([0.0, 0.0, 1.0])
    p_ws = p_wb + np.einsum("nij,j->ni", kin["R_wb"], t_gs)
    truth = _truth_samples(kin, body, rough, s, vehicle, road, t_imu, a, v, R_gs)
    return dict(t=t_imu, gyro=kin["gyro"], accel=kin["accel"], R_ws=kin["R_ws"], R_wr=kin["R_wr"],
                p_ws=p_ws, v_ws=kin["v_ws"], truth=truth, curves=[],
                road=dict(x=rough[0], h_left=rough[1], h_right=rough[2]))


def finish_drive(clean: dict, model: ImuErrorModel, seed: int, imu_rate: float, frame_rate: float,
                 R_gs, t_gs, params: dict, name: str, errors: tuple | None = None) -> SimResult:
    """Add the IMU errors of ``model`` to a clean drive and sample the truth at the frames.

    ``errors``: ``(bias_gyro, noise_gyro, bias_accel, noise_accel)``, each (N, 3), sensor frame (rad/s, m/s^2);
    default drawn by ``imu_errors`` from ``seed``.
    """
    import pandas as pd
    n = clean["t"].shape[0]
    bias_g, noise_g, bias_a, noise_a = imu_errors(model, n, imu_rate, seed) if errors is None else errors
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
    q = quat_wxyz(clean["R_ws"][idx])
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
        Everything random; the IMU errors have their own stream (another ``imu``: the same trajectory).
    imu : str or ImuErrorModel or None
        ``"nav"``, ``"mems"``, ``"perfect"`` (no error), or a model.
    imu_rate, frame_rate : float
        Hz; ``imu_rate / frame_rate`` a whole number (truth frames on IMU samples from t = 0).
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
    oversample = check_rates(duration, imu_rate, frame_rate, oversample)
    road = road or RoadParams()
    vehicle = vehicle or VehicleParams()
    speed = speed or SpeedParams()
    r, t = as_extrinsic(R_gs, t_gs)
    model = imu_error_model(imu)
    seed = check_seed(seed)
    clean = clean_drive(float(duration), seed, float(imu_rate), road, vehicle, speed, r, t, oversample)
    params = dict(duration=float(duration), seed=seed, imu=model, imu_rate=float(imu_rate),
                  frame_rate=float(frame_rate), road=road, vehicle=vehicle, speed=speed,
                  R_gs=r.tolist(), t_gs=t.tolist(), oversample=oversample, name=name)
    return finish_drive(clean, model, seed, float(imu_rate), float(frame_rate), r, t, params, name)
