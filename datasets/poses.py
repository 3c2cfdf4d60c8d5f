"""Odometry pose files (visual odometry, SLAM, ground truth) to relative rotations.

- KITTI odometry: one pose a line, 12 numbers, the row-major 3x4 ``[R | t]`` of world <- sensor_k, optionally
  after a frame index (ORB-SLAM2's, from 1); times from the benchmark's ``times/XX.txt`` (``times=``).
- TUM RGB-D: ``t x y z qx qy qz qw`` (s, m, unit quaternion of world <- sensor); ``#`` comments allowed.

Rotations stay in the sensor frame (a camera's x right, y down, z forward included: the extrinsic carries
them into the ground frame); :func:`moves_along_z` tells a camera's poses from a vehicle body's.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imu_ground.errors import ImuGroundError, ImuInputError


__all__ = ["PoseSequence", "detect_pose_format", "moves_along_z", "read_kitti_poses", "read_pose_times", "read_poses",
           "read_tum_poses", "relative_rotations", "write_tum_poses"]

_ORTHO_TOL = 1e-3      # text files carry 6-17 digits; worse than this is not a rotation


@dataclass
class PoseSequence:
    """Poses of a sensor, world <- sensor_k.

    Attributes
    ----------
    rotations : ndarray (N, 3, 3)
        world <- sensor_k, projected onto SO(3).
    translations : ndarray (N, 3)
        Sensor position in the world frame (the file's units, usually metres).
    t : ndarray (N,) or None
        Timestamps, s (None without times).
    index : ndarray (N,)
        Frame numbers (the file's index column, else 0..N-1).
    source, clock : str
        The file; what ``t`` is (the TUM file's own times, a KITTI times file, or "").
    """
    rotations: np.ndarray
    translations: np.ndarray
    t: np.ndarray | None
    index: np.ndarray
    source: str = ""
    clock: str = ""

    def __len__(self) -> int:
        return len(self.rotations)

    def relative_rotations(self) -> np.ndarray:
        """``sensor_{k-1} <- sensor_k`` rotations, shape (N-1, 3, 3); see :func:`relative_rotations`."""
        return relative_rotations(self.rotations)


def relative_rotations(rotations: np.ndarray) -> np.ndarray:
    """Relative rotations between consecutive poses.

    Parameters
    ----------
    rotations : ndarray (N, 3, 3)
        world <- sensor_k.

    Returns
    -------
    ndarray (N-1, 3, 3)
        ``R_{k-1}^T R_k`` (sensor_{k-1} <- sensor_k): ``R_k = R_{k-1} @ dR_k``.
    """
    r = np.asarray(rotations, dtype=float)
    return np.swapaxes(r[:-1], 1, 2) @ r[1:]


def _load_table(path: Path, widths: tuple[int, ...]) -> np.ndarray:
    """Numeric rows of a whitespace text file; every row must have one of ``widths`` columns."""
    if not path.is_file():
        raise FileNotFoundError(f"pose file not found: {path}")
    rows = []
    width = None
    for lineno, raw in enumerate(path.read_text().splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.replace(",", " ").split()
        if width is None:
            if len(parts) not in widths:
                raise ImuGroundError(f"{path}:{lineno}: expected {' or '.join(map(str, widths))} numbers, "
                                     f"got {len(parts)}")
            width = len(parts)
        elif len(parts) != width:
            raise ImuGroundError(f"{path}:{lineno}: expected {width} numbers like the first line, got {len(parts)} "
                                 f"(truncated or malformed line)")
        try:
            rows.append([float(v) for v in parts])
        except ValueError:
            raise ImuGroundError(f"{path}:{lineno}: not a number in {raw.strip()!r}") from None
    if not rows:
        raise ImuGroundError(f"{path}: no poses (empty file)")
    data = np.array(rows)
    bad = ~np.all(np.isfinite(data), axis=1)
    if bad.any():
        raise ImuGroundError(f"{path}: {bad.sum()} lines with NaN or inf values, "
                             f"first at pose {np.flatnonzero(bad)[0]}")
    return data


def _check_rotations(path: Path, r: np.ndarray, lines: np.ndarray) -> np.ndarray:
    err = np.abs(np.swapaxes(r, 1, 2) @ r - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(r)
    bad = (err > _ORTHO_TOL) | (det < 0)
    if bad.any():
        i = np.flatnonzero(bad)[0]
        raise ImuGroundError(f"{path}: {bad.sum()} poses are not rotations (first at line {lines[i]}: "
                             f"|R^T R - I| = {err[i]:.2e}, det = {det[i]:.4f})")
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(r).as_matrix()      # nearest rotation, float64


_BINARY_SUFFIXES = (".gz", ".bz2", ".bag", ".mcap", ".parquet", ".pq", ".json", ".npy", ".db3", ".zip")


def _first_rows(path: Path, n: int = 3) -> list[list[float]]:
    """Up to ``n`` first data rows as numbers ([] when a line is not whitespace-separated numbers)."""
    rows: list[list[float]] = []
    try:
        with path.open("rb") as fh:
            head = fh.read(8192).decode("utf-8")
    except (OSError, UnicodeDecodeError):
        return []
    lines = head.splitlines()
    if len(head) == 8192 and lines:
        lines = lines[:-1]  # the last line may be cut
    for raw in lines:
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if "," in line:
            return []
        try:
            rows.append([float(v) for v in line.split()])
        except ValueError:
            return []
        if len(rows) == n:
            break
    return rows


def detect_pose_format(path: str | Path) -> str | None:
    """``"kitti"`` or ``"tum"`` when ``path`` (any path) is a pose file, else None.

    From the first lines: 12 numbers (or an index then 12) with a rotation, or 8 with a unit quaternion; text
    with a header, commas or compressed files are not pose files.
    """
    p = Path(path)
    if not p.is_file() or p.name.lower().endswith(_BINARY_SUFFIXES):
        return None
    rows = _first_rows(p)
    if not rows or len({len(r) for r in rows}) != 1:
        return None
    width = len(rows[0])
    data = np.asarray(rows, dtype=float)
    if not np.isfinite(data).all():
        return None
    if width in (12, 13):
        m = data[:, -12:].reshape(-1, 3, 4)[:, :, :3]
        ortho = np.abs(np.swapaxes(m, 1, 2) @ m - np.eye(3)).max() < 1e-2
        index_ok = width == 12 or bool(np.all(data[:, 0] == np.round(data[:, 0])))
        return "kitti" if ortho and index_ok else None
    if width == 8:
        return "tum" if np.all(np.abs(np.linalg.norm(data[:, 4:8], axis=1) - 1.0) < 1e-2) else None
    return None


def read_pose_times(path: str | Path, frames: np.ndarray, source: str | Path = "", *,
                    every_line: bool = False) -> np.ndarray:
    """The times, s, of KITTI pose frames from the benchmark's ``times.txt`` (one time a line).

    Parameters
    ----------
    path : str or Path
        The times file (``times/XX.txt``).
    frames : ndarray of int (N,)
        Line of the times file (0-based) of each pose.
    source : str or Path
        The pose file (named in messages).
    every_line : bool
        One pose per line of the times file (a pose file without a frame index): as many lines in both.

    Raises
    ------
    FileNotFoundError
        No such file.
    ImuInputError
        Another sequence's times file, by the counts, naming both files and ``times``.
    ImuGroundError
        Not one number a line; times not strictly increasing over the frames.
    """
    path = Path(path)
    times = _load_table(path, (1,))[:, 0]
    frames = np.asarray(frames, dtype=np.int64)
    if every_line and times.size != frames.size:
        raise ImuInputError(f"{source}: {frames.size} poses but {times.size} times in {path}; a pose file without a "
                            "frame index has one pose per line of its sequence's times file ({opt}: the times file "
                            "of this sequence, times/XX.txt for poses/XX.txt)", option="times")
    if frames.size and (frames.min() < 0 or frames.max() >= times.size):
        raise ImuInputError(f"{source}: {times.size} time(s) in {path} but the poses need frames "
                            f"{int(frames.min())}..{int(frames.max())} ({{opt}}: the times file of this sequence)",
                            option="times")
    t = times[frames]
    if np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise ImuGroundError(f"{path}: times not strictly increasing at line {frames[i + 1] + 1} "
                             f"({t[i]!r} then {t[i + 1]!r})")
    return t


def moves_along_z(poses: PoseSequence, share: float = 0.9, min_steps: int = 10) -> bool:
    """Whether the sensor moves along its own +z axis, as a camera does (a vehicle body moves along +x).

    The steps ``R_{k-1}^T (p_k - p_{k-1})`` longer than a thousandth of the longest, as unit vectors: their
    mean's z component above ``share`` (with at least ``min_steps`` steps) says "camera".
    """
    r = np.asarray(poses.rotations, dtype=float)
    d = np.einsum("nji,nj->ni", r[:-1], np.diff(np.asarray(poses.translations, dtype=float), axis=0))
    norm = np.linalg.norm(d, axis=1)
    moving = norm > 1e-3 * norm.max() if norm.size and norm.max() > 0 else np.zeros(0, dtype=bool)
    if np.count_nonzero(moving) < min_steps:
        return False
    return bool(np.mean(d[moving, 2] / norm[moving]) > share)


def read_kitti_poses(path: str | Path, times: str | Path | None = None) -> PoseSequence:
    """Read a KITTI odometry pose file (12 numbers a line, optional leading frame index).

    Parameters
    ----------
    path : str or Path
        E.g. ``poses/XX.txt`` (12 numbers) or ORB-SLAM2's output (frame index, then 12).
    times : str or Path, optional
        The sequence's ``times.txt`` (one time a line, s; ``--times``): pose ``k`` takes line ``k``, or an
        index counts lines from 1 (from 0 when an index 0 is present). Without it ``t`` is None.

    Returns
    -------
    PoseSequence
        world <- sensor_k rotations (the first camera frame is the world), translations m, frame indices.

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file; malformed, truncated or non-numeric line (its number); NaN; matrices that are not
        rotations; frame indices not strictly increasing; a times file of another length.
    """
    path = Path(path)
    data = _load_table(path, (12, 13))
    indexed = data.shape[1] == 13
    if indexed:
        index = data[:, 0]
        if np.any(index != np.round(index)):
            raise ImuGroundError(f"{path}: the 13-column format needs an integer frame index in the first column")
        index = index.astype(np.int64)
        d = np.diff(index)
        if np.any(d <= 0):
            i = np.flatnonzero(d <= 0)[0]
            raise ImuGroundError(f"{path}: frame indices are not strictly increasing at line {i + 2} "
                                 f"({index[i]} then {index[i + 1]})")
        data = data[:, 1:]
    else:
        index = np.arange(len(data))
    m = data.reshape(-1, 3, 4)
    rot = _check_rotations(path, m[:, :, :3], np.arange(1, len(m) + 1))
    t, clock = None, ""
    if times is not None:
        frames = np.arange(len(m)) if index[0] == 0 and np.array_equal(index, np.arange(len(m))) else \
            index - (0 if index.min() == 0 else 1)
        t = read_pose_times(times, frames, path, every_line=not indexed)
        clock = f"KITTI times file {times}"
    return PoseSequence(rot, m[:, :, 3].copy(), t, index, str(path), clock)


def read_tum_poses(path: str | Path) -> PoseSequence:
    """Read a TUM-format trajectory (``t x y z qx qy qz qw`` a line).

    Parameters
    ----------
    path : str or Path
        Text file, whitespace separated, ``t`` in s.

    Returns
    -------
    PoseSequence
        world <- sensor_k rotations, positions, timestamps in seconds.

    Raises
    ------
    FileNotFoundError, ValueError
        Missing file; malformed line (line number); NaN; quaternions far from unit norm; timestamps unsorted
        or duplicated (which and where).
    """
    path = Path(path)
    data = _load_table(path, (8,))
    t = data[:, 0]
    d = np.diff(t)
    if np.any(d <= 0):
        bad = np.flatnonzero(d <= 0)
        kind = "duplicate" if np.all(d[bad] == 0) else "unsorted or duplicate"
        raise ImuGroundError(f"{path}: {bad.size} {kind} timestamps, first at pose {bad[0] + 1} "
                             f"(t = {t[bad[0]]!r} then {t[bad[0] + 1]!r})")
    q = data[:, 4:8]
    norm = np.linalg.norm(q, axis=1)
    if np.any(np.abs(norm - 1.0) > 1e-2):
        i = np.flatnonzero(np.abs(norm - 1.0) > 1e-2)[0]
        raise ImuGroundError(f"{path}: quaternion at pose {i} has norm {norm[i]:.4f}, expected 1 (order qx qy qz qw)")
    from scipy.spatial.transform import Rotation
    rot = Rotation.from_quat(q).as_matrix()
    return PoseSequence(rot, data[:, 1:4].copy(), t, np.arange(len(t)), str(path), "the TUM file's own times")


def read_poses(path: str | Path, format: str | None = None, times: str | Path | None = None) -> PoseSequence:
    """Read a pose file, KITTI or TUM, detected from the column count unless ``format`` is given.

    Parameters
    ----------
    path : str or Path
    format : {"kitti", "tum"}, optional
    times : str or Path, optional
        KITTI only: the sequence's ``times.txt`` (see :func:`read_kitti_poses`).
        A TUM file has its own times (refused with it).
    """
    path = Path(path)
    if format is None:
        if not path.is_file():
            raise FileNotFoundError(f"pose file not found: {path}")
        with path.open() as fh:
            first = next((ln for ln in fh if ln.split("#", 1)[0].strip()), "")
        n = len(first.split("#", 1)[0].replace(",", " ").split())
        format = {8: "tum", 12: "kitti", 13: "kitti"}.get(n)
        if format is None:
            raise ImuGroundError(f"{path}: cannot tell the pose format from a first line of {n} numbers "
                                 f"(KITTI has 12 or 13, TUM has 8)")
    if format == "kitti":
        return read_kitti_poses(path, times)
    if format == "tum":
        if times is not None:
            raise ImuGroundError(f"{path}: a TUM pose file carries its own times; a times file ({times}) is for "
                                 "KITTI pose files")
        return read_tum_poses(path)
    raise ImuGroundError(f"unknown pose format {format!r}: use 'kitti' or 'tum'")


def write_tum_poses(path: str | Path, t: np.ndarray, rotations: np.ndarray,
                    translations: np.ndarray | None = None, header: str = "t x y z qx qy qz qw") -> None:
    """Write a TUM trajectory (``t x y z qx qy qz qw``), readable by evo.

    Parameters
    ----------
    t : ndarray (N,), seconds.
    rotations : ndarray (N, 3, 3), world <- sensor (or any a <- b the caller documents).
    translations : ndarray (N, 3), metres; zeros by default.
    header : str
        The comment at the top.
    """
    from scipy.spatial.transform import Rotation
    t = np.asarray(t, dtype=float)
    q = Rotation.from_matrix(rotations).as_quat() if len(t) else np.zeros((0, 4))
    p = np.zeros((len(t), 3)) if translations is None else np.broadcast_to(translations, (len(t), 3))
    np.savetxt(path, np.column_stack([t, p, q]), fmt="%.9f", header=header)
