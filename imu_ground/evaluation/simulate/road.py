r"""The simulated road: layout along the distance travelled ``s`` (m), and its roughness.

Layout (:func:`road_layout`): horizontal curvature (1/m, > 0 turning left; the
heading follows), grade (rad, uphill +), cross-slope (rad, left edge higher +: the
crown on straights and in curves driven below ``superelevation_speed``,
superelevation above it).

Roughness (:func:`road_profile`): ISO 8608 displacement PSD ``G_d(n) = G_d(n0) (n /
n0)^-w``, ``n0 = 0.1`` cycles/m, classes A-D (:data:`ISO8608_CLASSES`, m^3); the
waviness ``w`` is 2 above ``n0`` and :data:`LONG_WAVINESS` below it by default
(``(2, 2)``: ISO 8608's simplified spectrum), in a band of spatial frequencies. The two
wheel tracks are Gaussian with the coherence ``exp(-k n B)`` (``B`` the track width).

The truth's road plane is the macro road plus the roughness smoothed over
:data:`ROAD_PLANE_WINDOW` metres (:func:`rough_plane`); shorter undulations shake the body.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from imu_ground.evaluation.simulate.smooth import Piecewise
from imu_ground.units import DEG, GRAVITY

__all__ = [
    "ISO8608_CLASSES", "ISO8608_N0", "ROAD_PLANE_WINDOW", "LONG_WAVINESS", "RoadParams", "iso8608_psd", "road_layout",
    "road_profile", "rough_plane"
]

ISO8608_N0 = 0.1                       # cycles/m
ISO8608_CLASSES = {"A": 16e-6, "B": 64e-6, "C": 256e-6, "D": 1024e-6}   # G_d(n0), m^3
#: Length of the centred window (m) over which the roughness counts as part of
#: the road plane in the truth (a triangular kernel: two boxcars of half this).
ROAD_PLANE_WINDOW = 10.0
#: Waviness (PSD exponent) of the roughness below ``n0`` (wavelengths over 10 m).
LONG_WAVINESS = 2.5


@dataclass
class RoadParams:
    """The road: roughness, grades, cross-slope, curves.

    ``roughness``: ISO 8608 class letter, a level ``G_d(n0)`` in m^3, or ``None`` (smooth).
    Grades and cross-slopes are rise over run. Explicit plans replace the random layout:
    ``curve_plan`` ``[(s_start, transition, arc, curvature), ...]`` (m, m, m, 1/m; > 0 left:
    ramp up over ``transition``, hold over ``arc``, ramp down) and ``grade_plan``
    ``[(s_start, transition, grade), ...]`` (to ``grade`` over ``transition`` m).
    """

    roughness: str | float | None = "B"
    band: tuple[float, float] = (0.011, 2.83)     # cycles/m
    waviness: tuple[float, float] = (LONG_WAVINESS, 2.0)   # PSD exponents below / above n0
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
    superelevation_speed: float = 14.0            # m/s: slower curves keep the crown
    curves: bool = True
    straight_length: tuple[float, float] = (60.0, 400.0)     # m
    turn_angle_deg: tuple[float, float] = (30.0, 100.0)
    lat_accel: tuple[float, float] = (0.6, 2.0)   # m/s^2 at the highest speed in the curve
    radius_range: tuple[float, float] = (12.0, 1500.0)       # m
    transition_time: tuple[float, float] = (1.5, 3.0)        # s of driving over a transition
    heading0: float | None = None                 # rad, None: random
    curve_plan: Sequence[tuple[float, float, float, float]] | None = None
    grade_plan: Sequence[tuple[float, float, float]] | None = None


# --------------------------------------------------------------------------- roughness
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


def iso8608_psd(n, roughness: str | float = "B", waviness: tuple[float, float] = (2.0, 2.0)) -> np.ndarray:
    """ISO 8608 displacement PSD ``G_d(n) = G_d(n0) (n / n0)^-w``, m^3 (one-sided).

    Parameters
    ----------
    n : array_like
        Spatial frequency, cycles/m (> 0).
    roughness : str or float
        Class letter or ``G_d(n0)`` in m^3.
    waviness : (float, float)
        Exponent ``w`` below and above ``n0``.
    """
    n = np.asarray(n, dtype=float)
    w = np.where(n < ISO8608_N0, waviness[0], waviness[1])
    return _roughness_level(roughness) * (n / ISO8608_N0) ** -w


def road_profile(length: float, roughness: str | float | None = "B", *, dx: float = 0.05,
                 band: tuple[float, float] = (0.011, 2.83), track: float = 1.6,
                 coherence_decay: float = 4.0, x0: float = 0.0,
                 rng: np.random.Generator | int | None = None,
                 waviness: tuple[float, float] = (2.0, 2.0)):
    """Random left and right wheel-track heights with the ISO 8608 PSD.

    Parameters
    ----------
    length, dx, x0 : float
        Metres of road, sample spacing and first position, m.
    roughness : str, float or None
        ISO 8608 class letter, ``G_d(n0)`` in m^3, or ``None`` (zero heights).
    band : (float, float)
        Spatial-frequency band with the ISO PSD, cycles/m; zero outside.
    track, coherence_decay : float
        Track width (m) and ``k`` of the left/right coherence ``exp(-k n track)``.
    rng : numpy Generator, seed or None
    waviness : (float, float)
        As :func:`iso8608_psd`.

    Returns
    -------
    x, h_left, h_right : ndarray (N,)
        Positions and heights, m (zero mean, the PSD in the band).
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
    psd[inband] = iso8608_psd(freqs[inband], level, waviness)
    amp = 0.5 * n_fft * np.sqrt(psd * dn)
    shape = (2, freqs.size)
    z = amp * (rng.standard_normal(shape) + 1j * rng.standard_normal(shape))
    coh = np.exp(-coherence_decay * freqs * track)
    zr = coh * z[0] + np.sqrt(1.0 - coh * coh) * z[1]
    return x, np.fft.irfft(z[0], n_fft)[:n_pts], np.fft.irfft(zr, n_fft)[:n_pts]


def rough_plane(x, h_l, h_r, s, track, dx):
    """Grade and cross-slope (rad) of the roughness smoothed over :data:`ROAD_PLANE_WINDOW`.

    Parameters
    ----------
    x, h_l, h_r : ndarray (N,)
        The roughness profile (m), as from :func:`road_profile`.
    s : ndarray (M,)
        Distances at which to evaluate, m.
    track, dx : float
        Track width and profile spacing, m.

    Returns
    -------
    grade, bank : ndarray (M,)
        Extra grade (uphill +) and cross-slope (left edge higher +), rad.
    """
    if not np.any(h_l) and not np.any(h_r):
        return np.zeros_like(s), np.zeros_like(s)
    half = max(int(round(0.5 * ROAD_PLANE_WINDOW / dx)), 1)

    def box(h):                       # centred moving average, edges padded with edge values
        hp = np.pad(h, (half, half), mode="edge")
        c = np.concatenate([[0.0], np.cumsum(hp)])
        lo = np.arange(len(h)) + half - half // 2
        return (c[lo + half] - c[lo]) / half

    hl, hr = box(box(h_l)), box(box(h_r))
    slope = np.gradient(0.5 * (hl + hr), x)
    grade = np.arctan(np.interp(s, x, slope))
    bank = np.arctan(np.interp(s, x, (hl - hr) / track))
    return grade, bank


# --------------------------------------------------------------------------- layout
def _max_speed_between(s_grid, v_grid, s_a, s_b):
    i0 = np.searchsorted(s_grid, s_a, side="left")
    i1 = np.searchsorted(s_grid, s_b, side="right")
    lo, hi = max(i0 - 1, 0), min(i1 + 1, len(s_grid))
    return float(v_grid[lo:hi].max()) if hi > lo else float(np.interp(s_a, s_grid, v_grid))


def _random_curves(p: RoadParams, length: float, s_grid, v_grid, rng: np.random.Generator):
    """Random curves ``(s_start, transition, arc, curvature)`` sized to the speed driven there."""
    curves: list[tuple[float, float, float, float]] = []
    s = rng.uniform(*p.straight_length) * rng.uniform(0.2, 1.0)
    while s < length:
        turn = rng.uniform(*p.turn_angle_deg) * DEG
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
    return curves


def _curvature_and_bank(p: RoadParams, curves, s_grid, v_grid, rng: np.random.Generator):
    """Curvature and bank profiles along s from the curves (superelevation from the speed)."""
    kappa_phases, bank_phases = [], []
    crown = math.atan(p.crown)
    s_prev = 0.0
    for s0, w, arc, kappa in curves:
        if s0 < s_prev - 1e-9 or w <= 0 or arc < 0:
            raise ValueError("curves must be sorted, non-overlapping, with transition > 0, arc >= 0")
        vmax = max(_max_speed_between(s_grid, v_grid, s0, s0 + 2 * w + arc), 0.0)
        e = min(p.superelevation_max, p.superelevation_factor * abs(kappa) * vmax * vmax / GRAVITY)
        bank = -math.copysign(math.atan(e), kappa)          # inside of the curve lower
        if vmax < p.superelevation_speed:
            bank = crown                                    # a street: the crown stays
        gap = s0 - s_prev
        kappa_phases += [(gap, 0.0), (w, kappa), (arc, 0.0), (w, -kappa)]
        bank_phases += [(gap, 0.0), (w, bank - crown), (arc, 0.0), (w, crown - bank)]
        s_prev = s0 + 2 * w + arc
    heading0 = rng.uniform(-math.pi, math.pi) if p.heading0 is None else float(p.heading0)
    return Piecewise(0.0, 0.0, kappa_phases, i1_0=heading0), Piecewise(0.0, crown, bank_phases)


def _grade_profile(p: RoadParams, length: float, rng: np.random.Generator) -> Piecewise:
    """Grade along s: constant grades joined by smooth vertical curves."""
    grades: list[tuple[float, float, float]] = []
    g_rand = float(np.clip(rng.normal(0.0, p.grade_std), -p.grade_max, p.grade_max)) if p.grade_std > 0 else 0.0
    g0 = g_rand if p.grade0 is None else float(p.grade0)
    if p.grade_plan is not None:
        grades = [(float(s0), float(w), float(g)) for s0, w, g in p.grade_plan]
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
    return Piecewise(0.0, math.atan(g0), grade_phases)


def road_layout(p: RoadParams, length: float, s_grid, v_grid, rng: np.random.Generator):
    """Curvature, grade and bank profiles along the road, and the list of curves.

    Parameters
    ----------
    p : RoadParams
    length : float
        Metres of road needed.
    s_grid, v_grid : ndarray
        Distance (m) and speed (m/s) on a coarse time grid (curves sized for ``p.lat_accel`` there).
    rng : numpy Generator

    Returns
    -------
    curvature, grade, bank : Piecewise
        Functions of s (m): curvature (1/m; its integral the heading, rad), grade and bank (rad).
    curves : list of (s_start, transition, arc, curvature)
    """
    if p.curve_plan is not None:
        curves = [tuple(map(float, c)) for c in p.curve_plan]
    elif p.curves:
        curves = _random_curves(p, length, s_grid, v_grid, rng)
    else:
        curves = []
    curvature, bank = _curvature_and_bank(p, curves, s_grid, v_grid, rng)
    grade = _grade_profile(p, length, rng)
    return curvature, grade, bank, curves
