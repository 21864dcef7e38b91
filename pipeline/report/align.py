"""Per-demo-set HTML page of trajectory learning (``results/report/align/<set>.html``).

The analogues of seed 004's Figs 5.20–5.35 from the four ``results/align/<set>/`` tables: per
maneuver the learned trajectory μ_t with ±2σ (diag Σ_t) over the demos on the hidden time axis
(position, velocity, acceleration, Euler angles from the quaternion), one velocity axis before
and after alignment, the 3-D path in the box frame, the τ curves and the model-prediction error;
for the set the log-likelihood traces. A table holds the digest §10 item 7 anchors
(:mod:`pipeline.align.anchors`: peak pitch, longest time within the pitch band, cross-track
RMS) of the learned trajectory and of each demo, and the learned path's RMS distance to each
demo; another the skipped maneuvers and dropped demos with their reasons. Like the other pages it
references one local ``plotly.min.js`` by a relative URL, so it opens offline from ``file://``.
"""

from __future__ import annotations

import os
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from ..align.anchors import anchors, nearest_rms
from ..align.demos import DEMO_COLUMNS
from ..frames.rotations import quat_to_euler
from ..io import schema
from ..io.parquet import read_table, read_table_meta
from ..io.stage import declared
from .pages import count_text, figure_divs, relative_href, render, table_html, write_page
from .plots import break_wraps, colour, label, label_colours, layout

_AXES = (("pos", "position", ("pos_n_m", "pos_e_m", "pos_d_m")),
         ("vel", "velocity", ("vel_n_mps", "vel_e_mps", "vel_d_mps")),
         ("acc", "acceleration", ("acc_n_mps2", "acc_e_mps2", "acc_d_mps2")))
_GREY = "rgba(90,90,90,0.45)"


def _euler_deg(q: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero quaternion reads NaN
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        return np.degrees(np.column_stack(quat_to_euler(q)))


def learned_figure(man: str, learned: pd.DataFrame, demos: pd.DataFrame) -> go.Figure:
    """Learned μ_t ±2σ over the demos on the hidden time axis (Figs 5.22–5.31 analogue)."""
    fig = make_subplots(rows=4, cols=3, shared_xaxes=True, vertical_spacing=0.05, horizontal_spacing=0.07,
                        # 'quantity [unit]', as every other label of the reports (was 'position north (m)')
                        subplot_titles=[*(label(c) for _, _, cs in _AXES for c in cs),
                                        "roll [°]", "pitch [°]", "yaw [°]"])
    t = learned["t_s"].to_numpy()
    for r, (_, _, cols) in enumerate(_AXES, start=1):
        for c, col in enumerate(cols, start=1):
            first = r == 1 and c == 1
            for k, (name, g) in enumerate(demos.groupby("demo", sort=False)):
                fig.add_trace(go.Scatter(x=g["t_s"], y=g[col], mode="lines", line=dict(width=1, color=_GREY),
                                         name="demos", legendgroup="demos", showlegend=first and k == 0),
                              row=r, col=c)
            mu = learned[f"mu_{col}"].to_numpy()
            sd = np.sqrt(np.maximum(learned[f"var_{col}"].to_numpy(), 0.0))
            fig.add_trace(go.Scatter(x=np.concatenate([t, t[::-1]]),
                                     y=np.concatenate([mu + 2 * sd, (mu - 2 * sd)[::-1]]), fill="toself",
                                     line=dict(width=0), fillcolor="rgba(31,119,180,0.18)", name="±2σ",
                                     legendgroup="band", showlegend=first, hoverinfo="skip"), row=r, col=c)
            fig.add_trace(go.Scatter(x=t, y=mu, mode="lines", line=dict(width=2.5, color=colour(col)),
                                     name="learned", legendgroup="learned", showlegend=first), row=r, col=c)
    eul_l = _euler_deg(learned[[f"mu_{c}" for c in ("q_w", "q_x", "q_y", "q_z")]].to_numpy())

    def wrapped(ts, v) -> pd.DataFrame:
        # roll and yaw wrap through ±180° (a rolling or turning aerobatic maneuver): a hole there
        return break_wraps(pd.DataFrame({"t_s": np.asarray(ts, np.float64), "v": v}))

    for c in range(3):
        for k, (name, g) in enumerate(demos.groupby("demo", sort=False)):
            e = wrapped(g["t_s"], _euler_deg(g[["q_w", "q_x", "q_y", "q_z"]].to_numpy())[:, c])
            fig.add_trace(go.Scatter(x=e["t_s"], y=e["v"], mode="lines", line=dict(width=1, color=_GREY),
                                     legendgroup="demos", showlegend=False), row=4, col=c + 1)
        e = wrapped(t, eul_l[:, c])
        fig.add_trace(go.Scatter(x=e["t_s"], y=e["v"], mode="lines", line=dict(width=2.5, color=_CYC[c]),
                                 legendgroup="learned", showlegend=False), row=4, col=c + 1)
    fig.update_xaxes(title="hidden time [s]", row=4)
    return layout(fig, f"{man}: learned trajectory and demos on the hidden time axis (box frame)",
                  height=900, margin=dict(l=50, r=20, t=70, b=60))


_CYC = ("#1f77b4", "#ff7f0e", "#2ca02c")


def alignment_figure(man: str, demos: pd.DataFrame, alignment: pd.DataFrame, learned: pd.DataFrame) -> go.Figure:
    """τ curves, north velocity before/after alignment (Figs 5.20–5.21) and the MPE (5.32–5.35)."""
    fig = make_subplots(rows=1, cols=4, horizontal_spacing=0.06,
                        subplot_titles=("τ_j (hidden step of demo sample j)", "north velocity [m/s], linear stretch",
                                        "north velocity [m/s], aligned",
                                        "model prediction error, acceleration [m/s²]"))
    T = len(learned)
    for name, g in demos.groupby("demo", sort=False):
        c = colour(name)
        j = g["j"].to_numpy()
        fig.add_trace(go.Scatter(x=j, y=g["tau"], mode="lines", line=dict(color=c), name=name, legendgroup=name),
                      row=1, col=1)
        stretch = j * (T - 1) / max(len(j) - 1, 1)
        fig.add_trace(go.Scatter(x=stretch, y=g["vel_n_mps"], mode="lines", line=dict(color=c, width=1),
                                 legendgroup=name, showlegend=False), row=1, col=2)
        fig.add_trace(go.Scatter(x=g["tau"], y=g["vel_n_mps"], mode="lines", line=dict(color=c, width=1),
                                 legendgroup=name, showlegend=False), row=1, col=3)
    for k, col in enumerate(("acc_n_mps2", "acc_e_mps2", "acc_d_mps2")):
        y = learned[f"mpe_{col}"]
        if y.notna().any():
            fig.add_trace(go.Scatter(x=learned["t"], y=y, mode="lines", line=dict(color=_CYC[k]),
                                     name=f"MPE {col.split('_')[1]}"), row=1, col=4)
    fig.update_xaxes(title="demo sample j", row=1, col=1)
    for c in (2, 3, 4):
        fig.update_xaxes(title="hidden step t", row=1, col=c)
    return layout(fig, f"{man}: time alignment", height=380, margin=dict(l=50, r=20, t=70, b=60))


def path_figure(man: str, learned: pd.DataFrame, demos: pd.DataFrame) -> go.Figure:
    """3-D path in the box frame (up = −d): demos thin, learned thick."""
    fig = go.Figure()
    for name, g in demos.groupby("demo", sort=False):
        fig.add_trace(go.Scatter3d(x=g["pos_e_m"], y=g["pos_n_m"], z=-g["pos_d_m"], mode="lines",
                                   line=dict(width=2, color=colour(name)), name=name))
    fig.add_trace(go.Scatter3d(x=learned["mu_pos_e_m"], y=learned["mu_pos_n_m"], z=-learned["mu_pos_d_m"],
                               mode="lines", line=dict(width=6, color="#111"), name="learned"))
    fig.update_layout(scene=dict(xaxis_title="box y [m]", yaxis_title="box x [m]", zaxis_title="up [m]",
                                 aspectmode="data"))
    return layout(fig, f"{man}: 3-D path in the box frame", height=480)


def loglik_figure(iterations: pd.DataFrame, tol: float | None = None) -> go.Figure | None:
    r"""EM convergence: the relative log-likelihood change per iteration,
    :math:`|\log L_k - \log L_{k-1}| / |\log L_{k-1}|`, one line per maneuver on a log axis, with
    the stopping tolerance ``tol`` (``align.tol``) as a line.

    The change, not the log-likelihood itself: divided by its first value every curve jumped to
    ≈ 1 after one iteration and looked converged, while the table said none of the 16 P23
    maneuvers converged in 30 iterations (their changes end near 3e-4, above the 1e-6 tolerance).
    """
    ok = iterations[iterations["status"] == "ok"]
    if not len(ok):
        return None
    fig = go.Figure()
    colours = label_colours(ok["maneuver"].astype(str).unique())
    n_conv = n_all = 0
    for man, g in ok.groupby("maneuver", sort=False):
        ll = g["loglik"].to_numpy(np.float64)
        n_all += 1
        n_conv += bool(g["converged"].iloc[-1]) if "converged" in g else 0
        if len(ll) < 2:
            continue
        rel = np.abs(np.diff(ll)) / np.maximum(np.abs(ll[:-1]), 1e-300)
        fig.add_trace(go.Scatter(x=g["iteration"].to_numpy()[1:], y=np.maximum(rel, 1e-16), mode="lines+markers",
                                 name=str(man), line=dict(color=colours[str(man)])))
    if not fig.data:
        return None
    if tol is not None:
        fig.add_hline(y=tol, line=dict(color="#222222", dash="dash"))
        # placed by hand: on a log axis an annotation's y is log10 of the value (plotly's
        # add_hline annotation lands at 10^tol, the top of the plot)
        fig.add_annotation(x=1.0, xref="paper", y=float(np.log10(tol)), yref="y", text=f"tol {tol:g}",
                           showarrow=False, xanchor="right", yanchor="bottom")
    fig.update_xaxes(title="EM iteration")
    fig.update_yaxes(title="|Δ log L| / |log L| (per iteration)", type="log")
    layout(fig, f"EM convergence ({n_conv} of {count_text(n_all, 'maneuver')} converged)", height=380)
    return fig.update_yaxes(exponentformat="power")   # 10⁻⁶, not 0.000001 (layout's plain numbers)


def anchor_table(learned: pd.DataFrame, demos: pd.DataFrame, band_deg: Sequence[float]) -> pd.DataFrame:
    """Digest §10 item 7 anchors per maneuver: the learned trajectory, then each demo."""
    rows = []
    for man, lg in learned.groupby("maneuver", sort=False):
        dt = float(np.median(np.diff(lg["t_s"]))) if len(lg) > 1 else float("nan")
        mu = lg[[f"mu_{c}" for c in DEMO_COLUMNS]].to_numpy()
        rows.append({"maneuver": man, "trajectory": "learned", **anchors(mu, dt, band_deg),
                     "rms_to_learned_m": 0.0})
        for name, g in demos[demos["maneuver"] == man].groupby("demo", sort=False):
            x = g[list(DEMO_COLUMNS)].to_numpy()
            ddt = float(np.median(np.diff(g["tau"]))) * dt if len(g) > 1 else dt
            rows.append({"maneuver": man, "trajectory": name, **anchors(x, ddt, band_deg),
                         "rms_to_learned_m": nearest_rms(mu, x)})
    return pd.DataFrame(rows)


#: column name -> table header (words, unit in brackets) for the page's tables
HEADERS = {"peak_pitch_deg": "peak pitch [°]", "time_in_band_s": "longest time in the pitch band [s]",
           "cross_track_rms_m": "cross-track RMS [m]", "rms_to_learned_m": "RMS to the learned path [m]",
           "loglik_first": "log-likelihood, first", "loglik_last": "log-likelihood, last",
           "flight_id": "flight", "iterations": "EM iterations (E-steps)"}


def build_align_report(paths: Mapping[str, str], out_html: str | os.PathLike, *, set_name: str,
                       template: str | os.PathLike, plotly_js: str, index_href: str = "../../index.html",
                       band_deg: Sequence[float] = (55.0, 89.0), tol: float | None = None) -> None:
    """Render one demo set's page from its four tables (``paths``: learned, alignment,
    iterations, demos); ``tol``: the EM tolerance drawn on the convergence plot."""
    learned = read_table(paths["learned"], schema.ALIGN_LEARNED)
    alignment = read_table(paths["alignment"], schema.ALIGN_ALIGNMENT)
    iterations = read_table(paths["iterations"], schema.ALIGN_ITERATIONS)
    demos = read_table(paths["demos"], schema.ALIGN_DEMOS)
    meta = read_table_meta(paths["learned"])
    diag = meta.get("align") or {}
    facts = [("status", meta.get("status", "?") + (f": {meta['error']}" if meta.get("error") else ""))]
    for f, info in (diag.get("flights") or {}).items():
        s = f"{info.get('frame')} frame, heading {np.degrees(info.get('heading_rad') or 0.0):.1f}°, {count_text(info.get('n_demos'), 'demo')}"
        if info.get("fit_rms_m") is not None:
            s += (f"; rigid fit to the reference: translation ({', '.join(f'{v:.1f}' for v in info.get('translation_m') or [])}) m, "
                  f"matched-pair RMS {info['fit_rms_m']:.1f} m")
            if info.get("fit_altitude_rms_m") is not None:
                # altitude alone, before any fit: a large value says the flight flies another schedule
                s += f"; altitude-profile RMS against the reference {info['fit_altitude_rms_m']:.1f} m"

        facts.append((f"flight {f}", s))
    for n in diag.get("notices") or []:
        facts.append(("notice", n))
    figs = [("EM convergence", loglik_figure(iterations, tol))]
    for man in learned["maneuver"].unique():
        lg, dg = learned[learned["maneuver"] == man], demos[demos["maneuver"] == man]
        figs += [(f"{man} learned", learned_figure(man, lg, dg)),
                 (f"{man} alignment", alignment_figure(man, dg, alignment[alignment["maneuver"] == man], lg)),
                 (f"{man} path", path_figure(man, lg, dg))]
    tables = []
    if len(learned):
        at = anchor_table(learned, demos, band_deg)
        tables.append((f"Anchors (digest §10 item 7): peak pitch, longest time within {band_deg[0]:g}–{band_deg[1]:g}°, "
                       "cross-track RMS about the track's own straight line; RMS distance of each demo to the learned path",
                       table_html(at.rename(columns=HEADERS), float_format="%.2f")))
    summary = iterations.groupby("maneuver", sort=False).agg(
        status=("status", "first"), reason=("reason", "first"), demos=("n_demos", "first"),
        # the rows are the E-steps 0..n-1: their count, not the last index (30 read 29)
        iterations=("iteration", "size"), converged=("converged", "first"),
        loglik_first=("loglik", "first"), loglik_last=("loglik", "last")).reset_index()
    tables.append(("Maneuvers", table_html(summary.rename(columns=HEADERS), float_format="%.1f")))
    left = alignment[alignment["status"] != "used"][["maneuver", "demo", "flight_id", "status", "reason"]]
    if len(left):
        tables.append(("Left out", table_html(left.rename(columns=HEADERS))))
    page = render(template, set_name=set_name, facts=facts, plots=figure_divs(figs), tables=tables,
                  plotly_js=plotly_js, index_href=index_href, failed=meta.get("status") == "failed",
                  error=meta.get("error"))
    write_page(page, out_html)


def run_align_report(inputs, outputs, config: Mapping | None = None, *, set_name: str, index: str) -> None:
    """One demo set's page ``outputs.page`` from ``inputs.{learned,alignment,iterations,demos}``,
    ``inputs.template`` and ``inputs.plotly``; ``config``: ``pitch_band_deg`` and ``tol``."""
    page = declared(outputs, "page")

    build_align_report({k: declared(inputs, k) for k in ("learned", "alignment", "iterations", "demos")}, page,
                       set_name=set_name, template=declared(inputs, "template"),
                       plotly_js=relative_href(declared(inputs, "plotly"), page), index_href=relative_href(index, page),
                       band_deg=tuple((config or {}).get("pitch_band_deg", (55.0, 89.0))),
                       tol=(config or {}).get("tol"))
