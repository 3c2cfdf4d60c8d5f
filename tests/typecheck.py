"""mypy on the whole package as it is installed: ``python tests/typecheck.py [mypy options]``.

The repository's ``datasets/`` and ``calib/`` folders are installed as ``imu_ground.datasets`` and
``imu_ground.calib`` (``[tool.setuptools.package-dir]`` in ``pyproject.toml``), a mapping mypy cannot be
told and that the editable install makes with an import hook mypy does not run. So this script lays the
installed layout out in ``build/typecheck/`` (a copy of each package's Python files, as the wheel has
them), runs ``mypy -p imu_ground`` there with the settings of ``pyproject.toml``, and prints mypy's
report with the repository's own paths. Its exit status is mypy's. Used by ``tests/test_static_checks.py``
and by the ``mypy`` hook of ``.pre-commit-config.yaml``.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

try:
    import tomllib
except ImportError:  # Python 3.10: pytest's own TOML reader
    import tomli as tomllib

REPO = Path(__file__).resolve().parents[1]
TREE = REPO / "build" / "typecheck"


def package_folders() -> dict[str, Path]:
    """Each installed package's dotted name -> the repository folder of its files (pyproject's mapping)."""
    setup = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    mapping = setup.get("package-dir", {})
    folders = {}
    for package in setup["packages"]:
        parts = package.split(".")
        for n in range(len(parts), 0, -1):       # the longest mapped prefix owns the package's folder
            prefix = ".".join(parts[:n])
            if prefix in mapping:
                folders[package] = REPO / mapping[prefix] / Path(*parts[n:])
                break
        else:
            folders[package] = REPO / Path(*parts)
    return folders


def lay_out() -> dict[Path, Path]:
    """Copy every package's ``.py``/``.pyi``/``py.typed`` files to :data:`TREE` as installed; copy -> source.

    Copies keep their modification times (mypy's cache stays valid between runs); files that are no longer
    in the repository are removed from the tree.
    """
    copies = {}
    for package, folder in package_folders().items():
        target = TREE / Path(*package.split("."))
        target.mkdir(parents=True, exist_ok=True)
        for src in folder.iterdir():
            if src.is_file() and (src.suffix in (".py", ".pyi") or src.name == "py.typed"):
                dst = target / src.name
                if not dst.exists() or dst.stat().st_mtime != src.stat().st_mtime or \
                        dst.stat().st_size != src.stat().st_size:
                    shutil.copy2(src, dst)
                copies[dst] = src
    for stale in [p for p in TREE.rglob("*") if p.is_file() and p not in copies]:
        stale.unlink()
    return copies


def main(argv: list[str]) -> int:
    copies = lay_out()
    cmd = [sys.executable, "-m", "mypy", "--config-file", str(REPO / "pyproject.toml"),
           "--cache-dir", str(REPO / ".mypy_cache"), *argv, "-p", "imu_ground"]
    run = subprocess.run(cmd, cwd=TREE, capture_output=True, text=True)
    out = run.stdout + run.stderr
    for dst, src in sorted(copies.items(), key=lambda c: -len(str(c[0]))):
        out = out.replace(str(dst.relative_to(TREE)), str(src.relative_to(REPO)))
    print(out, end="")
    return run.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
