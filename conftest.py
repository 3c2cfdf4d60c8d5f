"""Shared pytest fixtures: the real recordings in ../shared/data, skipped cleanly when absent.

Every test that uses the ``shared_data`` fixture is marked ``shared`` automatically
(``pytest -m "not shared"`` runs the suite without the real recordings), so the
marker cannot be forgotten on a real-data test.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent
SHARED_DATA = Path(os.environ.get("IMU_GROUND_SHARED_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def read_ros_topics():
    """A reader of ROS outputs for the tests: ``read(path)`` gives every message of a bag or MCAP as
    ``(record ns, message)`` lists by topic, deserialised with rosbags' reader (an independent reader of what the
    package wrote)."""
    def read(path: Path) -> dict[str, list]:
        from rosbags.highlevel import AnyReader
        out: dict[str, list] = {}
        with AnyReader([Path(path)]) as reader:
            for conn, ns, raw in reader.messages():
                out.setdefault(conn.topic, []).append((ns, reader.deserialize(raw, conn.msgtype)))
        return out
    return read


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ../shared/data; skips the test when the folder is not there."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real recordings not available at {SHARED_DATA}")
    return SHARED_DATA


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test that needs the real recordings (directly or through a fixture) ``shared``."""
    for item in items:
        if "shared_data" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.shared)


#: The shared kitti_imu100 drives whose GPS/INS reference is known to be unusable (named in
#: ../shared/data/README.md); every other drive listed in ``drives.csv`` is expected to be valid.
KITTI_FAULTY_DRIVES = frozenset({"2011_09_26_drive_0093", "2011_09_28_drive_0039"})


@pytest.fixture(scope="session")
def kitti_index(shared_data: Path):
    """``kitti_imu100/drives.csv`` as a DataFrame: the one list of shared drives tests count from."""
    import pandas as pd
    return pd.read_csv(shared_data / "kitti_imu100" / "drives.csv")


@pytest.fixture(scope="session")
def kitti_faulty_names() -> frozenset:
    """:data:`KITTI_FAULTY_DRIVES`, for tests (conftest is not importable under ``--import-mode=importlib``)."""
    return KITTI_FAULTY_DRIVES


@pytest.fixture(scope="session")
def kitti_valid_names(kitti_index) -> list:
    """Names of the drives of ``drives.csv`` whose reference should pass the evaluation's check."""
    return [n for n in kitti_index["drive"] if n not in KITTI_FAULTY_DRIVES]


@pytest.fixture(scope="session")
def kitti_drives(shared_data: Path) -> list:
    """Every shared ``kitti_imu100`` drive with its reference, loaded once for the whole session
    (:func:`imu_ground.evaluation.load_real_drives`; ``Drive.valid`` is the reference check's verdict)."""
    import warnings

    from imu_ground.evaluation import load_real_drives
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_real_drives(shared_data / "kitti_imu100", progress=False)


@pytest.fixture
def cli(capsys):
    """``cli(*args) -> (exit status, stdout, stderr)``: ``imu-ground ARGS`` run in this process.

    argparse's exits (usage errors, ``--help``, ``--version``) count as the status they exit with.
    """
    from imu_ground.cli import main

    def run(*args):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:
            code = e.code
        out, err = capsys.readouterr()
        return code, out, err
    return run


@pytest.fixture(scope="session")
def speed_drive():
    """``speed_drive(duration, seed, imu) -> (EgoMotion, Extrinsic, speed)``: a synthetic urban drive
    (rough road B, stops and turns) with a misaligned mount, its 10 Hz ego-motion, the true extrinsic
    and the true speed per frame (frame means, m/s)."""
    from imu_ground import so3
    from imu_ground.datasets.speed import frame_speed
    from imu_ground.evaluation.simulate import RoadParams, SpeedParams, simulate
    from imu_ground.filters import Extrinsic
    from imu_ground.imu.egomotion import imu_to_egomotion

    def make(duration: float, seed: int, imu: str):
        sim = simulate(duration, seed=seed, imu=imu, road=RoadParams(roughness="B"),
                       speed=SpeedParams(style="urban"), R_gs=so3.rotz(0.05) @ so3.roty(0.02))
        em = imu_to_egomotion(sim.imu)
        tr = sim.truth
        v = frame_speed(tr["t"].to_numpy(), tr["speed"].to_numpy(), em.t, em.delta_t)
        return em, Extrinsic(sim.R_gs), v
    return make


@pytest.fixture(scope="session")
def with_true_speed():
    """``with_true_speed(sim) -> (Drive, speed)``: the evaluation's drive of a simulation and its true
    speed per frame (m/s), what the speed-aided and mount-change tests feed the filters."""
    from imu_ground.evaluation.drives import synthetic_drive

    def make(sim):
        d = synthetic_drive(sim)
        return d, d.truth["speed"].to_numpy()
    return make


@pytest.fixture
def one_error():
    """``one_error(stderr, *words) -> line``: stderr is one error line (no traceback) holding every word."""
    def check(err: str, *words) -> str:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert len(lines) == 1 and "Traceback" not in err, err
        for w in words:
            assert str(w) in lines[0], (w, err)
        return lines[0]
    return check


@pytest.fixture
def heavy_modules_loaded():
    """``run(code) -> list``: the heavy modules (scipy and its submodules, pandas, matplotlib, tqdm) that
    ``code`` (after ``import imu_ground``, numpy as ``np``) loads in a fresh process beyond those numba brings
    itself (numba imports a part of scipy, and scipy.linalg once it compiles or loads a first function: a trivial
    one is compiled first when the compiled bodies are in use)."""
    import subprocess
    import sys

    def run(code: str) -> list:
        child = ("import sys; import numpy as np; from imu_ground import _jit; "
                 "_jit.JIT_ENABLED and __import__('numba').njit(lambda: 0)(); base = set(sys.modules); "
                 f"import imu_ground; {code}; "
                 "import json; print(json.dumps(sorted(m for m in set(sys.modules) - base "
                 "if m.split('.')[0] in ('scipy', 'pandas', 'matplotlib', 'tqdm'))))")
        out = subprocess.run([sys.executable, "-c", child], capture_output=True, text=True, check=True).stdout
        return json.loads(out.strip().splitlines()[-1])
    return run
