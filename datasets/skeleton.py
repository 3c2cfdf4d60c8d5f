"""The format registry: each format registers a *probe* and its reader (:func:`register_format`).

:func:`detect_format` asks the probes in priority order; :func:`read_imu` picks the reader, passes the reader
options it accepts (:data:`~imu_ground.datasets.options.READER_OPTIONS`) and names one that does not apply.
Every reader ends in :func:`finish` (validation, report in ``meta["validation"]``).
"""
from __future__ import annotations

import re
import textwrap
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, TypeVar

from imu_ground.errors import ImuInputError, PoseFileError, UnknownFormatError
from imu_ground.imu.data import ImuData

from . import storage
from .options import READER_OPTIONS

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["ALIASES", "FINISH_PARAMETERS", "FORMATS", "FormatSpec", "PoseFileError", "UnknownFormatError",
           "detect_format", "finish", "read_imu", "register_format", "with_finish_parameters"]

#: Options every reader takes (they go to :func:`finish`).
COMMON_OPTIONS = frozenset({"policy", "nonfinite"})

#: The readers' parameters passed to :func:`finish`, as numpydoc entries (:func:`with_finish_parameters`).
FINISH_PARAMETERS = """\
validate : bool
    Run :func:`imu_ground.datasets.validation.validate` (default True).
policy : {"retime", "drop", "sort", "strict", "recorded"}
    Time-order policy of the validation (default ``"retime"``).
**validate_kw
    Other options of :func:`~imu_ground.datasets.validation.validate`."""

_Reader = TypeVar("_Reader", bound=Callable[..., Any])


@dataclass(frozen=True)
class FormatSpec:
    """One registered log format.

    Attributes
    ----------
    name : str
        Format name (``read_imu(format=...)``, ``--format``).
    probe : callable
        ``probe(path: Path) -> bool``: cheap (names, a header line), never raises for a foreign path.
    reader : callable
        ``reader(path, **options) -> ImuData``, ending in :func:`finish`.
    description : str
        One line: what the format is and what the probe looks for.
    priority : int
        Probes run in increasing priority.
    options : frozenset of str
        Reader options (keys of ``READER_OPTIONS``) that apply besides ``policy`` and ``nonfinite``.
    """

    name: str
    probe: Callable[[Path], bool]
    reader: Callable[..., ImuData]
    description: str
    priority: int = 50
    options: frozenset = field(default_factory=frozenset)


#: Format name -> spec, in probe order once sorted by priority.
FORMATS: dict[str, FormatSpec] = {}
#: Other names accepted for ``format``.
ALIASES: dict[str, str] = {"csv": "table", "oxts": "kitti_oxts", "kitti": "kitti_oxts",
                           "nuscenes_can_bus": "nuscenes", "ms_imu": "nuscenes", "comma": "comma2k19",
                           "bag": "rosbag", "mcap": "rosbag", "ros": "rosbag"}


def register_format(name: str, probe: Callable[[Path], bool], reader: Callable[..., ImuData],
                    description: str, *, priority: int = 50, options: tuple[str, ...] = ()) -> FormatSpec:
    """Add (or replace) a format; see :class:`FormatSpec`. Returns the spec."""
    unknown = set(options) - set(READER_OPTIONS)
    if unknown:
        raise ValueError(f"options {sorted(unknown)} are not in READER_OPTIONS")
    spec = FormatSpec(name, probe, reader, description, priority, frozenset(options))
    FORMATS[name] = spec
    return spec


def finish(imu: ImuData, *, validate: bool = True, policy: str = "retime", **options: Any) -> ImuData:
    """The readers' last step: validate (time order, gaps, units) and store the report.

    Parameters
    ----------
    imu : ImuData
        As parsed, in ImuData units (``meta["row_lines"]`` may map rows to file lines).
    validate, policy, **options
        As :data:`FINISH_PARAMETERS`; ``validate=False`` returns ``imu`` unchanged and refuses options.

    Returns
    -------
    ImuData
        The cleaned log, ``meta["validation"]`` the report.
    """
    from .csvio import TRIM_SAMPLES, return_free_memory
    from .validation import validate as _validate
    if not validate:
        if options:
            raise TypeError(f"validation options {sorted(options)} given with validate=False")
    else:
        imu = _validate(imu, policy, **options)[0]  # type: ignore[arg-type]
    if len(imu) >= TRIM_SAMPLES:        # a long read freed much of what it used: give it back
        return_free_memory()
    return imu


def with_finish_parameters(reader: _Reader) -> _Reader:
    """Decorator: the line ``{finish_parameters}`` of ``reader``'s docstring becomes :data:`FINISH_PARAMETERS`."""
    doc = reader.__doc__
    if doc and "{finish_parameters}" in doc:    # docstrings are None under python -OO
        line = next(x for x in doc.splitlines() if "{finish_parameters}" in x)
        indent = line[:len(line) - len(line.lstrip())]
        reader.__doc__ = doc.replace(line, textwrap.indent(FINISH_PARAMETERS, indent))
    return reader


def _ordered() -> list[FormatSpec]:
    return sorted(FORMATS.values(), key=lambda s: s.priority)


@storage.reads_sources
def detect_format(path: str | Path | pd.DataFrame | IO) -> str:
    """Name of the format of ``path`` (what :func:`read_imu` takes), a key of :data:`FORMATS`.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    PoseFileError
        ``path`` is a KITTI odometry or TUM pose file, not an IMU log.
    UnknownFormatError
        No probe recognises it; the message lists what was looked for and names ``format``.
    """
    if not isinstance(path, (str, Path)):
        return "table"
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such file or folder")
    if p.is_file():
        from .poses import detect_pose_format
        kind = detect_pose_format(p)
        if kind is not None:
            what = {"kitti": "KITTI odometry poses (12 numbers a line)",
                    "tum": "TUM trajectory (t x y z qx qy qz qw)"}[kind]
            raise PoseFileError(f"{p}: a pose file ({what}), not an IMU log; `imu-ground estimate` accepts it "
                                f"as poses (read it with imu_ground.datasets.read_poses)")
    for spec in _ordered():
        if spec.probe(p):
            return spec.name
    kind = "folder" if p.is_dir() else "file"
    looked = "; ".join(f"{s.name}: {s.description}" for s in _ordered())
    raise UnknownFormatError(f"{p}: cannot tell the IMU log format of this {kind}; supported: {looked} "
                             f"(or pass {{hint}})", option="format")


def _resolve(path: Any, format: str | None) -> FormatSpec:
    fmt = detect_format(path) if format is None else ALIASES.get(format, format)
    if fmt not in FORMATS:
        raise UnknownFormatError(f"unknown format {format!r} for {path}; known: {sorted(FORMATS)} "
                                 f"(aliases {sorted(ALIASES)}); pass {{hint}}", option="format")
    return FORMATS[fmt]


@storage.reads_sources
def read_imu(path: str | Path | pd.DataFrame | IO, format: str | None = None, **kw: Any) -> ImuData:
    """Read an IMU log of any registered format.

    Parameters
    ----------
    path : str, Path, pandas.DataFrame or file object
        File or folder, an fsspec URL of one (``s3://bucket/x.csv.gz``, ``memory://...``, ``file://...``),
        an open file object (binary or text; the format from its name, else its first bytes), or a
        DataFrame (``table``).
    format : str, optional
        A key of :data:`FORMATS` or :data:`ALIASES`; detected from ``path`` when omitted.
    **kw
        Reader options (:data:`~imu_ground.datasets.options.READER_OPTIONS`; None means "not set")
        and reader-specific keywords (the column map of :func:`read_table`, ...).

    Returns
    -------
    ImuData
        ``t`` s, ``gyro`` rad/s, ``accel`` m/s^2 (specific force), validated.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist.
    UnknownFormatError
        The format cannot be detected, or ``format`` is not known.
    ImuInputError
        A reader option that does not apply to the format (named).
    MissingFilesystemError
        A URL whose filesystem package (``s3fs`` ...) is not installed.
    """
    spec = _resolve(path, format)
    for name in [k for k in kw if k in READER_OPTIONS]:
        value = kw[name]
        if value is None or (value is False and name == "allow_missing"):
            del kw[name]
        elif name not in COMMON_OPTIONS and name not in spec.options:
            raise ImuInputError(f"{path}: option {{hint}} does not apply to {spec.name} logs", option=name,
                                value=value)
    try:
        return spec.reader(path, **kw)
    except TypeError as e:              # a keyword no step of this reader takes: name read_imu, not the step
        bad = re.search(r"unexpected keyword argument '(\w+)'", str(e))
        if bad is None or bad.group(1) not in kw:
            raise
        raise TypeError(f"read_imu() got an unexpected keyword argument {bad.group(1)!r} for {spec.name} logs "
                        f"(reader options: {', '.join(sorted(COMMON_OPTIONS | spec.options))}; see "
                        f"help(imu_ground.datasets.{spec.reader.__name__}))") from None
