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
        if "derive_kitti" in info.name:
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


def test_every_exception_and_warning_class_is_under_one_root_in_the_foundation_layer():
    """Errors derive from ImuGroundError, warnings from ImuGroundWarning; the readers' and options' classes
    live in imu_ground.errors (which imports nothing of the package) and keep their old import paths."""
    import imu_ground.cli  # noqa: F401  (the command's classes count too)
    from imu_ground.errors import ImuGroundWarning
    classes = _package_error_classes()
    classes.update({f"{c.__module__}.{c.__name__}": c for c in vars(imu_ground.cli).values()
                    if inspect.isclass(c) and issubclass(c, BaseException) and c.__module__.startswith("imu_ground")})
    warns = {k: c for k, c in classes.items() if issubclass(c, Warning)}
    assert len(warns) >= 6
    for qualname, cls in classes.items():
        if issubclass(cls, KeyboardInterrupt):      # a signal turned into an exception (SIGTERM), not an error
            continue
        root = ImuGroundWarning if issubclass(cls, Warning) else ImuGroundError
        assert issubclass(cls, root), f"{qualname} does not derive from {root.__name__}"
    moved = {"datasets.options": ("OptionError", "ImuInputError", "OptionMessage", "option_hint"),
             "datasets.report": ("ImuValidationError", "MalformedFileError", "ImuValidationWarning", "TimestampWarning",
                                 "GapWarning", "NonFiniteWarning", "UnitsWarning", "SensorWarning", "warn_user"),
             "datasets.skeleton": ("UnknownFormatError", "PoseFileError"),
             "datasets.storage": ("StorageError", "MissingFilesystemError"),
             "datasets.kitti_oxts": ("MissingPacketsError",)}
    import imu_ground.errors as home
    for module, names in moved.items():
        old = importlib.import_module(f"imu_ground.{module}")
        for name in names:
            assert getattr(old, name) is getattr(home, name), f"imu_ground.{module}.{name}"
            assert getattr(home, name).__module__ == "imu_ground.errors", name


def test_missing_extra_is_a_user_error_and_an_import_error_naming_the_extra():
    with pytest.raises(MissingExtraError) as info:
        require_extra("imu_ground_no_such_module", "parquet", "out.parquet: writing Parquet")
    e = info.value
    assert isinstance(e, ImportError) and isinstance(e, ImuGroundError)
    assert e.extra == "parquet" and "pip install 'imu-ground[parquet]'" in str(e) and "out.parquet" in str(e)


def _block_imports(monkeypatch, *packages):
    """Make ``import`` of these packages fail, as on an install without the extra."""
    real_import = builtins.__import__

    def blocked(name, *args, **kwargs):
        if name.split(".")[0] in packages:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return real_import(name, *args, **kwargs)

    for mod in [m for m in sys.modules if m.split(".")[0] in packages]:
        monkeypatch.delitem(sys.modules, mod)
    monkeypatch.setattr(builtins, "__import__", blocked)


@pytest.mark.parametrize("suffix, packages, extra", [(".parquet", ("pyarrow",), "parquet"),
                                                      (".bag", ("rosbags", "mcap"), "ros"),
                                                      (".mcap", ("rosbags", "mcap"), "ros")])
def test_a_missing_writer_extra_exits_2_naming_the_file_and_the_extra(tmp_path, capsys, monkeypatch, suffix,
                                                                       packages, extra):
    _block_imports(monkeypatch, *packages)
    out = tmp_path / f"x{suffix}"
    assert main(["estimate", str(EXAMPLE), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(out) in err and f"imu-ground[{extra}]" in err, err
    assert not out.exists()


def test_reading_a_ros_log_without_the_ros_extra_exits_2_naming_it(tmp_path, capsys, monkeypatch):
    log = tmp_path / "drive.bag"
    log.write_bytes(b"#ROSBAG V2.0\n" + bytes(200))
    _block_imports(monkeypatch, "rosbags", "mcap")
    assert main(["estimate", str(log), "-o", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(log) in err and "imu-ground[ros]" in err, err


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


# ----------------------------------------------------------------------------- bad inputs that reached a bare error
def _one_error_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if "warning:" not in line]
    assert len(err) == 1, err
    return err[0]


def test_a_binary_extrinsic_file_is_a_user_error_naming_it(tmp_path, capsys):
    ext = tmp_path / "car.txt"
    ext.write_bytes(bytes(range(256)))
    assert main(["estimate", str(EXAMPLE), "--extrinsic", str(ext), "-o", str(tmp_path / "x.csv")]) == 2
    line = _one_error_line(capsys)
    assert str(ext) in line and "not a calibration file" in line


def test_calibrating_a_log_without_gravity_names_the_log(tmp_path, capsys):
    log = tmp_path / "dead_accel.csv"
    t = np.arange(3000) * 0.01
    rows = "\n".join(f"{v:.2f},0.01,0,0,0,0,0" for v in t)
    log.write_text("t,wx,wy,wz,ax,ay,az\n" + rows + "\n")
    assert main(["calibrate", str(log), "-o", str(tmp_path / "car.txt")]) == 2
    line = _one_error_line(capsys)
    assert str(log) in line and "no gravity in the accelerometer" in line
    assert not (tmp_path / "car.txt").exists()


def test_a_frame_the_estimator_refuses_is_a_user_error_named_with_the_log(tmp_path, capsys, monkeypatch):
    from imu_ground.filters import GroundNormalFilter
    from imu_ground.filters.frame_checks import bad_frame_error
    with pytest.raises(ImuGroundError, match="bad ego-motion frame"):
        GroundNormalFilter().step(np.full((3, 3), np.nan))
    import imu_ground.pipeline.estimate as estimate

    def refused(*args, **kwargs):
        raise bad_frame_error("delta_R is not finite", "frame index 0")

    monkeypatch.setattr(estimate, "_run_method", refused)
    assert main(["estimate", str(EXAMPLE), "-o", str(tmp_path / "x.csv")]) == 2
    line = _one_error_line(capsys)
    assert line.startswith(f"imu-ground estimate: error: {EXAMPLE}: bad ego-motion frame")


def test_preview_with_an_empty_images_folder_is_a_user_error(tmp_path, capsys):
    (tmp_path / "images").mkdir()
    times = tmp_path / "times.txt"
    times.write_text("1.0\n")
    assert main(["preview", str(EXAMPLE), "-o", str(tmp_path / "p.png"), "--images", str(tmp_path / "images"),
                 "--times", str(times), "--camera", "kitti_cam2"]) == 2
    assert "no image" in _one_error_line(capsys)


def test_a_batch_row_says_bug_for_an_unexpected_error_and_not_for_bad_input(tmp_path, monkeypatch):
    import imu_ground.pipeline.batch as batch
    monkeypatch.setattr(batch, "estimate_to_files", _numpy_value_error)
    row = batch.process_log(str(EXAMPLE), tmp_path / "a.csv", {})
    assert row["status"] == "failed" and row["error"].startswith("bug: unexpected ValueError: cannot reshape")

    def user_error(*args, **kwargs):
        raise ImuGroundError("some.csv: a user error")

    monkeypatch.setattr(batch, "estimate_to_files", user_error)
    row = batch.process_log(str(EXAMPLE), tmp_path / "b.csv", {})
    assert row["status"] == "failed" and row["error"] == "some.csv: a user error"


def test_a_binary_file_read_as_nuscenes_is_a_user_error(tmp_path, capsys):
    log = tmp_path / "scene-1_ms_imu.json"
    log.write_bytes(bytes(range(256)) * 4)
    assert main(["estimate", str(log), "--format", "nuscenes", "-o", str(tmp_path / "x.csv")]) == 2
    assert str(log) in _one_error_line(capsys)


def test_evaluate_on_drives_without_a_usable_reference_is_a_user_error(tmp_path, capsys):
    import gzip
    real = tmp_path / "real"
    real.mkdir()
    rows = "\n".join(f"{i * 0.01:.2f},0,0,0,0,0,9.8,0,0,0,0,0,0,0,0,0" for i in range(3000))
    with gzip.open(real / "parked.csv.gz", "wt") as fh:
        fh.write("t,wx,wy,wz,ax,ay,az,roll,pitch,yaw,ve,vn,vu,px,py,pz\n" + rows + "\n")
    assert main(["evaluate", "--real", str(real), "--methods", "naive", "--no-progress"]) == 2
    line = _one_error_line(capsys)
    assert str(real) in line and "no drive with a usable reference" in line and "parked" in line


def test_the_command_line_raises_no_bare_value_error_for_bad_input():
    """The CLI's own checks raise the root: a bare ValueError there would now be reported as a bug."""
    import ast
    cli = Path(imu_ground.__file__).resolve().parent / "cli"
    bare = []
    for path in sorted(cli.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and \
                    getattr(node.exc.func, "id", None) in ("ValueError", "TypeError", "ImportError"):
                bare.append(f"{path.name}:{node.lineno}")
    assert bare == []
