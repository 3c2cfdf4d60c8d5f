"""MkDocs hooks: the API reference finds every sub-package; the results file is a page of the site.

``imu_ground.datasets`` and ``imu_ground.calib`` live in the repository's top-level ``datasets/`` and
``calib/`` folders (``[tool.setuptools.package-dir]`` of ``pyproject.toml``). Python imports them through
setuptools' editable finder, but griffe reads packages from folders and only follows the top-level entry
of that finder. This hook lays out the package as installed, a temporary folder of symbolic links to the
repository's files (each package's ``__init__.py`` copied), and points the Python handler's ``paths`` at it.

``benchmarks/RESULTS.md`` (every measured figure, written by ``benchmarks/make_results.py``) lives outside
``docs/``: the pages link it as ``../benchmarks/RESULTS.md``, which reads right on GitHub and in an editor;
the site gets the file as its page ``results.md`` and those links point there.
"""
from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

if sys.version_info >= (3, 11):
    import tomllib
else:                                   # the docs extra installs tomli there
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "RESULTS.md"
#: How the pages write the link to the results file.
RESULTS_LINK = "../benchmarks/RESULTS.md"
_STAGE: Path | None = None


def package_tree(root: Path, stage: Path) -> Path:
    """Link ``root``'s packages into ``stage`` as they are installed; return the folder to search."""
    package_dir = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))[
        "tool"]["setuptools"]["package-dir"]
    # the shallowest names first, so a sub-package's link goes inside its parent's folder
    for name, folder in sorted(package_dir.items(), key=lambda kv: kv[0].count(".")):
        target = stage.joinpath(*name.split("."))
        target.mkdir(parents=True, exist_ok=True)
        for entry in (root / folder).iterdir():
            link = target / entry.name
            if link.exists() or entry.name == "__pycache__":
                continue
            if entry.name == "__init__.py":      # a copy: griffe lists a package's modules beside the
                shutil.copyfile(entry, link)     # resolved __init__, so a link would hide the linked folders
            else:
                link.symlink_to(entry)
    return stage


@event_priority(100)        # before mkdocstrings' own on_config, which starts the Python handler
def on_config(config, **kwargs):
    """Stage the package and search it first (before the editable install's top-level mapping)."""
    global _STAGE
    _STAGE = Path(tempfile.mkdtemp(prefix="imu-ground-api-"))
    python = config.plugins["mkdocstrings"].config.handlers.setdefault("python", {})
    python["paths"] = [str(package_tree(ROOT, _STAGE))]
    return config


def on_shutdown(**kwargs):
    """Remove the staged links."""
    if _STAGE is not None:
        shutil.rmtree(_STAGE, ignore_errors=True)


def on_files(files, config, **kwargs):
    """Add the results file as the site's page ``results.md``."""
    files.append(File.generated(config, "results.md", abs_src_path=str(RESULTS)))
    return files


def on_page_markdown(markdown, page, **kwargs):
    """Point the pages' links to ``../benchmarks/RESULTS.md`` at the site's ``results.md``."""
    depth = page.file.src_uri.count("/")
    return markdown.replace(f"]({RESULTS_LINK}", "](" + "../" * depth + "results.md")
