"""The simulated part of ``study_trajectory_learning`` at ``tiny`` size: ≥ 10 seeds per
reference, the learned trajectory against the best single demo, the DBA average, its smoothed
version and the per-demo smoother (position RMSE against the intent, through the true τ), the
table of means and spreads and the headline ``align_sim_refs_learned_best``."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from pipeline.simulate.demos import REFERENCES, YAK54_REFERENCES
from pipeline.studies.trajectory_sim import (BASELINES, METHODS, SIM_DEFAULTS, SIM_SIZES, YAK54_METHODS,
                                             simulated_study)

SEED = 20261123


@pytest.fixture(scope="module")
def tiny():
    lines = []
    with threadpool_limits(1):
        tables, results = simulated_study({**SIM_DEFAULTS, **SIM_SIZES["tiny"]}, seed=SEED, progress=lines.append)
    return tables, results, lines


@pytest.mark.slow
def test_at_tiny_size_the_learned_trajectory_beats_every_baseline_on_all_three_references(tiny):
    tables, results, lines = tiny
    cases, summ = tables["sim_cases"], tables["sim_summary"]
    assert SIM_DEFAULTS["n_seeds"] >= 10 and "n_seeds" not in SIM_SIZES["tiny"]
    assert set(cases["reference"]) == set(REFERENCES) | set(YAK54_REFERENCES)
    kin = cases[cases["reference"].isin(REFERENCES)]
    assert set(kin["method"]) == set(METHODS)
    assert (kin.groupby(["reference", "method"]).size() == SIM_DEFAULTS["n_seeds"]).all()
    yak = cases[cases["reference"].isin(YAK54_REFERENCES)]
    assert set(yak["method"]) == set(YAK54_METHODS)
    assert (yak.groupby(["reference", "method"]).size() == SIM_SIZES["tiny"]["yak54_n_seeds"]).all()
    assert np.isfinite(cases["rmse_m"]).all() and (cases["rmse_m"] > 0).all()
    assert {"rmse_mean_m", "rmse_std_m", "rmse_min_m", "rmse_max_m", "n_seeds", "learned_best"} <= set(summ.columns)
    name, value, definition = results[0]
    assert name == "align_sim_refs_learned_best" and value == 3 and definition
    # the optional airframe part is reported, not a target: its headline and candidates are there
    assert results[1][0] == "align_sim_yak54_refs_learned_best" and 0 <= results[1][1] <= 2
    names = {r[0] for r in results}
    for ref in YAK54_REFERENCES:
        assert {f"align_sim_{ref}_learned_no_bias_rmse_m", f"align_sim_{ref}_learned_kinematic_rmse_m"} <= names
    for ref in REFERENCES:
        m = summ[summ["reference"] == ref].set_index("method")["rmse_mean_m"]
        assert all(m["learned"] < m[b] for b in BASELINES), (ref, m.to_dict())
    assert len(lines) == 5 and all(line.startswith("trajectory sim: ") for line in lines)


@pytest.mark.slow
def test_the_simulated_tables_are_written_in_their_declared_schema(tiny, tmp_path):
    # the study writes these under trajectory_learning_<table> (io/schema.py STUDY_RESULTS); the
    # study's own tiny test skips the simulated part, so its declarations are checked here
    from pipeline.io.parquet import read_table_meta, write_table

    tables = tiny[0]
    for k in ("sim_cases", "sim_summary"):
        write_table(tables[k], tmp_path / f"{k}.parquet", name=f"trajectory_learning_{k}")
        assert read_table_meta(tmp_path / f"{k}.parquet")["columns"]["rmse_mean_m" if k == "sim_summary"
                                                                      else "rmse_m"]["unit"] == "m"


def test_one_seed_gives_every_method_and_reference_and_the_same_seed_the_same_numbers():
    s = {**SIM_DEFAULTS, **SIM_SIZES["tiny"], "n_seeds": 1, "max_iter": 3, "references": ["loop"],
         "yak54_references": []}
    with threadpool_limits(1):
        a, ra = simulated_study(s, seed=5)
        b, rb = simulated_study(s, seed=5)
    assert list(a["sim_cases"]["method"]) == list(METHODS)
    np.testing.assert_array_equal(a["sim_cases"]["rmse_m"], b["sim_cases"]["rmse_m"])
    assert ra == rb and [r[0] for r in ra] == ["align_sim_refs_learned_best", "align_sim_loop_learned_rmse_m",
                                                "align_sim_loop_best_baseline_rmse_m"]


def test_a_yak54_reference_gives_the_airframe_candidates_beside_the_baselines():
    s = {**SIM_DEFAULTS, **SIM_SIZES["tiny"], "max_iter": 3, "references": [], "yak54_n_seeds": 1,
         "yak54_references": ["yak54_pull_up"]}
    with threadpool_limits(1):
        t, r = simulated_study(s, seed=5)
    assert list(t["sim_cases"]["method"]) == list(YAK54_METHODS) and np.isfinite(t["sim_cases"]["rmse_m"]).all()
    assert [x[0] for x in r] == ["align_sim_refs_learned_best", "align_sim_yak54_refs_learned_best",
                                 "align_sim_yak54_pull_up_learned_rmse_m", "align_sim_yak54_pull_up_best_baseline_rmse_m",
                                 "align_sim_yak54_pull_up_learned_no_bias_rmse_m",
                                 "align_sim_yak54_pull_up_learned_kinematic_rmse_m"]


def test_bad_study_settings_name_the_key():
    with pytest.raises(ValueError, match=r"yak54_references: unknown \['barrel'\]"):
        simulated_study({"yak54_references": ["barrel"]}, seed=0)
    with pytest.raises(ValueError, match="references: unknown \\['barrel'\\]"):
        simulated_study({"references": ["barrel"]}, seed=0)
    with pytest.raises(ValueError, match="simulate: unknown key\\(s\\) \\['wind'\\]"):
        simulated_study({"simulate": {"wind": 3}}, seed=0)
    with pytest.raises(ValueError, match="n_demos >= 2"):
        simulated_study({"n_demos": 1}, seed=0)
