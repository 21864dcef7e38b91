"""The tables of the model and trajectory-learning pages read as words (report audit): a flag is
``yes``/``no``, never Python's ``True``/``False``, through one cell formatter
(:func:`pipeline.report.pages.table_html`)."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd


ROOT = Path(__file__).resolve().parents[2]


def _cells(page: str, title: str) -> list[list[str]]:
    """The body cells of the table under the ``<h2>`` that starts with ``title``."""
    text = page[page.index(f"<h2>{title}"):]
    table = text[text.index("<table"):text.index("</table>")]
    body = table[table.index("<tbody>"):] if "<tbody>" in table else table
    return [[html.unescape(c).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)]
            for row in re.findall(r"<tr[^>]*>(.*?)</tr>", body, re.S)]


def test_a_boolean_table_cell_reads_yes_or_no_and_a_missing_one_a_dash():
    from pipeline.report.pages import cell_text, table_html

    df = pd.DataFrame({"converged": [True, False, True], "flag": pd.array([True, None, False], dtype="boolean"),
                       "json": [np.True_, None, False], "n": [1, 2, 3], "x": [0.5, np.nan, 2.0]})
    out = table_html(df, float_format="%.1f")
    assert "True" not in out and "False" not in out and "None" not in out and "NaN" not in out
    rows = [[c for c in re.findall(r"<td>(.*?)</td>", r)] for r in re.findall(r"<tr>(.*?)</tr>", out, re.S)]
    assert rows == [["yes", "yes", "yes", "1", "0.5"], ["no", "–", "–", "2", "–"], ["yes", "no", "no", "3", "2.0"]]
    assert cell_text(np.False_) == "no" and cell_text(1) == 1 and cell_text("True") == "True"


def test_the_model_pages_training_table_says_whether_each_maneuver_converged_in_words(tmp_path):
    from pipeline.report.model import build_model_report

    d = tmp_path / "m"
    d.mkdir()
    n = 2
    np.savez(d / "params.npz", m0_startprob=np.full(n, 0.5), m0_transmat=np.full((n, n), 0.5),
             m0_means=np.zeros((n, 1, 3)), m1_startprob=np.full(n, 0.5), m1_transmat=np.full((n, n), 0.5),
             m1_means=np.zeros((n, 1, 3)))
    training = {lab: {"n_states": n, "n_iter": 4, "converged": conv, "n_recordings": 3, "n_sequences": 3,
                      "n_samples": 300, "history": [-900.0, -800.0], "threshold": -5.0}
                for lab, conv in (("loop", True), ("roll", False))}
    (d / "meta.json").write_text(json.dumps({"name": "m", "status": "ok", "labels": ["loop", "roll"],
                                             "training": training, "feature_names": ["a", "b", "c"],
                                             "config": {"rate_hz": 10}, "spec": {"data": "simulated"}}))
    build_model_report(d, d / "evaluation.parquet", tmp_path / "m.html",
                       template=ROOT / "reports" / "templates" / "model.html.j2", plotly_js="plotly.min.js")
    rows = _cells((tmp_path / "m.html").read_text(), "Training")
    assert [(r[0], r[3]) for r in rows] == [("loop", "yes"), ("roll", "no")]


def test_the_align_pages_maneuver_table_says_whether_each_maneuver_converged_in_words(tmp_path):
    from helpers_align import synthetic_align_page

    page = synthetic_align_page(tmp_path, [(0, 8, "a"), (8, 16, "b")], 500)
    head = [html.unescape(h) for h in re.findall(r"<th>(.*?)</th>", page[page.index("<h2>Maneuvers"):])]
    k = head.index("converged")
    rows = _cells(page, "Maneuvers")
    assert rows and all(r[k] in ("yes", "no") for r in rows), rows
    # max_iter 2: two E-steps whether or not the second converged (the table read the last index, 1)
    n = head.index("EM iterations (E-steps)")
    assert all(r[n] == "2" for r in rows), rows
    assert ">True<" not in page and ">False<" not in page


def test_the_model_pages_test_flights_table_has_no_empty_thesis_columns(tmp_path):
    from pipeline.io import schema
    from pipeline.io.parquet import write_table
    from pipeline.report.model import build_model_report

    d = tmp_path / "m"
    d.mkdir()
    (d / "meta.json").write_text(json.dumps({"name": "m", "status": "ok", "labels": [], "training": {},
                                             "config": {}, "spec": {"data": "flights"}}))
    np.savez(d / "params.npz")
    ev = pd.DataFrame({"table": "flights", "maneuver": ["loop", "roll"], "n_runs": [1, 2], "FA_pct": [100.0, 50.0],
                       "MAoT_pct": [91.4, 43.2], "thesis_FA_pct": np.nan, "thesis_MAoT_pct": np.nan,
                       "split": "test flights", "decision": "both"})
    write_table(ev[list(schema.EVAL_COLUMNS)], d / "evaluation.parquet", schema.MODEL_EVALUATION, name="model_evaluation")
    build_model_report(d, d / "evaluation.parquet", tmp_path / "m.html",
                       template=ROOT / "reports" / "templates" / "model.html.j2", plotly_js="plotly.min.js")
    page = (tmp_path / "m.html").read_text()
    text = page[page.index("<h2>Test flights"):]
    head = [html.unescape(h) for h in re.findall(r"<th>(.*?)</th>", text[:text.index("</table>")])]
    assert head == ["maneuver", "runs", "FA [%]", "MAoT [%]"]      # no "seed 000 §11" columns of dashes
    assert _cells(page, "Test flights") == [["loop", "1", "100.00", "91.40"], ["roll", "2", "50.00", "43.20"]]
