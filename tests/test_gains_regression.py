"""The online gain regression of the suspension model against scipy, and its saved state's checks."""
from __future__ import annotations

import numpy as np
import pytest

from imu_ground.evaluation.simulate import simulate
from imu_ground.filters.gains import TYPICAL_BAND_POWER, bandpass_gain_regression
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import imu_to_egomotion
from imu_ground.imu.warm_start import StateError


@pytest.fixture(scope="module")
def drive():
    return imu_to_egomotion(simulate(120.0, seed=11, imu="mems").imu)


def test_online_sums_are_the_prior_plus_scipys_band_pass_regression(drive):
    """From a fresh filter, the online sums are the prior's plus those of the whole-drive regression
    (:func:`scipy.signal.lfilter` over the integrated tilt and the acceleration), and the gains their ratio."""
    f = SuspensionAwareFilter(online_gains=True)
    tr = f.run(drive)
    gt = SuspensionAwareFilter(online_gains=True).gravity_filter.run(drive)   # the frames f.run regressed on
    _, sxy, sxx = bandpass_gain_regression(gt.body_increments, gt.acceleration, frame_rate=10.0)
    prior = f.gain_prior_seconds * 10.0 * np.asarray(TYPICAL_BAND_POWER)
    state = f.model.state_dict()
    np.testing.assert_allclose(state["sxx"], prior + sxx, rtol=1e-9)
    np.testing.assert_allclose(state["sxy"], prior * f.gains0 + sxy, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(f.gains, (prior * f.gains0 + sxy) / (prior + sxx), rtol=1e-9)
    assert np.array_equal(tr.gains[0], f.gains0) and not np.allclose(tr.gains[-1], f.gains0)


def test_one_frame_at_a_time_gives_the_same_gains_as_one_run(drive):
    a, b = SuspensionAwareFilter(online_gains=True), SuspensionAwareFilter(online_gains=True)
    for k in range(len(drive)):
        a.step(drive.delta_R[k], drive.delta_v[k], drive.delta_t[k], drive.stationary[k], drive.valid[k])
    b.run(drive)                                   # (the same sums, added up in another order)
    np.testing.assert_allclose(a.gains, b.gains, rtol=1e-9)
    sa, sb = a.model.state_dict(), b.model.state_dict()
    for name in ("phi", "sxx", "sxy"):
        np.testing.assert_allclose(sa[name], sb[name], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("null", ["sxx", "sxy"])
def test_a_state_with_one_of_the_two_sums_null_is_refused(drive, null):
    f = SuspensionAwareFilter(online_gains=True)
    f.run(drive)
    state = f.model.state_dict()
    before = f.model.state_dict()
    state[null] = None
    with pytest.raises(StateError, match=rf"entry {null} is null but its partner is not"):
        f.model.load_state_dict(state)
    assert f.model.state_dict() == before                      # unchanged
    both = dict(state, sxx=None, sxy=None)
    g = SuspensionAwareFilter()                                # fixed gains: no sums saved
    g.model.load_state_dict(both)
    assert g.model.state_dict()["sxx"] is None and g.model.state_dict()["sxy"] is None
