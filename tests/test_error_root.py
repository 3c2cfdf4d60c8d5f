"""One error root: user errors derive from ImuGroundError (exit 2), anything else is a bug (exit 3)."""
import builtins
import importlib
import inspect
import pkgutil
import sys
from pathlib import Path

import numpy as np
import pytest

import imu_ground
from imu_ground.cli import main
from imu_ground.errors import ImuGroundError, MissingExtraError, require_extra

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


def _package_error_classes() -> dict:
    """Every exception class defined in the package's modules (``imu_ground.*`` and the readers)."""
    import imu_ground.datasets
    found = {}
    infos = [*pkgutil.walk_packages(imu_ground.__path__, "imu_ground."),
             *pkgutil.walk_packages(imu_ground.datasets.__path__, "imu_ground.datasets.")]
    for info in infos:
        if info.name.startswith(("imu_ground.cli", "imu_ground.__main__")) or ".test_" in info.name:
            continue
        if "make_fixtures" in info.name or "derive_kitti" in info.name:
            continue
        mod = importlib.import_module(info.name)
        for name, obj in vars(mod).items():
            if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == mod.__name__:
                found[f"{mod.__name__}.{name}"] = obj
    return found


def test_every_error_class_of_the_package_derives_from_the_root_and_is_exported():
    classes = _package_error_classes()
    errors = {k: c for k, c in classes.items() if not issubclass(c, Warning) and not issubclass(c, KeyboardInterrupt)}
    # the classes the issue names, and those found by walking the package
    for name in ("OptionError", "ImuInputError", "ImuValidationError", "MalformedFileError", "UnknownFormatError",
                 "PoseFileError", "MissingPacketsError", "StateError", "TooLittleDataError", "MissingExtraError"):
        assert any(k.endswith("." + name) for k in errors), name
    for qualname, cls in errors.items():
        assert issubclass(cls, ImuGroundError), qualname
        assert cls.__name__ in imu_ground.__all__, qualname
        assert getattr(imu_ground, cls.__name__) is cls
    assert issubclass(ImuGroundError, ValueError) and "ImuGroundError" in imu_ground.__all__


def test_missing_extra_is_a_user_error_and_an_import_error_naming_the_extra():
    with pytest.raises(MissingExtraError) as info:
        require_extra("imu_ground_no_such_module", "parquet", "out.parquet: writing Parquet")
    e = info.value
    assert isinstance(e, ImportError) and isinstance(e, ImuGroundError)
    assert e.extra == "parquet" and "pip install 'imu-ground[parquet]'" in str(e) and "out.parquet" in str(e)


def test_a_missing_pyarrow_exits_2_naming_the_file_and_the_extra(tmp_path, capsys, monkeypatch):
    real_import = builtins.__import__

    def no_pyarrow(name, *args, **kwargs):
        if name == "pyarrow" or name.startswith("pyarrow."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return real_import(name, *args, **kwargs)

    for mod in [m for m in sys.modules if m == "pyarrow" or m.startswith("pyarrow.")]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setattr(builtins, "__import__", no_pyarrow)
    out = tmp_path / "x.parquet"
    assert main(["estimate", str(EXAMPLE), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(out) in err and "imu-ground[parquet]" in err
    assert not out.exists()


def _numpy_value_error(*args, **kwargs):
    np.ones(3).reshape(2, 2)            # numpy raises a ValueError (cannot reshape array of size 3)


def test_a_value_error_raised_by_a_bug_inside_the_pipeline_exits_3_in_one_line(tmp_path, capsys, monkeypatch):
    import imu_ground.pipeline.estimate as estimate
    monkeypatch.setattr(estimate, "imu_to_egomotion", _numpy_value_error)
    monkeypatch.delenv("IMU_GROUND_DEBUG", raising=False)
    out = tmp_path / "x.csv"
    assert main(["estimate", str(EXAMPLE), "-o", str(out)]) == 3
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "bug" in err and "ValueError" in err and "IMU_GROUND_DEBUG=1" in err and "Traceback" not in err
    assert not out.exists()


def test_imu_ground_debug_shows_the_traceback_and_still_exits_3(tmp_path, capsys, monkeypatch):
    import imu_ground.pipeline.estimate as estimate
    monkeypatch.setattr(estimate, "imu_to_egomotion", _numpy_value_error)
    monkeypatch.setenv("IMU_GROUND_DEBUG", "1")
    assert main(["estimate", str(EXAMPLE), "-o", str(tmp_path / "x.csv")]) == 3
    err = capsys.readouterr().err
    assert "Traceback" in err and "_numpy_value_error" in err and "bug" in err.strip().splitlines()[-1]


def test_a_type_error_bug_exits_3_and_a_root_error_exits_2(tmp_path, capsys, monkeypatch):
    import imu_ground.pipeline.estimate as estimate

    def type_bug(*args, **kwargs):
        raise TypeError("unsupported operand")

    def user_error(*args, **kwargs):
        raise ImuGroundError("some.csv: a user error")

    monkeypatch.delenv("IMU_GROUND_DEBUG", raising=False)
    real = estimate.imu_to_egomotion
    monkeypatch.setattr(estimate, "imu_to_egomotion", type_bug)
    assert main(["estimate", str(EXAMPLE), "-o", str(tmp_path / "x.csv")]) == 3
    capsys.readouterr()
    monkeypatch.setattr(estimate, "imu_to_egomotion", real)
    monkeypatch.setattr(estimate, "result_table", user_error)
    assert main(["estimate", str(EXAMPLE), "-o", str(tmp_path / "x.csv")]) == 2
    assert capsys.readouterr().err.strip() == "imu-ground estimate: error: some.csv: a user error"
