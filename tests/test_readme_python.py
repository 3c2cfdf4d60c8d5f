"""The README's Python blocks run as written (real-data lines skip without ../shared/data)."""
import re
from pathlib import Path

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
    assert namespace, "the block defined nothing"


def test_readme_has_python_blocks():
    assert len(BLOCKS) >= 2
