"""``track_reasons`` (a batch's status texts, vectorised where frames can be many) equals ``status_reason`` frame by
frame."""
import numpy as np

from imu_ground.filters.status import CONVERGING, DEGRADED, GAP, INVALID, OK, STANDSTILL, status_reason, track_reasons
from imu_ground.units import DEG


def test_track_reasons_equal_status_reason_of_every_frame():
    rng = np.random.default_rng(0)
    n = 3000
    codes = rng.choice([CONVERGING, OK, STANDSTILL, GAP, DEGRADED, INVALID], n).astype(np.uint8)
    std = rng.uniform(0.01, 2.0, n) * DEG
    dt = rng.uniform(0.05, 3.0, n)
    words = np.array([None, "", "mount moved: 0.9 deg", "NaN in delta_R", "road: no speed"], dtype=object)
    details = words[rng.integers(0, len(words), n)]
    got = track_reasons(codes, std, dt, details)
    want = [status_reason(int(c), float(g), float(s), d) for c, g, s, d in zip(codes, dt, std, details, strict=True)]
    assert got.tolist() == want
    got = track_reasons(codes, std, dt)                                 # no details at all
    assert got.tolist() == [status_reason(int(c), float(g), float(s)) for c, g, s in zip(codes, dt, std, strict=True)]
