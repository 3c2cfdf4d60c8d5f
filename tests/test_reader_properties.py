"""Property-based tests of the readers (hypothesis): random tables are read or refused, never anything else.

Random CSV tables, plain or gzip (the table layout or the kitti_imu100 one, columns in any
order, several units, NaN/inf, duplicated, reversed and gapped times, 0-10
rows, huge values, text in numeric columns, other column names given by
``columns=``) must:

- raise nothing but the documented errors (``ImuInputError`` and its
  ``ImuValidationError``, ``MalformedFileError``), each naming the file;
- never return a sample with a non-finite time, rate or specific force, and
  return strictly increasing times;
- never change the input file.

The counts of generated, read and refused tables are printed (``pytest -s``).
"""
from __future__ import annotations

import gzip
import hashlib
import re
import string
import tempfile
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from imu_ground.datasets import ImuInputError, read_imu  # noqa: E402
from imu_ground.datasets.kitti_imu100 import COLUMNS as KITTI_COLUMNS  # noqa: E402
from imu_ground.datasets.report import MalformedFileError  # noqa: E402

#: Examples per property (a few seconds each on a shared 2-core machine).
EXAMPLES = 200
QUANTITIES = ("t", "wx", "wy", "wz", "ax", "ay", "az")
DOCUMENTED = (ImuInputError, MalformedFileError)

_cell = st.one_of(
    st.floats(-20.0, 20.0, allow_nan=False, width=64),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), 1e300, -1e300, 0.0, 9.81, 1.0]),
    st.sampled_from(["abc", "", " ", "1,5", "1e", "--1", "nan", "inf"]),
)


@st.composite
def tables(draw) -> dict:
    """A table: its header, rows of text cells and the read options to use."""
    n = draw(st.integers(0, 10))
    kitti = draw(st.booleans())
    names = list(KITTI_COLUMNS) if kitti else list(QUANTITIES) + draw(st.sampled_from([[], ["speed"]]))
    if not kitti:
        names = draw(st.permutations(names))
    rename = {}
    if not kitti and draw(st.booleans()):                  # other names, said with columns=
        rename = {q: f"{q}_{draw(st.sampled_from(string.ascii_lowercase))}" for q in QUANTITIES}
    step = draw(st.sampled_from([0.01, 10.0, 1e7, 0.005]))  # 100 Hz in s, ms, ns; 200 Hz
    start = draw(st.sampled_from([0.0, 1.6e9, 1.6e18, 12.5]))
    times = start + step * np.arange(n)
    order = draw(st.sampled_from(["sorted", "reversed", "duplicates", "gap", "shuffled"]))
    if order == "reversed":
        times = times[::-1]
    elif order == "duplicates" and n > 1:
        times[1:] = np.maximum.accumulate(times[:-1])
    elif order == "gap" and n > 2:
        times[n // 2:] += 50 * step
    elif order == "shuffled":
        times = np.array(draw(st.permutations(list(times)))) if n else times
    gyro_scale = draw(st.sampled_from([1.0, 57.29577951308232]))
    accel_scale = draw(st.sampled_from([1.0, 1 / 9.80665]))
    rows = []
    for i in range(n):
        base = {"t": float(times[i]), "wx": 0.1 * np.sin(i), "wy": 0.05 * np.cos(i), "wz": 0.2 * np.sin(i / 2),
                "ax": 0.5 * np.sin(i / 3), "ay": 0.1, "az": 9.81}
        row = []
        for c in names:
            if c in base:
                value = base[c] * (gyro_scale if c[0] == "w" else accel_scale if c[0] == "a" else 1.0)
            else:
                value = 0.0
            if draw(st.integers(0, 9)) == 0:          # one cell in ten replaced by a random one
                value = draw(_cell)
            row.append(value if isinstance(value, str) else repr(float(value)))
        rows.append(row)
    header = [rename.get(c, c) for c in names]
    options = {}
    if rename:
        options["columns"] = ",".join(f"{q}={rename[q]}" for q in QUANTITIES)
    options["policy"] = draw(st.sampled_from(["retime", "drop", "sort", "strict"]))
    options["nonfinite"] = draw(st.sampled_from(["raise", "drop"]))
    return {"header": header, "rows": rows, "options": options, "gz": draw(st.booleans())}


def _text(table: dict) -> str:
    return "".join(",".join(r) + "\n" for r in [table["header"], *table["rows"]])


def test_random_tables_are_read_or_refused_with_a_documented_error():
    counts: Counter = Counter()

    @settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow],
              database=None)
    @given(table=tables())
    def read_or_refuse(table: dict) -> None:
        counts["generated"] += 1
        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / ("log.csv.gz" if table["gz"] else "log.csv")
            path.write_bytes(gzip.compress(_text(table).encode()) if table["gz"] else _text(table).encode())
            before = (hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    imu = read_imu(path, **table["options"])
            except DOCUMENTED as e:
                counts["refused"] += 1
                assert str(path) in str(e) or "columns" in str(e), str(e)      # names the file (or the option)
                assert not re.search(r"(than|step|magnitude|is) nan\b", str(e)), str(e)   # no NaN figure
            else:
                counts["read"] += 1
                assert np.isfinite(imu.t).all() and np.isfinite(imu.gyro).all() and np.isfinite(imu.accel).all()
                assert np.all(np.diff(imu.t) > 0)
                assert imu.gyro.shape == imu.accel.shape == (len(imu), 3)
            assert (hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns) == before

    read_or_refuse()
    print(f"\nreader properties: {counts['generated']} generated tables, {counts['read']} read, "
          f"{counts['refused']} refused with a documented error")
    assert counts["generated"] >= EXAMPLES // 2 and counts["read"] and counts["refused"]
