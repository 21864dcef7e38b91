"""Model and study pages define every metric they show in one sentence and cite the seed
section (issue 13, item 4)."""

from __future__ import annotations

import html
import re
from pathlib import Path

from pipeline.report.glossary import METRICS, glossary_rows, metrics_in

ROOT = Path(__file__).resolve().parents[2]


def test_each_metric_is_one_sentence_citing_a_seed_section():
    for m in METRICS:
        assert m.sentence.endswith(".") and m.sentence.count(". ") == 0, m.name   # one sentence
        assert re.match(r"^seed 00[0-4] §\d", m.cite), m.cite
        assert "thesis" not in m.sentence.lower()


def test_a_metric_is_found_by_its_name_inside_result_names_but_not_inside_words():
    names = [m.name for m in metrics_in("seed000_cf_test_min_FA_pct and <td>MAoT_pct</td>; acc_rmse_mps2")]
    assert names == ["FA", "MAoT", "RMSE"]
    assert metrics_in("FAIL, finish, all, code version 91c2") == []
    assert [m.name for m in metrics_in("seed000_1c_test_min_FA_pct")] == ["FA", "one-class"]


def test_a_study_page_defines_the_metrics_of_its_results_and_report(tmp_path):
    from pipeline.report.study import build_study_page

    (tmp_path / "results.txt").write_text("RESULT s_test_min_FA_pct 100.00\nRESULT s_ekf_acc_rmse 0.31\n")
    (tmp_path / "report.md").write_text("# Tables\n\n| maneuver | NEES |\n|---|---|\n| M1 | 9.1 |\n")
    page = tmp_path / "s.html"
    build_study_page("s", page, results=tmp_path / "results.txt", report_md=tmp_path / "report.md",
                     template=ROOT / "reports" / "templates" / "study.html.j2")
    text = html.unescape(page.read_text())
    assert "Metrics on this page" in text
    for name, _, sentence, cite in glossary_rows("FA RMSE NEES"):
        assert sentence in text and cite in text, name
    assert "MAoT (mean accuracy over time)" not in text        # not shown, not defined
    assert "the thesis" not in text
