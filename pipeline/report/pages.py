"""What every report page shares: plotly figures as ``<div>``s, the Jinja2 template, the
atomic write (a killed job never leaves half a page that a scheduler would take as done)."""

from __future__ import annotations

import os
from pathlib import Path

import jinja2


def figure_divs(figs) -> list[tuple[str, str | None]]:
    """``[(title, figure or None)]`` -> ``[(title, <div> or None)]`` (plotly.js loaded once per page)."""
    return [(title, None if f is None else f.to_html(full_html=False, include_plotlyjs=False,
                                                      div_id=f"plot-{i}", config={"responsive": True}))
            for i, (title, f) in enumerate(figs)]


def render(template: str | os.PathLike, **context) -> str:
    """Render a Jinja2 template file (HTML autoescaped) with ``context``."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(Path(template).parent)),
                             autoescape=jinja2.select_autoescape(["html", "j2"]))
    return env.get_template(Path(template).name).render(**context)


def write_page(page: str, out_html: str | os.PathLike) -> None:
    """Write ``page`` to ``out_html`` atomically (temporary file beside it, then rename)."""
    out = Path(out_html)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(page)
    os.replace(tmp, out)
