"""Baselines of trajectory learning: DBA and the framework's RTS smoother per feature."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.align.baselines import (AUTO_GRID, dba_average, medoid_index, per_demo_smooth, smooth,
                                      smooth_track)
from pipeline.align.dtw import dtw
from pipeline.estimate.base import ConstantAcceleration, GaussianState, position_measurement
from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter
from pipeline.estimate.smoother import rts_smooth

DT = 0.05


def _bumps(t):
    return np.c_[np.exp(-((t - 0.3) / 0.04) ** 2) + 0.6 * np.exp(-((t - 0.7) / 0.05) ** 2),
                 np.sin(2 * np.pi * t) * np.exp(-((t - 0.5) / 0.1) ** 2)]


def _warped_copies(rng, M=6, L=150):
    u = np.linspace(0, 1, L)
    out = []
    for _ in range(M):
        a, b = rng.uniform(-0.08, 0.08), rng.uniform(-0.05, 0.05)
        out.append(_bumps(u + a * np.sin(np.pi * u) + b * np.sin(2 * np.pi * u)))  # monotone warps
    return _bumps(u), out


def _track(rng, T=400):
    t = np.arange(T) * DT
    truth = np.c_[10 * np.sin(0.5 * t), 3 * np.cos(0.3 * t) + t, 0.05 * t ** 2]
    sd = np.array([0.5, 1.0, 0.2])
    return truth, truth + rng.standard_normal(truth.shape) * sd, sd


# --------------------------------------------------------------------------- DBA

def test_the_dba_average_of_identical_demos_is_that_demo(rng):
    d = rng.standard_normal((60, 3))
    np.testing.assert_allclose(dba_average([d, d, d]), d, rtol=0, atol=1e-14)
    np.testing.assert_allclose(dba_average([d]), d, rtol=0, atol=1e-14)


def test_each_dba_iteration_equals_dtaidistances_dba_update_from_the_same_start(rng):
    from dtaidistance import dtw_barycenter as barycenter
    demos = [np.cumsum(rng.standard_normal((n, 2)), axis=0) for n in (40, 45, 38, 50)]
    theirs = demos[1]
    for k in (1, 2, 3):
        theirs = barycenter.dba(demos, theirs, use_c=True)
        np.testing.assert_allclose(dba_average(demos, init=demos[1], n_iter=k), theirs, rtol=0, atol=1e-12)


def test_dba_of_time_warped_copies_is_closer_to_the_signal_than_the_plain_mean(rng):
    sig, demos = _warped_copies(rng)
    avg, mean = dba_average(demos), np.mean(demos, axis=0)
    d_avg, d_mean = dtw(avg, sig).normalized_distance, dtw(mean, sig).normalized_distance
    assert d_avg < 0.5 * d_mean
    # the plain mean smears the peak that DBA keeps
    assert avg[:, 0].max() == pytest.approx(sig[:, 0].max(), abs=0.05)
    assert mean[:, 0].max() < 0.8 * sig[:, 0].max()


def test_dba_is_deterministic_starts_at_the_medoid_and_keeps_its_length(rng):
    _, demos = _warped_copies(rng, M=4)
    demos[2] = demos[2][:130]
    k = medoid_index(demos)
    a, b = dba_average(demos), dba_average(demos)
    np.testing.assert_array_equal(a, b)
    assert a.shape == demos[k].shape
    np.testing.assert_array_equal(dba_average(demos, n_iter=0), demos[k])
    assert dba_average(demos, init=2).shape == (130, 2)
    assert dba_average(demos, init=np.zeros((90, 2)), n_iter=1).shape == (90, 2)


def test_dba_refinement_does_not_increase_the_summed_squared_dtw_cost(rng):
    _, demos = _warped_copies(rng, M=5)

    def cost(avg):
        return sum(dtw(avg, d, step_pattern="symmetric1", local="sqeuclidean").distance for d in demos)

    costs = [cost(dba_average(demos, n_iter=k)) for k in range(4)]
    assert all(b <= a + 1e-12 for a, b in zip(costs, costs[1:]))


def test_dba_with_a_window_and_std_scaling_on_demos_of_other_lengths_is_dba_of_the_divided_demos(rng):
    _, demos = _warped_copies(rng, M=3)
    demos = [demos[0], demos[1][:120], demos[2] * [1.0, 100.0]]
    s = np.concatenate(demos).std(axis=0)            # "std": per feature, pooled over all demos
    avg = dba_average(demos, window=10, scale="std")  # widened to |L − T_i| where needed
    k = medoid_index(demos, window=10, scale="std")
    assert avg.shape == demos[k].shape and np.isfinite(avg).all()
    np.testing.assert_array_equal(dba_average(demos, window=10, scale=s), avg)
    # the scale divides the DTW cost only: the average of the divided demos, multiplied back
    divided = [d / s for d in demos]
    np.testing.assert_allclose(dba_average(divided, window=10) * s, avg, rtol=1e-12, atol=1e-12)
    # and it matters here (the ×100 feature would dominate an unscaled cost; from one start, as
    # the medoid may move with the scaling)
    scaled, plain = (dba_average(demos, init=0, window=10, scale=sc) for sc in ("std", None))
    assert np.abs(scaled - plain).max() > 1e-3
    # a window at least as long as the longest demo constrains nothing
    np.testing.assert_array_equal(dba_average(demos, window=150, scale="std"), dba_average(demos, scale="std"))
    # ... which 10 does (from the same start: the medoid itself moves with the window)
    free, banded = (dba_average(demos, init=0, window=w, scale="std") for w in (None, 10))
    assert np.abs(free - banded).max() > 1e-3
    # one iteration stepped by hand from the first demo: each average sample is the mean of the
    # demo samples aligned to it, alignments with the band widened to |150 − T_i| (30 for the 120)
    acc, cnt = np.zeros((150, 2)), np.zeros(150)
    for d in demos:
        p = dtw(demos[0], d, step_pattern="symmetric1", local="sqeuclidean", scale=s,
                window=max(10, abs(150 - len(d)))).path
        assert np.abs(p[:, 0] - p[:, 1]).max() <= max(10, abs(150 - len(d)))
        np.add.at(acc, p[:, 0], d[p[:, 1]])
        np.add.at(cnt, p[:, 0], 1.0)
    np.testing.assert_allclose(dba_average(demos, init=0, n_iter=1, window=10, scale="std"),
                               acc / cnt[:, None], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("demos, kw, match", [
    ([], {}, "no demos"),
    ([np.zeros((5, 2)), np.zeros((5, 3))], {}, "different feature counts"),
    ([np.zeros((5, 2)), np.full((5, 2), np.nan)], {}, "demo 1 has a non-finite value in row 0"),
    ([np.zeros((5, 2))], {"init": 3}, "init index 3"),
    ([np.zeros((5, 2))], {"n_iter": -1}, "n_iter"),
])
def test_dba_refuses_bad_demos_with_one_clear_line(demos, kw, match):
    with pytest.raises(ValueError, match=match):
        dba_average(demos, **kw)


# --------------------------------------------------------------------------- smoother

def test_the_smoother_reduces_the_white_noise_rmse_on_a_known_signal(rng):
    truth, z, sd = _track(rng)
    raw = np.sqrt(((z - truth) ** 2).mean(axis=0))
    for kw in ({}, {"r": sd}, {"q": 1.0, "r": sd}, {"model": "cv"}):
        sm = smooth(z, DT, **kw)
        assert sm.shape == z.shape
        assert (np.sqrt(((sm - truth) ** 2).mean(axis=0)) < 0.5 * raw).all(), kw


def test_auto_noise_levels_recover_the_measurement_std(rng):
    truth, z, sd = _track(rng, T=800)
    res = smooth_track(z, DT)
    np.testing.assert_allclose(res.r, sd, rtol=0.1)
    assert res.q.shape == (3,) and (res.q > 0).all() and np.isfinite(res.loglik).all()


def test_given_noise_levels_reproduce_the_frameworks_ca_ekf_and_rts_smoother(rng):
    # with one q and r for all three axes the per-feature smoother is the framework's 9-state
    # CA filter with a position measurement, smoothed by rts_smooth, up to the prior
    truth, z, _ = _track(rng)
    q, r = 2.0, 0.7
    ours = smooth(z, DT, q=q, r=r)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), position_measurement(r))
    T = len(z)
    P0 = np.diag(np.r_[np.full(3, 1e6), np.full(3, 1e8), np.full(3, 1e10)])
    x0 = np.r_[z[0], np.zeros(6)]
    tr = run_filter(ekf, GaussianState(x0[None], P0[None], 0), np.arange(T) * 50_000_000, z[:, None, :])
    ref = rts_smooth(tr).mean[0, :, :3]
    np.testing.assert_allclose(ours[10:-10], ref[10:-10], atol=1e-3 * np.abs(ref).max())


def test_a_straight_line_comes_back_to_round_off_and_a_trend_does_not_change_the_result(rng):
    # the prior's velocity scale is the size of the steps, not their spread (a steady track's
    # steps hardly vary: its velocity prior was N(0, ~1e-20) and the line came back 42 off)
    line = np.arange(100.0)
    for model in ("ca", "cv"):
        np.testing.assert_allclose(smooth(line, 0.1, model=model)[:, 0], line, atol=1e-6)
    t = np.arange(200) * 0.1
    truth = 0.5 * np.sin(0.3 * t)
    y = truth + 0.01 * rng.standard_normal(200)
    flat = smooth(y, 0.1)[:, 0]
    moving = smooth(y + 10 * t, 0.1)[:, 0] - 10 * t
    err = [np.sqrt(np.mean((a - truth) ** 2)) for a in (flat, moving)]
    assert err[1] == pytest.approx(err[0], rel=0.25)


def test_nan_rows_are_smoothed_through(rng):
    truth, z, _ = _track(rng)
    z[100:120] = np.nan
    z[200, 1] = np.nan  # a NaN anywhere in a row makes the row missing
    sm = smooth(z, DT)
    assert np.isfinite(sm).all()
    assert np.sqrt(((sm[100:120] - truth[100:120]) ** 2).mean()) < 1.0


def test_per_demo_smooth_smooths_each_demo_on_its_own(rng):
    _, z, _ = _track(rng)
    demos = [z[:300], z[50:], z[:, :3]]
    out = per_demo_smooth(demos, DT)
    assert [o.shape for o in out] == [d.shape for d in demos]
    np.testing.assert_array_equal(out[0], smooth(z[:300], DT))


def test_the_auto_grid_is_dimensionless_and_wide():
    assert AUTO_GRID[0] <= 1e-9 and AUTO_GRID[-1] >= 10.0


@pytest.mark.parametrize("args, kw, match", [
    ((np.zeros((1, 2)), DT), {}, "T ≥ 2"),
    ((np.zeros((5, 2)), 0.0), {}, "dt must be"),
    ((np.zeros((5, 2)), DT), {"model": "singer"}, "unknown model"),
    ((np.zeros((5, 2)), DT), {"q": 1.0}, "r='auto' needs q='auto'"),
    ((np.zeros((5, 2)), DT), {"q": -1.0, "r": 1.0}, "q must be"),
    ((np.zeros((5, 2)), DT), {"r": [1.0, 2.0, 3.0]}, "r must be"),
    ((np.zeros((5, 2)), DT), {"q": "ml"}, "'auto' or numbers"),
    ((np.full((5, 2), np.nan), DT), {}, "fewer than 2 rows"),
    ((np.arange(8.0).reshape(4, 2), DT), {}, "q='auto' needs more than 4 rows"),   # r came back 0, ll NaN
    ((np.arange(6.0).reshape(3, 2), DT), {"model": "cv"}, "q='auto' needs more than 3 rows"),
])
def test_the_smoother_refuses_bad_input_with_one_clear_line(args, kw, match):
    with pytest.raises(ValueError, match=match):
        smooth(*args, **kw)
