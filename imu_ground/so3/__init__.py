r"""The rotation group SO(3): every rotation formula of the package, and the glossary of frames and signs.

Two submodules, every public name re-exported here: :mod:`imu_ground.so3.group` (hat/vee, exp/log, Jacobians,
projection, axis rotations, and the ``*_flat`` scalar kernels compiled into the package's loops,
:func:`imu_ground._jit.jitable`) and :mod:`imu_ground.so3.conversions` (rotations from any input form, heading
twist, ZYX Euler angles, quaternions, cumulative products).

Glossary of frames and signs (every module refers here)
-------------------------------------------------------
Rotations: ``R_{a<-b}`` is the rotation matrix that maps a vector expressed in frame b into frame a, acting on
column vectors: ``v_a = R_{a<-b} @ v_b``. Its columns are b's axes in a's coordinates;
``R_{b<-a} = R_{a<-b}.T``; they compose by matching inner frames, ``R_{a<-c} = R_{a<-b} @ R_{b<-c}``. In code a
rotation named ``R_xy`` (e.g. ``R_gs``) is ``R_{x<-y}``; where a rotation crosses a module boundary its
docstring says "a <- b".

Frames (all right-handed):

- ``s`` sensor: the IMU's (or camera's, or odometry's) own axes.
- ``b`` body / ``g`` ground: the vehicle frame, FLU (x forward, y left, z up); static extrinsic
  ``R_gs = R_{ground<-sensor}`` with the sensor position in the ground frame
  (:class:`~imu_ground.filters.extrinsics.Extrinsic`). Without an extrinsic the body frame is the sensor frame.
- ``body_k``: the body frame at the end of frame k. Ego-motion increments are
  ``delta_R_k = R_{body_{k-1}<-body_k}`` and the cumulative attitude is
  ``R_k = R_{w<-body_k} = R_{k-1} @ delta_R_k`` (``R_0``, default identity).
- ``w`` world: the gyro-integrated body frame at the start (not gravity aligned); the gravity/velocity filter
  finds gravity in it.
- ``r`` road: the slowly varying road-plane frame (z the road normal); the ground filters' slow state is
  ``X_k = R_{w<-road}`` and the residual ``E_k = X_k^T R_k = R_{road<-body}`` (the body's attitude on its
  suspension).

Signs:

- Rotation vector ``phi = theta * axis`` (rad), ``R = exp(hat(phi))``, right-handed: ``exp(hat([0, 0, t]))``
  turns x towards y.
- Pitch and roll of the body relative to the road, from the road normal in the body frame
  ``n_b = E^T e_z = [-sin p, sin r cos p, cos p cos r]``: pitch positive = nose down (right-handed about y-left),
  roll positive = left side up (right-handed about x-forward); KITTI's convention. Euler angles are ZYX:
  ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
- Gravity is stored as its reaction (what an accelerometer at rest reads): +9.81 m/s^2 up; specific force
  ``f = a - g_vector``.
- Perturbations: ``exp(phi + dphi) ~= exp(phi) @ exp(J_r(phi) @ dphi)`` ``~= exp(J_l(phi) @ dphi) @ exp(phi)``
  (Chirikjian; Forster et al. 2017, eq. 7-9). A left-invariant (body) error is ``X = Xhat @ Exp(xi)``, a
  right-invariant (world) error ``X = Exp(xi) @ Xhat``.
- Units: radians and seconds everywhere inside the library (:mod:`imu_ground.units` owns the constants); degrees
  only at the edges.
"""
from imu_ground.so3 import conversions, group
from imu_ground.so3.conversions import *  # noqa: F403 (the package re-exports each submodule's __all__)
from imu_ground.so3.group import *  # noqa: F403

__all__ = group.__all__ + conversions.__all__
