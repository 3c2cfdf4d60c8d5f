"""The README's Python blocks run as written (real-data lines skip without ../shared/data)."""
import ast
import re
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
BLOCKS = re.findall(r"```python\n(.*?)```", (REPO / "README.md").read_text(encoding="utf-8"), flags=re.DOTALL)


@pytest.mark.parametrize("index", [pytest.param(i, marks=[pytest.mark.shared] if "../shared/data" in b else [])
                                   for i, b in enumerate(BLOCKS)])
def test_readme_python_block_runs(index, tmp_path, monkeypatch, request):
    code = BLOCKS[index]
    if "../shared/data" in code:
        shared = request.getfixturevalue("shared_data")
        code = code.replace("../shared/data", str(shared))
    code = code.replace('"datasets/', f'"{REPO}/datasets/')
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(code, f"README.md python block {index}", "exec"), namespace)
    # what the block says it makes, checked against things it does not compute itself
    for name in _assigned_names(code):
        assert namespace.get(name) is not None, f"README block {index}: {name} is None"
    for written in re.findall(r'write_output\(\s*"([^"]+)"', code):
        assert (tmp_path / written).is_file() and (tmp_path / written).stat().st_size > 0, written
    if "result" in namespace and "table" in namespace:
        assert len(namespace["table"]) == len(namespace["result"].egomotion)
    if "track" in namespace and "frames" in namespace:
        track, frames = namespace["track"], namespace["frames"]
        assert len(track.pitch) == len(frames) and np.isfinite(track.pitch[track.valid]).all()
        if "imu" in namespace:                       # 10 Hz frames over the log's span
            imu = namespace["imu"]
            assert abs(len(frames) - (imu.t[-1] - imu.t[0]) * 10.0) <= 1


def _assigned_names(code: str) -> list[str]:
    """Names the block binds at top level (assignments and for-loop targets)."""
    names = []
    for node in ast.parse(code).body:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, (ast.For, ast.AnnAssign, ast.AugAssign)) else []
        names += [t.id for t in targets if isinstance(t, ast.Name)]
    return names


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 2
