"""The compiled kernels: every C source is built and loaded once, by one module, and the pure-Python switch works.

``setup.py`` builds each ``_*_native.c`` of ``imu_ground/`` as an *optional* extension,
so a failed compile does not stop the install; this test is what notices it. Without a C
compiler a kernel that is not built is a skip naming the reason; CI (``.ci/run``) sets
``IMU_GROUND_REQUIRE_NATIVE=1``, which makes it a failure. Each kernel's own tests compare
the C and the Python twin (``tests/twins.py``: the one equality rule).
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from imu_ground import _native
from imu_ground._native import PURE_PYTHON_ENV, REQUIRE_NATIVE_ENV, STREAMING_KERNELS, load_native, native_kernels

REPO = Path(__file__).resolve().parents[1]
#: Folders with kernels -> the package they are installed as (setup.py's NATIVE_FOLDERS).
FOLDERS = {"imu_ground": "imu_ground"}
SOURCES = sorted(src for folder in FOLDERS for src in (REPO / folder).rglob("_*_native.c"))
PURE = os.environ.get(PURE_PYTHON_ENV, "") not in ("", "0")
REQUIRED = os.environ.get(REQUIRE_NATIVE_ENV, "") not in ("", "0")


def _module_name(src: Path) -> str:
    folder = src.relative_to(REPO).parts[0]
    return ".".join((FOLDERS[folder],) + src.relative_to(REPO / folder).with_suffix("").parts)


def test_the_folders_are_setup_pys():
    text = (REPO / "setup.py").read_text()
    assert all(f'"{folder}": "{package}"' in text for folder, package in FOLDERS.items())
    assert not list((REPO / "datasets").rglob("_*_native.c")), "CSV text is parsed by pandas, not a kernel"


def test_sources_follow_the_naming_rule():
    for src in SOURCES:
        text = src.read_text()
        stem = src.stem
        assert f"PyInit_{stem}" in text, f"{src}: the init function must be PyInit_{stem}"


def test_every_streaming_kernel_has_a_source_and_is_known_from_the_first_import():
    names = {_module_name(s) for s in SOURCES}
    assert set(STREAMING_KERNELS) <= names
    assert set(STREAMING_KERNELS) <= set(native_kernels())      # before any filter has run


@pytest.mark.skipif(PURE and not REQUIRED, reason=f"{PURE_PYTHON_ENV} is set: the pure-Python kernels are in use")
@pytest.mark.parametrize("src", SOURCES, ids=[s.name for s in SOURCES])
def test_every_kernel_is_built_and_loads(src):
    name = _module_name(src)
    module = load_native(name)
    if module is None:
        why = (f"{name} is not built (no C compiler at install?): the pure-Python twin runs; reinstall with a "
               f"C compiler (`pip install -e .`) and read the compiler's output")
        if not REQUIRED:
            pytest.skip(why)
        pytest.fail(f"{why} [{REQUIRE_NATIVE_ENV} is set: a missing kernel is a failure]")
    assert native_kernels()[name] is True
    assert Path(module.__file__).stat().st_mtime >= src.stat().st_mtime - 1.0, \
        f"{module.__file__} is older than {src.name}: rebuild (`pip install -e .`)"


def test_the_kernel_owners_take_the_one_loaded_twin():
    from imu_ground.filters import invariant_ekf
    assert invariant_ekf._C is _native.EKF


def test_pure_python_switch_turns_every_kernel_off():
    names = [_module_name(s) for s in SOURCES] or ["imu_ground.filters._ekf_native"]
    code = ("import sys; from imu_ground import _native; "
            f"sys.exit(any(_native.load_native(n) is not None for n in {names!r}) "
            "or any(_native.native_kernels().values()) or 'pure Python' not in _native.kernels_in_use())")
    env = dict(os.environ, **{PURE_PYTHON_ENV: "1"})
    assert subprocess.run([sys.executable, "-c", code], check=False, env=env).returncode == 0


def test_a_missing_module_falls_back():
    assert load_native("imu_ground.filters._no_such_native") is None
    assert native_kernels()["imu_ground.filters._no_such_native"] is False
