"""The documentation site builds with warnings as errors, and its API reference covers every public module.

``mkdocs build --strict`` (``mkdocs.yml`` at the root, the API pages ``docs/api/*.md`` rendered from the
docstrings by mkdocstrings' Python handler, NumPy style): a docstring griffe cannot parse, a page missing
from the navigation or a broken link fails the build. Skipped without mkdocs (``pip install -e ".[docs]"``;
the ``test`` extra installs it, so ``.ci/run`` builds the docs).
"""
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
API = REPO / "docs" / "api"


def _public_modules() -> set[str]:
    """Dotted names of the library's modules that declare ``__all__`` (not private, not tests, not scripts)."""
    roots = {"imu_ground": REPO / "imu_ground", "imu_ground.datasets": REPO / "datasets"}
    names = set()
    for package, folder in roots.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("").parts
            if package == "imu_ground" and rel[0] == "datasets":
                continue
            if any(p.startswith("_") and p != "__init__" for p in rel) or rel[-1].startswith("test_") \
                    or rel[-1] == "__main__" or rel[0] == "cli":
                continue
            if not re.search(r"^__all__\b|^__getattr__, __dir__, __all__", path.read_text(encoding="utf-8"), re.M):
                continue
            parts = rel[:-1] if rel[-1] == "__init__" else rel
            names.add(".".join((package, *parts)))
    return names


def _documented() -> set[str]:
    return {m for page in API.glob("*.md")
            for m in re.findall(r"^::: ([\w.]+)", page.read_text(encoding="utf-8"), flags=re.M)}


def test_every_public_module_has_an_api_entry():
    modules = _public_modules()
    assert {"imu_ground.pipeline.estimate", "imu_ground.datasets.table", "imu_ground.filters.suspension"} <= modules
    missing = modules - _documented()
    assert not missing, f"add these to a page of docs/api/: {sorted(missing)}"
    assert not _documented() - modules, "docs/api names modules that do not exist or have no __all__"


def test_every_docs_page_is_in_the_navigation():
    nav = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    pages = {p.relative_to(REPO / "docs").as_posix() for p in (REPO / "docs").rglob("*.md")}
    assert pages and all(p in nav for p in pages), sorted(p for p in pages if p not in nav)


def test_the_docs_build_strict(tmp_path):
    pytest.importorskip("mkdocs", reason="needs mkdocs: pip install -e '.[docs]'")
    pytest.importorskip("mkdocstrings_handlers.python", reason="needs mkdocstrings[python]: pip install -e '.[docs]'")
    site = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(REPO / "mkdocs.yml"),
                        "--site-dir", str(site)], cwd=tmp_path, capture_output=True, text=True, timeout=900,
                       check=False)
    log = r.stdout + r.stderr
    assert r.returncode == 0, log
    assert "WARNING" not in log, log
    pipeline = (site / "api" / "pipeline" / "index.html").read_text(encoding="utf-8")
    assert "estimate_log" in pipeline and "StreamingEstimator" in pipeline
    readers = (site / "api" / "datasets" / "index.html").read_text(encoding="utf-8")
    assert "{finish_parameters}" not in readers and ":func:" not in readers     # the readers' shared options
    assert (site / "results" / "index.html").is_file()                         # benchmarks/RESULTS.md as a page
    assert not (site / "hooks.py").exists()


@pytest.mark.shared
def test_the_recalibrate_online_example_does_what_the_page_says(shared_data):
    """docs/commands.md: on 2011_09_30_drive_0034 (127 s with a speed) the monitor runs, raises no alarm, and the
    output equals the run without the flag; the page's command names that drive."""
    import numpy as np

    from imu_ground.pipeline import estimate_log, result_table
    drive = "2011_09_30_drive_0034.csv.gz"
    assert f"kitti_imu100/{drive} --recalibrate-online" in (REPO / "docs" / "commands.md").read_text(encoding="utf-8")
    log = shared_data / "kitti_imu100" / drive
    if not log.is_file():
        pytest.skip(f"{log} is absent")
    with_flag = result_table(estimate_log(log, recalibrate_online=True))
    without = result_table(estimate_log(log))
    assert (with_flag["t"].iloc[-1] - with_flag["t"].iloc[0]) > 120.0          # long enough for the monitor to act
    assert not with_flag["status_reason"].astype(str).str.contains("re-estimated|cannot act").any()
    assert (with_flag["status"] != "degraded").all()
    numbers = with_flag.select_dtypes("number").columns
    assert np.allclose(with_flag[numbers], without[numbers], rtol=0, atol=1e-9, equal_nan=True)


def test_the_api_reference_reads_the_docstrings_as_help_does(tmp_path):
    """The griffe extension: the readers' shared options expanded, Sphinx roles as code, choices with the
    signature's default (griffe alone shows ``"s"`` for ``time_unit``, whose default is None)."""
    griffe = pytest.importorskip("griffe", reason="needs mkdocstrings[python]: pip install -e '.[docs]'")
    sys.path.insert(0, str(REPO / "docs"))
    try:
        import griffe_extensions
        import hooks
    finally:
        sys.path.remove(str(REPO / "docs"))
    stage = hooks.package_tree(REPO, tmp_path)
    loader = griffe.GriffeLoader(search_paths=[str(stage)], docstring_parser="numpy",
                                 extensions=griffe.load_extensions(griffe_extensions.SphinxDocstrings))
    reader = loader.load("imu_ground.datasets.kitti_imu100")["read_kitti_imu100"]
    assert "{finish_parameters}" not in reader.docstring.value and ":func:" not in reader.docstring.value
    params = {p.name: p.value for s in reader.docstring.parsed if s.kind.value == "parameters" for p in s.value}
    assert params["time_unit"] == "None" and params["policy"] == "'retime'" and "validate" in params
    table = loader.load("imu_ground.datasets.table")["read_table"]           # its column options: **kw, not arguments
    other = [p.name for s in table.docstring.parsed if s.kind.value == "other parameters" for p in s.value]
    assert {"columns", "time_unit", "relative_time"} <= set(other)
