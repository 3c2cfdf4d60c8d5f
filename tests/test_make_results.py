"""benchmarks/make_results.py ``--only``: a part rewritten in place, the rest of RESULTS.md kept as it was."""
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))
import make_results  # noqa: E402  (the benchmark script, not a package module)

OLD = """# imu-ground results

Written long ago.

# Accuracy

## Real drives (shared KITTI, IMU only)

| old | table |

## Synthetic drives

| old | synthetic |

# Where the real-drive error is

## error_budget

| kept |
"""


def test_only_accuracy_replaces_the_accuracy_part_and_keeps_the_rest(tmp_path, monkeypatch):
    out = tmp_path / "RESULTS.md"
    out.write_text(OLD)
    seen = {}

    def fresh(data, quick):
        seen["args"] = (data, quick)
        return ["# Accuracy", "", "## Real drives (shared KITTI, IMU only)", "", "| new | table |", ""]

    monkeypatch.setattr(make_results, "accuracy_sections", fresh)
    assert make_results.main(["--only", "accuracy", "--out", str(out), "--data", str(tmp_path)]) == 0
    text = out.read_text()
    assert seen["args"] == (tmp_path, False)
    assert "| new | table |" in text and "| old |" not in text        # the whole part, synthetic table too
    assert text.startswith("# imu-ground results\n\nWritten long ago.\n\n# Accuracy\n\nPart rewritten alone")
    assert text.index("| new | table |") < text.index("# Where the real-drive error is")
    assert text.endswith("## error_budget\n\n| kept |\n")
