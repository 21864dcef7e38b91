"""Time base: grid, per-column methods, gap handling, timestamp repair."""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.frames.rotations import euler_to_quat, quat_to_dcm
from pipeline.preprocess.resample import make_grid, repair_timestamps, resample, valid_segments


def test_grid_uniform_and_covering():
    g = make_grid(1_000, 1_000 + 2_000_000_000, 30.0)
    assert g[0] == 1_000 and len(g) == 61 and g[-1] == 1_000 + 2_000_000_000
    assert np.all(np.abs(np.diff(g) - 1e9 / 30) <= 1)
    with pytest.raises(ValueError):
        make_grid(0, 10, 0.0)


def test_linear_matches_numpy_interp_and_flags_gap(rng):
    t = np.cumsum(rng.uniform(0.09, 0.11, size=200)) * 1e9
    t = t.astype(np.int64)
    t[100:] += 2_000_000_000  # a 2 s dropout
    x = rng.normal(size=200)
    df = pd.DataFrame({"t_ns": t, "x": x})
    g = make_grid(t[0], t[-1], 20.0)
    r, valid = resample(df, g, {"x": "linear"}, gap_multiple=3.0)
    ref = np.interp(g, t, x)
    inside_gap = (g > t[99]) & (g < t[100])
    assert inside_gap.sum() > 30
    assert not valid[inside_gap].any() and valid[~inside_gap].all()
    assert np.isnan(r["x"][inside_gap]).all()
    np.testing.assert_allclose(r["x"][~inside_gap], ref[~inside_gap], rtol=0, atol=1e-12)


def test_on_grid_samples_are_bit_exact_and_outside_span_invalid():
    t = np.arange(10, dtype=np.int64) * 40_000_000 + 80_000_000
    x = np.linspace(0.1, 0.9, 10) ** 3
    g = make_grid(0, 600_000_000, 25.0)
    r, valid = resample(pd.DataFrame({"t_ns": t, "x": x}), g, {"x": "linear"})
    assert not valid[:2].any() and not valid[g > t[-1]].any()
    on = np.isin(g, t)
    assert np.array_equal(r["x"].to_numpy()[on], x[np.isin(t, g)])


def test_previous_and_nearest_methods():
    t = np.array([0, 100, 200, 300], dtype=np.int64)
    df = pd.DataFrame({"t_ns": t, "m": [1.0, 2.0, 3.0, 4.0]})
    g = np.array([0, 40, 60, 100, 340, 390, 1000], dtype=np.int64)
    r, _ = resample(df, g, {"m": "previous"}, max_gap_ns=150)
    # held at most max_gap after the last sample (390 - 300 <= 150; 1000 is too far)
    np.testing.assert_array_equal(r["m"], [1, 1, 1, 2, 4, 4, np.nan])
    r, _ = resample(df, g, {"m": "nearest"}, max_gap_ns=150)
    np.testing.assert_array_equal(r["m"][:4], [1, 1, 2, 2])


def test_slerp_constant_rate_rotation_is_exact():
    # rotation about z at constant rate: slerp between samples is exact
    t = np.arange(0, 5.0, 0.1)
    yaw = 1.3 * t
    q = euler_to_quat(0 * t, 0 * t, yaw)
    q[1::2] *= -1  # sign flips in the source must not matter
    df = pd.DataFrame({"t_ns": (t * 1e9).round().astype(np.int64), **dict(zip(["q_w", "q_x", "q_y", "q_z"], q.T))})
    g = make_grid(0, int(4.9e9), 33.0)
    r, valid = resample(df, g, {c: "slerp" for c in ["q_w", "q_x", "q_y", "q_z"]})
    assert valid.all()
    ref = quat_to_dcm(euler_to_quat(0 * g, 0 * g, 1.3 * g * 1e-9))
    np.testing.assert_allclose(quat_to_dcm(r.to_numpy()), ref, atol=1e-9)
    with pytest.raises(ValueError, match="slerp"):
        resample(df, g, {"q_w": "slerp"})


def test_unknown_method_and_unsorted_input_raise():
    df = pd.DataFrame({"t_ns": np.array([0, 2, 1]), "x": [1.0, 2, 3]})
    with pytest.raises(ValueError, match="strictly increasing"):
        resample(df, np.array([0]), {"x": "linear"})
    with pytest.raises(ValueError, match="unknown method"):
        resample(df.iloc[:2], np.array([0]), {"x": "cubic"})


def test_repair_counts_duplicates_reorders_and_clock_jumps():
    t = np.array([0, 10, 20, 20, 15, 30, 40], dtype=np.int64) * 1_000_000
    df = pd.DataFrame({"t_ns": t, "x": np.arange(7.0)})
    out, d = repair_timestamps(df, clock_jump_s=None)
    assert d == {"non_monotonic": 1, "duplicate": 1, "clock_jumps": 0, "stray": 0}
    assert np.all(np.diff(out["t_ns"]) > 0)
    assert out["x"].tolist() == [0, 1, 4, 2, 5, 6]  # 15 ms sample put in order, first 20 ms kept
    # a host-clock jump of +1 h in the middle is closed to one median period
    t = np.arange(10, dtype=np.int64) * 100_000_000
    t[5:] += 3_600_000_000_000 * 2
    out, d = repair_timestamps(pd.DataFrame({"t_ns": t}), clock_jump_s=3600)
    assert d["clock_jumps"] == 1
    np.testing.assert_array_equal(out["t_ns"], np.arange(10) * 100_000_000)
    # and a backward jump too
    t = np.arange(10, dtype=np.int64) * 100_000_000 + 10**13
    t[5:] -= 10**13
    out, d = repair_timestamps(pd.DataFrame({"t_ns": t}), clock_jump_s=3600)
    assert d["clock_jumps"] == 1 and np.all(np.diff(out["t_ns"]) == 100_000_000)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(min_value=0, max_value=10**9), min_size=0, max_size=60))
def test_repair_always_gives_strictly_increasing(ts):
    df = pd.DataFrame({"t_ns": np.array(ts, dtype=np.int64)})
    out, d = repair_timestamps(df, clock_jump_s=None)
    assert np.all(np.diff(out["t_ns"].to_numpy()) > 0)
    assert len(out) == len(ts) - d["duplicate"]
    assert set(out["t_ns"]) == set(ts)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), max_size=50))
def test_valid_segments_roundtrip(v):
    segs = valid_segments(v)
    m = np.zeros(len(v), dtype=bool)
    for a, b in segs:
        assert b > a
        m[a:b] = True
    assert m.tolist() == list(v)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.integers(min_value=1, max_value=400), min_size=2, max_size=40),
       st.integers(min_value=0, max_value=2**31 - 1), st.floats(min_value=1.0, max_value=6.0))
def test_linear_resampling_property(steps, seed, mult):
    """Inside bridged intervals linear resampling equals numpy.interp; nothing is filled across a
    step longer than the gap limit, and values stay within the bracketing samples."""
    t = np.cumsum(np.asarray(steps, dtype=np.int64) * 1_000_000)
    x = np.random.default_rng(seed).normal(size=len(t))
    g = make_grid(int(t[0]) - 5_000_000, int(t[-1]) + 5_000_000, 97.0)
    # the documented bridge limit (bridge_limit_ns): m x the longer of the source and grid periods
    per = max(np.median(np.diff(t)), np.median(np.diff(g)) if len(g) > 1 else 0.0)
    r, valid = resample(pd.DataFrame({"t_ns": t, "x": x}), g, {"x": "linear"}, gap_multiple=mult)
    y = r["x"].to_numpy()
    k = np.searchsorted(t, g, side="right") - 1
    inside = (k >= 0) & (k < len(t) - 1)
    kk = np.clip(k, 0, len(t) - 2)
    bridged = inside & (t[kk + 1] - t[kk] <= mult * per)
    exact = np.isin(g, t)
    assert np.array_equal(valid, bridged | exact)
    np.testing.assert_allclose(y[valid], np.interp(g[valid], t, x), rtol=0, atol=1e-12)
    lo = np.minimum(x[kk], x[kk + 1])[bridged]
    hi = np.maximum(x[kk], x[kk + 1])[bridged]
    assert np.all((y[bridged] >= lo - 1e-12) & (y[bridged] <= hi + 1e-12))


@pytest.mark.parametrize("hz, phase_ms", [(50, 0.0), (50, 2.0), (100, 0.0), (200, 1.0), (37, 3.0)])
def test_the_mean_method_is_centred_on_the_grid_time(hz, phase_ms):
    # a ramp x = t must come back as x = g: the plain mean of the samples in [g - T/2, g + T/2)
    # was up to half a source period early (-10 ms for a 50 Hz IMU on the 25 Hz grid)
    ts = np.arange(0, 4_000_000_000, int(1e9 / hz)) + int(phase_ms * 1e6)
    g = make_grid(100_000_000, 3_800_000_000, 25.0)
    r, valid = resample(pd.DataFrame({"t_ns": ts, "x": ts * 1e-9}), g, {"x": "mean"})
    assert valid.all()
    np.testing.assert_allclose(r["x"], g * 1e-9, atol=1e-9)


def test_mean_method_is_an_anti_alias_boxcar(rng):
    # a 200 Hz gyro carrying 95 Hz vibration: point sampling on a 25 Hz grid aliases it to 5 Hz,
    # the cell mean removes most of it
    t = np.arange(0, 20, 0.005)
    x = 0.3 + 0.5 * np.sin(2 * np.pi * 95 * t)
    df = pd.DataFrame({"t_ns": np.round(t * 1e9).astype(np.int64), "x": x})
    g = make_grid(int(0.1e9), int(19.9e9), 25.0)
    lin, _ = resample(df, g, {"x": "linear"})
    avg, valid = resample(df, g, {"x": "mean"})
    assert valid.all()
    assert np.std(lin["x"]) > 0.3
    assert np.std(avg["x"]) < 0.05 and abs(np.mean(avg["x"]) - 0.3) < 0.01
    # slower sources fall back to linear interpolation in empty cells
    slow = df.iloc[::40]
    a, _ = resample(slow, g, {"x": "mean"})
    b, _ = resample(slow, g, {"x": "linear"})
    ts = slow["t_ns"].to_numpy()
    empty = np.searchsorted(ts, g - 20_000_000) == np.searchsorted(ts, g + 20_000_000)
    assert 0 < empty.sum() < len(g)
    np.testing.assert_allclose(a["x"][empty], b["x"][empty])


def test_a_few_stamps_far_from_the_rest_are_strays_and_a_logger_pause_is_not():
    from pipeline.preprocess.resample import stray_samples

    t = np.arange(0, 100, 0.1)
    ns_ = np.round(t * 1e9).astype(np.int64)
    # one record 2,734 s before the flight and two at 1e5 s: strays
    damaged = np.sort(np.r_[ns_, -2_734_000_000_000, 100_000_000_000_000, 100_000_100_000_000])
    s = stray_samples(damaged)
    assert s.sum() == 3 and not s[1:-2].any()
    # a 5 min pause with 10 s of samples after it: two islands, both kept
    pause = np.r_[ns_, ns_[:100] + 400_000_000_000]
    assert not stray_samples(pause).any()
    # no island dominates (two equal halves, or too few samples): nothing is called stray
    assert not stray_samples(np.r_[ns_[:5], ns_[:5] + 10**15]).any()
    assert not stray_samples(ns_).any()
    # the repair drops them before it looks for clock jumps (they are not moved next to the flight)
    df = pd.DataFrame({"t_ns": damaged, "x": 1.0})
    out, d = repair_timestamps(df)
    assert d["stray"] == 3 and d["clock_jumps"] == 0 and np.array_equal(out["t_ns"], ns_)


@pytest.mark.parametrize("method", ["mean", "linear", "nearest"])
def test_a_run_of_missing_values_stays_missing_on_the_grid_for_every_method(method):
    # a 200 Hz sensor with 5 s of readings set to NaN (implausible values): the cell mean drew a
    # line across them and filled all 125 grid points of the hole as if measured
    t = np.arange(0, 20_000_000_000, 5_000_000, dtype=np.int64)
    x = np.sin(t * 1e-9)
    hole = (t >= 5_000_000_000) & (t < 10_000_000_000)
    x[hole] = np.nan
    g = np.arange(0, 20_000_000_000, 40_000_000, dtype=np.int64)
    y, valid = resample(pd.DataFrame({"t_ns": t, "a": x}), g, {"a": method})
    inside = (g >= 5_000_000_000) & (g < 10_000_000_000)
    assert valid[inside].all()                       # the time stamps have no gap ...
    assert np.isnan(y["a"].to_numpy()[inside]).all()  # ... but the values do
    # away from the hole the values are kept (the edges: at most one grid point either side)
    outside = (g < 4_950_000_000) | (g > 10_040_000_000)
    assert np.isfinite(y["a"].to_numpy()[outside]).all()
