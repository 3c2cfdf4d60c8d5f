"""The Python blocks of the README and the ``docs/`` pages run as written (real-data lines skip without ../shared/data)."""
import ast
import re
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
#: (page, index on the page, code) of every Python block.
PAGE_BLOCKS = [(page.relative_to(REPO).as_posix(), i, b) for page in PAGES for i, b in
               enumerate(re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.DOTALL))]
BLOCKS = [b for page, _, b in PAGE_BLOCKS if page == "README.md"]


@pytest.mark.parametrize("page, index, code", [
    pytest.param(p, i, b, marks=[pytest.mark.shared] if "../shared/data" in b else [], id=f"{p} block {i}")
    for p, i, b in PAGE_BLOCKS])
def test_readme_python_block_runs(page, index, code, tmp_path, monkeypatch, request):
    if "../shared/data" in code:
        shared = request.getfixturevalue("shared_data")
        code = code.replace("../shared/data", str(shared))
    code = code.replace('"datasets/', f'"{REPO}/datasets/')
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(code, f"{page} python block {index}", "exec"), namespace)
    # what the block says it makes, checked against things it does not compute itself
    for name in _assigned_names(code):
        assert namespace.get(name) is not None, f"{page} block {index}: {name} is None"
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
    assert {p for p, _, _ in PAGE_BLOCKS} >= {"docs/library.md", "docs/live.md", "docs/camera.md"}
