"""EKF estimates of the simulated bulk sets (pipeline/estimate/sets.py): the bulk-set schema,
one generator per seed and set name, an error below the radar's own, NaN jerk, clear errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pipeline.config import ConfigError
from pipeline.estimate.models import STATE_COLUMNS, RadarModel
from pipeline.estimate.ekf_hmm import prior_increment_track
from pipeline.estimate.sets import (JERK_COLUMNS, SET_COLUMNS, SetsSettings, ekf_rng, ekf_set, prior_increment_set,
                                  run_ekf_sets)
from pipeline.io.parquet import read_table, read_table_meta, write_table

SEED = 20261123


@pytest.fixture(scope="module")
def truth():
    """Six simulated M1 runs at 5 Hz, exactly as ``uavpipe simulate`` writes a bulk set."""
    from pipeline.simulate.datasets import DatasetSettings, simulate_set
    from pipeline.simulate.scenarios import SimSettings
    from pipeline.simulate.sensors import SensorSettings

    return simulate_set("maneuver", "M1", 6, SimSettings.from_config({}), DatasetSettings.from_config({}),
                        SensorSettings.from_config({}), SEED, "maneuver/M1")


@pytest.fixture(scope="module")
def written(truth, tmp_path_factory):
    d = tmp_path_factory.mktemp("ekfsets")
    sim = d / "sim"
    sim.mkdir()
    paths = {}
    for name, runs in (("M1_train", [0, 1, 2, 3]), ("M1_test", [4, 5])):
        p = sim / f"{name}.parquet"
        write_table(truth[truth.run_id.isin(runs)].reset_index(drop=True), p, SET_COLUMNS, name="simulate_set",
                    extra={"set": name})
        paths[name] = p
    out = {n: d / "est" / f"{n}.parquet" for n in paths}
    res = run_ekf_sets({"sets": list(paths.values())}, {"sets": list(out.values())}, {}, seed=SEED)
    return paths, out, res


def test_the_estimate_is_written_in_the_bulk_set_schema_with_the_truths_runs_labels_and_attitude(written):
    paths, out, res = written
    assert res.status == "ok" and set(res.diagnostics) == {"M1_train", "M1_test"}
    for name in paths:
        tr, est = read_table(paths[name], SET_COLUMNS), read_table(out[name], SET_COLUMNS)
        assert list(est.columns) == [c.name for c in SET_COLUMNS]
        assert len(est) == len(tr)
        for c in ("t_ns", "run_id", "label", "q_w", "yaw_rad", "roll_rad", "p_radps", "thr", "gap"):
            pd.testing.assert_series_equal(est[c], tr[c], check_names=False)
        assert not np.allclose(est["pos_n_m"], tr["pos_n_m"])          # estimated, not copied
        np.testing.assert_array_equal(est["alt_cal_m"], -est["pos_d_m"])
        meta = read_table_meta(out[name])
        assert meta["input"] == "ekf" and meta["seed"] == SEED and meta["q"] == 3.0


def test_the_jerk_columns_are_nan_and_the_state_columns_finite(written):
    _, out, _ = written
    est = read_table(out["M1_test"], SET_COLUMNS)
    assert est[list(JERK_COLUMNS)].isna().all().all()
    assert np.isfinite(est[list(STATE_COLUMNS)].to_numpy()).all()


def test_one_seed_and_set_name_give_one_estimate_and_another_seed_or_name_another(truth):
    r = RadarModel()
    a, _ = ekf_set(truth, radar=r, q=3.0, rng=ekf_rng(SEED, "M1_train"))
    b, _ = ekf_set(truth, radar=r, q=3.0, rng=ekf_rng(SEED, "M1_train"))
    pd.testing.assert_frame_equal(a, b)
    c, _ = ekf_set(truth, radar=r, q=3.0, rng=ekf_rng(SEED + 1, "M1_train"))
    d, _ = ekf_set(truth, radar=r, q=3.0, rng=ekf_rng(SEED, "M1_test"))
    assert not np.allclose(a["pos_n_m"], c["pos_n_m"]) and not np.allclose(a["pos_n_m"], d["pos_n_m"])


def test_a_set_does_not_depend_on_which_other_sets_are_filtered(written, tmp_path):
    paths, out, _ = written
    alone = tmp_path / "M1_test.parquet"
    run_ekf_sets({"sets": [paths["M1_test"]]}, {"sets": [alone]}, {}, seed=SEED)
    pd.testing.assert_frame_equal(read_table(alone, SET_COLUMNS), read_table(out["M1_test"], SET_COLUMNS))


def test_the_sets_hold_the_predicted_increment_track_by_default_and_the_posteriors_on_request(written, tmp_path):
    paths, out, _ = written
    post = tmp_path / "M1_test.parquet"
    run_ekf_sets({"sets": [paths["M1_test"]]}, {"sets": [post]}, {"increments": "posterior"}, seed=SEED)
    posterior = read_table(post, SET_COLUMNS)
    # the same radar draw filtered: the posteriors are ekf_set's, the default is their predicted-increment track
    want, _ = ekf_set(read_table(paths["M1_test"], SET_COLUMNS), radar=RadarModel(), q=3.0,
                      rng=ekf_rng(SEED, "M1_test"))
    np.testing.assert_array_equal(posterior[list(STATE_COLUMNS)].to_numpy(), want[list(STATE_COLUMNS)].to_numpy())
    pd.testing.assert_frame_equal(read_table(out["M1_test"], SET_COLUMNS),
                                  prior_increment_set(posterior), check_dtype=False)
    assert read_table_meta(post)["increments"] == "posterior"
    assert read_table_meta(out["M1_test"])["increments"] == "prior"
    with pytest.raises(ConfigError, match="estimate.sets.increments"):
        SetsSettings.from_config({"increments": "both"})


def _radar_only_position(radar: RadarModel, z: np.ndarray, below: np.ndarray) -> np.ndarray:
    """The position one radar measurement gives alone: ``R_n + ρ [u, v, ±√(1 − u² − v²)]``
    (τ_RD = 0; the sign of the third direction cosine from the truth)."""
    rho, u, v = z[..., 0], z[..., 1], z[..., 2]
    w = np.sqrt(np.clip(1 - u ** 2 - v ** 2, 0, None)) * np.where(below, 1.0, -1.0)
    return np.asarray(radar.site_ned_m) + rho[..., None] * np.stack([u, v, w], axis=-1)


def test_the_ekf_position_error_is_well_below_the_radar_only_error(truth):
    r = RadarModel()
    est, diag = ekf_set(truth, radar=r, q=3.0, rng=ekf_rng(SEED, "x"))
    x = truth.sort_values(["run_id", "t_ns"])[list(STATE_COLUMNS)].to_numpy()
    z = r.measure(x, np.random.default_rng(1))
    raw = _radar_only_position(r, z, x[:, 2] > r.site_ned_m[2])
    raw_rmse = np.sqrt(np.mean((raw - x[:, :3]) ** 2))
    ekf_rmse = np.sqrt(np.mean((est[list(STATE_COLUMNS[:3])].to_numpy() - x[:, :3]) ** 2))
    assert raw_rmse > 0.5                                   # σ_ρ = 1.5 m along the line of sight
    assert ekf_rmse < 0.6 * raw_rmse, (ekf_rmse, raw_rmse)
    assert diag["rmse_pos"] == pytest.approx(ekf_rmse)
    assert diag["rmse_acc"] < 5.0                           # converged (a few m/s² at most)
    assert diag["n_diverged"] == 0


def test_a_target_above_the_radar_plane_can_be_tracked_as_its_mirror_image_below_it(truth):
    # range and the two direction cosines give the third cosine's size, not its sign: started at
    # the mirror image of its start (below the radar's horizontal plane), the filter stays there
    # (why ekf_set counts n_diverged; 4 of 2300 M1 runs at 10 m height and ~900 m range flip)
    from pipeline.estimate.base import ConstantAcceleration, GaussianState
    from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter
    from pipeline.estimate.models import initial_cov

    r = RadarModel()
    one = truth[truth.run_id == 0].copy()
    x0 = one[list(STATE_COLUMNS)].to_numpy()[0]
    h = -(x0[2] - r.site_ned_m[2])                            # height above the radar (m)
    assert h > 0
    x = one[list(STATE_COLUMNS)].to_numpy()[None]
    z = np.swapaxes(r.measure(x, np.random.default_rng(3)), 0, 1)
    start = x[:, 0].copy()
    start[:, 2] += 2 * h                                      # the mirror image of the start
    track = run_filter(ExtendedKalmanFilter(ConstantAcceleration(3.0), r),
                       GaussianState(start, initial_cov()[None], int(one.t_ns.iloc[0])),
                       one.t_ns.to_numpy(), z, store="mean")
    mirrored = track.mean[0, :, 2] - r.site_ned_m[2] > 0       # estimated below the radar plane
    assert mirrored.mean() > 0.5 and np.all(np.abs(track.mean[0, :, 0:2] - x[0, :, 0:2]) < 20)


def test_runs_of_unequal_length_fail_in_one_line_naming_the_set(truth):
    bad = truth[~((truth.run_id == 2) & (truth.t_ns > 10e9))]
    with pytest.raises(ValueError, match=r"^sets/M1\.parquet: runs differ in length") as exc:
        ekf_set(bad, radar=RadarModel(), q=3.0, rng=ekf_rng(1, "M1"), where="sets/M1.parquet")
    assert "\n" not in str(exc.value)
    with pytest.raises(ValueError, match="missing column"):
        ekf_set(truth.drop(columns="vel_n_mps"), radar=RadarModel(), q=3.0, rng=ekf_rng(1, "M1"))


def test_a_bad_estimate_sets_key_or_mismatched_outputs_fail_naming_them(tmp_path):
    with pytest.raises(ConfigError, match=r"^estimate\.sets\.qq: unknown key"):
        SetsSettings.from_config({"qq": 1})
    with pytest.raises(ConfigError, match=r"^simulate\.sensors\.radar\.sigma_rnage_m: unknown key"):
        SetsSettings.from_config({"radar": {"sigma_rnage_m": 1}})
    with pytest.raises(ConfigError, match="does not match input"):
        run_ekf_sets({"sets": [tmp_path / "M1_train.parquet"]}, {"sets": [tmp_path / "M2_train.parquet"]}, {},
                     seed=1)
    st = SetsSettings.from_config({"q": 0.5, "radar": {"sigma_range_m": 2.0}})
    assert st.q == 0.5 and st.p0_sigma == (1.0, 0.1, 0.01) and st.radar.sigma[0] == 2.0


def test_the_printed_increment_set_replaces_each_runs_states_by_its_predicted_increment_track(truth):
    est, _ = ekf_set(truth, radar=RadarModel(), q=3.0, rng=ekf_rng(SEED, "M1"))
    shuffled = est.sample(frac=1.0, random_state=0)                  # run and time order restored
    pr = prior_increment_set(shuffled, where="M1_test")
    assert list(pr.columns) == list(est.columns) and len(pr) == len(est)
    for rid, g in pr.groupby("run_id"):
        e = est[est.run_id == rid]
        want = prior_increment_track(e[list(STATE_COLUMNS)].to_numpy(), e["t_ns"].to_numpy())
        np.testing.assert_allclose(g[list(STATE_COLUMNS)].to_numpy(), want)
        np.testing.assert_array_equal(g["label"].to_numpy(), e["label"].to_numpy())
        np.testing.assert_array_equal(g["alt_cal_m"].to_numpy(), -g["pos_d_m"].to_numpy())
    with pytest.raises(ValueError, match="^M1_test: not a bulk set"):
        prior_increment_set(est.drop(columns="acc_d_mps2"), where="M1_test")
