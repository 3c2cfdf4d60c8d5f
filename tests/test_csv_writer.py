"""The estimate's CSV writer (pipeline/output.py write_csv_rows): pyarrow's CSV writer, pandas' without pyarrow;
the file reads back equal to the table (every double exact), text quoted, header comments first."""
import io
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.pipeline import estimate_log, result_table, write_output
from imu_ground.pipeline import output as output_mod
from imu_ground.pipeline.output import COLUMNS, TEXT_COLUMNS, write_csv_rows

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(params=["pyarrow", "pandas"])
def writer(request, monkeypatch):
    """Which library writes the rows: pyarrow (installed by the test extras), or pandas with pyarrow hidden."""
    if request.param == "pandas":
        monkeypatch.setitem(sys.modules, "pyarrow.csv", None)      # import pyarrow.csv: ImportError
    else:
        pytest.importorskip("pyarrow")
    return request.param


def _text(table: pd.DataFrame) -> bytes:
    buf = io.BytesIO()
    write_csv_rows(buf, table)
    return buf.getvalue()


def _read_back(data: bytes) -> pd.DataFrame:
    return pd.read_csv(io.BytesIO(data), comment="#", keep_default_na=False, na_values=["nan", ""])


def _awkward_table(n: int = 5000, seed: int = 0) -> pd.DataFrame:
    """The output's columns with values that stress number formatting and quoting."""
    rng = np.random.default_rng(seed)
    data = {c: rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n) for c in COLUMNS
            if c not in TEXT_COLUMNS}
    table = pd.DataFrame(data)
    table["valid"] = rng.random(n) > 0.2
    words = np.array(["ok", "3.2 s gap, integrated", 'a "quoted" word', "line\nbreak", "standstill", "x;y"],
                     dtype=object)
    for c in TEXT_COLUMNS:
        table[c] = words[rng.integers(0, len(words), n)]
    table = table[list(COLUMNS)]
    special = [np.nan, np.inf, -np.inf, -0.0, 0.0, 5e-324, 1.7976931348623157e308, 0.1, 1e16, 123456789.5,
               -2.5e-5, 1.0000000005]
    table.iloc[:len(special), 1] = special
    table.iloc[7:20, 4:10] = np.nan
    return table


def _assert_reads_back_equal(back: pd.DataFrame, table: pd.DataFrame) -> None:
    assert list(back.columns) == [str(c) for c in table.columns]
    for c in table.columns:
        want = table[c].to_numpy()
        if want.dtype.kind == "b":
            assert np.array_equal(back[c].to_numpy(), want.astype(int)), c
        elif want.dtype.kind in "fiu":
            got = back[c].to_numpy(dtype=float)
            assert np.array_equal(got, want.astype(float), equal_nan=True), c       # every double exact
        else:
            assert back[c].fillna("").astype(str).tolist() == [str(v) for v in want], c


def test_awkward_values_read_back_exactly(writer):
    table = _awkward_table()
    _assert_reads_back_equal(_read_back(_text(table)), table)


def test_nan_is_written_nan_and_text_is_quoted(writer):
    table = _awkward_table(50)
    assert _text(table).decode().split("\n")[0] == ",".join(COLUMNS)      # the header names, unquoted
    raw = pd.read_csv(io.BytesIO(_text(table)), dtype=str, keep_default_na=False)     # the fields' text
    assert raw["normal_x"].iloc[:3].tolist() == ["nan", "inf", "-inf"]
    assert '"a ""quoted"" word"' in _text(table).decode()
    assert '"3.2 s gap, integrated"' in _text(table).decode()


def test_empty_table_is_the_header_line(writer):
    table = _awkward_table().iloc[:0]
    assert _text(table).decode() == ",".join(COLUMNS) + "\n"


@pytest.mark.parametrize("change", ["object column", "quoted name", "mixed object column", "integer column"])
def test_other_tables_read_back_too(writer, change):
    table = _awkward_table(300)
    if change == "object column":
        table["note"] = ["a,b"] * len(table)
    elif change == "quoted name":
        table = table.rename(columns={"qx": "q,x"})
    elif change == "mixed object column":
        table["note"] = ["a", 1.5] * (len(table) // 2)
    else:
        table["n"] = np.arange(len(table), dtype=np.int64) - 7
    data = _text(table)
    back = pd.read_csv(io.BytesIO(data), keep_default_na=False, na_values=["nan", ""])
    if change == "mixed object column":
        assert back["note"].astype(str).tolist() == [str(v) for v in table["note"]]
        table = table.drop(columns="note")
        back = back.drop(columns="note")
    _assert_reads_back_equal(back, table)


def test_written_file_reads_back_equal_to_the_table(tmp_path, writer):
    res = estimate_log(EXAMPLE)
    table = result_table(res)
    out = write_output(tmp_path / "x.csv", table, res.meta)
    text = out.read_text()
    assert text.startswith("# imu-ground ")
    assert [ln for ln in text.splitlines() if not ln.startswith("#")][0] == ",".join(COLUMNS)
    back = pd.read_csv(out, comment="#", keep_default_na=False, na_values=["nan"])
    assert tuple(back.columns) == COLUMNS
    _assert_reads_back_equal(back, table)


@pytest.mark.parametrize("parts", [2, 3, 4])
def test_rows_formatted_in_blocks_on_threads_are_the_bytes_of_one_call(monkeypatch, parts):
    pytest.importorskip("pyarrow")
    table = _awkward_table(4099, seed=parts)
    monkeypatch.setattr(output_mod, "CSV_PARALLEL_ROWS", 10**9)          # one call, one thread
    whole = _text(table)
    monkeypatch.setattr(output_mod, "CSV_PARALLEL_ROWS", 100)
    monkeypatch.setattr(output_mod, "CSV_PARTS", parts)
    assert _text(table) == whole
    _assert_reads_back_equal(_read_back(whole), table)
