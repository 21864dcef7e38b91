"""Per-model HTML report: HMM states, transition matrices, training log-likelihood curves and
the FA / MAoT tables beside seed 000's values.

Reads only the model directory (``params.npz``, ``meta.json``, written by
:meth:`pipeline.models.classifier.ManeuverModelSet.save` or a failed-model placeholder) and the
evaluation table of :func:`pipeline.models.run.evaluate_model`. Like the flight reports it
references one local ``plotly.min.js`` by a relative URL, so it opens offline from ``file://``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from ..io.parquet import read_table, read_table_meta
from .glossary import glossary_rows
from .pages import count_text, figure_divs, render, table_html, write_page
from .plots import label_colours, layout


def training_curves(training: dict) -> go.Figure | None:
    """Baum-Welch log-likelihood per iteration, one line per maneuver model."""
    fig = go.Figure()
    colours = label_colours(training)   # 16 F3A models: plotly's 10 default colours repeat
    for lab, t in training.items():
        h = t.get("history") or []
        if h:
            fig.add_trace(go.Scatter(x=np.arange(1, len(h) + 1), y=h, mode="lines+markers", name=str(lab),
                                     line=dict(color=colours[str(lab)])))
    if not fig.data:
        return None
    fig.update_xaxes(title="Baum-Welch iteration")
    fig.update_yaxes(title="training log-likelihood")
    return layout(fig, "Training log-likelihood")


def hmm_figure(label: str, startprob: np.ndarray, transmat: np.ndarray, means: np.ndarray,
               feature_names: list[str]) -> go.Figure:
    """Transition matrix ``a_ij`` and the state means (normalised features) of one HMM."""
    n = len(startprob)
    states = [f"s{i}" for i in range(n)]
    fig = make_subplots(rows=1, cols=2, column_widths=[0.4, 0.6], horizontal_spacing=0.12,
                        subplot_titles=("transition matrix a_ij (row i → column j)",
                                        "state means (normalised features)"))
    fig.add_trace(go.Heatmap(z=transmat, x=states, y=states, colorscale="Blues", zmin=0, zmax=1,
                             text=np.round(transmat, 2), texttemplate="%{text}", showscale=False,
                             name="a_ij"), row=1, col=1)
    fig.add_trace(go.Heatmap(z=means, x=feature_names or [f"f{j}" for j in range(means.shape[1])],
                             y=[f"{s} (π={p:.2f})" for s, p in zip(states, startprob)],
                             colorscale="RdBu", zmid=0.5, colorbar=dict(title="mean"), name="means"),
                  row=1, col=2)
    fig.update_yaxes(autorange="reversed", row=1, col=1)
    fig.update_yaxes(autorange="reversed", row=1, col=2)
    return layout(fig, f"HMM of {label}: {count_text(n, 'state')}", height=340 + 12 * n, margin=dict(l=60, r=20, t=90, b=80))


#: display names of the evaluation table's columns (the seed's values cited by section)
_EVAL_COLUMNS = {"n_runs": "runs", "FA_pct": "FA [%]", "MAoT_pct": "MAoT [%]",
                 "thesis_FA_pct": "FA [%], seed 000 §11", "thesis_MAoT_pct": "MAoT [%], seed 000 §11"}


def _table_html(df: pd.DataFrame) -> str:
    fmt = {_EVAL_COLUMNS.get(c, c): (lambda v: "–" if pd.isna(v) else f"{v:.2f}")
           for c in df.columns if c.endswith("_pct")}
    return table_html(df.rename(columns=_EVAL_COLUMNS), classes="eval", formatters=fmt)


def build_model_report(model_dir: str | os.PathLike, evaluation: str | os.PathLike,
                       out_html: str | os.PathLike, *, template: str | os.PathLike, plotly_js: str,
                       index_href: str = "../../index.html") -> None:
    """Render one model's report.

    Parameters
    ----------
    model_dir : path-like
        ``results/models/<model>/`` with ``params.npz`` and ``meta.json``.
    evaluation : path-like
        ``results/models/<model>/evaluation.parquet``.
    out_html : path-like
        Output page.
    template : path-like
        Jinja2 template (``reports/templates/model.html.j2``).
    plotly_js : str
        URL of plotly.min.js relative to the page.
    """
    d = Path(model_dir)
    meta = json.loads((d / "meta.json").read_text())
    name = meta.get("name") or d.name
    failed = meta.get("status") == "failed"
    figs, tables, facts = [], [], []
    spec = meta.get("spec") or {}
    facts.append(("training data", spec.get("data", "?")))
    facts.append(("classifies vehicles", ", ".join(spec.get("vehicles", [])) or "–"))
    if not failed:
        z = np.load(d / "params.npz", allow_pickle=False)
        labels = list(meta.get("labels", []))
        training = meta.get("training", {})
        cfg = meta.get("config", {})
        facts += [("maneuvers", ", ".join(labels)), ("feature set", cfg.get("feature_set")),
                  ("model rate", f"{cfg.get('rate_hz')} Hz"), ("decision", cfg.get("decision")),
                  # the one-class rule the decision uses (pipeline.models.classifier, module docstring)
                  ("one-class threshold", "θ_m(n) = f q_m(n) + (1 − f) n l_m − s n with f = "
                   f"{meta.get('threshold_fraction', 1.0):g}, s = {meta.get('threshold_slack', 0.0):g} nats/sample "
                   "(q_m: training percentile curve; l_m: mean per-sample LL of the other training maneuvers)"),
                  ("mode", cfg.get("mode")), ("seed", cfg.get("seed")), ("code version", meta.get("code_version"))]
        figs.append(("Training log-likelihood", training_curves(training)))
        for i, lab in enumerate(labels):
            figs.append((f"HMM {lab}", hmm_figure(lab, z[f"m{i}_startprob"], z[f"m{i}_transmat"],
                                                  z[f"m{i}_means"][:, 0], meta.get("feature_names", []))))
        rows = [{"maneuver": lab, "states": t.get("n_states"), "iterations": t.get("n_iter"),
                 "converged": t.get("converged"), "recordings": t.get("n_recordings"),
                 "sequences": t.get("n_sequences"), "samples": t.get("n_samples"),
                 "final LL": (t.get("history") or [float("nan")])[-1], "threshold": t.get("threshold")}
                for lab, t in training.items()]
        tables.append(("Training", table_html(pd.DataFrame(rows), float_format="%.1f")))
    ev = read_table(evaluation) if Path(evaluation).exists() else pd.DataFrame()
    if len(ev):
        for (table, split, decision), g in ev.groupby(["table", "split", "decision"], sort=False):
            title = (f"Table {table} ({split} set, {decision} classifier) — ours beside seed 000 §11 (thesis Table {table})"
                     if table != "flights" else f"Test flights ({decision} classifier), one run per labelled segment")
            g = g.drop(columns=["table", "split", "decision"])
            if table == "flights":      # the thesis has no number for a real flight's segment
                g = g.drop(columns=[c for c in ("thesis_FA_pct", "thesis_MAoT_pct") if c in g and g[c].isna().all()])
            tables.append((title, _table_html(g)))
    elif not failed:
        ev_meta = read_table_meta(evaluation) if Path(evaluation).exists() else {}
        tables.append(("Evaluation", f"<p class='absent'>no evaluation data {ev_meta.get('error') or ''}</p>"))
    divs = figure_divs(figs)
    # every metric the page shows, defined once with its seed section (FA, MAoT, LL, V, ...)
    shown = " ".join([*(f"{k} {v}" for k, v in facts), *(f"{t} {h}" for t, h in tables),
                      *(f.layout.title.text or "" for _, f in figs if f is not None)])
    page = render(template,
        model=name, facts=facts, plots=divs, tables=tables, plotly_js=plotly_js, index_href=index_href,
        failed=failed, error=meta.get("error"), glossary=glossary_rows(shown))
    write_page(page, out_html)
