"""What every report page shares: plotly figures as ``<div>``s drawn when they come near the
viewport, the Jinja2 template, the atomic write (a killed job never leaves half a page that a
scheduler would take as done)."""

from __future__ import annotations

import html
import json
import math
import os
import re
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
import pandas as pd

from ..io.atomic import write_text_atomic

#: plotly's own height when a figure sets none (the placeholder keeps the page's layout fixed)
DEFAULT_HEIGHT_PX = 450
#: plotly.js options of every figure (``responsive``: redraw when the window is resized)
PLOT_CONFIG = {"responsive": True}


def figure_div(fig, div_id: str, label: str | None = None) -> str:
    """One figure as an empty ``<div>`` of its final height and a script that registers its
    drawing function in ``window.uavpipePlots[div_id]``; nothing is drawn here.

    The page's loader (``reports/templates/_linked_axes.html.j2``) calls the function when the
    ``<div>`` comes near the viewport: a flight page holds 20 figures, and drawing them all at
    load cost seconds of the browser's main thread that nobody was looking at. The function
    takes ``(gd, edit)``: ``edit(layout)`` may change the layout before the draw (the linked
    time axis gives a late panel the range already zoomed to). The figure's JSON is plotly's
    own (``plotly.io.json.to_json_plotly``: typed arrays as base64, ``<``, ``>`` and ``/``
    escaped, so it cannot end the ``<script>``).

    The ``<div>`` is an image to assistive technology (``role="img"``) named by ``label`` (the
    panel's title, else the figure's) and the names of its traces: the plot's text lives in an
    SVG that a screen reader does not read as a caption."""
    from plotly.io.json import to_json_plotly

    d = fig.to_dict()
    lay = d.get("layout", {})
    height = lay.get("height") or lay.get("template", {}).get("layout", {}).get("height") or DEFAULT_HEIGHT_PX
    data, layout = to_json_plotly(d.get("data", [])), to_json_plotly(lay)
    title = label or (lay.get("title") or {}).get("text") or "plot"
    names = [str(t["name"]) for t in d.get("data", []) if t.get("name") and t.get("showlegend", True) is not False]
    traces = f"{len(names)} trace{'s' if len(names) != 1 else ''}"
    aria = title + (f" ({traces}: {', '.join(names[:12])}{' …' if len(names) > 12 else ''})" if names else "")
    return (f'<div id="{div_id}" class="plotly-graph-div" role="img" aria-label="{html.escape(aria, quote=True)}" '
            f'style="height:{float(height):g}px; width:100%;"></div>'
            f'<script>(window.uavpipePlots = window.uavpipePlots || {{}})["{div_id}"] = function (gd, edit) {{ '
            f'return Plotly.newPlot(gd, {data}, edit({layout}), {json.dumps(PLOT_CONFIG)}); }};</script>')


def figure_divs(figs) -> list[tuple[str, str | None]]:
    """``[(title, figure or None)]`` -> ``[(title, <div> or None)]`` (:func:`figure_div`, ids
    ``plot-<i>``; plotly.js loaded once per page)."""
    return [(title, None if f is None else figure_div(f, f"plot-{i}", title)) for i, (title, f) in enumerate(figs)]


def render(template: str | os.PathLike, **context) -> str:
    """Render a Jinja2 template file (HTML autoescaped) with ``context``."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(Path(template).parent)),
                             autoescape=jinja2.select_autoescape(["html", "j2"]))
    return env.get_template(Path(template).name).render(**context)


#: an ``<html>`` start tag without a ``lang`` attribute
_HTML_TAG = re.compile(r"<html(?![^>]*\blang=)([^>]*)>", re.I)


def relative_href(target: str | os.PathLike, page: str | os.PathLike) -> str:
    """``target`` relative to the folder of ``page`` (POSIX separators, for an href)."""
    return Path(os.path.relpath(Path(target).resolve(), Path(page).resolve().parent)).as_posix()


def with_lang(page: str, lang: str = "en") -> str:
    """``page`` with ``lang`` on its ``<html>`` element (screen readers pick the voice, the
    browser the hyphenation and spelling from it); a page that names a language keeps it."""
    return _HTML_TAG.sub(lambda m: f'<html lang="{lang}"{m.group(1)}>', page, count=1)


def write_page(page: str, out_html: str | os.PathLike) -> None:
    """Write ``page`` to ``out_html`` atomically (:func:`pipeline.io.atomic.write_text_atomic`),
    its ``<html>`` element marked English (:func:`with_lang`)."""
    write_text_atomic(out_html, with_lang(page))


def number_text(x: Any, decimals: int = 1) -> str:
    """A number for reading: ``3000.0`` -> ``3000``, ``0.20`` -> ``0.2``, at most ``decimals``
    decimals, never a ``-0``; ``–`` when not a finite number."""
    try:
        v = round(float(x), decimals)
    except (TypeError, ValueError):
        return "–"
    if not math.isfinite(v):
        return "–"
    if v == int(v):
        return str(int(v))
    return f"{v:.{decimals}f}".rstrip("0").rstrip(".")


def count_text(n: Any, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` agreeing in number: ``1 sample``, ``0 samples``, ``2 samples``
    (``plural``: an irregular plural, default ``noun + "s"``); a count that is not a number
    (``None`` from an old table's metadata) reads ``– samples``.

    Examples
    --------
    >>> count_text(1, "demo"), count_text(3, "demo"), count_text(None, "step")
    ('1 demo', '3 demos', '– steps')
    """
    try:
        k = float(n)
    except (TypeError, ValueError):
        k = float("nan")
    many = plural or noun + "s"
    if not math.isfinite(k):
        return f"– {many}"
    return f"{int(k) if k == int(k) else k} {noun if k == 1 else many}"


def vector_text(v: Any, unit: str, decimals: int = 1) -> str:
    """``[3000.0, 0.0]`` -> ``(3000, 0) m``."""
    try:
        parts = [number_text(x, decimals) for x in v]
    except TypeError:
        return "–"
    return f"({', '.join(parts)}) {unit}".rstrip()


def cell_text(v: Any) -> Any:
    """A table cell for reading: a boolean as ``yes`` or ``no`` (never Python's ``True`` or
    ``False``), any other value as it is."""
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    return v


def table_html(df: pd.DataFrame, **kw: Any) -> str:
    """``df`` as an HTML table for a report page: no index, no border, a missing value as ``–``
    and every boolean cell as ``yes``/``no`` (:func:`cell_text`); ``kw`` are further options of
    :meth:`pandas.DataFrame.to_html` (``float_format``, ``formatters``, ``classes``)."""
    out = df.copy()
    for c in out.columns:
        # bool, nullable boolean, or object columns (flags read from JSON may hold None too)
        if pd.api.types.is_bool_dtype(out[c]) or out[c].dtype == object:
            out[c] = out[c].astype(object).map(cell_text)
    return out.to_html(**{"index": False, "border": 0, "na_rep": "–", **kw})
