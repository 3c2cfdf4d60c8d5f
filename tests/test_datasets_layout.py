"""The readers' house rules: CSV text through pandas alone, words a reader without a tracker understands (the
package-wide limit of a module's size is in test_rooms.py)."""
from __future__ import annotations

import re
from pathlib import Path


REPO = Path(__file__).resolve().parents[1]
DATASETS = sorted((REPO / "datasets").glob("*.py"))


def _reader_files() -> list[Path]:
    tests = [p for pattern in ("test_read*.py", "test_validation*.py", "test_units_detection.py", "test_retime*.py",
                               "test_rosbag.py") for p in sorted((REPO / "tests").glob(pattern))]
    return DATASETS + [REPO / "benchmarks" / "bench_readers.py"] + tests


def test_csv_text_has_one_parser():
    assert not list((REPO / "datasets").glob("*.c")), "CSV text is parsed by pandas' C engine, not a kernel"
    assert not (REPO / "datasets" / "numeric_csv.py").exists()


def test_no_tracker_numbers_in_the_readers():
    pattern = re.compile(r"\bissues? #?\d+", re.IGNORECASE)
    found = [f"{p.relative_to(REPO)}:{i}" for p in _reader_files()
             for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert not found, found
