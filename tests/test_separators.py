"""Tables with tabs or semicolons and decimal commas: read as what they are, told from the file."""
import gzip
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.datasets import read_imu
from imu_ground.datasets import csvio

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(scope="module")
def example():
    return pd.read_csv(EXAMPLE), read_imu(EXAMPLE)


def _same(a, b):
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.gyro, b.gyro)
    np.testing.assert_array_equal(a.accel, b.accel)


@pytest.mark.parametrize("name, sep, decimal", [
    ("drive.tsv", "\t", "."),
    ("drive.tsv.gz", "\t", "."),
    ("drive.csv", ";", ","),            # a spreadsheet's export in a decimal-comma locale
    ("drive.txt", "\t", ","),
    ("drive.csv", ";", "."),
])
def test_tabs_semicolons_and_decimal_commas_read_the_same_samples(example, tmp_path, name, sep, decimal):
    df, ref = example
    path = tmp_path / name
    text = df.to_csv(sep=sep, decimal=decimal, index=False, float_format="%.17g")
    if name.endswith(".gz"):
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    assert csvio.detect_dialect(path) == (sep, decimal)
    _same(read_imu(path), ref)


def test_the_command_reads_a_semicolon_file_without_a_columns_hint(example, tmp_path, cli):
    df, _ = example
    path = tmp_path / "drive.csv"
    path.write_text(df.to_csv(sep=";", decimal=",", index=False, float_format="%.17g"))
    code, out, err = cli("estimate", path, "-o", tmp_path / "o.csv")
    assert code == 0 and "--columns" not in err, err
    code, _, err = cli("estimate", EXAMPLE, "-o", tmp_path / "ref.csv")
    a, b = (pd.read_csv(tmp_path / f, comment="#") for f in ("o.csv", "ref.csv"))
    np.testing.assert_array_equal(a["pitch_deg"].to_numpy(), b["pitch_deg"].to_numpy())


def test_a_comma_file_stays_a_comma_file(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("t,wx,wy,wz,ax,ay,az,note\n0.0,0,0,0,0,0,9.81,a;b\n")
    assert csvio.detect_dialect(path) == (",", ".")
    path.write_text("t;wx;wy;wz;ax;ay;az\n0.0;0;0,5;0;0;0;9.81\n")   # a point and a comma: not decimal commas
    assert csvio.detect_dialect(path) == (";", ".")
