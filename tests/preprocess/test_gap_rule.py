"""The gap rule follows the output grid (issue 13, defect 10): a jittery fast source must not
turn grid points that have samples around them into gaps; real dropouts still are gaps."""

import numpy as np
import pandas as pd

from pipeline.frames.rotations import euler_to_quat
from pipeline.io.base import FlightLog
from pipeline.preprocess.resample import bridge_limit_ns, make_grid, median_period_ns, resample
from pipeline.preprocess.state import preprocess_log

RATE_IMU = 183.0
GRID_HZ = 25.0


def _jittery_stamps(rng, duration_s: float = 20.0) -> np.ndarray:
    """183 Hz stamps, each late by up to 3 median steps (driver buffering), sorted."""
    d0 = 1e9 / RATE_IMU
    k = np.arange(int(duration_s * RATE_IMU))
    t = np.sort((k * d0 + rng.uniform(0.0, 3.0 * d0, size=len(k))).astype(np.int64))
    return np.unique(t)


def _attitude(t: np.ndarray) -> pd.DataFrame:
    s = t * 1e-9
    q = euler_to_quat(0.2 * np.sin(s), 0.1 * np.cos(0.5 * s), 0.3 * s)
    return pd.DataFrame({"t_ns": t, "q_w": q[:, 0], "q_x": q[:, 1], "q_y": q[:, 2], "q_z": q[:, 3]})


def test_a_jittery_183hz_source_makes_no_gap_on_a_25hz_grid(rng):
    t = _jittery_stamps(rng)
    steps = np.diff(t)
    per = median_period_ns(t)
    assert steps.max() > 3.0 * per  # the jitter the old rule (3 source periods) called dropouts
    g = make_grid(int(t[0]), int(t[-1]), GRID_HZ)
    methods = {"q_w": "slerp", "q_x": "slerp", "q_y": "slerp", "q_z": "slerp"}
    _, old_valid = resample(_attitude(t), g, methods, max_gap_ns=3.0 * per)
    assert (~old_valid).mean() > 0.05
    r, valid = resample(_attitude(t), g, methods, gap_multiple=3.0)
    assert valid.all() and np.isfinite(r.to_numpy()).all()
    assert bridge_limit_ns(t, g, 3.0) == 3.0 * median_period_ns(g)


def test_bridge_limits_follow_the_grid_and_real_dropouts_stay_gaps(rng):
    t = _jittery_stamps(rng, 10.0)
    # dropouts of 2 and of 5 grid periods: the first is bridged, the second is a gap
    cut2 = (t > 3.0e9) & (t < 3.0e9 + 2 / GRID_HZ * 1e9)
    cut5 = (t > 6.0e9) & (t < 6.0e9 + 5 / GRID_HZ * 1e9)
    t = t[~cut2 & ~cut5]
    g = make_grid(int(t[0]), int(t[-1]), GRID_HZ)
    _, valid = resample(pd.DataFrame({"t_ns": t, "x": np.ones(len(t))}), g, {"x": "linear"})
    before, after = t[t <= 6.0e9].max(), t[t >= 6.0e9 + 5 / GRID_HZ * 1e9].min()
    inside5 = (g > before) & (g < after)
    assert inside5.sum() >= 4
    np.testing.assert_array_equal(valid, ~inside5)
    # a 5 Hz source on the 25 Hz grid keeps its own limit: 3 of its periods
    t5 = np.arange(0, 10_000_000_000, 200_000_000, dtype=np.int64)
    assert bridge_limit_ns(t5, g, 3.0) == 600_000_000


def test_preprocessed_state_of_a_jittery_imu_attitude_has_no_gaps(rng):
    t = _jittery_stamps(rng, 12.0)
    tp = np.linspace(t[0], t[-1], 121).astype(np.int64)  # 10 Hz navigation over the same span
    pos = pd.DataFrame({"t_ns": tp, "pos_n_m": tp * 1e-9, "pos_e_m": 0.0, "pos_d_m": -10.0,
                        "vel_n_mps": 1.0, "vel_e_mps": 0.0, "vel_d_mps": 0.0})
    log = FlightLog.from_streams({"flight_id": "jitter"}, {"attitude": _attitude(t), "local_position": pos})
    res = preprocess_log(log, {"rate_hz": GRID_HZ})
    assert res.diagnostics["sources"]["attitude"] == "attitude"
    assert res.diagnostics["gap_fraction"] == 0.0
