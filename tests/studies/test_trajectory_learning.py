"""Study trajectory_learning at tiny size: the real-data leave-one-out on synthetic flights (fast),
and on the real FlightCoach / kd0aij flights when ../shared/realdata is there."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import need_shared
from helpers_align import synthetic_segments, synthetic_state, write_flight

from pipeline.config import load_config, section
from pipeline.io.parquet import read_table
from pipeline.studies import STUDIES, STUDY_TABLES, run_study, study_outputs


def _align(sets):
    a = section(load_config(), "align")
    a.update(sets=sets, max_iter=2)
    return a


def test_the_study_is_registered_with_its_tables():
    assert "trajectory_learning" in STUDIES
    assert STUDY_TABLES["trajectory_learning"] == ("sim_cases", "sim_summary", "real_loo", "real_summary")


def test_the_real_leave_one_out_writes_a_row_per_fold_and_the_result_line(tmp_path):
    seg = synthetic_segments([(0, 5, "a"), (5, 10, "b")])
    paths = [write_flight(tmp_path, f"f{k}", synthetic_state(260, heading_rad=0.3 * k, seed=k), seg, 0.3 * k)
             for k in range(3)]
    inputs = {"states": [p[0] for p in paths], "segments": [p[1] for p in paths]}
    out = study_outputs("trajectory_learning", results_dir=tmp_path / "results", models=False)
    res = run_study("trajectory_learning", inputs, out,
                    {"size": "tiny", "trajectory_learning": {"sets": ["s"], "skip": ["simulated"],
                                                             "sizes": {"tiny": {"real_max_iter": 2}}}},
                    seed=1, align=_align({"s": {"flights": ["f0", "f1", "f2"], "reference": None}}))
    loo = read_table(out["real_loo"])
    assert len(loo) == 12 and set(loo["status"]) == {"ok"}  # 2 maneuvers x 3 folds x (box, centred)
    assert loo.groupby("frame").size().to_dict() == {"box": 6, "centred": 6}
    assert "align_real_loo_better_pct_centred" in res.results
    assert np.isfinite(loo[["rms_learned_m", "rms_best_other_m", "rms_dba_m"]].to_numpy()).all()
    pct = float(res.results["align_real_loo_better_pct"])
    assert 0.0 <= pct <= 100.0
    assert "RESULT align_real_loo_better_pct" in Path(out["results"]).read_text()
    assert "align_real_loo_better_pct" in Path(out["page"]).read_text()


def test_a_set_whose_flights_are_absent_is_skipped_with_a_notice(tmp_path):
    out = study_outputs("trajectory_learning", results_dir=tmp_path / "results", models=False)
    res = run_study("trajectory_learning", {"states": [], "segments": []}, out,
                    {"size": "tiny", "trajectory_learning": {"sets": ["s"], "skip": ["simulated"]}},
                    seed=1, align=_align({"s": {"flights": ["gone1", "gone2"], "reference": None}}))
    assert "set s: no demos (its flights are not available): skipped" in res.diagnostics["notices"]
    assert "align_real_loo_better_pct" not in res.results


@pytest.mark.slow
def test_the_tiny_study_on_the_real_flights_prints_both_result_lines(tmp_path):
    need_shared("FlightCoach JSON and kd0aij CSV flights")
    root = Path("results")
    flights = ["fc-p23-036", "fc-p23-350", "fc-p21-026", "kd0aij-p21", "kd0aij-141"]
    if not all((root / "state" / f"{f}.parquet").exists() for f in flights):
        pytest.skip("results/state of the P23/P21 flights not built (snakemake results/state/<flight>.parquet)")
    inputs = {"states": [str(root / "state" / f"{f}.parquet") for f in flights],
              "segments": [str(root / "segments" / f"{f}.parquet") for f in flights]}
    out = study_outputs("trajectory_learning", results_dir=tmp_path / "results", models=False)
    res = run_study("trajectory_learning", inputs, out, {"size": "tiny"}, seed=20261123,
                    align=section(load_config(), "align"))
    assert math.isfinite(float(res.results["align_real_loo_better_pct"]))
