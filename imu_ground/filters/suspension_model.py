"""The suspension model of :class:`~imu_ground.filters.suspension.SuspensionAwareFilter`: load in, body tilt out.

Step 2 of that filter's pipeline (the model is in its module docstring). :meth:`SuspensionModel.step` (a
frame) and :meth:`SuspensionModel.run` (a batch) drive the same filters (:class:`~imu_ground.filters.design.IIRFilter`)
and regression, and continue each other.
"""
from __future__ import annotations

from typing import Optional, Sequence, Union

import numpy as np

from imu_ground import so3
from imu_ground._jit import njit
from imu_ground.filters.design import IIRFilter, butter_bandpass, foh_filter, lfilter_df2t
from imu_ground.filters.gains import TYPICAL_BAND_POWER
from imu_ground.filters.status import tilt_weights
from imu_ground.imu.warm_start import as_reader

__all__ = ["SuspensionModel", "load_share"]

_LOADS = {"specific_force": 1.0, "acceleration": 0.0}
# The online regression's state (floats): the tilt integrated so far (pitch, roll; rad), the sums
# sxx (acceleration^2) and sxy (tilt x acceleration) per axis, the current gains (k_pitch, k_roll)
_R_PHI, _R_SXX, _R_SXY, _R_GAINS, _R_SIZE = 0, 2, 4, 6, 8


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
        self._reg = np.zeros(_R_SIZE)
        self._reg[_R_GAINS:] = self.gains0
        self._frame1, self._ks1 = np.empty((1, 4)), np.empty((1, 2))    # step's one frame of the regression
        self._has_sums = False                  # sxx, sxy set (designed with online gains, or loaded)
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
                "phi": self._reg[_R_PHI:_R_SXX].tolist(),
                "sxx": self._reg[_R_SXX:_R_SXY].tolist() if self._has_sums else None,
                "sxy": self._reg[_R_SXY:_R_GAINS].tolist() if self._has_sums else None, "load": list(self.load)}

    def load_state_dict(self, state) -> None:
        """Back to a :meth:`state_dict` (a dict or a StateReader), every entry checked before the model changes."""
        st = as_reader(state, "SuspensionModel")
        rate = st.float("rate", optional=True)
        gains, phi, load = st.floats("gains", (2,)), st.floats("phi", (2,)), st.floats("load", (2,))
        sxx, sxy = st.floats("sxx", (2,), optional=True), st.floats("sxy", (2,), optional=True)
        if rate is not None and not rate > 0:
            raise st.error("rate", f"is {rate!r}, expected a frame rate > 0 Hz")
        if (sxx is None) != (sxy is None):
            raise st.error("sxx" if sxx is None else "sxy", "is null but its partner is not: the regression's "
                           "two sums are saved together or not at all")
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
        self._reg[_R_PHI:_R_SXX], self._reg[_R_GAINS:] = phi, gains
        self._has_sums = sxx is not None
        if sxx is not None:
            self._reg[_R_SXX:_R_SXY], self._reg[_R_SXY:_R_GAINS] = sxx, sxy
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
            self._reg[_R_SXX:_R_SXY] = w          # the sums include the prior: gains = sxy / sxx
            self._reg[_R_SXY:_R_GAINS] = w * self.gains0
            self._has_sums = True

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
            Rgs = self._Rgs
            db = d if Rgs is None else Rgs @ d @ Rgs.T
            wx, wy, _ = so3.log_flat(db.ravel().tolist())
            frame = self._frame1
            frame[0, 0], frame[0, 1], frame[0, 2], frame[0, 3] = wy, wx, ax, ay
            self._online_gains(frame, self._ks1)
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
            w = so3.log(np.asarray(gt.body_increments, dtype=float))
            ks = self._online_gains(np.column_stack([w[:, 1], w[:, 0], gt.acceleration[:, :2]]), np.empty((m, 2)))
        else:
            ks = np.tile(self.gains, (m, 1))
        return u, ks, self.tilt(ks, u)

    def tilt(self, gains: np.ndarray, load: np.ndarray) -> np.ndarray:
        """``(pitch, roll) = (k_pitch u_x + k_cross u_y, k_roll u_y)`` per frame, rad, (N, 2)."""
        susp = gains * load
        susp[:, 0] += self.cross_gain * load[:, 1]
        return susp

    def _online_gains(self, frames: np.ndarray, ks: np.ndarray) -> np.ndarray:
        """Gains used at each of N frames (the frame before's estimate) written into ``ks`` (N, 2) and returned,
        from ``frames`` (N, 4, C-contiguous): each frame's body tilt increment (pitch, roll; rad; the rotation
        vector's y and x of its body increment) and ``(a_x, a_y)`` (m/s^2); advances the regression
        (:func:`_regression`)."""
        bpf = self._bpf
        assert bpf is not None and self._has_sums      # designed, online gains
        reg = self._reg
        _regression(bpf.b, bpf.a, bpf.z, reg, frames, ks)
        bpf.started = True
        self.gains = reg[_R_GAINS:].copy()
        self._kp, self._kr = self.gains.tolist()
        self._set_tilt_weights()
        return ks


@njit
def _regression(b: np.ndarray, a: np.ndarray, z: np.ndarray, reg: np.ndarray, frames: np.ndarray,
                ks: np.ndarray) -> None:
    """The online gain regression over N frames (one frame live, a drive in a batch), the state ``reg`` advanced.

    Per frame: the tilt integrated (``phi``), ``(a_x, a_y, phi_pitch, phi_roll)`` band-passed by the filter
    ``b, a`` with memory ``z`` (4 channels), then ``sxy += a_bp phi_bp``, ``sxx += a_bp^2`` per axis and the gains
    ``sxy / sxx``; ``ks[i]`` gets the gains before frame ``i``'s update. The increments and the products are
    summed from zero, then added to the state (one call over N frames and N calls over one agree to rounding).

    Parameters
    ----------
    b, a, z : ndarray
        The band-pass (:func:`~imu_ground.filters.design.lfilter_df2t`); ``z`` (M, 4) advanced in place.
    reg : ndarray (8,)
        ``phi`` (rad), ``sxx`` ((m/s^2)^2), ``sxy`` (rad m/s^2), gains (rad per m/s^2), two each, advanced.
    frames : ndarray (N, 4)
        Tilt increment (pitch, roll; rad) and ``(a_x, a_y)`` (m/s^2) per frame.
    ks : ndarray (N, 2)
        Written: ``(k_pitch, k_roll)`` used at each frame.
    """
    n = frames.shape[0]
    u = np.empty((n, 4))
    c0 = c1 = 0.0
    for i in range(n):
        c0 += frames[i, 0]
        c1 += frames[i, 1]
        u[i, 0], u[i, 1] = frames[i, 2], frames[i, 3]
        u[i, 2], u[i, 3] = reg[_R_PHI] + c0, reg[_R_PHI + 1] + c1
    y = np.empty((n, 4))
    lfilter_df2t(b, a, z, u, y)
    x0 = x1 = p0 = p1 = 0.0
    k0, k1 = reg[_R_GAINS], reg[_R_GAINS + 1]
    sxx0, sxx1, sxy0, sxy1 = reg[_R_SXX], reg[_R_SXX + 1], reg[_R_SXY], reg[_R_SXY + 1]
    for i in range(n):
        ks[i, 0], ks[i, 1] = k0, k1
        p0 += y[i, 0] * y[i, 2]
        p1 += y[i, 1] * y[i, 3]
        x0 += y[i, 0] * y[i, 0]
        x1 += y[i, 1] * y[i, 1]
        k0, k1 = (sxy0 + p0) / (sxx0 + x0), (sxy1 + p1) / (sxx1 + x1)
    if n:
        reg[_R_PHI], reg[_R_PHI + 1] = u[n - 1, 2], u[n - 1, 3]
        reg[_R_SXX], reg[_R_SXX + 1], reg[_R_SXY], reg[_R_SXY + 1] = sxx0 + x0, sxx1 + x1, sxy0 + p0, sxy1 + p1
        reg[_R_GAINS], reg[_R_GAINS + 1] = k0, k1
