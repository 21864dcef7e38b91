"""The study page: markdown subset converter, RESULT parsing, and the index's study links."""

from __future__ import annotations

from pipeline.report.study import markdown_to_html, read_results


def test_markdown_headings_tables_lists_and_paragraphs_become_html():
    md = "# Title\n\nSome `code` and **bold** text\ncontinued.\n\n| a | b |\n|---|---|\n| 1.50 | x<y |\n\n- one\n- two\n"
    out = markdown_to_html(md)
    assert "<h2>Title</h2>" in out
    assert "<p>Some <code>code</code> and <strong>bold</strong> text continued.</p>" in out
    assert '<div class="wide"><table><thead><tr><th>a</th><th>b</th></tr></thead>' in out   # scrolls sideways
    assert "<td class=num>1.50</td><td>x&lt;y</td>" in out
    assert "<ul><li>one</li><li>two</li></ul>" in out


def test_result_lines_are_read_by_metric(tmp_path):
    p = tmp_path / "results.txt"
    p.write_text("RESULT a 1.5\nnot a result\nRESULT b 3/4\n")
    assert read_results(p) == {"a": "1.5", "b": "3/4"}


def test_the_index_links_only_the_study_pages_that_exist_and_names_the_target_of_the_others(tmp_path):
    from pipeline.report.index import build_index

    (tmp_path / "report" / "studies").mkdir(parents=True)
    (tmp_path / "report" / "studies" / "s1.html").write_text("<html></html>")
    build_index([], [], tmp_path / "index.html", studies={"s1": "report/studies/s1.html",
                                                          "s2": "report/studies/s2.html"})
    page = (tmp_path / "index.html").read_text()
    assert '<h2>Studies</h2><ul><li><a href="report/studies/s1.html">s1</a></li>' in page
    # a study not built when the index was written is no dead link: its name and its target
    assert ('<li>s2 <span class="absent">(not built: run <code>snakemake study_s2</code>)</span></li>') in page
    assert 'href="report/studies/s2.html"' not in page
    build_index([], [], tmp_path / "index2.html")                 # without studies: as before
    assert "Studies" not in (tmp_path / "index2.html").read_text()
