"""The C InvariantEKF kernels (filters/_ekf_native.c) against their Python twins (invariant_ekf_kernel).

The whole state buffer (estimate, covariance, prior/posterior, y, K, S, S^-1, det S, counters)
held to the twin rule (:func:`imu_ground._native.assert_twins_equal`): the C kernels are the
Python ones term for term, compiled without FMA contraction. Skipped when the extension is not built
(or IMU_GROUND_PURE_PYTHON=1).
"""
from __future__ import annotations

import gc
import sys
import tracemalloc
from array import array
from contextlib import contextmanager

import numpy as np
import pytest

from imu_ground import so3
from imu_ground._native import EKF as NATIVE
from imu_ground._native import assert_twins_equal
from imu_ground.filters import invariant_ekf
from imu_ground.filters import invariant_ekf_kernel as kernel
from imu_ground.filters.invariant_ekf import InvariantEKF
from imu_ground.filters.invariant_ekf_kernel import (
    B_DET,
    B_P,
    B_X,
    B_XV,
    STATE_SIZE,
    new_state,
)

pytestmark = pytest.mark.skipif(NATIVE is None, reason="C kernels not built or IMU_GROUND_PURE_PYTHON set")

Q_DIAG = np.diag([1e-2, 2e-2, 5e-3])
R_FULL = np.array([[1.0, 0.1, 0.0], [0.1, 0.5, 0.05], [0.0, 0.05, 2.0]])
ATTRIBUTES = ("x", "P", "x_prior", "P_prior", "x_post", "P_post", "y", "K", "S", "SI", "log_likelihood")
HALF_TURNS = [np.diag(d) for d in ([1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0])]


def _pair(x0=np.eye(3), P=np.eye(3), Q=Q_DIAG, R=np.diag([1.0, 0.5, 2.0]), left=True, b=(0.0, 0.0, 1.0)):  # noqa: B008 (read-only defaults, never modified)
    s = new_state(so3.quat_from_flat(x0.ravel().tolist()), P.ravel().tolist(), Q.ravel().tolist(),
                  R.ravel().tolist(), list(b), left, 100)
    s[B_X:B_X + 9] = x0.ravel().tolist()
    s[B_XV] = 1.0
    return s, array("d", s)


def _same(py: list, c: array) -> None:
    assert_twins_equal(np.frombuffer(c), np.array(py, dtype=float), "state buffer")


def _step(py, c, u, z, Q=None, R=None):
    assert kernel.predict(py, u, Q) is True and NATIVE.predict(c, u, Q) is True
    assert kernel.update(py, z, R) is True and NATIVE.update(c, z, R) is True
    assert len(py) == STATE_SIZE
    _same(py, c)


def _measurements(rng, k):
    """Increments and measurements over the kernels' branches: identity, small angles, large ones,
    half turns (every Shepperd branch, Log near pi), rotation vectors, skipped updates."""
    scale = (0.0, 1e-9, 1e-5, 0.05, 1.0, 3.0)[k % 6]
    u = so3.exp(rng.normal(scale=scale, size=3))
    if k % 9 == 4:
        u = HALF_TURNS[k % 3]
    elif k % 9 == 7:
        u = rng.normal(scale=0.3, size=3)                  # a rotation vector
    elif k % 9 == 8:
        u = None
    zr = so3.exp(rng.normal(scale=(1e-9, 0.3, 2.5)[k % 3], size=3))
    if k % 7 == 3:
        zr = zr @ HALF_TURNS[k % 3]
    zd = rng.normal(size=3)
    return u, zr, zd / np.linalg.norm(zd)


@pytest.mark.parametrize("left", [True, False])
@pytest.mark.parametrize("R", [np.diag([1.0, 0.5, 2.0]), R_FULL])
def test_kernels_equal_python_over_every_branch(left, R):
    rng = np.random.default_rng(5)
    py, c = _pair(x0=so3.exp([0.3, -0.2, 1.0]), P=np.diag([0.5, 0.3, 0.2]), R=R, left=left)
    for k in range(1500):
        u, zr, zd = _measurements(rng, k)
        z = (zr, zd, None)[k % 3] if k % 10 else zd
        per_call = k % 13 == 0
        _step(py, c, u, z, Q=0.5 * Q_DIAG if per_call else None, R=2.0 * R if per_call else None)
    assert py[kernel.B_NUP] > 900


def test_zero_noise_half_turns_and_identity():
    for left in (True, False):
        py, c = _pair(P=np.diag([1e-3, 2e-3, 5e-4]), Q=np.zeros((3, 3)), left=left)
        for k, h in enumerate(HALF_TURNS * 3):
            _step(py, c, h, h if k % 2 else np.eye(3))
            _step(py, c, None, np.array([0.0, 0.0, 1.0]))


def test_singular_innovation_leaves_the_state_unchanged():
    py, c = _pair(P=np.zeros((3, 3)), Q=np.zeros((3, 3)), R=np.zeros((3, 3)))
    before = c.tobytes()
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        kernel.update(py, so3.exp([0.1, 0.2, 0.3]), None)
    assert NATIVE.update(c, so3.exp([0.1, 0.2, 0.3]), None) == 0.0      # det S, nothing written
    assert c.tobytes() == before
    _same(py, c)
    f = InvariantEKF(P=0.0, Q=0.0, R=0.0)
    with pytest.raises(np.linalg.LinAlgError, match="singular"):
        f.update(np.array([0.0, 0.0, 1.0]))


def test_arguments_the_c_kernels_leave_to_python():
    s = array("d", new_state((1.0, 0.0, 0.0, 0.0), [1.0] * 9, [0.0] * 9, [1.0] * 9, [0.0, 0.0, 1.0], True, 100))
    before = s.tobytes()
    for u in ([[1, 0, 0], [0, 1, 0], [0, 0, 1]], np.eye(3, dtype=int), np.asfortranarray(so3.rotx(0.3)),
              np.zeros(4), np.eye(3, dtype=np.float32)):
        assert NATIVE.predict(s, u, None) is False and s.tobytes() == before
    assert NATIVE.update(s, np.zeros((2, 2)), None) is False and s.tobytes() == before
    with pytest.raises(ValueError, match="123 doubles"):
        NATIVE.predict(array("d", [0.0] * 10), None, None)
    with pytest.raises(TypeError, match="3 arguments"):
        NATIVE.update(s, None)


@contextmanager
def _python_kernels():
    """InvariantEKF on the pure-Python kernels (a list buffer) inside this block, in this process."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(invariant_ekf, "_predict", kernel.predict)
        mp.setattr(invariant_ekf, "_update", kernel.update)
        mp.setattr(invariant_ekf, "_buffer", list)
        mp.setattr(invariant_ekf, "_view", lambda s: s)
        mp.setattr(invariant_ekf, "_from_array", lambda a: a.ravel().tolist())
        mp.setattr(invariant_ekf, "_fill_x", kernel.state_x)
        yield


def _run_both(f, g, steps):
    """Run ``steps`` (callables taking a filter) on the C-backed ``f`` and the Python-backed ``g``."""
    for step in steps:
        step(f)
        with _python_kernels():
            step(g)
            got = {name: getattr(g, name) for name in ATTRIBUTES}
        for name in ATTRIBUTES:
            assert_twins_equal(getattr(f, name), got[name], name)
        assert f._updates == g._updates


@pytest.mark.parametrize("error", ["left", "right"])
def test_whole_calls_equal_with_every_argument_form(error):
    """The wrapper's coercions (lists, ints, Fortran order, scalars), filterpy's in-place idioms."""
    kw = dict(x=so3.exp([0.3, -0.2, 1.0]), P=0.4, Q=Q_DIAG, R=R_FULL, error=error)
    f = InvariantEKF(**kw)
    with _python_kernels():
        g = InvariantEKF(**kw)
    assert type(f._s) is array and type(g._s) is list
    steps = [lambda h: h.predict(so3.rotx(0.2).tolist()),
             lambda h: h.update(so3.roty(0.1).tolist()),
             lambda h: h.predict([0.01, 0.02, 0.03], Q=1e-3),
             lambda h: h.update(np.array([0.1, 0.0, 1.0]) / np.hypot(0.1, 1.0), R=0.5),
             lambda h: h.predict(np.asfortranarray(so3.rotz(0.4)), Q=np.asfortranarray(Q_DIAG)),
             lambda h: h.update(np.eye(3, dtype=int)),
             lambda h: h.P.__imul__(2.0),
             lambda h: h.predict(None),
             lambda h: h.Q.__setitem__((2, 2), 0.3),
             lambda h: setattr(h, "R", R_FULL.T),
             lambda h: h.update(so3.exp([0.2, 0.1, -0.3])),
             lambda h: h.x.__setitem__(slice(None), so3.rotx(0.05)),
             lambda h: h.update(None),
             lambda h: h.predict(so3.exp([0.0, 0.0, 3.0])),
             lambda h: h.update(np.array([0.0, 0.0, 1.0]))]
    _run_both(f, g, steps)
    for bad, match in ((np.zeros(4), "z must be a 3x3 rotation"), (np.zeros((2, 3)), "z must be a 3x3 rotation")):
        with pytest.raises(ValueError, match=match):
            f.update(bad)
        with _python_kernels(), pytest.raises(ValueError, match=match):
            g.update(bad)
    with pytest.raises(ValueError, match="rotation increment"):
        f.predict(np.zeros(2))


@pytest.mark.shared
def test_kitti_oxts_attitudes_bit_identical(shared_data):
    """Real KITTI OXTS attitudes: increments between rows predict, the attitude (rotation) and
    its up axis (direction) correct, left and right error."""
    import warnings

    from imu_ground.datasets import read_kitti_imu100
    files = sorted((shared_data / "kitti_imu100").glob("*.csv.gz"))[:2]
    assert files
    for path in files:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = read_kitti_imu100(path).to_dataframe()
        Rw = so3.rotz(d["yaw"].to_numpy()) @ so3.roty(d["pitch"].to_numpy()) @ so3.rotx(d["roll"].to_numpy())
        U = np.swapaxes(Rw[:-1], 1, 2) @ Rw[1:]
        for left in (True, False):
            py, c = _pair(x0=Rw[0], P=np.diag([1e-2, 1e-2, 1e-1]), Q=1e-4 * np.eye(3), R=R_FULL * 1e-3, left=left)
            for k in range(min(len(U), 3000)):
                z = Rw[k + 1] if k % 2 else np.ascontiguousarray(Rw[k + 1][:, 2])
                _step(py, c, np.ascontiguousarray(U[k]), z)
            assert np.array_equal(np.array(py[B_P:B_P + 9]), np.array(py[B_P:B_P + 9]).reshape(3, 3).T.ravel())


def test_no_leaks_over_many_calls():
    """1e5 predict/update pairs allocate nothing that stays; the inputs' refcounts are unchanged."""
    f = InvariantEKF(P=1.0, Q=Q_DIAG, R=R_FULL)
    u, zr, zd = so3.exp([0.01, -0.02, 0.03]), so3.exp([0.1, 0.2, -0.1]), np.array([0.0, 0.6, 0.8])
    refs = [sys.getrefcount(o) for o in (u, zr, zd, f._s)]
    predict, update = f.predict, f.update
    for k in range(2000):
        predict(u)
        update(zr if k % 2 else zd)
    gc.collect()
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    for k in range(100_000):
        predict(u)
        update(zr if k % 2 else zd)
    gc.collect()
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    assert grown < 16 * 1024, grown
    assert [sys.getrefcount(o) for o in (u, zr, zd, f._s)] == refs
    assert np.array_equal(f.P, f.P.T) and np.isfinite(f._s[B_DET])
