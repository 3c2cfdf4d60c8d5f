r"""On-manifold IMU preintegration (Forster, Carlone, Dellaert, Scaramuzza, IEEE T-RO 2017).

Between two frame times ``t_i < t_j`` the gyro and accelerometer samples are
summarised, independently of the unknown attitude, velocity and gravity, by

.. math::

    \Delta R_{ij} = \prod_k \operatorname{Exp}((\tilde\omega_k - b_g)\,\delta t_k), \quad
    \Delta v_{ij} = \sum_k \Delta R_{ik} (\tilde a_k - b_a)\,\delta t_k, \quad
    \Delta p_{ij} = \sum_k \Delta v_{ik}\,\delta t_k + \tfrac12 \Delta R_{ik}(\tilde a_k - b_a)\,\delta t_k^2

(Forster et al. 2017, Sec. VI; gravity is *not* included). With the state
``R = R_{world<-body}``, velocity and position in the world frame and gravity
``g`` (world):

.. math::

    R_j = R_i \Delta R_{ij}, \quad
    v_j = v_i + g\,\Delta t_{ij} + R_i \Delta v_{ij}, \quad
    p_j = p_i + v_i \Delta t_{ij} + \tfrac12 g \Delta t_{ij}^2 + R_i \Delta p_{ij}.

Frames
------
- ``delta_R`` is ``R_{start<-end}`` (glossary: :mod:`imu_ground.so3`): it maps
  vectors from the body frame at the frame's *end* into the body frame at the
  frame's *start*, so ``R_k = R_{k-1} @ delta_R_k`` for ``R_{world<-body}`` attitudes.
- ``delta_v`` and ``delta_p`` are expressed in the body frame at the frame's start
  (m/s and m).

Signal model (how a sample is held over its interval)
-----------------------------------------------------
The IMU signal is taken as piecewise linear between samples. Each interval
between consecutive *knots* (the samples, plus the frame boundaries that fall
between samples) is integrated with one constant rate and specific force:

- ``hold="midpoint"`` (default): the mean of the signal at the interval's two
  ends (trapezoid / midpoint rule; second order for the rotation). A frame boundary between two
  samples gets the linearly interpolated signal, so the two pieces of a split
  interval use ``(y_k + y_b)/2`` and ``(y_b + y_{k+1})/2``.
- ``hold="left"``: the value of the left sample, held until the next sample
  (zero-order hold, first order; what Forster's discrete model and GTSAM assume).
  A boundary between samples gets the left sample's value, so the rotation of
  the two pieces composes exactly to that of the unsplit interval.

In both cases two frames that meet between samples compose (:meth:`PreintegratedImu.combine`)
exactly to the integration over the samples with the boundary inserted as a
knot. Within an interval the specific force is rotated with the attitude at the
interval's start (Forster's discretisation): rotation is exact for the held
rate, velocity and position are first order in ``|omega| dt`` (an error of
about ``|omega| dt / 2`` of each interval's velocity change).

The streaming and batch paths run the same step (:func:`~imu_ground.imu.preint_kernel.push_step`).

Noise and bias Jacobians
------------------------
``gyro_noise_density`` (rad/s/sqrt(Hz)) and ``accel_noise_density``
(m/s^2/sqrt(Hz)) are continuous-time white-noise densities, equal on the three
axes; an interval of length ``dt`` receives discrete noise of variance
``sigma^2 / dt`` on its held value (Forster's discrete noise). The 9x9 covariance is in
the order ``[rotation, velocity, position]`` with the rotation error on the
right, ``delta_R_measured = delta_R_true @ Exp(dphi)`` (as in Forster, Sec. VI-B).
The bias Jacobians are the exact derivatives of the discrete deltas at the
bias they were integrated with (Forster, Sec. VI-C and appendix); use
:meth:`PreintegratedImu.corrected` / :meth:`FrameDeltas.corrected` for the
first-order update ``delta_R Exp(dR_dbg dbg)``, ``delta_v + dv_dbg dbg + dv_dba dba``, ...

Where it lives
--------------
- :mod:`~imu_ground.imu.preint_params`: :class:`PreintegrationParams` (noise, bias, gravity, hold
  and gap rules), the one place the options are defined.
- :mod:`~imu_ground.imu.preint_kernel`: the one body, compiled: the kinematics of one interval
  (with or without covariance and bias Jacobians, left error form internally) and the step of one
  sample into frames.
- :mod:`~imu_ground.imu.preint_measurement`: :class:`PreintegratedImu` (the measurement; its
  composition :meth:`~PreintegratedImu.combine`, prediction, the right-error read-out).
- :mod:`~imu_ground.imu.preint_frames`: :func:`make_frame_times`, :func:`preintegrate` (the step
  over a whole log), :class:`FrameDeltas`.
- :mod:`~imu_ground.imu.live.preint_stream`: :class:`StreamingPreintegrator` (the step per sample).
"""
from __future__ import annotations

from imu_ground.imu.preint_frames import FrameDeltas, make_frame_times, preintegrate
from imu_ground.imu.preint_measurement import PreintegratedImu
from imu_ground.imu.preint_params import PreintegrationParams
from imu_ground.imu.live.preint_stream import StreamingPreintegrator

__all__ = [
    "FrameDeltas",
    "PreintegratedImu",
    "PreintegrationParams",
    "StreamingPreintegrator",
    "make_frame_times",
    "preintegrate",
]
