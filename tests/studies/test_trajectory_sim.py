"""The simulated part of ``study_trajectory_learning`` at ``tiny`` size: ≥ 10 seeds per
reference, the learned trajectory against the best single demo, the DBA average, its smoothed
version and the per-demo smoother (position RMSE against the intent, through the true τ), the
table of means and spreads and the headline ``align_sim_refs_learned_best``."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from pipeline.simulate.demos import REFERENCES
from pipeline.studies.trajectory_sim import BASELINES, METHODS, SIM_DEFAULTS, SIM_SIZES, simulated_study

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
    assert set(cases["reference"]) == set(REFERENCES) and set(cases["method"]) == set(METHODS)
    assert (cases.groupby(["reference", "method"]).size() == SIM_DEFAULTS["n_seeds"]).all()
    assert np.isfinite(cases["rmse_m"]).all() and (cases["rmse_m"] > 0).all()
    assert {"rmse_mean_m", "rmse_std_m", "rmse_min_m", "rmse_max_m", "n_seeds", "learned_best"} <= set(summ.columns)
    name, value, definition = results[0]
    assert name == "align_sim_refs_learned_best" and value == 3 and definition
    for ref in REFERENCES:
        m = summ[summ["reference"] == ref].set_index("method")["rmse_mean_m"]
        assert all(m["learned"] < m[b] for b in BASELINES), (ref, m.to_dict())
    assert len(lines) == 3 and all(line.startswith("trajectory sim: ") for line in lines)


def test_one_seed_gives_every_method_and_reference_and_the_same_seed_the_same_numbers():
    s = {**SIM_DEFAULTS, **SIM_SIZES["tiny"], "n_seeds": 1, "max_iter": 3, "references": ["loop"]}
    with threadpool_limits(1):
        a, ra = simulated_study(s, seed=5)
        b, rb = simulated_study(s, seed=5)
    assert list(a["sim_cases"]["method"]) == list(METHODS)
    np.testing.assert_array_equal(a["sim_cases"]["rmse_m"], b["sim_cases"]["rmse_m"])
    assert ra == rb and [r[0] for r in ra] == ["align_sim_refs_learned_best", "align_sim_loop_learned_rmse_m",
                                                "align_sim_loop_best_baseline_rmse_m"]


def test_bad_study_settings_name_the_key():
    with pytest.raises(ValueError, match="references: unknown \\['barrel'\\]"):
        simulated_study({"references": ["barrel"]}, seed=0)
    with pytest.raises(ValueError, match="simulate: unknown key\\(s\\) \\['wind'\\]"):
        simulated_study({"simulate": {"wind": 3}}, seed=0)
    with pytest.raises(ValueError, match="n_demos >= 2"):
        simulated_study({"n_demos": 1}, seed=0)
