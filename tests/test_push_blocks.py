"""The live front end's compiled block opening (:func:`~imu_ground.imu.live.causal_standstill.open_row`): the row it
opens, the ring that must grow, and a stream whose new-block samples go through it equal to one fed block by block."""
import numpy as np

from imu_ground.imu.live.causal_standstill import StandstillBlocks, open_row
from imu_ground.pipeline.streaming import StreamingEstimator


def test_open_row_free_held_and_taken():
    bl = StandstillBlocks(10.0)
    ring, keys = bl.buffers
    R = ring.shape[0]
    ring[3 % R] = 7.0
    i = open_row(ring, keys, 3)                      # a free row: zeroed, keyed
    assert i == 3 % R and keys[i] == 3 and not ring[i].any()
    ring[i, 0] = 2.0
    assert open_row(ring, keys, 3) == i and ring[i, 0] == 2.0     # held already: kept
    before = ring.copy(), keys.copy()
    assert open_row(ring, keys, 3 + R) == -1         # another block's row: nothing changed
    assert (ring == before[0]).all() and (keys == before[1]).all()


def test_open_block_grows_the_ring():
    bl = StandstillBlocks(10.0)
    R = bl.ring.shape[0]
    bl.add(0, (1.0, 0, 0), (0, 0, 9.8))
    bl.add(R, (2.0, 0, 0), (0, 0, 9.8))              # row 0 holds block 0: the ring grows
    assert bl.ring.shape[0] > R and bl.open_k == R
    assert bl.block(0) == (1, 1.0, 0.0, 0.0) and bl.block(R) == (1, 2.0, 0.0, 0.0)


def _noisy_still_log(seed: int, n: int):
    """``n`` samples at about 100 Hz (jittered stamps), a still IMU with noise: t (s), gyro, accel."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01 + rng.normal(0, 5e-4, n)
    return t, rng.normal(0, 0.02, (n, 3)), rng.normal(0, 0.05, (n, 3)) + [0, 0, 9.81]


def test_stream_equal_to_its_state_resumed_each_frame():
    n = 600
    t, g, a = _noisy_still_log(3, n)
    one, two = StreamingEstimator(), StreamingEstimator()
    got, again = [], []
    for i in range(n):
        got += one.push_imu(float(t[i]), g[i], a[i])
        if i % 10 == 5:                              # a new estimator from the state, mid-frame
            fresh = StreamingEstimator()
            fresh.load_state_dict(two.state_dict())
            two = fresh
        again += two.push_imu(float(t[i]), g[i], a[i])
    got += one.flush()
    again += two.flush()
    assert len(got) == len(again) > 40
    assert [(e.t, e.pitch, e.roll, e.status_reason) for e in got] == [(e.t, e.pitch, e.roll, e.status_reason)
                                                                       for e in again]


def test_copies_and_pickles_go_on_alike():
    import copy
    import pickle
    n = 500
    t, g, a = _noisy_still_log(4, n)
    one = StreamingEstimator()
    for i in range(205):                              # mid-frame, the blocks and preintegrator under way
        one.push_imu(float(t[i]), g[i], a[i])
    others = [copy.deepcopy(one), pickle.loads(pickle.dumps(one))]
    outs = [[] for _ in range(3)]
    for i in range(205, n):
        for est, out in zip([one, *others], outs, strict=True):
            out += est.push_imu(float(t[i]), g[i], a[i])
    for est, out in zip([one, *others], outs, strict=True):
        out += est.flush()
    key = [[(e.t, e.pitch, e.roll, e.status_reason) for e in out] for out in outs]
    assert len(key[0]) > 25 and key[0] == key[1] == key[2]
