"""Warm start of the streaming filters: what ``state_dict()`` / ``load_state_dict()`` save and restore.

The format and its checks are :mod:`imu_ground.imu.warm_start`'s. Each filter's
dynamic state is its kernels' flat buffers (the residual filter's, the
gravity/velocity filter's, the invariant EKF's: restored bit for bit, so a resumed
run continues exactly) plus the few Python attributes around them (frame count,
convergence latch, online-gain sums, the discrete-time filters' memories). The
settings saved beside it are the constructor's options; loading into a filter
built with other options is refused.
"""
from __future__ import annotations

from array import array

import numpy as np

from imu_ground.imu.warm_start import pack_state, unpack_state

__all__ = ["STATE_VERSION", "ground_state", "load_ground_state", "gravity_state", "load_gravity_state",
           "suspension_state", "load_suspension_state"]

#: Layout of the saved states of this module (raised when one changes).
STATE_VERSION = 1


def _like(old, values):
    """``values`` in the container type of ``old`` (array('d'), numpy array or list)."""
    if isinstance(old, array):
        return array("d", values)
    if isinstance(old, np.ndarray):
        return np.array(values, dtype=float)
    return [float(v) for v in values]


def _extrinsic(ext) -> dict:
    return {"rotation": ext.rotation, "translation": ext.translation}


# ---------------------------------------------------------------------------------------- gravity / velocity
def _gravity_settings(f) -> dict:
    return dict(sigma_speed=f.sigma_speed, sigma_nhc=f.sigma_nhc, sigma_zupt=f.sigma_zupt, q_v=f.q_v, q_g=f.q_g,
                q_gap=f.q_gap, sigma_v0=f.sigma_v0, sigma_g0=f.sigma_g0, zupt_gate=f.zupt_gate,
                extrinsic=_extrinsic(f.extrinsic), lever_arm=f.lever_arm, R0=f.R0, v0=f._v0, g0=f._g0)


def _gravity_buffer(f) -> list:
    if f._w.sync is not None:
        f._pull()
    return [float(v) for v in f._s]


def _load_gravity_buffer(f, values) -> None:
    f._w.sync = None
    if len(values) != len(f._s):
        raise ValueError(f"the saved gravity/velocity state has {len(values)} values, this filter {len(f._s)}")
    f._s = _like(f._s, values)


def gravity_state(f) -> dict:
    """``GravityVelocityFilter.state_dict()``."""
    return pack_state("GravityVelocityFilter", STATE_VERSION, _gravity_settings(f), {"buffer": _gravity_buffer(f)})


def load_gravity_state(f, saved) -> None:
    """``GravityVelocityFilter.load_state_dict(saved)``."""
    st = unpack_state(saved, "GravityVelocityFilter", STATE_VERSION, _gravity_settings(f))
    _load_gravity_buffer(f, st["buffer"])


# ---------------------------------------------------------------------------------------- invariant filter
def _ground_settings(f) -> dict:
    return dict(Q=f._Q, R=f._R, P=f._P0, extrinsic=_extrinsic(f.extrinsic), measurement=f.measurement,
                follow_heading=f.follow_heading, R0=f.R0, on_invalid=f.on_invalid)


def ground_state(f) -> dict:
    """``GroundNormalFilter.state_dict()``."""
    st = {"frames": f._frames, "converged": f._converged, "kernel": list(f._kernel.buf)}
    if f.ekf is not None:
        f.ekf._take_held()
        st["ekf"], st["cumulative"] = list(f.ekf._s), f._engine.cumulative
    return pack_state("GroundNormalFilter", STATE_VERSION, _ground_settings(f), st)


def load_ground_state(f, saved) -> None:
    """``GroundNormalFilter.load_state_dict(saved)``."""
    st = unpack_state(saved, "GroundNormalFilter", STATE_VERSION, _ground_settings(f))
    f.reset()
    f._frames, f._converged = int(st["frames"]), bool(st["converged"])
    k = f._kernel
    k.buf = _like(k.buf, st["kernel"])
    if f.ekf is None:
        f._engine._buf = k.buf                      # the residual engine's fast path holds the buffer
    else:
        e = f.ekf
        e._s = _like(e._s, st["ekf"])
        e._x_a = e._P_a = e._Q_a = e._R_a = None
        e._x_t, e._held = b"", False
        f._engine.cumulative = np.array(st["cumulative"], dtype=float)


# ---------------------------------------------------------------------------------------- suspension-aware
def _suspension_settings(f) -> dict:
    return dict(gains=f.gains0, sigma_e=f.sigma_e, q_time=f.q_time, q_dist=f.q_dist, q_yaw=f.q_yaw, r_yaw=f.r_yaw,
                P0=f.P0, load=f.load_share, response=f.response, online_gains=f.online_gains,
                gain_prior_seconds=f.gain_prior_seconds, gain_band=f.gain_band, frame_rate=f.frame_rate,
                smoother_weight=f.smoother_weight, extrinsic=_extrinsic(f.extrinsic), lever_arm=f.lever_arm,
                gravity=dict(f._gravity_kw), R0=f.R0, on_invalid=f.on_invalid, cross_gain=f.cross_gain,
                lateral=f.lateral, q_turn=f.q_turn,
                **({"recalibrate_online": True} if f.recalibrate_online else {}))


def _iir(filt):
    return None if filt is None else {"z": filt.z, "started": filt.started}


def _load_iir(filt, saved) -> None:
    if filt is not None and saved is not None:
        filt.z = np.array(saved["z"], dtype=float).reshape(filt.z.shape)
        filt.started = bool(saved["started"])


def suspension_state(f) -> dict:
    """``SuspensionAwareFilter.state_dict()``."""
    m = f.model
    st = {"frames": f._frames, "converged": f._converged, "kernel": list(f._kernel.buf),
          "gravity": _gravity_buffer(f.gravity_filter), "gains": m.gains, "rate": m.rate,
          "response": _iir(m._resp), "bandpass": _iir(m._bpf), "phi": m._phi, "sxx": m._sxx, "sxy": m._sxy,
          "load": m.load, "speed": f.speed, "q_last": f._q_last,
          "road": None if f.road_filter.gravity_filter is None else _gravity_buffer(f.road_filter.gravity_filter),
          "monitor": f.mount_monitor.state(), "time": f._time}
    if f.recalibrator is not None:             # the online re-estimation: its record and the mount now
        st["recalibrator"] = f.recalibrator.state()
        st["mount"] = None if f._Rgs is None else f._Rgs.ravel().tolist()
    return pack_state("SuspensionAwareFilter", STATE_VERSION, _suspension_settings(f), st)


def load_suspension_state(f, saved) -> None:
    """``SuspensionAwareFilter.load_state_dict(saved)``."""
    st = unpack_state(saved, "SuspensionAwareFilter", STATE_VERSION, _suspension_settings(f))
    f.reset()
    m = f.model
    if st["rate"] is not None:
        m.design(float(st["rate"]))
    k = f._kernel
    k.buf = _like(k.buf, st["kernel"])
    f._kbuf = k.buf
    _load_gravity_buffer(f.gravity_filter, st["gravity"])
    f._frames, f._converged = int(st["frames"]), bool(st["converged"])
    m.gains = np.array(st["gains"], dtype=float)
    m._kp, m._kr = (float(g) for g in m.gains)
    m._set_tilt_weights()
    _load_iir(m._resp, st["response"])
    _load_iir(m._bpf, st["bandpass"])
    m._phi = np.array(st["phi"], dtype=float)
    m._sxx = None if st["sxx"] is None else np.array(st["sxx"], dtype=float)
    m._sxy = None if st["sxy"] is None else np.array(st["sxy"], dtype=float)
    m.load = tuple(float(v) for v in st["load"])
    f.speed, f._q_last = float(st["speed"]), float(st["q_last"])
    if st["road"] is not None:
        _load_gravity_buffer(f.road_filter.start(), st["road"])
    f.mount_monitor.load(st["monitor"])
    f._time = float(st["time"])
    if f.recalibrator is not None:
        f.recalibrator.load(st["recalibrator"])
        if st["mount"] is not None:                 # (the kernels' buffers hold it already)
            f.recalibrator.restore_mount(f, np.array(st["mount"], dtype=float).reshape(3, 3))
