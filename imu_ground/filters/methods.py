"""The ground estimators by name, the one registry: what ``imu-ground estimate --method NAME`` and the evaluation run.

:data:`METHODS` maps a CLI name to a :class:`MethodSpec`; adding a method is one entry here. ``estimate --method``
and ``batch`` take their choices and ``--help`` lines from it, ``stream --method`` (and
:class:`~imu_ground.pipeline.streaming.StreamingEstimator`, ``estimate --causal``) its :func:`live_methods`,
:func:`imu_ground.pipeline.estimate_log` runs it and the evaluation (:mod:`imu_ground.evaluation.runner`) compares
it. A method accepts exactly the options of its estimator's constructor; anything else is rejected with a message
listing what it accepts.
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Callable

from imu_ground.errors import OptionError
from imu_ground.filters.constant_normal import ConstantNormal
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.suspension import SuspensionAwareFilter, SuspensionTrack

__all__ = ["METHODS", "MethodSpec", "default_method", "estimate", "estimate_suspension_aware", "live_methods",
           "make_estimator", "recalibrating_methods", "reference_methods"]


@dataclass(frozen=True)
class MethodSpec:
    """One named ground-estimation method.

    Attributes
    ----------
    name, description : str
        CLI name and its one ``--help`` line.
    factory : callable
        ``factory(**options) -> estimator`` (a :class:`~imu_ground.filters.estimator.GroundEstimator`).
    needs_accel : bool
        The method uses ``delta_v`` (an IMU log, not poses).
    smooth : bool
        ``run(..., smooth=True)``: offline, results depend on the future.
    speed_aided : bool
        ``run(..., speed=v)`` takes a measured forward speed per frame (m/s).
    live : bool
        Runs live, sample by sample (``StreamingEstimator``, ``imu-ground stream``, ``estimate --causal``).
    reference : bool
        A reference the reports compare every method with and draw bold (:func:`reference_methods`).
    """
    name: str
    description: str
    factory: Callable[..., Any]
    needs_accel: bool
    smooth: bool
    speed_aided: bool = False
    live: bool = False
    reference: bool = False

    @property
    def options(self) -> tuple:
        """Names of the options the factory accepts."""
        return tuple(p for p in inspect.signature(self.factory).parameters if p != "self")

    def make(self, **options):
        """The estimator with these options; unknown options raise :class:`OptionError` naming the accepted ones."""
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            raise OptionError(f"method {self.name!r} does not take option(s) {', '.join(unknown)}; "
                              f"it takes: {', '.join(self.options)}", unknown[0])
        return self.factory(**options)


class _Factory:
    """A factory with its estimator constructor's signature (so a method lists the options it takes)."""

    def __init__(self, fn: Callable[..., Any], cls: type[Any]) -> None:
        self.fn = fn
        init = inspect.signature(cls.__init__).parameters
        self.__signature__ = inspect.Signature([p for name, p in init.items() if name != "self"])

    def __call__(self, **options):
        return self.fn(**options)


#: CLI name -> method, in the order ``--help`` lists them. "suspension" is the default for IMU input,
#: "filter" for poses; "naive" is the baseline the others are compared with.
METHODS: dict[str, MethodSpec] = {
    "suspension": MethodSpec(
        "suspension", "suspension-aware invariant EKF: road attitude plus the body's load-transfer tilt "
        "(streaming; needs an accelerometer)",
        _Factory(SuspensionAwareFilter, SuspensionAwareFilter), True, False, True, live=True),
    "suspension-offline": MethodSpec(
        "suspension-offline", "suspension-aware filter with the offline smoother (zero lag; uses the future)",
        _Factory(SuspensionAwareFilter, SuspensionAwareFilter), True, True, True),
    "filter": MethodSpec(
        "filter", "heading-following invariant EKF on the cumulative rotation (rotations only: any odometry)",
        _Factory(GroundNormalFilter, GroundNormalFilter), False, False, live=True),
    "paper": MethodSpec(
        "paper", "the paper's method: random-walk invariant EKF, Q = 1e-2 I, R = I (Zhang et al. 2022)",
        _Factory(GroundNormalFilter.paper, GroundNormalFilter), False, False, live=True, reference=True),
    "naive": MethodSpec(
        "naive", "constant normal: the static extrinsic alone, pitch and roll 0 relative to the road "
        "(the paper's naive baseline, a reference to compare with)",
        _Factory(ConstantNormal, ConstantNormal), False, False, reference=True),
}


def default_method(has_accel: bool) -> str:
    """The method to use by default: ``"suspension"`` with an accelerometer, ``"filter"`` without (poses)."""
    return "suspension" if has_accel else "filter"


def live_methods() -> tuple[str, ...]:
    """Names of the methods that run live (:attr:`MethodSpec.live`), in the registry's order."""
    return tuple(name for name, spec in METHODS.items() if spec.live)


def reference_methods() -> tuple[str, ...]:
    """Names of the methods the reports compare every other with (:attr:`MethodSpec.reference`), in order."""
    return tuple(name for name, spec in METHODS.items() if spec.reference)


def recalibrating_methods() -> tuple[str, ...]:
    """Names of the live methods that re-estimate the mount online (their estimator takes ``recalibrate_online``)."""
    return tuple(name for name, spec in METHODS.items() if spec.live and "recalibrate_online" in spec.options)


def make_estimator(name: str, **options):
    """The estimator of method ``name`` with ``options`` (:meth:`MethodSpec.make`)."""
    if name not in METHODS:
        raise OptionError(f"unknown {{opt}} {name!r}; choose from {', '.join(METHODS)}", "method")
    return METHODS[name].make(**options)


def estimate(egomotion, method=None, speed=None, **options):
    """Run a method over a whole drive.

    Parameters
    ----------
    egomotion : EgoMotion
        Per-frame ego-motion (sensor frame).
    method : str, optional
        A name of :data:`METHODS`; default :func:`default_method` of the input.
    speed : ndarray (F,), optional
        Measured forward speed per frame, m/s (NaN: unknown), for a ``speed_aided`` method.
    **options
        Options of the method's estimator.

    Returns
    -------
    GroundTrack

    Raises
    ------
    OptionError
        Unknown method or option, or a method that needs an accelerometer on input without one.
    """
    has_accel = bool(getattr(egomotion, "has_accel", True))
    name = default_method(has_accel) if method is None else method
    est = make_estimator(name, **options)
    if METHODS[name].needs_accel and not has_accel:
        without = ", ".join(repr(m) for m, spec in METHODS.items() if not spec.needs_accel)
        raise OptionError(f"{{opt}} {name!r} needs accelerometer data and this input has none (rotations or poses "
                          f"only); use one of {without}", "method")
    if speed is None:
        return est.run(egomotion, smooth=METHODS[name].smooth)
    if not METHODS[name].speed_aided:
        aided = ", ".join(repr(m) for m, spec in METHODS.items() if spec.speed_aided)
        raise OptionError(f"method {name!r} does not take a speed; use one of {aided}", "speed")
    return est.run(egomotion, smooth=METHODS[name].smooth, speed=speed)


def estimate_suspension_aware(egomotion, extrinsic=None, smooth: bool = False, calibration=None,
                              **params) -> SuspensionTrack:
    """Suspension-aware ground normal of a whole drive in one call.

    Parameters
    ----------
    egomotion : EgoMotion or ImuData
        Per-frame ego-motion (an ImuData is preintegrated at 10 Hz, or at ``frame_rate``).
    extrinsic : Extrinsic, ndarray (3, 3), str or Path, optional
        Static ground <- sensor extrinsic or a calibration file (:func:`~imu_ground.filters.extrinsics.resolve_platform`
        reads it).
    smooth : bool
        Offline mode (forward filter and RTS smoother).
    calibration : Calibration, optional
        Extrinsic and gains from :func:`imu_ground.filters.calibration.calibrate`.
    **params
        Any :class:`SuspensionAwareFilter` parameter (these win).

    Returns
    -------
    SuspensionTrack
    """
    kw: dict = {} if calibration is None else calibration.filter_kwargs()
    if extrinsic is not None:
        kw["extrinsic"] = extrinsic
    kw.update(params)
    return SuspensionAwareFilter(**kw).run(egomotion, smooth=smooth)
