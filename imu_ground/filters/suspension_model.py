"""The suspension model of :class:`~imu_ground.filters.suspension.SuspensionAwareFilter`: load in, body tilt out.

Step 2 of that filter's pipeline (the model is in its module docstring). :meth:`SuspensionModel.step` (a
frame) and :meth:`SuspensionModel.run` (a batch) drive the same filters (:class:`~imu_ground.filters.design.IIRFilter`)
and regression, and continue each other.
"""
from __future__ import annotations

from typing import Optional, Sequence, Union

import numpy as np

from imu_ground import so3
from imu_ground.filters.design import IIRFilter, butter_bandpass, foh_filter
from imu_ground.filters.gains import TYPICAL_BAND_POWER, tilt_angles
from imu_ground.filters.status import tilt_weights
from imu_ground.imu.warm_start import as_reader

__all__ = ["SuspensionModel", "load_share"]

_LOADS = {"specific_force": 1.0, "acceleration": 0.0}


def load_share(load: Union[str, float]) -> float:
    """The share ``s`` (0 to 1) of gravity's road-plane component in the load, from its name or value.

    Raises
    ------
    ValueError
        Not ``"specific_force"`` (1), ``"acceleration"`` (0) or a number in [0, 1].
    """
    if isinstance(load, str):
        if load not in _LOADS:
            raise ValueError(f"load must be 'specific_force', 'acceleration' or a share in [0, 1], got {load!r}")
        return _LOADS[load]
    share = float(load)
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"load share must be in [0, 1], got {load!r}")
    return share


class SuspensionModel:
    """Load, gains and body tilt of one filter (its state: the response, the online regression).

    Parameters
    ----------
    gains0 : ndarray (2,)
        ``(k_pitch, k_roll)`` at the start (the prior with ``online_gains``), rad per m/s^2.
    load_share, response, cross_gain, online_gains, gain_prior_seconds, gain_band
        As ``load`` (its share ``s``) and these parameters of
        :class:`~imu_ground.filters.suspension.SuspensionAwareFilter`.
    Rgs : ndarray (3, 3) or None
        Static rotation ground <- sensor of the increments given to :meth:`step`; None: identity.

    Attributes
    ----------
    gains, load : ndarray (2,), (float, float)
        Current ``(k_pitch, k_roll)`` (rad per m/s^2); the last frame's ``(u_x, u_y)`` (m/s^2).
    rate : float or None
        Frame rate of the design, Hz (None before the first frame).
    tilt_weights : (float, float)
        :func:`~imu_ground.filters.status.tilt_weights` of the current gains.
    """

    def __init__(self, gains0: np.ndarray, load_share: float, response: Optional[Sequence[float]],
                 cross_gain: float, online_gains: bool, gain_prior_seconds: float,
                 gain_band: Sequence[float], Rgs: Optional[np.ndarray]) -> None:
        self.gains0, self.load_share, self.response = gains0, load_share, response
        self.cross_gain, self.online_gains = cross_gain, online_gains
        self.gain_prior_seconds, self.gain_band, self._Rgs = gain_prior_seconds, gain_band, Rgs
        self.reset()

    def reset(self) -> None:
        """Prior gains, no design yet, zero load."""
        self.gains = self.gains0.copy()
        self._kp, self._kr = (float(g) for g in self.gains0)
        self.rate: Optional[float] = None
        self._resp: Optional[IIRFilter] = None
        self._bpf: Optional[IIRFilter] = None
        self._phi = np.zeros(2)
        self._sxx: Optional[np.ndarray] = None
        self._sxy: Optional[np.ndarray] = None
        self.load: tuple[float, ...] = (0.0, 0.0)
        self._set_tilt_weights()

    def _set_tilt_weights(self) -> None:
        self.tilt_weights = tilt_weights(self._kp, self._kr, self.load_share, self.cross_gain)

    def set_mount(self, Rgs: Optional[np.ndarray]) -> None:
        """The static rotation ground <- sensor of the increments given to :meth:`step` from now on."""
        self._Rgs = Rgs

    def state_dict(self) -> dict:
        """The model's state as plain values (gains, design rate, the filters' memories, the sums, the load)."""
        return {"gains": self.gains.tolist(), "rate": self.rate,
                "response": None if self._resp is None else self._resp.state_dict(),
                "bandpass": None if self._bpf is None else self._bpf.state_dict(),
                "phi": self._phi.tolist(), "sxx": None if self._sxx is None else self._sxx.tolist(),
                "sxy": None if self._sxy is None else self._sxy.tolist(), "load": list(self.load)}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (a dict or a StateReader), every entry checked before the model changes."""
        st = as_reader(state, "SuspensionModel")
        rate = st.float("rate", optional=True)
        gains, phi, load = st.floats("gains", (2,)), st.floats("phi", (2,)), st.floats("load", (2,))
        sxx, sxy = st.floats("sxx", (2,), optional=True), st.floats("sxy", (2,), optional=True)
        if rate is not None and not rate > 0:
            raise st.error("rate", f"is {rate!r}, expected a frame rate > 0 Hz")
        self.reset()
        if rate is not None:
            self.design(rate)
        for name, filt in (("response", self._resp), ("bandpass", self._bpf)):
            part = st.part(name, optional=True)
            if filt is not None and part is not None:
                filt.load_state_dict(part)
        self.gains = gains
        self._kp, self._kr = (float(g) for g in gains)
        self._set_tilt_weights()
        self._phi, self._sxx, self._sxy = phi, sxx, sxy
        self.load = tuple(float(v) for v in load)

    def design(self, rate: float) -> None:
        """Discrete-time design for frames at ``rate`` Hz (once; a later rate more than 2 % off is an error)."""
        if self.rate is not None:
            if abs(rate - self.rate) > 0.02 * self.rate and (self.online_gains or self.response is not None):
                raise ValueError(f"the filter is designed for {self.rate:g} Hz frames but got {rate:g} Hz "
                                 f"(reset() or a new filter for another frame rate)")
            return
        self.rate = float(rate)
        if self.response is not None:
            num, _, den = foh_filter(self.response[0], self.response[1], 1.0 / rate)
            self._resp = IIRFilter(num, den, 2, steady=True)
        if self.online_gains:
            self._bpf = IIRFilter(*butter_bandpass(self.gain_band, rate), 4)
            w = self.gain_prior_seconds * rate * np.asarray(TYPICAL_BAND_POWER)
            self._sxx = w.copy()          # the sums include the prior: gains = sxy / sxx
            self._sxy = w * self.gains0

    def step(self, d: np.ndarray, fx: float, fy: float, ax: float, ay: float,
             lateral: Optional[float] = None) -> tuple:
        """One frame: its load, the tilt from the gains so far, then (online) the gains updated.

        Parameters
        ----------
        d : ndarray (3, 3)
            The frame's sensor increment (sensor_{k-1} <- sensor_k), for the online regression.
        fx, fy, ax, ay : float
            Horizontal specific force and acceleration, body frame, m/s^2.
        lateral : float, optional
            Kinematic lateral acceleration (speed times yaw rate), m/s^2, in place of ``ay`` in ``u_y``.

        Returns
        -------
        tilt_x, tilt_y : float
            Roll ``k_roll u_y`` and pitch ``k_pitch u_x + k_cross u_y``, rad (the residual kernel's tilt inputs).
        """
        s = self.load_share
        ux, uy = ax + s * (fx - ax), ay + s * (fy - ay)
        if lateral is not None:
            uy += lateral - ay
        if self._resp is not None:
            ux, uy = self._resp.step(np.array([ux, uy])).tolist()
        self.load = (ux, uy)
        kp, kr = self._kp, self._kr
        if self.online_gains:
            db = d if self._Rgs is None else self._Rgs @ d @ self._Rgs.T
            self._online_gains(so3.log_one(db)[None, [1, 0]], np.array([[ax, ay]]))
        return kr * uy, kp * ux + self.cross_gain * uy

    def run(self, gt, lateral: Optional[np.ndarray] = None) -> tuple:
        """A drive: loads, the gains used at each frame, and the tilt, continuing as :meth:`step` would.

        Parameters
        ----------
        gt : GravityTrack
            The gravity/velocity filter's track of the frames.
        lateral : ndarray (N,), optional
            ``lateral`` of :meth:`step` per frame (NaN: the filter's ``a_y``).

        Returns
        -------
        load, gains, tilt : ndarray (N, 2)
            ``(u_x, u_y)`` (m/s^2), ``(k_pitch, k_roll)`` and ``(pitch, roll)`` of :meth:`tilt` (rad).
        """
        m = len(gt.acceleration)
        u = (gt.acceleration + self.load_share * (gt.specific_force - gt.acceleration))[:, :2]
        if lateral is not None:
            use = np.isfinite(lateral)
            u[use, 1] += lateral[use] - gt.acceleration[use, 1]
        if self._resp is not None:
            u = self._resp.run(u)
        if m:
            self.load = tuple(u[-1].tolist())
        if self.online_gains and m:
            ks = self._online_gains(tilt_angles(gt.body_increments), gt.acceleration[:, :2])
        else:
            ks = np.tile(self.gains, (m, 1))
        return u, ks, self.tilt(ks, u)

    def tilt(self, gains: np.ndarray, load: np.ndarray) -> np.ndarray:
        """``(pitch, roll) = (k_pitch u_x + k_cross u_y, k_roll u_y)`` per frame, rad, (N, 2)."""
        susp = gains * load
        susp[:, 0] += self.cross_gain * load[:, 1]
        return susp

    def _online_gains(self, tilt: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
        """Gains used at each of N frames (the frame before's estimate), (N, 2), from the body tilt (pitch, roll;
        rad) accumulated since the first of them (:func:`~imu_ground.filters.gains.tilt_angles`) and
        ``(a_x, a_y)``; advances the regression."""
        assert self._bpf is not None and self._sxx is not None and self._sxy is not None  # designed, online gains
        phi = self._phi + tilt
        z = self._bpf.run(np.concatenate([acceleration, phi], axis=1))
        sxy = self._sxy + np.cumsum(z[:, :2] * z[:, 2:], axis=0)
        sxx = self._sxx + np.cumsum(z[:, :2] * z[:, :2], axis=0)
        ks = np.vstack([self.gains[None], (sxy / sxx)[:-1]])
        self._phi, self._sxy, self._sxx = phi[-1].copy(), sxy[-1].copy(), sxx[-1].copy()
        self.gains = self._sxy / self._sxx
        self._kp, self._kr = self.gains.tolist()
        self._set_tilt_weights()
        return ks
