"""Property-based tests of the streaming filters: random frame streams never break them.

Streams mix good frames with what logs and callers really produce: NaN and
infinite entries, huge values, zero, negative and huge frame durations, matrices
that are not rotations, 4x4 poses, rotation vectors, bare rotations, gaps
(``valid=False``), negative and non-finite speeds. The documented contract:

- ``step`` raises nothing but ``ValueError`` (a bad frame with ``on_invalid="raise"``,
  or a frame of the wrong kind), and a frame it refuses leaves the state as it was:
  a filter fed the whole stream (refusals swallowed) and one fed only the frames the
  first accepted give the same estimates;
- with ``on_invalid="skip"`` a bad frame gives ``valid=False`` and never an exception;
- an estimate with ``valid=True`` is finite, its normal a unit vector;
- ``run`` over an ego-motion with gaps gives finite values on every frame.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from imu_ground.filters import GroundNormalFilter, SuspensionAwareFilter
from imu_ground.imu import EgoFrame, EgoMotion

#: Examples per property (each a stream of up to MAX_FRAMES frames); the total is reported by
#: ``pytest --hypothesis-show-statistics``.
EXAMPLES = 80
MAX_FRAMES = 25
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

BAD_FLOATS = st.sampled_from([math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300, 0.0])
ANGLE = st.floats(-0.3, 0.3, allow_nan=False)


@st.composite
def rotations(draw):
    """A delta_R as callers give it: mostly good rotations, else broken matrices and other shapes."""
    rv = np.array([draw(ANGLE), draw(ANGLE), draw(st.floats(-3.2, 3.2))])
    R = Rotation.from_rotvec(rv).as_matrix()
    kind = draw(st.sampled_from(["good"] * 6 + ["bad entry", "scaled", "zeros", "pose", "rotvec", "huge rotvec"]))
    if kind == "bad entry":
        R = R.copy()
        R[draw(st.integers(0, 2)), draw(st.integers(0, 2))] = draw(BAD_FLOATS)
    elif kind == "scaled":
        R = R * draw(st.sampled_from([1.001, 0.5, 2.0, -1.0, 1e150]))
    elif kind == "zeros":
        R = np.zeros((3, 3))
    elif kind == "pose":
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = [draw(st.floats(-1e3, 1e3)) for _ in range(3)]
        R = T
    elif kind == "rotvec":
        R = rv
    elif kind == "huge rotvec":
        R = rv * 1e200
    return R


@st.composite
def velocity_increments(draw):
    dv = np.array([draw(st.floats(-5.0, 5.0)), draw(st.floats(-1.0, 1.0)), draw(st.floats(0.5, 1.5))])
    if draw(st.integers(0, 5)) == 0:
        dv = dv.copy()
        dv[draw(st.integers(0, 2))] = draw(BAD_FLOATS)
    return dv


DURATIONS = st.one_of(st.sampled_from([0.1] * 5 + [0.01, 2.5, 0.0, -0.1, math.nan, math.inf, 1e-300, 1e-7, 1e6, 1e300]),
                      st.floats(1e-4, 5.0))


@st.composite
def frames(draw):
    """One EgoFrame (delta_R, delta_v, delta_t, stationary, valid, t)."""
    return EgoFrame(draw(rotations()), draw(velocity_increments()), draw(DURATIONS), draw(st.booleans()),
                    draw(st.booleans()), float(draw(st.integers(0, 10_000))) / 10.0)


SPEEDS = st.one_of(st.none(), st.floats(-3.0, 40.0), st.sampled_from([math.nan, math.inf, -50.0, 1e300]))
STREAMS = st.lists(st.tuples(frames(), SPEEDS, st.booleans()), min_size=1, max_size=MAX_FRAMES)


def _finite_estimate(est) -> None:
    if est.valid:
        assert math.isfinite(est.pitch) and math.isfinite(est.roll)
        n = est.normal
        assert np.all(np.isfinite(n)) and abs(np.linalg.norm(n) - 1.0) < 1e-6


def _feed(f, frame, speed, bare):
    """One step as a caller would make it: an EgoFrame, or a bare delta_R (the ground filter takes both)."""
    if isinstance(f, SuspensionAwareFilter):
        return f.step(frame.delta_R if bare else frame, speed=speed)
    return f.step(frame.delta_R if bare else frame)


def _make(kind: str, on_invalid: str):
    if kind == "suspension":
        return SuspensionAwareFilter(on_invalid=on_invalid)
    return GroundNormalFilter(on_invalid=on_invalid, measurement=kind)


KINDS = ["suspension", "rotation", "up", "forward"]


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(stream=STREAMS)
def test_skipping_filters_never_raise_on_bad_frames_and_valid_means_finite(kind, stream):
    f = _make(kind, "skip")
    for frame, speed, bare in stream:
        try:
            est = _feed(f, frame, speed, bare)
        except ValueError as e:
            # only a frame of the wrong kind (a bare rotation has no accelerometer data) is refused
            assert kind == "suspension" and bare, e
            continue
        _finite_estimate(est)


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(stream=STREAMS)
def test_a_refused_frame_leaves_the_state_as_it_was(kind, stream):
    whole, accepted_only = _make(kind, "raise"), _make(kind, "raise")
    for frame, speed, bare in stream:
        try:
            est = _feed(whole, frame, speed, bare)
        except ValueError:
            continue                                  # documented: the state is unchanged
        _finite_estimate(est)
        again = _feed(accepted_only, frame, speed, bare)
        assert (again.pitch, again.roll, again.valid) == (est.pitch, est.roll, est.valid) or (
            np.isclose(again.pitch, est.pitch, rtol=0, atol=1e-12) and np.isclose(again.roll, est.roll, rtol=0,
                                                                                   atol=1e-12))


@st.composite
def drives(draw):
    """A finite ego-motion with gaps, standstills and unusual but legal durations (EgoMotion accepts it)."""
    n = draw(st.integers(1, 40))
    rv = np.array([[draw(ANGLE), draw(ANGLE), draw(st.floats(-1.0, 1.0))] for _ in range(n)]) * 0.1
    dR = Rotation.from_rotvec(rv).as_matrix()
    dv = np.array([[draw(st.floats(-3.0, 3.0)), draw(st.floats(-1.0, 1.0)), draw(st.floats(0.0, 2.0))]
                   for _ in range(n)])
    dt = np.array([draw(st.sampled_from([0.1, 0.1, 0.1, 0.05, 1e-4, 3.0, 600.0])) for _ in range(n)])
    valid = np.array([draw(st.booleans()) or i == 0 for i in range(n)])
    stationary = np.array([draw(st.booleans()) for _ in range(n)])
    speed = np.array([draw(st.one_of(st.floats(-2.0, 40.0), st.just(math.nan))) for _ in range(n)])
    return EgoMotion(np.cumsum(dt), dR, dv, dt, stationary, valid), speed


@pytest.mark.parametrize("kind", KINDS)
@SETTINGS
@given(drive=drives())
def test_run_over_gaps_and_odd_durations_is_finite(kind, drive):
    em, speed = drive
    f = _make(kind, "raise")
    track = f.run(em, speed=speed) if kind == "suspension" else f.run(em)
    assert np.all(np.isfinite(track.pitch)) and np.all(np.isfinite(track.roll))
    assert np.all(np.isfinite(track.normal)) and np.allclose(np.linalg.norm(track.normal, axis=1), 1.0)


# ------------------------------------------------------------------------------------------ cases it found
def test_a_huge_velocity_increment_is_a_bad_frame_not_a_nan_estimate():
    f = SuspensionAwareFilter(on_invalid="skip")
    est = f.step(EgoFrame(np.eye(3), np.array([1e300, 0.0, 0.5]), 0.1, False, True))
    assert est.valid is False and math.isfinite(est.pitch)
    with pytest.raises(ValueError, match="delta_v is not finite or beyond"):
        SuspensionAwareFilter().step(EgoFrame(np.eye(3), np.array([1e300, 0.0, 0.5]), 0.1))


def test_a_huge_rotation_vector_is_a_bad_frame_not_a_math_error():
    est = GroundNormalFilter(on_invalid="skip").step(np.array([1e200, 0.0, 0.0]))
    assert est.valid is False
    with pytest.raises(ValueError, match="delta_R is not finite"):
        GroundNormalFilter().step(np.array([1e200, 0.0, 0.0]))


def test_an_infinite_speed_is_no_measurement():
    frame = EgoFrame(np.eye(3), np.array([0.0, 0.0, 0.981]), 0.1)
    a, b = SuspensionAwareFilter(), SuspensionAwareFilter()
    ea, eb = a.step(frame, speed=math.inf), b.step(frame)
    assert ea.valid and (ea.pitch, ea.roll) == (eb.pitch, eb.roll)
