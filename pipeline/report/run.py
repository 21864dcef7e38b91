"""Entry points of the report stage: flight pages, model-set pages, the index, plotly.js.

Each takes the declared ``inputs``/``outputs`` paths (Snakemake's namedlists or plain dicts),
the ``report`` config (unused today, kept for the one signature) and per-job values; links
between pages are made relative to the page written, so the tree opens from ``file://``.
"""

from __future__ import annotations

import os
import sys
from html import escape
from pathlib import Path
from typing import Mapping

from ..io.stage import declared, declared_list, one_line
from .compare import build_compare_page
from .flight import build_flight_report, write_plotly_js
from .index import build_index
from .model import build_model_report
from .pages import relative_href, write_page






def _model_set_of(classification: str) -> str:
    # results/classify/<model_set>/<flight>.parquet
    return Path(classification).parent.name


def run_plotly_js(inputs, outputs, config: Mapping | None = None) -> None:
    """Copy plotly's bundled ``plotly.min.js`` to ``outputs.js`` (one local copy for every page)."""
    write_plotly_js(declared(outputs, "js"))


def run_flight_report(inputs, outputs, config: Mapping | None = None, *, index: str,
                      vehicle: str | None = None) -> None:
    """One flight's page ``outputs.page``.

    ``inputs``: ``meta`` (ingest ``meta.json``, its streams beside it), ``state``, ``segments``,
    ``calibration``, ``classified`` (``results/classify/<model_set>/<flight>.parquet`` for each
    model set that classifies the flight), ``estimates`` (``results/estimate/<estimator>/<flight>.parquet``,
    none when the flight is not estimated), ``template``, ``plotly``. ``index``: the path of the
    index page, for the back link; ``vehicle``: the manifest's, for the summary table.
    """
    page = declared(outputs, "page")
    ingest_dir = Path(declared(inputs, "meta")).parent
    try:
        build_flight_report(ingest_dir, page, template=declared(inputs, "template"),
                            plotly_js=relative_href(declared(inputs, "plotly"), page),
                            index_href=relative_href(index, page),
                            state=declared(inputs, "state"), segments=declared(inputs, "segments"),
                            calibration=declared(inputs, "calibration"),
                            classified={_model_set_of(p): p for p in declared_list(inputs, "classified")},
                            estimates={Path(p).parent.name: p for p in declared_list(inputs, "estimates")},
                            vehicle=vehicle)
    except Exception as exc:  # one flight's unreadable table must not cost the index its page
        reason = f"{type(exc).__name__}: {one_line(exc)}"[:500]
        print(f"uavpipe report: {ingest_dir.name}: page not built: {reason}", file=sys.stderr)
        failure_page(page, ingest_dir.name, reason, relative_href(index, page))


def failure_page(out_html: str | os.PathLike, flight: str, reason: str, index_href: str) -> None:
    """A flight page that says, in one line, why the real one could not be built (a damaged
    stream or derived table), with the link back to the index; no plots, no script."""
    write_page(f"<!doctype html><html><head><meta charset='utf-8'><title>{escape(flight)}: page not built</title>"
               f"</head><body style='font-family:system-ui,sans-serif;margin:2em'>"
               f"<p><a href='{escape(index_href)}'>&larr; all flights</a></p><h1>{escape(flight)}</h1>"
               f"<p class='reason' style='color:#b00020'>The page could not be built: {escape(reason)}</p>"
               f"<p>The flight's tables are under <code>results/</code>; rerun its jobs after fixing the input.</p>"
               f"</body></html>", out_html)


def run_compare_report(inputs, outputs, config: Mapping | None = None, *, vehicle: str,
                       flights: list[str], index: str) -> None:
    """The comparison page ``outputs.page`` of ``vehicle``'s ``flights``.

    ``inputs``: ``metas``, ``states``, ``params`` (one per flight, in ``flights`` order: the
    ingest ``meta.json``, ``results/state/<flight>.parquet``, the ingest ``params`` stream),
    ``template``, ``plotly``. Flight names link to their pages beside the page's folder
    (``results/report/flights/<flight>.html``)."""
    page = declared(outputs, "page")
    flights_dir = Path(page).parent.parent / "flights"
    build_compare_page(vehicle, flights, page, metas=declared_list(inputs, "metas"),
                       states=declared_list(inputs, "states"), params=declared_list(inputs, "params"),
                       template=declared(inputs, "template"), plotly_js=relative_href(declared(inputs, "plotly"), page),
                       index_href=relative_href(index, page),
                       flight_links={f: relative_href(flights_dir / f"{f}.html", page) for f in flights})


def run_model_report(inputs, outputs, config: Mapping | None = None, *, index: str) -> None:
    """One model set's page ``outputs.page`` from ``inputs.params``/``meta``/``evaluation``."""
    page = declared(outputs, "page")
    build_model_report(Path(declared(inputs, "params")).parent, declared(inputs, "evaluation"), page,
                       template=declared(inputs, "template"), plotly_js=relative_href(declared(inputs, "plotly"), page),
                       index_href=relative_href(index, page))


def run_index(inputs, outputs, config: Mapping | None = None, *, flights: list[str],
              model_sets: list[str], studies: list[str] = (), vehicles: Mapping[str, str] | None = None,
              skipped: Mapping[str, str] | None = None, align_sets: list[str] = (),
              bearing_pairs: list[str] = ()) -> None:
    """The index page ``outputs.index``.

    ``inputs``: ``metas`` and ``pages`` (one per flight, in ``flights`` order), ``segments``
    (idem), ``classified`` (``results/classify/<model_set>/<flight>.parquet``), ``models``
    (one page per model set, in ``model_sets`` order), ``compare`` (``results/report/compare/<vehicle>.html``,
    one per vehicle of ``vehicles``). ``studies``: study names, linked to
    ``report/studies/<name>.html`` beside the index's ``report/`` folder. ``vehicles``:
    ``{flight: vehicle}``; ``skipped``: manifest rows left out, ``{flight: reason}``. ``align_sets``:
    the trajectory-learning demo sets, their pages in ``inputs.align`` (same order). ``bearing_pairs``: the bearing-only replay pairs, their pages in
    ``inputs.bearing`` (same order).
    """
    out = declared(outputs, "index")
    classified: dict[str, dict[str, str]] = {}
    for p in declared_list(inputs, "classified"):
        classified.setdefault(Path(p).stem, {})[_model_set_of(p)] = p
    build_index(flights, declared_list(inputs, "metas"), out,
                links={f: relative_href(p, out) for f, p in zip(flights, declared_list(inputs, "pages"))},
                segments=dict(zip(flights, declared_list(inputs, "segments"))), classified=classified,
                models={m: relative_href(p, out) for m, p in zip(model_sets, declared_list(inputs, "models"))},
                studies={s: f"report/studies/{s}.html" for s in studies}, vehicles=vehicles,
                compare={Path(p).stem: relative_href(p, out) for p in declared_list(inputs, "compare")},
                skipped=skipped,
                align={s: relative_href(p, out) for s, p in zip(align_sets, declared_list(inputs, "align"))},
                bearing={b: relative_href(p, out) for b, p in zip(bearing_pairs, declared_list(inputs, "bearing"))})
