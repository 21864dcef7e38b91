"""Flight-page panels of the particle filters (issue 17): mode fractions beside the classifier."""

import numpy as np
import pandas as pd

from pipeline.estimate.pf_run import pf_frame, write_pf
from pipeline.io import schema
from pipeline.report.flight import estimate_panels


def _pf_table(path, with_cls=True):
    T = 50
    mode_p = np.tile([0.6, 0.3, 0.1], (T, 1))
    extra = {"cls_p_M1": np.full(T, 0.8), "cls_p_M2": np.full(T, 0.2)} if with_cls else {}
    df = pf_frame(np.arange(T, dtype=np.int64) * 100_000_000, np.zeros((T, 7)), np.zeros((T, 7, 7)), mode_p,
                  np.full(T, 100.0), np.zeros(T, bool), extra=extra)
    write_pf(df, path, {"status": "ok", "n_steps": T, "n_particles": 100, "n_resampled": 0, "resample": "systematic",
                        "threshold": 1 / 3, "n_predict_only": 0, "n_reinit": 0, "classifier": "sim" if with_cls else None,
                        "mode_fraction_mean": {"cv": 0.6, "ca": 0.3, "ct": 0.1}})


def test_the_pf_panel_stacks_the_mode_fractions_beside_the_classifier_softmax(tmp_path):
    p = tmp_path / "pf_jm" / "f.parquet"
    p.parent.mkdir()
    _pf_table(p)
    figs, facts = estimate_panels({"pf_jm": p}, truth=None, state=None)
    title, fig = figs[-1]
    assert title == "jump-Markov PF mode fractions" and fig is not None
    stacked = [t for t in fig.data if t.stackgroup == "modes"]
    assert [t.name for t in stacked] == ["jump-Markov PF: CV", "jump-Markov PF: CA", "jump-Markov PF: CT"]
    assert {t.name for t in fig.data if t.yaxis == "y2"} == {"classifier: M1", "classifier: M2"}
    assert any(k == "jump-Markov PF" and "classifier sim" in v for k, v in facts)


def test_a_pf_placeholder_keeps_a_titled_empty_panel_with_its_reason(tmp_path):
    p = tmp_path / "pf_jm" / "f.parquet"
    p.parent.mkdir()
    write_pf(schema.empty("pf"), p, {"status": "failed", "error": "no position in the state table"})
    figs, facts = estimate_panels({"pf_jm": p}, truth=None, state=None)
    assert ("jump-Markov PF mode fractions (placeholder: no position in the state table)", None) in figs
    assert ("jump-Markov PF", "placeholder: no position in the state table") in facts


def test_pf_tables_never_enter_the_error_panels_of_the_kalman_estimators(tmp_path):
    p = tmp_path / "pf_jm" / "f.parquet"
    p.parent.mkdir()
    _pf_table(p, with_cls=False)
    figs, _ = estimate_panels({"pf_jm": p}, truth=pd.DataFrame(), state=None)
    assert figs[0] == ("Estimates (the flight's vehicle is not in estimate.vehicles)", None)
    assert figs[-1][1] is not None and not [t for t in figs[-1][1].data if t.yaxis == "y2"]


def test_the_flight_pages_classification_is_put_beside_a_pf_table_without_one(tmp_path):
    p = tmp_path / "pf_jm" / "f.parquet"
    p.parent.mkdir()
    _pf_table(p, with_cls=False)
    from pipeline.io.parquet import write_table

    cls = pd.DataFrame({"run_id": "0", "t_ns": np.arange(0, 5_000_000_000, 200_000_000, dtype=np.int64),
                        "ll_M1": -2.0, "ll_M2": -2.0})
    cp = tmp_path / "f.parquet"
    write_table(cls, cp, name="classification", extra={"status": "ok"})
    figs, facts = estimate_panels({"pf_jm": p}, truth=None, state=None, classified={"sim": cp})
    fig = figs[-1][1]
    right = [t for t in fig.data if t.yaxis == "y2"]
    assert {t.name for t in right} == {"classifier: M1", "classifier: M2"}
    assert np.allclose(right[0].y, 0.5)
    assert any(k == "jump-Markov PF" and "classifier sim" in v for k, v in facts)
