"""The compiled numeric CSV parse (datasets/numeric_csv.py, datasets/_csv_native.c) against pandas and float().

Its references: ``pandas.read_csv`` (the parse it replaces, dtypes included) and
Python's ``float`` of each field (correct rounding). Everything outside its
grammar must come back as None, so that the pandas parse (and its messages)
takes over: checked by reading each such file with the kernel on and off.
"""
import gzip
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from imu_ground.datasets import csvio, numeric_csv, read_imu
from imu_ground.datasets.report import MalformedFileError

pytestmark = pytest.mark.skipif(numeric_csv._native is None, reason="the compiled CSV kernel is not in use")

SHARED = Path(os.environ.get("IMU_GROUND_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))
STACK = {"gyro": ("wx", "wy", "wz"), "accel": ("ax", "ay", "az")}


def _native(path, sep=",", stack=None, piece=1 << 20, threads=2):
    return numeric_csv.parse_numeric(Path(path), sep, stack, piece_bytes=piece, threads=threads,
                                     parallel_min_bytes=0)


def _pandas(path, sep=",", stack=None, monkeypatch=None):
    """read_delimited with the kernel off (the pandas parse), or its message."""
    with monkeypatch.context() as m:
        m.setattr(numeric_csv, "_native", None)
        try:
            return csvio.read_delimited(path, sep, stack=stack)
        except MalformedFileError as e:
            return str(e)


def _same_as_pandas(path, monkeypatch, sep=",", stack=None, **kw):
    got = _native(path, sep, stack, **kw)
    assert got is not None, "the kernel refused a file in its grammar"
    cols, n, blank = got
    ref, ref_lines = _pandas(path, sep, stack, monkeypatch)
    assert list(cols) == list(ref) and blank.size == 0
    assert np.array_equal(ref_lines(np.arange(n)), np.arange(n) + 2)     # no blank line: row r on line r + 2
    for c in ref:
        assert cols[c].dtype == ref[c].dtype, c
        assert cols[c].shape == ref[c].shape and cols[c].shape[0] == n, c
        assert np.array_equal(cols[c], ref[c]), c
        if cols[c].dtype.kind == "f":           # -0.0 and 0.0 too
            assert np.array_equal(np.signbit(cols[c]), np.signbit(ref[c])), c
    return cols


def _fields(rng, n):
    """Numbers written in every way a logger or a script writes them."""
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-25, 25, n)
    x[rng.random(n) < 0.02] = 0.0
    fmts = ["%.9g", "%.6f", "%.17g", "%.18e", "%.3E", "%.12g", "%.20f", "%.1f", "%g"]
    out = [fmts[k % len(fmts)] % v for k, v in enumerate(x)]
    special = ["0", "-0", "+5", "-0.0", ".5", "-.25", "5.", "1e5", "1E-5", "+1e+05", "007", "0.000000",
               "2.28881909e-05", "9007199254740991", "123456789012345.6", "1e-320", "4.9e-324", "1e308",
               "00000000000000000000012.5", "0.1000000000000000000000001", "9007199254740993.0"]
    for k, s in enumerate(special):
        out[7 * k % n] = s
    return out


def test_every_number_is_as_pandas_and_float_read_it(tmp_path, monkeypatch):
    rng = np.random.default_rng(7)
    fields = _fields(rng, 60_000)
    p = tmp_path / "a.csv"
    rows = np.array(fields).reshape(-1, 6)
    p.write_text("a,b,c,d,e,f\n" + "".join(",".join(r) + "\n" for r in rows))
    cols = _same_as_pandas(p, monkeypatch, piece=4096)
    got = np.column_stack([cols[c] for c in "abcdef"]).ravel()
    assert np.array_equal(got, [float(s) for s in fields])


def test_integer_columns_are_int64_and_mixed_ones_float(tmp_path, monkeypatch):
    p = tmp_path / "a.csv"
    p.write_text("n,t,x\n" + "".join(f"{i},{1_300_000_000 + i},{i if i % 7 else i + 0.5}\n" for i in range(3000)))
    cols = _same_as_pandas(p, monkeypatch, piece=500)
    assert cols["n"].dtype == np.int64 and cols["t"].dtype == np.int64 and cols["x"].dtype == np.float64


@pytest.mark.parametrize("ending", ["\n", "\r\n"])
@pytest.mark.parametrize("final", [True, False])
def test_line_endings_and_pieces(ending, final, tmp_path, monkeypatch):
    rng = np.random.default_rng(3)
    body = ending.join(f"{0.01 * i:.6f},{rng.standard_normal():.9g},{rng.standard_normal():.9g}" for i in range(4000))
    p = tmp_path / "a.csv"
    p.write_bytes(("t,x,y" + ending + body + (ending if final else "")).encode())
    for piece, threads in [(64, 2), (999, 3), (1 << 20, 1)]:
        _same_as_pandas(p, monkeypatch, piece=piece, threads=threads)


def test_stacked_columns(tmp_path, monkeypatch):
    p = tmp_path / "a.csv"
    p.write_text("t,wx,wy,wz,ax,ay,az\n" + "".join(f"{i / 100:.2f},{i},{-i},{i * 1e-3:.9g},0.1,0.2,9.8\n"
                                                  for i in range(2000)))
    cols = _same_as_pandas(p, monkeypatch, stack=STACK, piece=300)
    assert cols["gyro"].shape == (2000, 3) and cols["gyro"].flags.c_contiguous
    assert cols["gyro"].dtype == np.float64            # stacked integers are floats, as the pandas path's


#: Files outside the grammar -> the kernel says None and the pandas parse (and its message) decides.
REFUSED = {
    "quoted": 't,x\n1,"2"\n3,4\n',
    "blank field": "t,x\n1,\n3,4\n",
    "blank line": "t,x\n1,2\n\n3,4\n",
    "blank last line": "t,x\n1,2\n3,4\n\n",
    "space": "t,x\n1, 2\n3,4\n",
    "nan word": "t,x\n1,nan\n3,4\n",
    "inf word": "t,x\n1,inf\n3,4\n",
    "text": "t,x\n1,abc\n3,4\n",
    "short line": "t,x\n1,2\n3\n",
    "long line": "t,x\n1,2\n3,4,5\n",
    "bare cr": "t,x\r1,2\r3,4\r",
    "cr inside": "t,x\n1,2\r3,4\n",
    "bom": "\ufefft,x\n1,2\n3,4\n",
    "huge integer": "t,x\n1,12345678901234567890123\n3,4\n",
    "integer past 2**53": "t,x\n1,9007199254740993\n3,4\n",
    "header only": "t,x\n",
    "no header end": "t,x",
    "empty": "",
    "duplicate names": "t,t\n1,2\n",
    "empty name": "t,\n1,2\n",
    "exponent without digits": "t,x\n1,2e\n3,4\n",
    "lone sign": "t,x\n1,-\n3,4\n",
    "two points": "t,x\n1,2.3.4\n3,4\n",
    "nul byte": "t,x\n1,2\x00\n3,4\n",
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_anything_else_goes_to_pandas(case, tmp_path, monkeypatch):
    p = tmp_path / "a.csv"
    p.write_bytes(REFUSED[case].encode())
    assert _native(p, piece=4) is None
    try:
        on = csvio.read_delimited(p)
    except MalformedFileError as e:
        on = str(e)
    off = _pandas(p, monkeypatch=monkeypatch)
    if isinstance(off, str) or isinstance(on, str):
        assert on == off
    else:
        assert list(on[0]) == list(off[0])
        for c in off[0]:
            assert np.array_equal(on[0][c], off[0][c], equal_nan=off[0][c].dtype.kind == "f")


def test_a_refusal_late_in_a_big_file_still_gives_pandas_columns(tmp_path, monkeypatch):
    p = tmp_path / "a.csv"
    p.write_text("t,x\n" + "".join(f"{i},{i * 0.5}\n" for i in range(20_000)) + "20000,nan\n")
    assert _native(p, piece=1000) is None
    cols, _ = csvio.read_delimited(p)
    assert np.isnan(cols["x"][-1]) and cols["x"].size == 20_001


def test_other_separators(tmp_path, monkeypatch):
    p = tmp_path / "a.tsv"
    p.write_text("t\tx\n" + "".join(f"{i * 0.01:.2f}\t{np.sin(i):.9g}\n" for i in range(500)))
    _same_as_pandas(p, monkeypatch, sep="\t", piece=100)
    assert _native(p, sep="1") is None and _native(p, sep="ab") is None


def test_compressed_files_are_left_to_pandas(tmp_path):
    p = tmp_path / "a.csv.gz"
    with gzip.open(p, "wt") as f:
        f.write("t,x\n1,2\n")
    assert _native(p) is None


def test_the_pure_python_switch_gives_the_same_reader_output(tmp_path, monkeypatch):
    p = tmp_path / "kitti.csv"
    cols = "t,wx,wy,wz,ax,ay,az,roll,pitch,yaw,ve,vn,vu,px,py,pz"
    rng = np.random.default_rng(0)
    base = np.array([0.0] * 5 + [9.8] + [0.0] * 9)          # wx .. az (az = g), then the 9 extra columns
    rows = [f"{0.01 * i:.6f}," + ",".join(f"{v:.9g}" for v in rng.standard_normal(15) * 0.1 + base)
            for i in range(3000)]
    p.write_text(cols + "\n" + "\n".join(rows) + "\n")
    a = read_imu(p, drives_csv=False)
    monkeypatch.setattr(numeric_csv, "_native", None)
    b = read_imu(p, drives_csv=False)
    for k in ("t", "gyro", "accel"):
        assert np.array_equal(getattr(a, k), getattr(b, k))
    pd.testing.assert_frame_equal(a.extra, b.extra)


@pytest.mark.shared
@pytest.mark.skipif(not (SHARED / "kitti_imu100").is_dir(), reason="../shared/data is not here")
def test_shared_drives_read_as_pandas_reads_them(tmp_path, monkeypatch):
    drives = sorted((SHARED / "kitti_imu100").glob("*.csv.gz"))[:6]
    assert drives
    for gz in drives:
        p = tmp_path / gz.name.removesuffix(".gz")
        with gzip.open(gz, "rb") as f:
            p.write_bytes(f.read())
        _same_as_pandas(p, monkeypatch, stack=STACK, piece=1 << 18)


def test_the_kernel_leaks_nothing_and_checks_its_arguments(tmp_path):
    """2e4 calls (good pieces and refused ones) leave no memory or references behind; bad arguments raise."""
    import gc
    import sys
    import tracemalloc
    k = numeric_csv._native
    p = tmp_path / "a.csv"
    good, bad = b"1,2.5\n3,4e-3\n", b"1,x\n"
    p.write_bytes(good + bad)
    fd = os.open(p, os.O_RDONLY)
    try:
        buf, out = bytearray(64), np.empty(4)
        layout = np.array([[0, 0, 2], [0, 1, 2]], dtype=np.int64)
        arrays, sep = (out,), b","
        refs = [sys.getrefcount(o) for o in (buf, out, layout, arrays, sep)]

        def calls(n):
            for _ in range(n):
                assert k.count_lines(fd, 0, len(good), buf) == 2
                assert k.parse_piece(fd, 0, len(good), buf, sep, arrays, layout, 0, 2) == (b"\x00\x01", b"\x00\x00")  # column 0 all integers
                with pytest.raises(ValueError, match="not a decimal number at byte"):
                    k.parse_piece(fd, len(good), len(good) + len(bad), buf, sep, arrays, layout, 0, 1)

        calls(500)
        gc.collect()
        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
        calls(10_000)
        gc.collect()
        grown = tracemalloc.get_traced_memory()[0] - base
        tracemalloc.stop()
        assert grown < 16 * 1024, grown
        assert [sys.getrefcount(o) for o in (buf, out, layout, arrays, sep)] == refs
        assert out.tolist() == [1.0, 2.5, 3.0, 4e-3]
        with pytest.raises(ValueError, match="do not fit"):
            k.parse_piece(fd, 0, len(good), buf, sep, arrays, layout, 1, 2)
        with pytest.raises(ValueError, match="sentinel"):
            k.parse_piece(fd, 0, len(good), bytearray(len(good)), sep, arrays, layout, 0, 2)
        with pytest.raises(TypeError):
            k.parse_piece(fd, 0, len(good), buf, sep, (out.astype(np.float32),), layout, 0, 2)
        with pytest.raises(ValueError, match="fewer lines than counted|more lines"):
            k.parse_piece(fd, 0, len(good), buf, sep, arrays, layout, 0, 1)
        with pytest.raises(OSError):
            k.count_lines(fd, 0, 10_000, bytearray(10_001))       # past the end of the file
    finally:
        os.close(fd)
