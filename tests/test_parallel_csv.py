"""The parallel pandas parse of plain CSV files (datasets/csvio.py): the same columns, lines and errors as the serial parse.

The compiled numeric parse (datasets/numeric_csv.py, tested in test_numeric_csv.py)
comes first for plain all-number files; it is switched off here, so that these
tests reach the pandas paths it leaves the other files to (and every file,
without a C compiler).
"""
import gzip

import numpy as np
import pytest
from imu_ground.datasets import csvio, numeric_csv, read_imu
from imu_ground.datasets.report import MalformedFileError


@pytest.fixture(autouse=True)
def _pandas_paths(monkeypatch):
    monkeypatch.setattr(numeric_csv, "_native", None)

HEADER = "t,wx,wy,wz,ax,ay,az\n"
#: Cases the pieces represent exactly (the others go to the serial parse, which names the bad line).
PARALLEL_CASES = ("blank lines", "integers then floats", "crlf", "no final newline", "blank last line",
                  "long lines then short")


def _rows(n: int, t0: float = 0.0) -> str:
    return "".join(f"{t0 + 0.01 * i:.6f},{0.001 * i:.9g},-0.002,{1e-3 * np.sin(i):.9g},0.1,-0.2,9.81\n"
                   for i in range(n))


def _read(path, parallel: bool, monkeypatch):
    """read_delimited with pieces of 300 bytes (parallel) or the serial parse only."""
    with monkeypatch.context() as m:
        if parallel:
            m.setattr(csvio, "PARALLEL_MIN_BYTES", 0)
            m.setattr(csvio, "PIECE_BYTES", 300)
            m.setattr(csvio, "_threads", lambda: 2)
        else:
            m.setattr(csvio, "PARALLEL_MIN_BYTES", 1 << 62)
        try:
            return csvio.read_delimited(path)
        except MalformedFileError as e:
            return str(e)


def _same(a, b) -> None:
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return
    (ca, la), (cb, lb) = a, b
    assert list(ca) == list(cb)
    for c in ca:
        assert ca[c].dtype == cb[c].dtype, c
        assert np.array_equal(ca[c], cb[c], equal_nan=ca[c].dtype.kind == "f"), c
    rows = np.arange(len(next(iter(ca.values()))))
    assert np.array_equal(la(rows), lb(rows))


def test_pieces_are_used_and_give_the_serial_columns(tmp_path, monkeypatch):
    p = tmp_path / "a.csv"
    p.write_text(HEADER + _rows(500))
    calls = []
    real = csvio._parse_piece
    monkeypatch.setattr(csvio, "_parse_piece", lambda *a: calls.append(a[1]) or real(*a))
    par = _read(p, True, monkeypatch)
    assert len(calls) > 10                                   # really cut into pieces
    _same(par, _read(p, False, monkeypatch))
    assert par[0]["t"].size == 500 and par[0]["t"][-1] == pytest.approx(4.99)


@pytest.mark.parametrize("case", ["blank lines", "integers then floats", "crlf", "no final newline",
                                  "short line", "long line", "not a number", "quoted", "bare cr",
                                  "blank last line", "whitespace line", "long lines then short"])
def test_every_case_reads_as_the_serial_parse(case, tmp_path, monkeypatch):
    body = _rows(300)
    lines = body.splitlines(keepends=True)
    if case == "blank lines":
        lines[40:40] = ["\n", "\n"]
        lines[200:200] = ["\n"]
    elif case == "integers then floats":
        lines[:150] = [f"{i},1,2,3,4,5,6\n" for i in range(150)]
    elif case == "crlf":
        lines = [ln.replace("\n", "\r\n") for ln in lines]
    elif case == "no final newline":
        lines[-1] = lines[-1].rstrip("\n")
    elif case == "short line":
        lines[170] = "1.70,0.1,0.2\n"
    elif case == "long line":
        lines[170] = lines[170].rstrip("\n") + ",7\n"
    elif case == "not a number":
        lines[250] = lines[250].replace("-0.002", "abc")
    elif case == "quoted":
        lines[100] = lines[100].replace("-0.002", '"-0.002"')
    elif case == "bare cr":
        lines[100] = lines[100].replace("\n", "\r")
    elif case == "blank last line":
        lines.append("\n")
    elif case == "long lines then short":          # more rows than the first piece suggests: columns grow
        lines[:8] = [",".join([f"{0.1 * i:.15e}"] * 7) + "\n" for i in range(8)]
        lines[8:] = [f"{i},1,2,3,4,5,6\n" for i in range(8, 300)]
    else:
        lines[120] = "   \n"
    p = tmp_path / "x.csv"
    p.write_bytes((HEADER + "".join(lines)).encode())
    _same(_read(p, True, monkeypatch), _read(p, False, monkeypatch))
    with monkeypatch.context() as m:                     # the clean cases do not fall back
        m.setattr(csvio, "PARALLEL_MIN_BYTES", 0)
        m.setattr(csvio, "PIECE_BYTES", 300)
        m.setattr(csvio, "_threads", lambda: 2)
        took_pieces = csvio._parse_parallel(p, ",", None) is not None
    assert took_pieces == (case in PARALLEL_CASES)


def test_reader_messages_name_the_same_file_line(tmp_path, monkeypatch):
    lines = _rows(400).splitlines(keepends=True)
    lines[330] = lines[330].replace("0.1,", "0.1x,")
    p = tmp_path / "bad.csv"
    p.write_text(HEADER + "".join(lines))
    for parallel in (True, False):
        with monkeypatch.context() as m:
            m.setattr(csvio, "PARALLEL_MIN_BYTES", 0 if parallel else 1 << 62)
            m.setattr(csvio, "PIECE_BYTES", 300)
            with pytest.raises(MalformedFileError, match=r"bad\.csv, line 332: column 'ax': '0.1x'"):
                read_imu(p, format="table")


def test_compressed_files_take_the_serial_path(tmp_path, monkeypatch):
    p = tmp_path / "a.csv.gz"
    p.write_bytes(gzip.compress((HEADER + _rows(300)).encode()))
    monkeypatch.setattr(csvio, "PARALLEL_MIN_BYTES", 0)
    monkeypatch.setattr(csvio, "_parse_piece", lambda *a: pytest.fail("a piece of a gzip file"))
    cols, _ = csvio.read_delimited(p)
    assert cols["t"].size == 300


@pytest.mark.parametrize("parallel", [True, False])
def test_stacked_columns_equal_the_columns_side_by_side(parallel, tmp_path, monkeypatch):
    p = tmp_path / "s.csv"
    p.write_text(HEADER + "".join(f"{i},1,2,3,4,5,6\n" for i in range(100)) + _rows(300, t0=1.0))
    plain = _read(p, parallel, monkeypatch)[0]
    with monkeypatch.context() as m:
        if parallel:
            m.setattr(csvio, "PARALLEL_MIN_BYTES", 0)
            m.setattr(csvio, "PIECE_BYTES", 300)
            m.setattr(csvio, "_threads", lambda: 2)
        cols, _ = csvio.read_delimited(p, stack={"gyro": ("wx", "wy", "wz"), "accel": ("ax", "ay", "az")})
    assert list(cols) == ["t", "gyro", "accel"]
    for name, members in (("gyro", ("wx", "wy", "wz")), ("accel", ("ax", "ay", "az"))):
        assert cols[name].dtype == float and cols[name].flags.c_contiguous
        assert np.array_equal(cols[name], np.column_stack([plain[c].astype(float) for c in members]))


@pytest.mark.parametrize("stack", [{"g": ("wy", "wx")}, {"g": ("wx", "wz")}, {"t": ("wx", "wy")},
                                   {"g": ("wx", "nope")}, {"g": ("wx", "wy", "text")}])
def test_columns_are_stacked_only_when_consecutive_numbers_under_a_new_name(stack, tmp_path):
    p = tmp_path / "s.csv"
    p.write_text("t,wx,wy,text,wz\n" + "".join(f"{i},1,2,a{i},3\n" for i in range(20)))
    cols, _ = csvio.read_delimited(p, stack=stack)
    assert list(cols) == ["t", "wx", "wy", "text", "wz"]


def test_kitti_header_with_gyro_and_accel_swapped_is_still_refused(tmp_path):
    from imu_ground.datasets.kitti_imu100 import COLUMNS
    names = list(COLUMNS)
    names[1:4], names[4:7] = names[4:7], names[1:4]
    p = tmp_path / "swap.csv"
    p.write_text(",".join(names) + "\n" + "".join(",".join(["0.01"] * 16) + "\n" for _ in range(20)))
    with pytest.raises(MalformedFileError, match=r"swap\.csv, line 1: expected columns t,wx,wy,wz,ax"):
        read_imu(p, format="kitti_imu100")


def test_sink_grows_and_promotes_like_concatenate():
    sink = csvio._ColumnSink(["a", "x", "y"], {"x": ("xy", 0), "y": ("xy", 1)}, capacity=2)
    parts = [[np.arange(3), np.arange(3) * 1.5, np.arange(3)], [np.array([0.5, 7.0]), np.ones(2), np.zeros(2)]]
    for p in parts:
        sink.add(p)
    cols = sink.finish()
    assert list(cols) == ["a", "xy"]
    assert cols["a"].dtype == np.concatenate([parts[0][0], parts[1][0]]).dtype == float
    assert np.array_equal(cols["a"], [0, 1, 2, 0.5, 7.0])
    assert np.array_equal(cols["xy"], [[0, 0], [1.5, 1], [3, 2], [1, 0], [1, 0]])
