"""The package's layers import only downward, and no module imports itself back through others.

Layers, lowest first (see ``imu_ground/__init__.py``): foundation (``so3``,
``units``, ``errors``, ``_lazy``, ``_jit``) < ``imu`` < ``datasets`` and ``filters`` (siblings: the readers and the
estimators do not import each other) < ``perception`` < ``pipeline`` and ``evaluation`` (siblings too) < ``cli`` < ``__main__``. Every
``import`` statement counts, including those inside functions (lazy imports
hide a dependency from the import system but not from a reader).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import imu_ground

ROOT = Path(imu_ground.__file__).resolve().parent
DATASETS = Path(imu_ground.__file__).resolve().parent.parent / "datasets"

RANK = {"_lazy": 0, "_jit": 0, "_version": 0, "errors": 0, "so3": 0, "units": 0, "imu": 1, "datasets": 2,
        "filters": 2, "perception": 3.5, "pipeline": 4, "evaluation": 4, "cli": 5, "__main__": 6}
#: Scripts and tests that live in package folders but are not part of the package's import graph.
NOT_LIBRARY = ("test_", "derive_kitti")


def _modules() -> dict[str, Path]:
    mods: dict[str, Path] = {}
    for base, prefix in ((ROOT, "imu_ground"), (DATASETS, "imu_ground.datasets")):
        for p in sorted(base.rglob("*.py")):
            if p.name.startswith(NOT_LIBRARY) or "calib" in p.relative_to(base).parts[:1]:
                continue
            if prefix == "imu_ground" and p.relative_to(base).parts[0] == "datasets":
                continue
            parts = list(p.relative_to(base).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join([prefix, *parts])] = p
    return mods


MODULES = _modules()


def _resolve(importer: str, node: ast.AST) -> list[str]:
    """Absolute names of the project modules an import statement reaches."""
    is_pkg = MODULES[importer].name == "__init__.py"
    out: list[str] = []
    if isinstance(node, ast.Import):
        out = [a.name for a in node.names]
    elif isinstance(node, ast.ImportFrom):
        if node.level:
            base = importer.split(".")
            base = base[: len(base) - node.level + (1 if is_pkg else 0)]
            mod = ".".join(base + ([node.module] if node.module else []))
        else:
            mod = node.module or ""
        for a in node.names:
            sub = f"{mod}.{a.name}"
            out.append(sub if sub in MODULES else mod)
    return [m for m in out if m.split(".")[0] == "imu_ground"]


def _edges() -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        targets = set()
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                targets.update(m for m in _resolve(name, node) if m != name)
        edges[name] = targets
    return edges


def _layer(module: str) -> tuple[str, int]:
    parts = module.split(".")
    if len(parts) == 1:
        return "imu_ground", 99            # the top-level namespace re-exports everything
    return parts[1], RANK[parts[1]]


def test_every_module_has_a_layer():
    unknown = sorted(m for m in MODULES if m != "imu_ground" and m.split(".")[1] not in RANK)
    assert not unknown, f"modules outside every layer: {unknown}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if m != "imu_ground"))
def test_imports_go_downward(module):
    layer, rank = _layer(module)
    bad = []
    for target in sorted(_edges_cache()[module]):
        t_layer, t_rank = _layer(target)
        if t_layer != layer and t_rank >= rank:
            bad.append(f"{target} ({t_layer})")
    assert not bad, f"{module} ({layer}) imports upward or sideways: {bad}"


def test_no_import_cycle():
    edges = _edges_cache()
    state: dict[str, int] = {}
    stack: list[str] = []
    cycles: list[list[str]] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(edges.get(m, ())):
            if t not in edges:
                continue
            if state.get(t) == 1:
                cycles.append(stack[stack.index(t):] + [t])
            elif t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_the_errors_import_nothing_of_the_package_and_the_filters_not_the_readers():
    """Errors and warnings are foundation: ``imu_ground.errors`` imports no package module, and
    ``filters/`` raises its errors without importing :mod:`imu_ground.datasets`."""
    edges = _edges_cache()
    assert not edges["imu_ground.errors"], sorted(edges["imu_ground.errors"])
    readers = sorted(f"{m} -> {t}" for m, ts in edges.items() if m.startswith("imu_ground.filters")
                     for t in ts if t.startswith("imu_ground.datasets"))
    assert not readers, readers


def test_the_checker_sees_an_upward_import(tmp_path):
    """The walk is not vacuous: a lazy upward import inside a function is found."""
    src = "def f():\n    from imu_ground.cli import main\n    return main\n"
    tree = ast.parse(src)
    node = [n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)][0]
    assert _resolve("imu_ground.so3", node) == ["imu_ground.cli"]
    assert _layer("imu_ground.cli")[1] > _layer("imu_ground.so3")[1]


_CACHE: dict[str, set[str]] = {}


def _edges_cache() -> dict[str, set[str]]:
    if not _CACHE:
        _CACHE.update(_edges())
    return _CACHE


def test_every_sub_package_is_packaged():
    """pyproject lists every sub-package (an editable install hides a missing one; a wheel would lack it)."""
    import tomllib
    pyproject = ROOT.parent / "pyproject.toml"
    if not pyproject.is_file():
        pytest.skip("not a source checkout")
    listed = set(tomllib.loads(pyproject.read_text())["tool"]["setuptools"]["packages"])
    found = {"imu_ground." + ".".join(p.parent.relative_to(ROOT).parts) if p.parent != ROOT else "imu_ground"
             for p in ROOT.rglob("__init__.py") if "datasets" not in p.relative_to(ROOT).parts}
    missing = sorted(found - listed)
    assert not missing, f"sub-packages missing from pyproject's [tool.setuptools] packages: {missing}"


def test_top_level_names_resolve():
    """Every lazily exported name of every package namespace imports and is what it says."""
    import importlib
    for pkg in ("imu_ground", "imu_ground.imu", "imu_ground.filters", "imu_ground.perception", "imu_ground.pipeline",
                "imu_ground.evaluation"):
        mod = importlib.import_module(pkg)
        for name in mod.__all__:
            if name != "__version__":
                assert getattr(mod, name) is not None, f"{pkg}.{name}"
    with pytest.raises(AttributeError):
        imu_ground.NoSuchName  # noqa: B018


def test_import_is_light(heavy_modules_loaded):
    """``import imu_ground`` loads none of numba, scipy, pandas; building a filter loads nothing heavy beyond
    numba (and the part of scipy numba imports itself)."""
    import subprocess
    import sys
    code = ("import sys, imu_ground; "
            "print(sorted(m for m in ('numba', 'scipy', 'pandas', 'matplotlib', 'tqdm') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out
    assert heavy_modules_loaded("imu_ground.GroundNormalFilter(); imu_ground.SuspensionAwareFilter()") == []
