"""One concept a module: a library module holds one concept and takes the lines it needs up to a limit, and no
module-level function reaches into another object's private attributes (that function belongs to the object).

The limit is one of concepts, not of lines: an estimator class may be long (its state, step, batch run, saved
state and online re-estimation are one concept), a module of several concepts is split by concept. The line
cap only catches a module that has clearly grown into several.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import imu_ground

ROOT = Path(imu_ground.__file__).resolve().parent
DATASETS = ROOT.parent / "datasets"
#: The most lines a library module may have.
MAX_LINES = 1000
#: Scripts that live in package folders but are not library modules.
NOT_LIBRARY = ("test_", "derive_kitti")


def _library() -> list[Path]:
    files = sorted(ROOT.rglob("*.py")) + sorted(DATASETS.glob("*.py"))
    return [p for p in files if not p.name.startswith(NOT_LIBRARY) and "calib" not in p.relative_to(ROOT.parent).parts[:1]]


LIBRARY = _library()


def _ids(paths) -> list[str]:
    return [str(p.relative_to(ROOT.parent)) for p in paths]


@pytest.mark.parametrize("module", LIBRARY, ids=_ids(LIBRARY))
def test_no_library_module_over_the_limit(module):
    lines = len(module.read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_LINES, f"{module.name}: {lines} lines; split it by concept"


def private_reaches(tree: ast.Module) -> list[tuple[str, int, str]]:
    """``(function, line, expression)`` of every ``x._name`` (not a dunder) in a module-level function, where
    ``x`` is neither ``self`` / ``cls`` (a method made by a property factory) nor an imported module
    (``sys._getframe`` is the standard library's API)."""
    modules = {(a.asname or a.name).split(".")[0] for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))
               for a in n.names}
    out = []
    for fn in tree.body:
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                    and not (isinstance(node.value, ast.Name) and node.value.id in modules | {"self", "cls"})):
                out.append((fn.name, node.lineno, ast.unparse(node)))
    return out


def test_the_private_reach_finder_finds_one():
    tree = ast.parse("import sys\ndef f(g):\n    return g._s + sys._getframe(0).f_lineno\nclass A:\n"
                     "    def m(self, o):\n        return self._x + o._y\n")
    assert private_reaches(tree) == [("f", 3, "g._s")]


def test_no_module_function_reaches_into_another_objects_private_attributes():
    found = [f"{p.relative_to(ROOT.parent)}:{line} {fn}: {expr}" for p in LIBRARY
             for fn, line, expr in private_reaches(ast.parse(p.read_text(encoding="utf-8")))]
    assert not found, "make these methods of the object they reach into:\n" + "\n".join(found)


def _room_table() -> dict[str, tuple[set[str], set[str]]]:
    """Layer -> the room table's names (docs/library.md): those outside parentheses (modules), and all."""
    import re
    rows = {}
    for line in (ROOT.parent / "docs" / "library.md").read_text(encoding="utf-8").splitlines():
        m = re.match(r"\| `imu_ground\.(\w+)` \| (.*?) \| ", line)
        if not m:
            continue
        text = everything = m.group(2)
        while re.search(r"\([^()]*\)", text):
            text = re.sub(r"\([^()]*\)", "", text)
        rows[m.group(1)] = set(re.findall(r"`(\w+)`", text)), set(re.findall(r"`(\w+)`", everything))
    return rows


@pytest.mark.parametrize("layer, complete", [("imu", True), ("filters", True), ("pipeline", True),
                                             ("perception", True), ("datasets", False), ("evaluation", False)])
def test_the_readme_room_table_follows_the_tree(layer, complete):
    """Every module the table names exists; for the layers it lists whole, every module is named."""
    base = DATASETS if layer == "datasets" else ROOT / layer
    tree = {p.stem for p in base.glob("*.py") if not p.name.startswith(("__", *NOT_LIBRARY))}
    tree |= {p.name for p in base.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    named, mentioned = _room_table()[layer]
    assert named <= tree, f"docs/library.md names modules that are not in imu_ground/{layer}: {sorted(named - tree)}"
    if complete:
        assert tree <= mentioned, f"modules of imu_ground/{layer} missing from docs/library.md's table: {sorted(tree - mentioned)}"


def test_the_pipeline_reads_no_private_attribute_of_another_object():
    """``x._name`` read anywhere in ``pipeline/`` (methods included) where ``x`` is not ``self``/``cls`` or a
    module: the owning class gives what is read (e.g. :meth:`GroundEstimate.copy_of`)."""
    found = set()
    for path in sorted((ROOT / "pipeline").glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        modules = {(a.asname or a.name).split(".")[0] for n in ast.walk(tree)
                   if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Load) and node.attr.startswith("_")
                    and not node.attr.startswith("__") and node.attr != "_replace"
                    and not (isinstance(node.value, ast.Name) and node.value.id in modules | {"self", "cls"})):
                found.add((path.name, ast.unparse(node)))
    assert not found, sorted(found)
