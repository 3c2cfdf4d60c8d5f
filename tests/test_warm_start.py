"""Warm start: state_dict() / load_state_dict() resume a stopped run exactly, and refuse a foreign state."""
import json
from dataclasses import replace

import numpy as np
import pytest

from imu_ground.evaluation.simulate import simulate
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import imu_to_egomotion
from imu_ground.imu.live.preint_stream import StreamingPreintegrator
from imu_ground.imu.warm_start import StateError


@pytest.fixture(scope="module")
def drive():
    sim = simulate(duration=40.0, seed=3, imu="mems", R_gs=np.eye(3))
    em = imu_to_egomotion(sim.imu, rate=10.0)
    return sim, em


def _through_json(state: dict) -> dict:
    return json.loads(json.dumps(state))


def _estimates(f, frames, speed=None):
    out = []
    for i, fr in enumerate(frames):
        e = f.step(fr) if speed is None else f.step(fr, speed=speed[i])
        out.append((e.pitch, e.roll, e.pitch_std, e.roll_std, e.status, *e.normal))
    return np.array([o[:4] + o[5:] for o in out]), [o[4] for o in out]


@pytest.mark.parametrize("make", [
    lambda: SuspensionAwareFilter(),
    lambda: SuspensionAwareFilter(online_gains=True, response=(1.5, 0.5)),
    lambda: GroundNormalFilter(),
    lambda: GroundNormalFilter(measurement="forward"),            # the general (InvariantEKF) path
], ids=["suspension", "suspension-online-response", "filter", "filter-ekf"])
@pytest.mark.parametrize("k", [0, 1, 137])
def test_stopped_and_resumed_stream_equals_the_uninterrupted_one(drive, make, k):
    _, em = drive
    frames = list(em.frames())
    want, want_status = _estimates(make(), frames)
    first = make()
    _estimates(first, frames[:k])
    resumed = make()
    resumed.load_state_dict(_through_json(first.state_dict()))
    got, got_status = _estimates(resumed, frames[k:])
    np.testing.assert_allclose(got, want[k:], rtol=0, atol=1e-12)
    assert got_status == want_status[k:]


def test_resumed_batch_run_equals_the_uninterrupted_run(drive):
    _, em = drive
    speed = np.full(len(em), 8.0)
    whole = SuspensionAwareFilter().run(em, speed=speed)
    f = SuspensionAwareFilter()
    for i, fr in enumerate(list(em.frames())[:90]):
        f.step(fr, speed=speed[i])
    g = SuspensionAwareFilter()
    g.load_state_dict(_through_json(f.state_dict()))
    tail = replace(em, t=em.t[90:], delta_R=em.delta_R[90:], delta_v=em.delta_v[90:], delta_t=em.delta_t[90:],
                   stationary=em.stationary[90:], valid=em.valid[90:])
    rest = g.run(tail, speed=speed[90:])
    np.testing.assert_allclose(rest.pitch, whole.pitch[90:], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rest.roll_std, whole.roll_std[90:], rtol=0, atol=1e-12)


def test_gravity_velocity_filter_resumes(drive):
    _, em = drive
    frames = list(em.frames())
    a = GravityVelocityFilter()
    want = [a.step(fr).gravity.copy() for fr in frames]
    b = GravityVelocityFilter()
    for fr in frames[:50]:
        b.step(fr)
    c = GravityVelocityFilter()
    c.load_state_dict(_through_json(b.state_dict()))
    got = [c.step(fr).gravity.copy() for fr in frames[50:]]
    np.testing.assert_allclose(got, want[50:], rtol=0, atol=1e-12)


@pytest.mark.parametrize("kw", [dict(rate=10.0), dict(every=7), dict(rate=10.0, uncertainty=True)])
@pytest.mark.parametrize("j", [0, 1, 555])
def test_preintegrator_resumes_between_any_two_samples(drive, kw, j):
    sim, _ = drive
    imu = sim.imu
    rows = list(zip(imu.t.tolist(), imu.gyro.tolist(), imu.accel.tolist(), strict=True))[:1500]

    def frames(p, part):
        return [f for s in part for f in p.push(*s)]
    want = frames(StreamingPreintegrator(**kw), rows)
    p = StreamingPreintegrator(**kw)
    head = frames(p, rows[:j])
    q = StreamingPreintegrator(**kw)
    q.load_state_dict(_through_json(p.state_dict()))
    got = head + frames(q, rows[j:])
    assert len(got) == len(want) > 10
    for a, b in zip(got, want, strict=True):
        np.testing.assert_allclose(a.delta_R, b.delta_R, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.delta_v, b.delta_v, rtol=0, atol=1e-12)
        assert (a.t_start, a.t_end, a.valid) == (b.t_start, b.t_end, b.valid)


def test_a_foreign_state_is_refused_with_a_clear_message(drive):
    _, em = drive
    s = SuspensionAwareFilter()
    s.step(next(iter(em.frames())))
    state = s.state_dict()
    with pytest.raises(StateError, match="saved by SuspensionAwareFilter, not GroundNormalFilter"):
        GroundNormalFilter().load_state_dict(state)
    old = dict(state, state_version=0)
    with pytest.raises(ValueError, match="layout 0"):
        SuspensionAwareFilter().load_state_dict(old)
    with pytest.raises(ValueError, match="other settings.*q_time"):
        SuspensionAwareFilter(q_time=0.5).load_state_dict(state)
    with pytest.raises(ValueError, match="not a saved state"):
        SuspensionAwareFilter().load_state_dict({"x": 1})
    with pytest.raises(ValueError, match="StreamingPreintegrator"):
        StreamingPreintegrator(rate=10.0).load_state_dict(state)
