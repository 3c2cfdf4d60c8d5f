"""A saved state is checked entry by entry when it is loaded: corrupt numbers, shapes and version fields are
refused naming the entry (StateError, a ValueError), and settings that differ are named field by field."""
import json

import numpy as np
import pytest

from imu_ground.evaluation.simulate import simulate
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.gravity_velocity import GravityVelocityFilter
from imu_ground.filters.suspension import SuspensionAwareFilter
from imu_ground.imu.egomotion import imu_to_egomotion
from imu_ground.imu.preint_stream import StreamingPreintegrator
from imu_ground.imu.warm_start import StateError

MAKERS = {
    "suspension": lambda: SuspensionAwareFilter(),
    "suspension-online-recal": lambda: SuspensionAwareFilter(online_gains=True, response=(1.5, 0.5),
                                                             recalibrate_online=True),
    "filter": lambda: GroundNormalFilter(),
    "filter-ekf": lambda: GroundNormalFilter(measurement="forward"),
    "gravity": lambda: GravityVelocityFilter(),
}


@pytest.fixture(scope="module")
def drive():
    sim = simulate(duration=30.0, seed=5, imu="mems", R_gs=np.eye(3))
    return sim, imu_to_egomotion(sim.imu, rate=10.0)


def _speeds(n: int) -> np.ndarray:
    v = np.full(n, 9.0)
    v[40:60] = np.nan                                   # a stretch without a measured speed
    return v


def _saved(name: str, drive, frames: int = 120) -> dict:
    sim, em = drive
    f = MAKERS[name]()
    speed = _speeds(len(em))
    for k, fr in enumerate(list(em.frames())[:frames]):
        f.step(fr, speed=speed[k]) if isinstance(f, SuspensionAwareFilter) else f.step(fr)
    return json.loads(json.dumps(f.state_dict()))


def _preintegrator_state(drive) -> dict:
    sim, _ = drive
    p = StreamingPreintegrator(rate=10.0, uncertainty=True)
    imu = sim.imu
    for k in range(257):
        p.push(float(imu.t[k]), imu.gyro[k], imu.accel[k])
    return json.loads(json.dumps(p.state_dict()))


def _leaves(value, path=()):
    """(path, value) of every number (and bool) in a nested state."""
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _leaves(v, path + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _leaves(v, path + (i,))
    elif isinstance(value, (int, float)):
        yield path, value


def _set(state: dict, path: tuple, value) -> dict:
    out = json.loads(json.dumps(state))
    node = out["state"]
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return out


def _entry_name(path: tuple) -> str:
    """The dotted entry name the error should give: dict keys up to the first list index."""
    keys = []
    for p in path:
        if isinstance(p, int):
            break
        keys.append(p)
    return ".".join(keys)


def _loader(name: str):
    return (lambda: StreamingPreintegrator(rate=10.0, uncertainty=True)) if name == "preint" else MAKERS[name]


@pytest.mark.parametrize("name", list(MAKERS) + ["preint"])
def test_a_huge_number_in_any_entry_is_refused_naming_it(drive, name):
    state = _preintegrator_state(drive) if name == "preint" else _saved(name, drive)
    leaves = list(_leaves(state["state"]))
    assert len(leaves) > 20
    for path, _ in leaves:
        bad = _set(state, path, 1e300)
        with pytest.raises(StateError, match=r"entry " + _entry_name(path).replace(".", r"\.") + r"\b"):
            _loader(name)().load_state_dict(bad)


@pytest.mark.parametrize("name", list(MAKERS))
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")], ids=["nan", "inf", "-inf"])
def test_non_finite_state_values_are_refused(drive, name, bad):
    """The filter's state proper (its kernels' states, speed, clock, gains): NaN and infinities are refused at load.
    On the old code a NaN there was accepted and every later frame was NaN with valid=True."""
    state = _saved(name, drive)
    entry = {"suspension": ("kernel", 4), "suspension-online-recal": ("gravity", 3), "filter": ("kernel", 0),
             "filter-ekf": ("ekf", 5), "gravity": ("buffer", 3)}[name]
    with pytest.raises(StateError, match=rf"entry {entry[0]} holds"):
        MAKERS[name]().load_state_dict(_set(state, entry, bad))
    if name.startswith("suspension"):
        for path in (("speed",), ("time",), ("q_last",), ("gains", 0), ("phi", 1), ("monitor", "drift")):
            with pytest.raises(StateError, match=_entry_name(path).replace(".", r"\.")):
                MAKERS[name]().load_state_dict(_set(state, path, bad))


@pytest.mark.parametrize("name, path, value", [
    ("suspension", ("kernel",), [0.0] * 5),
    ("suspension", ("gains",), [0.1, 0.2, 0.3]),
    ("suspension", ("gravity",), "abc"),
    ("suspension", ("frames",), 2.5),
    ("suspension", ("converged",), "yes"),
    ("suspension-online-recal", ("monitor",), [1, 2]),
    ("suspension-online-recal", ("recalibrator", "prev_R"), [1.0, 0.0]),
    ("suspension-online-recal", ("bandpass", "z"), [[0.0, 0.0]]),
    ("filter-ekf", ("cumulative",), [[1.0, 0.0, 0.0]]),
    ("gravity", ("buffer",), [1.0, 2.0]),
])
def test_wrong_shapes_and_types_are_refused_at_load_naming_the_entry(drive, name, path, value):
    state = _saved(name, drive)
    with pytest.raises(StateError, match=r"entry " + ".".join(path).replace(".", r"\.")):
        MAKERS[name]().load_state_dict(_set(state, path, value))


def test_a_corrupt_state_leaves_the_suspension_filter_as_after_reset(drive):
    _, em = drive
    state = _saved("suspension", drive)
    f = SuspensionAwareFilter()
    for fr in list(em.frames())[:30]:
        f.step(fr)
    with pytest.raises(StateError):
        f.load_state_dict(_set(state, ("monitor", "drift"), float("nan")))
    fresh = SuspensionAwareFilter()
    frames = list(em.frames())[:20]
    got = [f.step(fr).pitch for fr in frames]
    assert got == [fresh.step(fr).pitch for fr in frames]


def test_states_with_gaps_and_missing_speeds_load(drive):
    """The entries that hold NaN by design (no speed yet, the monitor not armed, a record) still load."""
    sim, em = drive
    speed = _speeds(len(em))
    f = SuspensionAwareFilter(recalibrate_online=True)
    for k, fr in enumerate(em.frames()):
        f.step(fr, speed=speed[k])
        if k % 25 == 0:
            g = SuspensionAwareFilter(recalibrate_online=True)
            g.load_state_dict(json.loads(json.dumps(f.state_dict())))
            assert json.dumps(g.state_dict()) == json.dumps(f.state_dict())     # (NaN as text: equal)


def test_state_version_given_as_text_says_so():
    state = SuspensionAwareFilter().state_dict()
    state["state_version"] = "1"
    with pytest.raises(StateError) as err:
        SuspensionAwareFilter().load_state_dict(state)
    msg = str(err.value)
    assert "state_version" in msg and "str '1'" in msg and "integer" in msg
    assert "reads layout 1 only" not in msg


def test_a_settings_mismatch_names_the_field_and_both_values():
    state = SuspensionAwareFilter(gravity={"q_v": 0.1}, q_time=0.2).state_dict()
    with pytest.raises(StateError) as err:
        SuspensionAwareFilter(gravity={"q_v": 0.05}).load_state_dict(state)
    msg = str(err.value)
    assert "gravity.q_v: saved 0.1, this SuspensionAwareFilter 0.05" in msg
    assert "q_time: saved 0.2, this SuspensionAwareFilter 0.1" in msg
    state = SuspensionAwareFilter(extrinsic="kitti_imu").state_dict()
    with pytest.raises(StateError, match=r"extrinsic\.translation: saved \[0\.0, 0\.0, 0\.93\]"):
        SuspensionAwareFilter().load_state_dict(state)


@pytest.mark.parametrize("entry, value", [("deltas", [0.0] * 10), ("prev", [0.0] * 6), ("_next", float("nan")),
                                          ("_cd", -1)])
def test_a_preintegrator_state_of_another_shape_is_refused(drive, entry, value):
    state = _preintegrator_state(drive)
    with pytest.raises(StateError, match=rf"entry {entry}\b"):
        StreamingPreintegrator(rate=10.0, uncertainty=True).load_state_dict(_set(state, (entry,), value))
