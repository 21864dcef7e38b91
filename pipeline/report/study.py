"""Per-study HTML page: the headline figures (each defined in one sentence), the study's
``report.md`` rendered, and its plotly figures.

Reads the study's ``results.txt`` (``RESULT <metric> <value>`` lines) and ``report.md``; the
markdown is converted by a small converter for what the studies write (headings, pipe
tables, bullet lists, paragraphs, inline code and bold), so no markdown package is needed.
Like the other pages it references one local ``plotly.min.js`` by a relative URL and opens
offline from ``file://``.
"""

from __future__ import annotations

import html
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import plotly.graph_objects as go

from .glossary import glossary_rows
from .pages import figure_divs, render, write_page


def read_results(path: str | os.PathLike) -> dict[str, str]:
    """``{metric: value}`` of the ``RESULT <metric> <value>`` lines of a ``results.txt``."""
    out = {}
    for line in Path(path).read_text().splitlines():
        if line.startswith("RESULT "):
            parts = line.split(maxsplit=2)
            if len(parts) == 3:
                out[parts[1]] = parts[2]
    return out


def _inline(text: str) -> str:
    """Escape, then ``code`` and **bold** spans."""
    s = html.escape(text, quote=False)
    s = re.sub(r"``(.+?)``|`(.+?)`", lambda m: f"<code>{m.group(1) or m.group(2)}</code>", s)
    return re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", s)


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def markdown_to_html(md: str) -> str:
    """HTML of the markdown subset the studies write.

    Headings (``#``–``####``), pipe tables (a header row, a ``|---|`` rule, body rows),
    ``-`` bullet lists and paragraphs (consecutive non-blank lines); inline ``code`` and
    ``**bold**``. Everything else is escaped text.
    """
    lines = md.splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        s = line.strip()
        if not s:
            i += 1
            continue
        m = re.match(r"^(#{1,4})\s+(.*)$", s)
        if m:
            # the page's own h1 is the study title: report headings start one level lower
            lev = min(len(m.group(1)) + 1, 6)
            out.append(f"<h{lev}>{_inline(m.group(2))}</h{lev}>")
            i += 1
            continue
        if s.startswith("|") and i + 1 < len(lines) and re.match(r"^\|(\s*:?-+:?\s*\|)+\s*$", lines[i + 1].strip()):
            head = _cells(s)
            i += 2
            body = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                body.append(_cells(lines[i]))
                i += 1
            num = re.compile(r"^[−+-]?[\d.,]+%?$|^–$")
            th = "".join(f"<th>{_inline(c)}</th>" for c in head)
            rows = "".join("<tr>" + "".join(f'<td{" class=num" if num.match(c) else ""}>{_inline(c)}</td>'
                                            for c in r) + "</tr>" for r in body)
            # in a box that scrolls sideways: a wide study table (flightcoach_ekf_hmm's 14
            # columns) ran past the page's right edge
            out.append(f'<div class="wide"><table><thead><tr>{th}</tr></thead><tbody>{rows}</tbody></table></div>')
            continue
        if s.startswith("- "):
            items = []
            while i < len(lines) and lines[i].strip().startswith("- "):
                item = lines[i].strip()[2:]
                i += 1
                # continuation lines of a bullet are indented
                while i < len(lines) and lines[i].startswith("  ") and lines[i].strip() and \
                        not lines[i].strip().startswith("- "):
                    item += " " + lines[i].strip()
                    i += 1
                items.append(f"<li>{_inline(item)}</li>")
            out.append("<ul>" + "".join(items) + "</ul>")
            continue
        para = []
        while i < len(lines) and lines[i].strip() and not lines[i].strip().startswith(("#", "|", "- ")):
            para.append(lines[i].strip())
            i += 1
        if not para:  # a lone table row or heading-like line the rules above did not take
            para.append(s)
            i += 1
        out.append(f"<p>{_inline(' '.join(para))}</p>")
    return "\n".join(out)


def build_study_page(name: str, out_html: str | os.PathLike, *, results: str | os.PathLike,
                     report_md: str | os.PathLike, template: str | os.PathLike,
                     definitions: Mapping[str, str] | None = None,
                     figures: Sequence[tuple[str, go.Figure | None]] = (), title: str | None = None,
                     facts: Sequence[tuple[str, str]] = (), plotly_js: str = "../assets/plotly.min.js",
                     index_href: str = "../../index.html") -> None:
    """Render one study's page.

    Parameters
    ----------
    name : str
        Study name (``seed000_classification``).
    out_html : path-like
        Output page (``results/report/studies/<name>.html``).
    results, report_md : path-like
        The study's ``results.txt`` and ``report.md``.
    template : path-like
        Jinja2 template (``reports/templates/study.html.j2``).
    definitions : mapping, optional
        ``{metric: one sentence}``; a metric without one shows ``–``.
    figures : sequence of (title, Figure or None)
        Plotly figures, drawn with the page's local plotly.js.
    title : str, optional
        Page heading (default: the name).
    facts : sequence of (key, value)
        Size, seed, settings: a small table under the heading.
    plotly_js, index_href : str
        URLs relative to the page of plotly.min.js and of the index.
    """
    defs = dict(definitions or {})
    res = read_results(results)
    rows = [(k, v, defs.get(k, "–")) for k, v in res.items()]
    md = Path(report_md).read_text() if Path(report_md).exists() else ""
    # every metric the page shows (headline names, their sentences, the report, the figures),
    # defined once with its seed section
    shown = " ".join([*(" ".join(map(str, r)) for r in rows), md, *(f"{k} {v}" for k, v in facts),
                      *(f.layout.title.text or "" for _, f in figures if f is not None)])
    page = render(template, name=name, title=title or name, facts=list(facts), results=rows,
                  report=markdown_to_html(md), plots=figure_divs(figures), plotly_js=plotly_js,
                  index_href=index_href, glossary=glossary_rows(shown))
    write_page(page, out_html)


def layout(fig: go.Figure, title: str, **kw) -> go.Figure:
    """The study pages' figure layout (title, white template, legend on the right)."""
    fig.update_layout(title=title, template="plotly_white", height=kw.pop("height", 420),
                      margin=kw.pop("margin", dict(l=60, r=20, t=60, b=50)), **kw)
    return fig
