"""The estimate's CSV writer (pipeline/output.py write_csv_rows): the same bytes as pandas' to_csv, read back equal."""
import io
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.pipeline import estimate_log, result_table, write_output
from imu_ground.pipeline import output as output_mod
from imu_ground.pipeline.output import COLUMNS, TEXT_COLUMNS, write_csv_rows

EXAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "fixtures" / "example_drive.csv"


def _pandas_text(table: pd.DataFrame) -> str:
    """What the writer wrote before (pandas' per-value formatter), the reference."""
    df = table.copy()
    for c in df.columns:
        if df[c].dtype == bool:
            df[c] = df[c].astype(np.int8)
    buf = io.StringIO()
    df.to_csv(buf, index=False, float_format="%.9g", na_rep="nan", lineterminator="\n")
    return buf.getvalue()


def _ours(table: pd.DataFrame) -> str:
    buf = io.StringIO()
    write_csv_rows(buf, table)
    return buf.getvalue()


def _awkward_table(n: int = 5000, seed: int = 0) -> pd.DataFrame:
    """The output's columns with values that stress number formatting."""
    rng = np.random.default_rng(seed)
    data = {c: rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n) for c in COLUMNS
            if c not in TEXT_COLUMNS}
    table = pd.DataFrame(data)
    table["valid"] = rng.random(n) > 0.2
    words = np.array(["ok", "", "3.2 s gap, integrated", 'a "quoted" word', "line\nbreak", "standstill"], dtype=object)
    for c in TEXT_COLUMNS:
        table[c] = words[rng.integers(0, len(words), n)]
    table = table[list(COLUMNS)]
    special = [np.nan, np.inf, -np.inf, -0.0, 0.0, 5e-324, 1.7976931348623157e308, 0.1, 1e16, 123456789.5,
               -2.5e-5, 1.0000000005]
    table.iloc[:len(special), 1] = special
    table.iloc[7:20, 4:10] = np.nan
    return table


def test_same_bytes_as_pandas_on_awkward_values(monkeypatch):
    table = _awkward_table()
    monkeypatch.setattr(output_mod, "CSV_BLOCK_ROWS", 333)          # blocks that do not divide the rows
    assert _ours(table) == _pandas_text(table)


def test_same_bytes_as_pandas_on_a_real_estimate():
    table = result_table(estimate_log(EXAMPLE))
    assert _ours(table) == _pandas_text(table)


def test_empty_table_is_the_header_line():
    table = _awkward_table().iloc[:0]
    assert _ours(table) == _pandas_text(table) == ",".join(COLUMNS) + "\n"


@pytest.mark.parametrize("change", ["object column", "quoted name", "huge integer", "integer column"])
def test_other_tables_match_pandas_too(change):
    table = _awkward_table(300)
    if change == "object column":
        table["note"] = ["a,b"] * len(table)
    elif change == "quoted name":
        table = table.rename(columns={"qx": "q,x"})
    elif change == "huge integer":
        table["n"] = np.arange(len(table), dtype=np.int64) + 2 ** 60
    else:
        table["n"] = np.arange(len(table), dtype=np.int64) - 7
    assert _ours(table) == _pandas_text(table)


def test_written_file_reads_back_equal_to_the_table_at_nine_digits(tmp_path):
    res = estimate_log(EXAMPLE)
    table = result_table(res)
    out = write_output(tmp_path / "x.csv", table, res.meta)
    text = out.read_text()
    assert text.startswith("# imu-ground ")
    back = pd.read_csv(out, comment="#")
    assert tuple(back.columns) == COLUMNS
    assert np.array_equal(back["valid"].to_numpy(), table["valid"].to_numpy().astype(int))
    for c in TEXT_COLUMNS:                                          # (an empty field reads back as NaN)
        assert back[c].fillna("").tolist() == table[c].tolist(), c
    for c in (c for c in COLUMNS if c not in TEXT_COLUMNS + ("valid",)):
        want = np.array([float(f"{x:.9g}") for x in table[c].to_numpy()])
        assert np.array_equal(back[c].to_numpy(), want, equal_nan=True), c
        assert np.allclose(back[c].to_numpy(), table[c].to_numpy(), rtol=1e-8, atol=0, equal_nan=True), c
