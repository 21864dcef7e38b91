"""The bearing-only replay's page (``results/report/bearing/<pair>.html``, issue 16).

:func:`run_bearing_report` is the ``estimate_bearing`` rule's entry point: it runs the replay
(:func:`pipeline.estimate.bearing_run.run_bearing_replay`, which writes the estimate tables) and
hands it :func:`build_bearing_page` as its page writer, so the page is built here, in the report
stage, with the template and the plot conventions of the other pages (estimate does not import
report).

The page (template ``reports/templates/bearing.html.j2``, a back link to the index, English):
the pair's settings and the scores of each estimator; then range, course and turn rate of each
estimator against the truth with the ±1σ band of its covariance, the IMM's P(CV) and the
bearings, one panel each on one linked time axis, its title on every x axis. Course and bearing
are unwrapped (degrees, :func:`unwrap_deg`), so a track through south does not jump by 360°, and
an estimate is drawn on the truth's turn. Numbers read as numbers: an offset ``(3000, 0) m``.
Like the other pages it references one local ``plotly.min.js`` by a relative URL.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import plotly.graph_objects as go

from ..estimate.bearing_run import (CONVERGED_SIGMA_DEG, BearingPair, BearingReplayResult, BearingTrack,
                                    heading_converged_s, range_error_pct_at, run_bearing_replay)
from ..estimate.models import wrap_angle
from ..io.stage import declared
from .pages import figure_divs, number_text, relative_href, render, vector_text, write_page
from .plots import break_wraps, layout

#: the page's template when a caller declares none (the rule declares it)
TEMPLATE = Path(__file__).resolve().parents[2] / "reports" / "templates" / "bearing.html.j2"
#: the x axis of every panel
TIME_TITLE = "t since the first bearing [s]"
#: one colour per estimator (and its band)
COLOURS = {"bank_cppv": "#1f77b4", "bank_mpc": "#ff7f0e", "imm": "#2ca02c"}
TRUTH_COLOUR = "black"


def estimator_label(name: str, track: BearingTrack | None = None) -> str:
    """The legend and table name of a replay estimator: ``bank_cppv`` -> ``CPPV bank (25 ranges
    × 6 courses × 1 turn rate = 150 filters)``, ``imm`` -> ``CV/CT IMM``; an unknown id as it is."""
    bank = (track.meta.get("bank") if track is not None else None) or {}

    def grid() -> str:
        try:
            return (f" ({bank['n_r']} ranges × {bank['n_theta']} courses × {bank['n_omega']} turn rate"
                    f"{'s' if int(bank['n_omega']) != 1 else ''} = {bank['n_filters']} filters)")
        except (KeyError, TypeError, ValueError):
            return ""

    if name == "bank_cppv":
        return "CPPV bank" + grid()
    if name == "bank_mpc":
        return "MPC bank" + grid()
    if name == "imm":
        ct = f" (CT mode: the CPPV bank of {bank['n_filters']} filters)" if "n_filters" in bank else ""
        return "CV/CT IMM" + ct
    return name


def _short(name: str) -> str:
    """The legend name (no grid)."""
    return {"bank_cppv": "CPPV bank", "bank_mpc": "MPC bank", "imm": "CV/CT IMM"}.get(name, name)


def _rgba(hex_colour: str, alpha: float) -> str:
    h = hex_colour.lstrip("#")
    r, g, b = (int(h[i:i + 2], 16) for i in (0, 2, 4))
    return f"rgba({r},{g},{b},{alpha})"


def unwrap_deg(angle_rad: np.ndarray, near_deg: np.ndarray | None = None) -> np.ndarray:
    """An angle history in degrees without ±180° jumps (``np.unwrap``); with ``near_deg`` (the
    truth, unwrapped, same steps) shifted by the whole turns that put it on the reference's turn
    (their median difference within ±180°), so an estimate is drawn beside the truth, not 360°
    off, and stays continuous."""
    a = np.asarray(angle_rad, dtype=np.float64)
    out = np.full(a.shape, np.nan)
    ok = np.isfinite(a)
    if not ok.any():
        return out
    out[ok] = np.degrees(np.unwrap(a[ok]))
    if near_deg is not None:
        d = np.asarray(near_deg, dtype=np.float64) - out
        d = d[np.isfinite(d)]
        if len(d):
            out = out + 360.0 * np.round(float(np.median(d)) / 360.0)
    return out


#: the range panel's axis reaches 1.2x the larger of the true range's maximum and this
#: percentile of every estimate's range (plotly's autoscale button shows all of it)
RANGE_AXIS_PERCENTILE = 95.0


def range_sigma(track: BearingTrack) -> np.ndarray:
    """The range 1σ of a track, ``sqrt(gᵀ P_pos g)`` with ``g`` the unit line of sight (the
    ``range_sigma_m`` column of its table)."""
    m, p = track.mean, track.cov
    r = np.hypot(m[:, 0], m[:, 1])
    g = m[:, :2] / np.where(r > 0, r, 1.0)[:, None]
    return np.sqrt(np.maximum(np.einsum("ki,kij,kj->k", g, p[:, :2, :2], g), 0.0))


def _band(fig: go.Figure, t: np.ndarray, mean: np.ndarray, sigma: np.ndarray, name: str, colour: str,
          floor: float | None = None) -> None:
    """``mean ± sigma`` as a filled band behind the line (nothing where sigma is not finite; the
    lower edge no lower than ``floor``: a range is never negative)."""
    ok = np.isfinite(mean) & np.isfinite(sigma)
    if not ok.any():
        return
    lo, hi = np.where(ok, mean - sigma, np.nan), np.where(ok, mean + sigma, np.nan)
    if floor is not None:
        lo = np.maximum(lo, floor)
    first, last = np.flatnonzero(ok)[[0, -1]]
    if not ok[first:last + 1].all():
        # holes inside (a wrapped angle's breaks): "tonexty" joins the edges across a hole into
        # wedges over the panel, so each run is a closed outline of its own ("toself" fills each
        # piece of a trace between gaps)
        xs, ys = [], []
        edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
        for a, b in zip(edges[::2], edges[1::2]):
            xs += [*t[a:b], *t[a:b][::-1], None]
            ys += [*hi[a:b], *lo[a:b][::-1], None]
        fig.add_trace(go.Scatter(x=xs, y=ys, mode="lines", line=dict(width=0), fill="toself",
                                 fillcolor=_rgba(colour, 0.15), legendgroup=name, name=f"{name} ±1σ",
                                 hoverinfo="skip"))
        return
    fig.add_trace(go.Scatter(x=t, y=hi, mode="lines", line=dict(width=0), legendgroup=name, showlegend=False,
                             hoverinfo="skip", name=f"{name} +1σ"))
    fig.add_trace(go.Scatter(x=t, y=lo, mode="lines", line=dict(width=0), fill="tonexty",
                             fillcolor=_rgba(colour, 0.15), legendgroup=name, name=f"{name} ±1σ",
                             hoverinfo="skip"))


def _panel(title: str, ytitle: str, height: int = 320) -> go.Figure:
    fig = go.Figure()
    fig.update_xaxes(title=TIME_TITLE)
    fig.update_yaxes(title=ytitle)
    fig.update_layout(title=title, height=height)
    return fig


def bearing_figures(bp: BearingPair, tracks: Mapping[str, BearingTrack]) -> list[tuple[str, go.Figure | None]]:
    """The page's panels ``[(title, figure or None)]``: range, course (unwrapped), turn rate
    (each estimator ±1σ against the truth), the IMM's P(CV), the bearings (measured and true,
    unwrapped). Every panel's x axis is :data:`TIME_TITLE`."""
    t = bp.t_s
    truth_course = unwrap_deg(bp.truth[:, 3])
    specs = (("Range", "range [m]", lambda tr: (np.hypot(tr.mean[:, 0], tr.mean[:, 1]), range_sigma(tr)),
              np.hypot(bp.truth[:, 0], bp.truth[:, 1]), 0.0),
             ("Course (unwrapped)", "course [°]",
              lambda tr: (unwrap_deg(tr.mean[:, 3], truth_course),
                          np.degrees(np.sqrt(np.maximum(tr.cov[:, 3, 3], 0.0)))),
              truth_course, None),
             ("Turn rate", "turn rate [°/s]",
              lambda tr: (np.degrees(tr.mean[:, 4]), np.degrees(np.sqrt(np.maximum(tr.cov[:, 4, 4], 0.0)))),
              np.degrees(bp.truth[:, 4]), None))
    out = []
    for title, ytitle, of, truth, floor in specs:
        fig = _panel(f"{title}: estimates ±1σ (their covariance) and the truth", ytitle)
        for e, tr in tracks.items():
            c = COLOURS.get(e, "#7f7f7f")
            mean, sig = of(tr)
            _band(fig, t, mean, sig, _short(e), c, floor)
            fig.add_trace(go.Scatter(x=t, y=mean, mode="lines", name=_short(e), legendgroup=_short(e),
                                     line=dict(color=c)))
        fig.add_trace(go.Scatter(x=t, y=truth, mode="lines", name="truth", line=dict(color=TRUTH_COLOUR)))
        if title == "Range":
            # a bank's first seconds can reach 10x the true range (its widest filters): scaled to
            # them, the truth and the converged estimates were a flat line at the bottom
            est = np.concatenate([np.hypot(tr.mean[:, 0], tr.mean[:, 1]) for tr in tracks.values()] or [np.zeros(0)])
            est = est[np.isfinite(est)]
            top = max(np.nanmax(truth) if np.isfinite(truth).any() else 0.0,
                      float(np.percentile(est, RANGE_AXIS_PERCENTILE)) if len(est) else 0.0)
            if top > 0:
                fig.update_yaxes(range=[0.0, 1.2 * top])
        out.append((title, layout(fig, fig.layout.title.text, height=340)))
        if title.startswith("Course"):
            # each estimate and the truth unwrapped on their own drift whole turns apart (a spin
            # of the aerobatic intruder): the error itself, wrapped, reads without that ambiguity
            fig = _panel("Course error: estimate − truth, wrapped to ±180°, ±1σ (its covariance)",
                         "course error [°]", height=300)
            for e, tr in tracks.items():
                c = COLOURS.get(e, "#7f7f7f")
                # a hole where the wrapped error jumps across ±180°, not a stroke over the panel
                d = break_wraps(pd.DataFrame({"t_s": t, "v": np.degrees(wrap_angle(tr.mean[:, 3] - bp.truth[:, 3])),
                                              "s": np.degrees(np.sqrt(np.maximum(tr.cov[:, 3, 3], 0.0)))}))
                te, err = d["t_s"].to_numpy(), d["v"].to_numpy()
                _band(fig, te, err, d["s"].to_numpy(), _short(e), c)
                fig.add_trace(go.Scatter(x=te, y=err, mode="lines", name=_short(e), legendgroup=_short(e),
                                         line=dict(color=c)))
            fig.update_yaxes(range=[-180, 180], tickvals=[-180, -90, 0, 90, 180])
            out.append(("Course error", layout(fig, fig.layout.title.text, height=300)))
    imm = {e: tr for e, tr in tracks.items() if tr.mode_p is not None}
    if imm:
        fig = _panel("IMM mode probability P(CV)", "P(CV) [1]")
        for e, tr in imm.items():
            fig.add_trace(go.Scatter(x=t, y=tr.mode_p[:, 0], mode="lines", name=f"{_short(e)}: P(CV)",
                                     line=dict(color=COLOURS.get(e, "#7f7f7f"))))
        fig.update_yaxes(range=[0, 1])
        out.append(("IMM mode probability", layout(fig, fig.layout.title.text, height=280)))
    else:
        out.append(("IMM mode probability (no IMM in this replay)", None))
    b0 = unwrap_deg(bp.bearing_true)
    fig = _panel("Bearings (unwrapped)", "bearing [°]")
    fig.add_trace(go.Scatter(x=t, y=unwrap_deg(bp.bearing, b0), mode="markers",
                             name="measured", marker=dict(size=3, color="grey")))
    fig.add_trace(go.Scatter(x=t, y=b0, mode="lines", name="true", line=dict(color=TRUTH_COLOUR, width=1)))
    out.append(("Bearings", layout(fig, fig.layout.title.text, height=300)))
    return out


def _facts(pair: str, bp: BearingPair | None, info: Mapping) -> list[tuple[str, str]]:
    settings = dict(info.get("settings") or {})
    facts = [("pair", pair)]
    if info.get("ownship") or info.get("intruder"):
        facts.append(("flights", f"ownship {info.get('ownship', '–')}, intruder {info.get('intruder', '–')}"))
    if info.get("track"):
        facts.append(("ownship track", {"local_position": "the autopilot's local position (ingest)",
                                        "state": "the preprocessed state"}.get(info["track"],
                                                                                            str(info["track"]))))
    m = bp.meta if bp is not None else settings
    if bp is not None:
        facts.append(("bearings", f"{m['n_bearings']} synthetic bearings, "
                                  f"σ = {number_text(m['sigma_bearing_deg'], 3)}°, bias {number_text(m['bias_deg'], 3)}°, median step "
                                  f"{number_text(m['median_dt_s'], 3)} s (at most {number_text(m['rate_hz'])} Hz)"))
    if "offset_m" in m:
        facts.append(("intruder offset", f"{vector_text(m['offset_m'], 'm')} (north, east)"))
    if "t_offset_s" in m or "duration_s" in m:
        facts.append(("time", f"intruder at ownship t + {number_text(m.get('t_offset_s'))} s, first "
                              f"{number_text(m.get('duration_s'))} s"))
    if bp is not None:
        facts.append(("truth turn rate", str(m.get("truth_omega", "–"))))
        facts.append(("noise seed", str(m.get("noise_seed", "–"))))
    return facts


SCORE_HEADERS = ["estimator", f"heading converged (course 1σ < {CONVERGED_SIGMA_DEG:g}°) [s]",
                 "range error at 60 s [%]", "filters diverged (end)"]


def _scores(bp: BearingPair, tracks: Mapping[str, BearingTrack]) -> list[list[str]]:
    rows = []
    truth_r = np.hypot(bp.truth[:, 0], bp.truth[:, 1])
    for e, tr in tracks.items():
        conv = heading_converged_s(bp.t_s, np.sqrt(np.maximum(tr.cov[:, 3, 3], 0.0)))
        err = range_error_pct_at(bp.t_s, np.hypot(tr.mean[:, 0], tr.mean[:, 1]), truth_r)
        div = int(np.asarray(tr.n_diverged)[-1]) if len(tr.n_diverged) else 0
        rows.append([estimator_label(e, tr), "never" if not np.isfinite(conv) else number_text(conv),
                     number_text(err), str(div)])
    return rows


def build_bearing_page(out_html: str | os.PathLike, pair: str, bp: BearingPair | None,
                       tracks: Mapping[str, BearingTrack], reason: str | None = None, info: Mapping | None = None,
                       *, template: str | os.PathLike = TEMPLATE, plotly_js: str = "../assets/plotly.min.js",
                       index_href: str = "../../index.html") -> None:
    """Render one pair's page (module docstring) to ``out_html``; a skipped or failed pair
    (``bp`` None) says why under the title. ``info``: the replay's ``flights``, ``track``,
    ``settings`` and ``status``; ``plotly_js`` and ``index_href`` are relative to the page."""
    info = dict(info or {})
    figs = bearing_figures(bp, tracks) if bp is not None else []
    divs = figure_divs(figs)
    status = str(info.get("status") or ("ok" if bp is not None else "skipped"))
    page = render(template, pair=pair, status=status.capitalize(), reason=reason, facts=_facts(pair, bp, info),
                  scores=_scores(bp, tracks) if bp is not None else [], score_headers=SCORE_HEADERS, plots=divs,
                  linked=[f"plot-{i}" for i, (_, f) in enumerate(figs) if f is not None], plotly_js=plotly_js,
                  index_href=index_href)
    write_page(page, out_html)


def run_bearing_report(inputs: Mapping | Any, outputs: Mapping | Any, config: Mapping | None, *, pair: str,
                       seed: int = 0, index: str | os.PathLike | None = None, **job) -> BearingReplayResult:
    """The ``estimate_bearing`` rule: the replay of ``pair``
    (:func:`pipeline.estimate.bearing_run.run_bearing_replay`, its tables) and its page
    ``outputs.page`` (:func:`build_bearing_page`).

    ``inputs``: the replay's, ``template`` (``reports/templates/bearing.html.j2``; default
    :data:`TEMPLATE`) and ``plotly`` (``results/report/assets/plotly.min.js``). ``index``: the
    index page for the back link (default ``results/index.html`` two folders above the page:
    ``../../index.html``)."""
    template = declared(inputs, "template") or TEMPLATE
    plotly = declared(inputs, "plotly")

    def write(path: Path, pair_: str, bp: BearingPair | None, tracks: Mapping[str, BearingTrack],
              reason: str | None, info: dict) -> None:
        build_bearing_page(path, pair_, bp, tracks, reason, info, template=template,
                           plotly_js=relative_href(plotly, path) if plotly else "../assets/plotly.min.js",
                           index_href=relative_href(index, path) if index else "../../index.html")

    return run_bearing_replay(inputs, outputs, config, pair=pair, seed=seed, write_page=write, **job)
