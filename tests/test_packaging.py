"""What the wheel and the sdist carry: the licence, ``py.typed``, the metadata, no tests in the wheel, and in the
sdist everything its own test suite needs."""
from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _typecheck():
    """tests/typecheck.py as a module (tests are not importable under ``--import-mode=importlib``)."""
    spec = importlib.util.spec_from_file_location("_typecheck", REPO / "tests" / "typecheck.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def pyproject() -> dict:
    return _typecheck().tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))


def test_the_wheel_packages_hold_no_tests():
    folders = _typecheck().package_folders()
    assert folders["imu_ground.datasets"] == REPO / "datasets" and folders["imu_ground.calib"] == REPO / "calib"
    found = [str(p.relative_to(REPO)) for folder in folders.values()
             for p in sorted(folder.glob("*.py")) if p.name.startswith("test_") or p.name == "conftest.py"]
    assert not found, f"tests inside installed packages (they belong in tests/): {found}"


def test_the_licence_and_py_typed_are_shipped(pyproject):
    project = pyproject["project"]
    assert project["license"] == "MIT" and project["license-files"] == ["LICENSE"]
    text = (REPO / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License") and "imu-ground developers" in text
    assert "py.typed" in pyproject["tool"]["setuptools"]["package-data"]["imu_ground"]
    assert (REPO / "imu_ground" / "py.typed").is_file()


def test_the_metadata_names_authors_keywords_classifiers(pyproject):
    project = pyproject["project"]
    assert project["authors"] == [{"name": "imu-ground developers"}]
    assert "imu" in project["keywords"]
    assert "Typing :: Typed" in project["classifiers"]
    # PEP 639: the SPDX expression is the licence; a licence classifier beside it is refused by setuptools
    assert not [c for c in project["classifiers"] if c.startswith("License ::")]


def test_the_sdist_carries_every_tracked_file(tmp_path):
    """The sdist's tests run (`pip install -e ".[test]" && python -m pytest` in the unpacked folder) only if it
    has the root conftest.py, tests/, benchmarks/, README.md, .ci/run...: here every file git tracks."""
    pytest.importorskip("build")
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("not a git checkout (e.g. the unpacked sdist itself): nothing to compare with")
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, text=True, check=True)
    files = {f for f in tracked.stdout.split("\0") if f and (REPO / f).is_file()}
    run = subprocess.run([sys.executable, "-m", "build", "--sdist", "--no-isolation", "-o", str(tmp_path), str(REPO)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    (sdist,) = tmp_path.glob("*.tar.gz")
    with tarfile.open(sdist) as tar:
        shipped = {name.split("/", 1)[1] for name in tar.getnames() if "/" in name}
    missing = sorted(files - shipped - {".gitignore"})
    assert not missing, f"tracked files the sdist lacks (MANIFEST.in): {missing}"
    assert {"conftest.py", "LICENSE", "README.md", "tests/test_readme.py"} <= shipped
