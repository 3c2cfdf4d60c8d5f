"""Every ``imu-ground`` line of the README and of the ``docs/`` pages, verbatim, and each sub-command with only its
required arguments.

``../shared/data`` is the real recordings (lines that use them skip when they are absent); the examples name
real files, no placeholder (``LOG``, ``LOG2`` stand for the shipped example drive in the required-arguments
runs only). Lines run in a fresh folder in which ``datasets`` points at the repository's, so outputs land in
that folder's ``out/``; the README's lines first, then each page's in name order, each in its page's order.
"""
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from imu_ground.cli import main

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
#: The reference pages (the API pages hold no commands); a page without a command adds none.
PAGES = [README, *sorted((REPO / "docs").glob("*.md"))]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"
PLACEHOLDERS = {"LOG": str(EXAMPLE), "LOG2": str(EXAMPLE)}
OUTPUT_FLAGS = ("-o", "--output", "--tum", "--markdown", "--csv", "--plots", "--truth", "--plot", "--planes")


def readme_commands(page: Path = README) -> list[str]:
    """``imu-ground ...`` commands of a page's bash blocks (after ``&&`` too), comments removed."""
    blocks = re.findall(r"```bash\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.DOTALL)
    commands = []
    for block in blocks:
        for line in block.splitlines():
            for part in line.split("&&"):
                words = shlex.split(part, comments=True)
                if words and words[0] == "imu-ground":
                    commands.append(shlex.join(words))
    return commands


COMMANDS = readme_commands()
#: (page, command) for the README and every docs page, in run order.
PAGE_COMMANDS = [(page.relative_to(REPO).as_posix(), c) for page in PAGES for c in readme_commands(page)]
#: The same, each command once (where it is first shown): a line the README and a page both show runs once.
RUN_COMMANDS = [pc for i, pc in enumerate(PAGE_COMMANDS) if pc[1] not in {c for _, c in PAGE_COMMANDS[:i]}]


def _argv(command: str, shared: Path | None) -> list[str]:
    argv = []
    for w in shlex.split(command)[1:]:
        if "../shared/data" in w:
            if shared is None:
                pytest.skip("needs the real recordings in ../shared/data")
            w = w.replace("../shared/data", str(shared))
        argv.append(PLACEHOLDERS.get(w, w))
    return argv


@pytest.fixture(scope="module")
def readme_dir(tmp_path_factory):
    """One folder for all README lines, run in order (a line may use an earlier line's output)."""
    d = tmp_path_factory.mktemp("readme")
    (d / "datasets").symlink_to(REPO / "datasets")
    return d


@pytest.fixture
def workdir(readme_dir, monkeypatch):
    monkeypatch.chdir(readme_dir)
    return readme_dir


def test_the_readme_has_the_commands():
    assert COMMANDS[0].startswith("imu-ground estimate datasets/fixtures/example_drive.csv")
    assert {c.split()[1] for c in COMMANDS} >= {"estimate", "batch", "evaluate", "simulate", "calibrate"}


def test_the_pages_show_every_command_and_no_placeholder():
    """The README and docs pages together show every sub-command, each example with real files."""
    assert {c.split()[1] for _, c in PAGE_COMMANDS} >= {"estimate", "batch", "evaluate", "simulate", "calibrate",
                                                         "stream", "preview"}
    placeholders = [f"{page}: {c}" for page, c in PAGE_COMMANDS if set(shlex.split(c)) & set(PLACEHOLDERS)]
    assert not placeholders, "name a shipped or shared file instead of a placeholder:\n" + "\n".join(placeholders)


@pytest.mark.parametrize("page, command", RUN_COMMANDS, ids=[f"{p}: {c}" for p, c in RUN_COMMANDS])
def test_readme_command_verbatim(page, command, workdir, request, capsys):
    shared = None
    if "../shared/data" in command:
        shared = request.getfixturevalue("shared_data")
    argv = _argv(command, shared)
    assert main(argv) == 0, capsys.readouterr().err
    outputs = [argv[i + 1] for i, w in enumerate(argv[:-1]) if w in OUTPUT_FLAGS]
    for out in outputs:
        assert (workdir / out).exists(), out


def test_readme_outputs_go_to_one_ignored_folder():
    for _, command in PAGE_COMMANDS:
        words = shlex.split(command)
        for i, w in enumerate(words[:-1]):
            if w in OUTPUT_FLAGS:
                assert words[i + 1].startswith("out/"), command
    ignored = subprocess.run(["git", "check-ignore", "-q", "out/example_ground.csv"], cwd=REPO, check=False)
    if ignored.returncode == 128:
        pytest.skip("not a git checkout")
    assert ignored.returncode == 0, "out/ is not ignored by .gitignore"


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "imu_ground", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=600, check=False)


@pytest.mark.parametrize("args", [
    ("estimate", "LOG"),
    ("batch", "LOG", "-o", "fleet"),
    ("simulate", "-o", "sim.csv"),
    ("calibrate", "LOG", "-o", "car.txt"),
    ("evaluate", "--synthetic", "1"),
    ("preview", "-o", "bev.png"),
], ids=lambda a: a[0])
def test_each_command_with_only_its_required_arguments(args, tmp_path):
    r = _cli(*[PLACEHOLDERS.get(a, a) for a in args], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    made = {p.name for p in tmp_path.iterdir()}
    expected = {"estimate": "example_drive_ground.csv", "batch": "fleet", "simulate": "sim_truth.csv",
                "calibrate": "car.txt", "preview": "bev.png"}.get(args[0])
    assert expected is None or expected in made, made


def test_evaluate_without_a_data_source_says_what_to_give(tmp_path):
    r = _cli("evaluate", cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "--real" in r.stderr and "--synthetic" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert "--lidar" in r.stderr                    # the third source, LiDAR road planes


def test_console_script(tmp_path):
    import shutil
    exe = shutil.which("imu-ground")
    if exe is None:
        pytest.skip("imu-ground is not on PATH (package not installed)")
    r = subprocess.run([exe, "estimate", str(EXAMPLE), "-o", "g.csv"], cwd=tmp_path, capture_output=True, text=True, check=False)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "g.csv").is_file()


def test_ci_runs_exactly_the_readme_test_command():
    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.DOTALL)
    test_command = blocks[1].strip()
    assert "pytest" in test_command
    ci = (REPO / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert ci[-1].strip() == test_command
    assert any("venv" in ln for ln in ci)
