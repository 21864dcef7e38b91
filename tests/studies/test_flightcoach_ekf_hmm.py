"""The FlightCoach EKF vs EKF+HMM study through its entry point, on the real flights of
../shared/realdata, with the inputs the Snakemake rule declares (``flightcoach_inputs`` with the
study's two files).

At ``tiny`` size (3 Baum-Welch iterations, three q, one Q₂ scale) it writes every declared output
with a well-formed headline; at ``small`` size (the full study, the size issue 14 means) the
headline is asserted against the acceptance target (≥ 12 of 17; missed on the faithful data, a
strict xfail). Both skip when ../shared/realdata is absent
(fail under UAVPIPE_REQUIRE_SHARED=1).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import REALDATA, realdata_file

from pipeline.studies import STUDY_TABLES, flightcoach_inputs
from pipeline.studies.base import FLIGHTCOACH_DIR, FLIGHTCOACH_EKF_HMM_FILES, StudyError

NAME = "flightcoach_ekf_hmm"


def _inputs():
    realdata_file(FLIGHTCOACH_DIR)   # skips, or fails under UAVPIPE_REQUIRE_SHARED=1, when absent
    return flightcoach_inputs(REALDATA, FLIGHTCOACH_EKF_HMM_FILES, study=NAME)


def _rule_count(man: pd.DataFrame) -> int:
    """Issue 14's rule on written per-maneuver RMSEs: EKF+HMM acceleration RMSE below 0.95 × the
    EKF's, with HMM inputs on at least 20 % of the maneuver's steps."""
    ratio = man["ekf_hmm_acc_rmse_mps2"].to_numpy() / man["ekf_acc_rmse_mps2"].to_numpy()
    return int(np.sum((ratio < 0.95) & (man["hmm_share_pct"].to_numpy() >= 20.0)))


def _rmse(err: np.ndarray) -> float:
    e = err[np.isfinite(err).all(axis=1)]
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


def _check_results_against_the_tables(run) -> None:
    """The RESULT lines that summarise the test flight, recomputed from the written tables
    (``maneuvers``, ``train_maneuvers``, ``timeline``), not from the study's own ``better`` column."""
    f = run.figures
    man, man_tr, tl = run.table("maneuvers"), run.table("train_maneuvers"), run.table("timeline")
    assert f["flightcoach_ekf_hmm_n_maneuvers"] == str(len(man)) == "17"
    assert f["flightcoach_ekf_hmm_acc_better_maneuvers"] == str(_rule_count(man))
    assert f["flightcoach_ekf_hmm_train_acc_better_maneuvers"] == str(_rule_count(man_tr))
    ratio = man["ekf_hmm_acc_rmse_mps2"].to_numpy() / man["ekf_acc_rmse_mps2"].to_numpy()
    assert float(f["flightcoach_ekf_hmm_median_acc_ratio"]) == pytest.approx(float(np.median(ratio)), abs=5e-4 + 1e-12)
    for g, unit in (("vel", "mps"), ("pos", "m")):
        lower = int(np.sum(man[f"ekf_hmm_{g}_rmse_{unit}"].to_numpy() < man[f"ekf_{g}_rmse_{unit}"].to_numpy()))
        assert f[f"flightcoach_ekf_hmm_{g}_lower_maneuvers"] == str(lower), g
    right = int(np.sum(man["pred_end"].astype(str).to_numpy() == man["label"].astype(str).to_numpy()))
    assert f["flightcoach_ekf_hmm_correct_at_segment_end"] == f"{right}/{len(man)}"
    # over the test maneuvers' steps (a label, take-off and landing left out), from the 5 Hz timeline
    inside = ~tl["label"].astype(str).isin(["", "tkOf", "tkoff", "lnd"]).to_numpy()
    mode = tl["mode"].to_numpy(dtype=bool)
    acc = {k: tl[[f"{k}_acc_{a}_mps2" for a in "ned"]].to_numpy() for k in ("ref", "ekf", "ekf_hmm", "gmr")}
    assert float(f["flightcoach_ekf_hmm_hmm_share_pct"]) == pytest.approx(100.0 * mode[inside].mean(), abs=0.05 + 1e-9)
    for key, est, rows in (("ekf_acc_rmse", "ekf", inside), ("ekf_hmm_acc_rmse", "ekf_hmm", inside),
                           ("gmr_acc_rmse", "gmr", inside & mode)):
        want = _rmse((acc[est] - acc["ref"])[rows])
        assert float(f[f"flightcoach_ekf_hmm_{key}"]) == pytest.approx(want, abs=5e-4 + 1e-12), key


@pytest.fixture(scope="module")
def tiny(ran, tmp_path_factory):
    inputs = _inputs()
    return ran(NAME, tmp_path_factory.mktemp("fe_tiny"), {"size": "tiny"}, inputs)


@pytest.mark.realdata
@pytest.mark.slow
def test_the_tiny_study_writes_results_report_tables_and_page(tiny):
    assert tiny.result.status == "ok" and tiny.result.diagnostics["size"] == "tiny"
    text = Path(tiny.outputs["results"]).read_text().splitlines()
    assert text and all(line.startswith("RESULT ") and len(line.split()) == 3 for line in text)
    assert tiny.figures == tiny.result.results
    _check_results_against_the_tables(tiny)
    assert float(tiny.figures["flightcoach_ekf_hmm_q"]) in (10.0, 30.0, 100.0)
    for t in STUDY_TABLES[NAME]:
        assert len(tiny.table(t)), t
    page = Path(tiny.outputs["page"]).read_text()
    assert 'src="../assets/plotly.min.js"' in page and "flightcoach_ekf_hmm_acc_better_maneuvers" in page
    assert Path(tiny.outputs["model_params"]).is_file() and Path(tiny.outputs["model_meta"]).is_file()


@pytest.mark.realdata
@pytest.mark.slow
def test_the_maneuver_table_follows_the_acceptance_rule(tiny):
    man = tiny.table("maneuvers")
    assert len(man) == 17 and not set(man["label"]) & {"tkOf", "tkoff", "lnd"}
    # better = below 0.95 × the EKF's acceleration RMSE with HMM inputs on >= 20 % of the steps
    rule = (man["ekf_hmm_acc_rmse_mps2"] < 0.95 * man["ekf_acc_rmse_mps2"]) & (man["hmm_share_pct"] >= 20.0)
    assert (man["better"] == rule).all()
    assert int(man["better"].sum()) == int(tiny.figures["flightcoach_ekf_hmm_acc_better_maneuvers"])
    np.testing.assert_allclose(man["acc_ratio"], man["ekf_hmm_acc_rmse_mps2"] / man["ekf_acc_rmse_mps2"])
    assert (man[["ekf_acc_rmse_mps2", "ekf_hmm_acc_rmse_mps2", "ekf_pos_rmse_m", "ekf_vel_rmse_mps"]] > 0).all().all()
    tuning = tiny.table("tuning")
    assert tuning.groupby("parameter")["chosen"].sum().to_dict() == {"q": 1, "q2_scale": 1}
    # the GMR input is tuned jointly with the Q₂ scale: the chosen pair has the lowest training score
    q2 = tuning[tuning.parameter == "q2_scale"]
    chosen = q2[q2.chosen].iloc[0]
    assert chosen["score"] == q2["score"].min()
    assert chosen["gmr_input"] == tiny.figures["flightcoach_ekf_hmm_gmr_input"]
    assert float(chosen["value"]) == float(tiny.figures["flightcoach_ekf_hmm_q2_scale"])
    tl = tiny.table("timeline")
    assert tl["mode"].dtype == bool and set(tl["pred"]) - {"unknown"} <= set(man["label"])


@pytest.mark.realdata
@pytest.mark.slow
# Issue 14's real-data target, asserted as stated. On the faithful data it is missed (measured
# 0/17: the EKF+HMM acceleration RMSE is above 0.95× the EKF's on every maneuver, median ratio 1.70 with
# the printed (4.1) increments and the GMR input tuned on the training flight (pos), seed 20261123;
# because the GMR acceleration and jerk of HMMs trained on one flight are worse on the other than
# the EKF's own acceleration; see the study's report.md). The diagnosis (seed 0, small): the A_H/B
# filter fed the reference's current acceleration and jerk reaches 2.34 m/s² against the EKF's
# 4.34, but fed the same exact inputs one step late 4.72; the GMR fed the exact reference state
# matches the reference 0.12 s in the past (4.57), in-sample 3.19 on the reference and 4.58 on EKF
# posteriors against the EKF's 4.46. strict: the day it passes, this marker must go.
@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="issue-14 real-data target missed on faithful data (0/17 better)")
def test_the_full_study_meets_the_real_data_acceptance(ran, tmp_path):
    r = ran(NAME, tmp_path, {"size": "small"}, _inputs()).figures
    # the precondition fails as a failure (pytest.fail raises Failed), not as the expected miss
    if r.get("flightcoach_ekf_hmm_n_maneuvers") != "17":
        pytest.fail(f"precondition: 17 labelled test maneuvers, got {r.get('flightcoach_ekf_hmm_n_maneuvers')!r}")
    assert int(r["flightcoach_ekf_hmm_acc_better_maneuvers"]) >= 12


def test_a_missing_flight_fails_with_one_line_naming_the_file_and_the_study(tmp_path):
    with pytest.raises(StudyError) as e:
        flightcoach_inputs(tmp_path, FLIGHTCOACH_EKF_HMM_FILES, study=NAME)
    msg = str(e.value)
    assert "\n" not in msg and str(tmp_path / FLIGHTCOACH_DIR) in msg and NAME in msg
    assert set(FLIGHTCOACH_EKF_HMM_FILES) == {"train", "test"}


def test_the_radar_is_synthesised_at_5_hz_from_the_reference_with_gaps_left_out(rng):
    from pipeline.estimate.models import STATE_COLUMNS, RadarModel
    from pipeline.studies.flightcoach_ekf_hmm import synthesise_radar

    n = 51
    st = pd.DataFrame({"t_ns": np.arange(n, dtype=np.int64) * 40_000_000})
    for i, c in enumerate(STATE_COLUMNS):
        st[c] = 100.0 + i + rng.normal(size=n)
    st.loc[10, "pos_n_m"] = np.nan                      # step 2 of the 5 Hz grid
    radar = RadarModel(site_ned_m=(0.0, 0.0, 0.0))
    t, x, z = synthesise_radar(st, radar, np.random.default_rng(1))
    assert z.shape == (11, 1, 4) and np.all(np.diff(t) == 200_000_000)
    np.testing.assert_array_equal(x, st[list(STATE_COLUMNS)].to_numpy()[::5])
    assert np.isnan(z[2]).all() and np.isfinite(np.delete(z, 2, axis=0)).all()
    # the noise is the seed-000 radar's
    np.testing.assert_allclose(radar.sigma, (1.5, 45e-6, 45e-6, 0.2))
    ok = np.delete(np.arange(11), 2)
    assert (np.abs(z[ok, 0] - radar.h(x[ok])) < 6 * np.asarray(radar.sigma)).all()


@pytest.mark.realdata
@pytest.mark.slow
def test_the_diagnosis_shows_a_sound_filter_and_a_late_gmr(tiny):
    """The study's diagnosis (issue 14): with the reference's current acceleration and jerk as its
    inputs the A_H/B filter beats the EKF on the test flight, the same exact inputs one step late
    lose that, and the GMR fed the exact reference state matches an acceleration from the past."""
    from pipeline.studies.flightcoach_ekf_hmm import DIAGNOSTICS

    f = {k: float(tiny.figures[f"flightcoach_ekf_hmm_{k}"]) for k in DIAGNOSTICS}
    ekf = float(tiny.figures["flightcoach_ekf_hmm_ekf_acc_rmse"])
    assert all(np.isfinite(v) for v in f.values())
    assert f["oracle_input_acc_rmse"] < 0.8 * ekf < f["late_oracle_input_acc_rmse"]
    assert -0.4 <= f["gmr_on_reference_best_offset_s"] < 0.0
    assert 0 < f["train_gmr_on_reference_acc_rmse"] < f["train_gmr_acc_rmse"]
    assert "## Diagnosis" in Path(tiny.outputs["report"]).read_text()
