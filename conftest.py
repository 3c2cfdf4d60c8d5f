"""Shared pytest fixtures: the real recordings in ../shared/data, skipped cleanly when absent.

Every test that uses the ``shared_data`` fixture is marked ``shared`` automatically
(``pytest -m "not shared"`` runs the suite without the real recordings), so the
marker cannot be forgotten on a real-data test.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent
SHARED_DATA = Path(os.environ.get("IMU_GROUND_SHARED_DATA", REPO.parent / "shared" / "data"))


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
