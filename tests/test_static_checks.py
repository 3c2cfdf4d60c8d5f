"""The tree stays clean for ruff (the rules of ``[tool.ruff.lint]``) and the package for mypy (default settings
and the stricter ones of ``[tool.mypy]``), as the pre-commit hooks check before a commit. Each skips when its
tool is not installed (both are in the ``test`` extra)."""
from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.skip("ruff is not installed (pip install -e '.[test]')")
    run = subprocess.run([ruff, "check", "--no-cache", "--output-format", "concise", str(REPO)], cwd=REPO,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]


def test_ruff_is_configured_for_the_rules_of_the_project():
    tomllib = pytest.importorskip("tomllib")
    lint = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["ruff"]["lint"]
    assert {"E4", "E7", "E9", "F", "B"} <= set(lint["select"])
    assert not lint.get("ignore") and not lint.get("per-file-ignores")        # (a finding is fixed or noqa'd)


def test_the_mypy_settings_add_strictness_only():
    tomllib = pytest.importorskip("tomllib")
    tool = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]
    silencing = {"ignore_errors", "disable_error_code", "ignore_missing_imports", "follow_imports",
                 "allow_untyped_globals", "allow_redefinition"}
    assert not silencing & set(tool)
    for override in tool.get("overrides", []):
        # ignore_missing_imports only for a third-party module that ships neither annotations nor stubs
        assert set(override) <= {"module", "ignore_missing_imports"}
        modules = override["module"] if isinstance(override["module"], list) else [override["module"]]
        assert not [m for m in modules if m.split(".")[0] in ("imu_ground", "datasets", "calib")]


@pytest.mark.slow
def test_mypy_finds_nothing_in_the_package():
    """``python tests/typecheck.py``: mypy on the installed layout (about a minute on a quiet machine; its cache
    in .mypy_cache makes the next run quicker)."""
    if importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed (pip install -e '.[test]')")
    run = subprocess.run([sys.executable, str(REPO / "tests" / "typecheck.py")], cwd=REPO, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stdout[-6000:] + run.stderr[-2000:]
    assert "Success: no issues found" in run.stdout
