"""The package's size by area and by kind of line, and what a line budget leaves for the docstrings.

    python benchmarks/studies/package_size.py

Counts the physical lines of the ``.py`` files of ``imu_ground/``, ``datasets/`` and ``calib/`` (tests are
outside them) as issue 37 does (``wc -l``), each line of one kind: ``docstring`` (a module's, class's or
function's docstring, private ones included), ``comment``, ``blank`` or ``code``. The budget table sets a
total (:data:`BUDGET`, the issue's) against the code and blank lines, and divides what is left by the public
objects (classes and functions whose names do not start with ``_``) whose NumPy-style docstrings it must
carry; it also counts their parameters (``self`` and ``cls`` left out), each of which a Parameters section
describes.
"""
from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
ROOTS = ("imu_ground", "datasets", "calib")
#: The line budget of issue 37 for the package.
BUDGET = 22_000
KINDS = ("docstring", "code", "blank", "comment")


def _area(path: Path) -> str:
    """``imu_ground/filters/x.py`` -> ``filters``; a top-level module -> ``imu_ground``; ``datasets``, ``calib``."""
    parts = path.relative_to(REPO).parts
    return parts[1] if parts[0] == "imu_ground" and len(parts) > 2 else parts[0]


def line_kinds(source: str) -> list[str]:
    """The kind of each physical line of a Python source (one of :data:`KINDS`)."""
    lines = source.splitlines()
    kinds = ["blank" if not s.strip() else "comment" if s.strip().startswith("#") else "code" for s in lines]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                    and isinstance(first.value.value, str) and first.end_lineno is not None):
                kinds[first.lineno - 1:first.end_lineno] = ["docstring"] * (first.end_lineno - first.lineno + 1)
    return kinds


def _public_objects(source: str) -> tuple[int, int]:
    """(public classes and functions, their parameters) of a source."""
    objects = parameters = 0
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and not node.name.startswith("_"):
            objects += 1
            if not isinstance(node, ast.ClassDef):
                args = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                parameters += sum(a.arg not in ("self", "cls") for a in args)
    return objects, parameters


def rows() -> list[dict]:
    """The ``by area`` table (lines of each kind) and the ``budget`` table."""
    areas: dict[str, Counter] = {}
    objects = parameters = 0
    for root in ROOTS:
        for path in sorted((REPO / root).rglob("*.py")):
            source = path.read_text()
            areas.setdefault(_area(path), Counter()).update(line_kinds(source))
            o, p = _public_objects(source)
            objects, parameters = objects + o, parameters + p
    total = sum(areas.values(), Counter())
    out = [{"table": "by area", "area": a, "lines": sum(c.values()), **{k: c[k] for k in KINDS}}
           for a, c in sorted(areas.items(), key=lambda item: -sum(item[1].values()))]
    out.append({"table": "by area", "area": "all", "lines": sum(total.values()), **{k: total[k] for k in KINDS}})
    fixed = total["code"] + total["blank"]
    left = BUDGET - fixed - total["comment"]
    out.append({"table": "budget", "budget": BUDGET, "code + blank": fixed, "comment": total["comment"],
                "left for docstrings": left, "docstrings now": total["docstring"], "public objects": objects,
                "public parameters": parameters, "modules": sum(1 for r in ROOTS for _ in (REPO / r).rglob("*.py")),
                "docstring lines a public object": round(left / objects, 2)})
    return out


if __name__ == "__main__":
    for row in rows():
        print(row)
