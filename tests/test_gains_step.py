"""SuspensionAwareFilter.step with online gains: its reused one-frame buffers never leak into what it returns."""
from __future__ import annotations

import numpy as np
import pytest

from imu_ground.evaluation.simulate import simulate
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import EgoFrame, imu_to_egomotion


@pytest.fixture(scope="module")
def frames():
    return list(imu_to_egomotion(simulate(30.0, seed=5, imu="mems").imu).frames())


def test_gains_read_after_a_step_stay_as_read(frames):
    """The gains an online filter shows are a copy: later steps (which reuse the regression's buffers) leave
    an array read earlier as it was, and each frame's gains follow the regression."""
    f = SuspensionAwareFilter(online_gains=True)
    seen = []
    for fr in frames:
        f.step(fr)
        seen.append((f.gains, f.gains.copy()))
    for shown, copied in seen:
        np.testing.assert_array_equal(shown, copied)
    assert len({tuple(c) for _, c in seen}) > 1          # the gains did move


def test_step_of_an_egoframe_equals_step_of_its_fields(frames):
    """``step(EgoFrame)`` (the fast path) and ``step(delta_R, delta_v, delta_t, stationary, valid)`` agree bit
    for bit, with online gains; a subclass of EgoFrame (the general path) too."""
    class Frame(EgoFrame):
        pass

    a, b, c = (SuspensionAwareFilter(online_gains=True) for _ in range(3))
    for fr in frames:
        ea, eb = a.step(fr), b.step(fr.delta_R, fr.delta_v, fr.delta_t, fr.stationary, fr.valid)
        ec = c.step(Frame(*fr))
        assert (ea.pitch, ea.roll, ea.status_code) == (eb.pitch, eb.roll, eb.status_code) == \
            (ec.pitch, ec.roll, ec.status_code)
    np.testing.assert_array_equal(a.gains, b.gains)


def test_step_of_a_rotation_alone_is_refused():
    """A bare rotation (no accelerometer data) is still refused with the message naming the EgoFrame."""
    with pytest.raises(ValueError, match="needs an EgoFrame"):
        SuspensionAwareFilter().step(np.eye(3))
