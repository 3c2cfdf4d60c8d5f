"""One registry of methods: a method added to ``imu_ground.filters.methods.METHODS`` is offered everywhere.

``estimate --method`` / ``batch --method``, ``stream --method`` (a live method), the live
estimator, ``estimate --causal`` and ``evaluate --methods`` all take their lists from the
registry; no other list of method names exists to update.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from imu_ground.cli import build_parser, main
from imu_ground.filters import methods as registry
from imu_ground.filters.ground import GroundNormalFilter
from imu_ground.filters.methods import MethodSpec

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture
def dummy(monkeypatch):
    """A live, rotations-only method registered the one way there is: an entry of the registry."""
    spec = MethodSpec("dummy-live", "a dummy method for the registry test", GroundNormalFilter, False, False,
                      live=True)
    monkeypatch.setitem(registry.METHODS, spec.name, spec)
    return spec


def _option(command: str, flag: str) -> argparse.Action:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return next(a for a in sub.choices[command]._actions if flag in a.option_strings)


@pytest.mark.parametrize("command", ["estimate", "batch", "stream"])
def test_a_registered_method_is_a_cli_choice(dummy, command):
    action = _option(command, "--method")
    assert action.choices is not None and dummy.name in action.choices and "auto" in action.choices


def test_stream_offers_exactly_the_live_methods(dummy):
    choices = list(_option("stream", "--method").choices or ())
    assert choices == ["auto", *(n for n, s in registry.METHODS.items() if s.live)]
    assert dummy.name in str(_option("stream", "--method").help)


def test_the_stream_help_line_is_unchanged_for_the_shipped_registry():
    assert _option("stream", "--method").help == "auto (suspension, default), suspension, filter or paper"


def test_a_registered_method_is_evaluated(dummy):
    from imu_ground.cli.evaluate import _methods_help
    from imu_ground.evaluation.runner import EVALUATION_METHODS, METHODS, methods_from_list
    assert dummy.name in METHODS and METHODS[dummy.name] is dummy
    assert dummy in list(EVALUATION_METHODS)
    assert dummy.name in methods_from_list(None)
    assert methods_from_list(f"naive,{dummy.name}") == ["naive", dummy.name]
    assert f"{dummy.name}: {dummy.description}" in _methods_help()


def test_a_registered_live_method_runs_live_and_offline(dummy, tmp_path):
    from imu_ground.pipeline.streaming import StreamingEstimator
    assert StreamingEstimator(dummy.name).method == dummy.name
    for extra in ([], ["--causal"]):
        out = tmp_path / f"out{len(extra)}.csv"
        assert main(["estimate", str(EXAMPLE), "--method", dummy.name, *extra, "-o", str(out)]) == 0
        assert out.is_file()


def test_the_reports_references_come_from_the_registry(monkeypatch):
    from imu_ground.evaluation.plots import HIGHLIGHTED
    assert HIGHLIGHTED == ("suspension", "paper", "naive")          # the default, then the registry's references
    spec = MethodSpec("dummy-ref", "a reference", GroundNormalFilter, False, False, reference=True)
    monkeypatch.setitem(registry.METHODS, spec.name, spec)
    assert registry.reference_methods() == ("paper", "naive", "dummy-ref")
