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
from imu_ground.imu.live.preint_stream import StreamingPreintegrator
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
             "filter-ekf": ("kernel", 5), "gravity": ("buffer", 3)}[name]
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
    ("filter-ekf", ("kernel",), [0.0] * 5),
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


# --------------------------------------------------------------------------- the live estimator's state
def _live_state():
    """A StreamingEstimator halfway through a drive with a speed (its state through JSON), and the rest."""
    from imu_ground.pipeline.streaming import StreamingEstimator
    sim = simulate(duration=20.0, seed=8, imu="mems", R_gs=np.eye(3))
    imu = sim.imu
    t, g, a = imu.t.tolist(), imu.gyro.tolist(), imu.accel.tolist()
    est = StreamingEstimator()
    half = len(t) // 2
    for i in range(half):
        est.push_speed(t[i], 8.0)
        est.push_imu(t[i], g[i], a[i])
    return est, json.loads(json.dumps(est.state_dict())), (t[half:], g[half:], a[half:])


def _rest(est, rest):
    out = []
    for ti, gi, ai in zip(*rest, strict=True):
        est.push_speed(ti, 8.0)
        out += est.push_imu(ti, gi, ai)
    return [(f.t, f.pitch, f.roll, f.status_reason) for f in out + est.flush()]


def _edit(state, path, value):
    out = json.loads(json.dumps(state))
    node = out
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value(node[path[-1]]) if callable(value) else value
    return out


def _garble(packed):
    text = packed["float64_zlib_base64"]
    i = len(text) // 2
    return {**packed, "float64_zlib_base64": text[:i] + ("A" if text[i] != "A" else "B") + text[i + 1:]}


def _short_by_3(packed):
    import base64
    import zlib
    raw = np.frombuffer(zlib.decompress(base64.b64decode(packed["float64_zlib_base64"])), dtype=float)[:-3]
    return {**packed, "float64_zlib_base64": base64.b64encode(zlib.compress(raw.tobytes())).decode()}


def _bomb(packed):
    """Half a megabyte of base64 that inflates to 400 MiB of zeros."""
    import base64
    import zlib
    z = zlib.compressobj(9)
    chunk = bytes(1 << 20)
    raw = b"".join(z.compress(chunk) for _ in range(400)) + z.flush()
    return {**packed, "float64_zlib_base64": base64.b64encode(raw).decode()}


LIVE_CORRUPT = {
    "clock.dt NaN": (("clock", "dt"), None, r"clock\.dt"),
    "clock.dt negative": (("clock", "dt"), -0.01, r"clock\.dt"),
    "clock.t 1e308": (("clock", "t"), 1e308, r"clock\.t"),
    "clock.counts NaN": (("clock", "counts"), lambda c: [c[0], float("nan"), *c[2:]], r"clock\.counts"),
    "gyro bias 1000 rad/s": (("bias", "value"), [1000.0, 0.0, 0.0], r"bias\.value"),
    "filter garbled": (("filter", "state", "kernel"), _garble, r"filter\.state\.kernel"),
    "filter truncated": (("filter", "state", "kernel", "float64_zlib_base64"), lambda x: x[:len(x) // 2],
                         r"filter\.state\.kernel"),
    "filter 3 floats short": (("filter", "state", "kernel"), _short_by_3, r"filter\.state\.kernel"),
    "preintegrator inflating": (("preintegrator", "state", "deltas"), _bomb, r"preintegrator\.state\.deltas"),
    "blocks garbled": (("blocks", "sums"), _garble, r"blocks\.sums"),
    "queue record": (("queue",), [[1, 2, 3]], r"queue\[0\]"),
    "speed received not a bool": (("speed", "received"), "yes", r"speed\.received"),
}


@pytest.mark.parametrize("case", list(LIVE_CORRUPT))
def test_a_corrupt_live_state_is_refused_naming_the_entry_and_changes_nothing(case):
    """Issue 38, case 6: a failed load left the estimator half overwritten (the next good sample raised "IMU
    timestamps must be strictly increasing"); garbled, truncated or short payloads raised zlib.error,
    binascii.Error or StopIteration; NaN or negative clock.dt, clock.t 1e308 and a 1000 rad/s bias loaded; a
    0.5 MB payload inflated to 400 MiB. Each is now a StateError (of the package's error root) naming the entry,
    quickly, and the estimator goes on as if no load had been tried."""
    import time

    from imu_ground.errors import ImuGroundError
    from imu_ground.pipeline.streaming import StreamingEstimator
    est, state, rest = _live_state()
    path, value, name = LIVE_CORRUPT[case]
    if path[0] in ("filter", "preintegrator", "blocks") and "float64_zlib_base64" not in json.dumps(
            _edit(state, path[:-1], lambda x: x)[path[0]]):
        pytest.skip("not packed")
    bad = _edit(state, path, value)
    twin = StreamingEstimator()
    twin.load_state_dict(json.loads(json.dumps(state)))
    start = time.perf_counter()
    with pytest.raises(StateError, match=name) as err:
        est.load_state_dict(bad)
    assert time.perf_counter() - start < 2.0
    assert isinstance(err.value, ImuGroundError) and "\n" not in str(err.value)
    assert _rest(est, rest) == _rest(twin, rest)


def test_stream_state_corrupt_is_exit_2_one_line(cli, tmp_path):
    """A --state file with NaN in clock.counts was exit 3 (a bug's traceback); now exit 2, one line naming it."""
    est, state, _ = _live_state()
    bad = _edit(state, ("clock", "counts"), lambda c: [c[0], float("nan"), *c[2:]])
    path = tmp_path / "s.json"
    path.write_text(json.dumps(bad))
    from pathlib import Path
    example = Path(__file__).resolve().parent.parent / "datasets" / "fixtures" / "example_drive.csv"
    code, out, err = cli("stream", "--replay", example, "--state", path)
    assert code == 2, err
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and "clock.counts" in lines[0] and "--state" in lines[0]
    assert json.loads(path.read_text()) == json.loads(json.dumps(bad))     # the file given is not replaced
