"""``.gz`` logs: python-isal's igzip (the optional ``fast`` extra) and the standard gzip module read the same values.

Without isal installed, both parametrisations run the standard module (the fallback is what is tested then).
"""
import builtins
import gzip
import sys
import warnings

import numpy as np
import pytest

from imu_ground.datasets import read_imu
from imu_ground.datasets.csvio import open_gzip
from imu_ground.datasets.report import MalformedFileError


@pytest.fixture(params=["isal if installed", "standard gzip"])
def gzip_backend(request, monkeypatch):
    """Which module decompresses: the default choice, or the standard one with isal made unimportable."""
    if request.param == "standard gzip":
        real = builtins.__import__

        def no_isal(name, *args, **kwargs):
            if name == "isal" or name.startswith("isal."):
                raise ImportError("isal hidden by the test")
            return real(name, *args, **kwargs)
        monkeypatch.setattr(builtins, "__import__", no_isal)
        for mod in [m for m in sys.modules if m == "isal" or m.startswith("isal.")]:
            monkeypatch.delitem(sys.modules, mod)
    return request.param


def test_the_backend_is_the_one_asked(gzip_backend, tmp_path):
    p = tmp_path / "x.csv.gz"
    p.write_bytes(gzip.compress(b"t,a\n1,2\n"))
    with open_gzip(p) as f:
        assert f.read() == b"t,a\n1,2\n"
        standard = isinstance(f, gzip.GzipFile)
    if gzip_backend == "standard gzip":
        assert standard
    else:
        try:
            import isal  # noqa: F401
        except ImportError:
            assert standard
        else:
            assert not standard


def test_both_backends_read_the_same_values(gzip_backend, shared_data, kitti_index):
    name = kitti_index["drive"].iloc[0]
    gz = shared_data / "kitti_imu100" / f"{name}.csv.gz"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = read_imu(gz)
    with gzip.open(gz, "rb") as f:
        text = f.read()
    import pandas as pd
    ref = pd.read_csv(__import__("io").BytesIO(text))          # pandas on the bytes the standard module gives
    assert len(a) == len(ref)
    np.testing.assert_array_equal(a.gyro, ref[["wx", "wy", "wz"]].to_numpy())
    np.testing.assert_array_equal(a.accel, ref[["ax", "ay", "az"]].to_numpy())


@pytest.mark.parametrize("damage", ["truncated", "corrupt", "not gzip"])
def test_a_damaged_gzip_is_one_clear_error_with_either_backend(gzip_backend, tmp_path, damage):
    rows = "".join(f"{0.01 * k:.2f},0.01,0.02,0.03,0.1,0.2,9.8\n" for k in range(20000))
    data = gzip.compress(("t,wx,wy,wz,ax,ay,az\n" + rows).encode())
    if damage == "truncated":
        data = data[: len(data) // 2]
    elif damage == "corrupt":
        mid = len(data) // 2
        data = data[:mid] + b"\x00" * 64 + data[mid + 64:]
    else:
        data = b"t,wx,wy,wz,ax,ay,az\n" + rows.encode()[:200]
    p = tmp_path / "bad.csv.gz"
    p.write_bytes(data)
    with pytest.raises(MalformedFileError, match=r"bad\.csv\.gz: (truncated or corrupt gzip|cannot parse)"):
        read_imu(p, format="table")
