"""Output table and writers (pipeline/output.py): columns, gaps, suffixes, atomic writes, Parquet metadata."""
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from imu_ground.pipeline import estimate_log, result_table, write_output, write_outputs
from imu_ground.pipeline.output import (
    COLUMNS,
    GAP_NAN_FRAMES,
    check_output_path,
    default_output_name,
    summarize_table,
)

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "datasets" / "fixtures" / "example_drive.csv"


@pytest.fixture(scope="module")
def result():
    return estimate_log(EXAMPLE)


@pytest.fixture(scope="module")
def gap_log(tmp_path_factory):
    """The example drive with 3 s of samples removed in the middle (a long gap) and one short one."""
    df = pd.read_csv(EXAMPLE)
    t = df["t"].to_numpy()
    keep = ~((t > 20.0) & (t < 23.0)) & ~((t > 40.0) & (t < 40.15))
    path = tmp_path_factory.mktemp("gap") / "gap.csv"
    df[keep].to_csv(path, index=False)
    return path


def test_table_has_the_briefs_columns(result):
    table = result_table(result)
    assert tuple(table.columns) == COLUMNS
    assert table["valid"].dtype == bool
    q = table[["qw", "qx", "qy", "qz"]].to_numpy()
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    assert len(table) == len(result.egomotion)


def test_long_gap_frames_are_nan_and_left_out_of_summary_and_tum(gap_log, tmp_path):
    res = estimate_log(gap_log)
    table = result_table(res)
    invalid = ~table["valid"].to_numpy()
    assert invalid.sum() > GAP_NAN_FRAMES                        # the 3 s gap
    nan = table["pitch_deg"].isna().to_numpy()
    assert nan.any() and np.all(invalid[nan])                     # only invalid frames are NaN
    assert np.any(invalid & ~nan)                                 # the short gap keeps its (flagged) values
    s = summarize_table(table)
    ok = table["valid"].to_numpy()
    assert s["pitch_mean_deg"] == pytest.approx(table["pitch_deg"].to_numpy()[ok].mean())
    tum = write_output(tmp_path / "g.tum", table, res.meta)
    rows = np.loadtxt(tum)
    assert len(rows) == ok.sum()
    assert not np.isin(np.round(rows[:, 0], 6), np.round(table["t"].to_numpy()[~ok], 6)).any()


def test_csv_header_says_what_valid_holds(result, tmp_path):
    out = write_output(tmp_path / "x.csv", result_table(result), result.meta)
    header = [ln for ln in out.read_text().splitlines() if ln.startswith("#")]
    valid_line = next(ln for ln in header if ln.startswith("# valid:"))
    assert "1 =" in valid_line and "0 =" in valid_line
    back = pd.read_csv(out, comment="#")
    assert set(back["valid"].unique()) <= {0, 1}
    assert "method suspension" in header[0]


def test_parquet_is_typed_with_units_and_settings(result, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    out = write_output(tmp_path / "x.parquet", result_table(result), result.meta)
    schema = pq.read_schema(out)
    assert str(schema.field("valid").type) == "bool" and str(schema.field("pitch_deg").type) == "double"
    assert b"deg" in schema.field("pitch_deg").metadata[b"unit"]
    info = json.loads(schema.metadata[b"imu_ground"])
    assert info["method"] == "suspension" and info["settings"]["rate"] == 10.0
    back = pd.read_parquet(out)
    pd.testing.assert_frame_equal(back, result_table(result))


def test_unknown_suffix_folder_input_and_under_a_file_are_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown output type"):
        check_output_path(tmp_path / "x.xlsx")
    with pytest.raises(ValueError, match="is a folder"):
        check_output_path(tmp_path)
    log = tmp_path / "log.csv"
    log.write_text("t\n")
    with pytest.raises(ValueError, match="is the input log"):
        check_output_path(log, [str(log)])
    with pytest.raises(ValueError, match="is a file, not a folder"):
        check_output_path(log / "x.csv")


def test_a_failing_writer_leaves_nothing_behind(result, tmp_path, monkeypatch):
    from imu_ground.pipeline import output
    table = result_table(result)

    def broken(path, table, meta):
        Path(path).write_text("half")
        raise RuntimeError("disk full")

    monkeypatch.setitem(output._WRITERS, ".tum", broken)
    with pytest.raises(RuntimeError):
        write_outputs([tmp_path / "a.csv", tmp_path / "a.tum"], table, result.meta)
    assert sorted(os.listdir(tmp_path)) == []                    # no CSV, no partial TUM, no temporary folder


def test_default_output_name():
    assert default_output_name("x/2011_09_26_drive_0009.csv.gz") == "2011_09_26_drive_0009_ground.csv"
    assert default_output_name("scene/", ".parquet") == "scene_ground.parquet"


def test_mcap_output_through_the_ros_writer(result, tmp_path):
    pytest.importorskip("rosbags")
    out = write_output(tmp_path / "x.mcap", result_table(result), result.meta)
    assert out.is_file() and out.stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.mcap"]
    from rosbags.highlevel import AnyReader
    with AnyReader([out]) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
    assert max(topics.values()) == len(result.egomotion)
