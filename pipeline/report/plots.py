"""Plot builders for the HTML reports (plotly figures as JSON-able dicts).

Every builder takes plain DataFrames (canonical streams or derived tables) and returns a
``plotly.graph_objects.Figure`` or ``None`` when the data for it are absent, so a report shows
what a flight has and says what it lacks. Traces are decimated to a bounded number of points so
reports stay small and fast in the browser.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import plotly.graph_objects as go

MAX_POINTS = 4000


def decimate(df: pd.DataFrame, max_points: int = MAX_POINTS) -> pd.DataFrame:
    """Every k-th row so that at most ``max_points`` remain (keeps the last row)."""
    n = len(df)
    if n <= max_points:
        return df
    idx = np.unique(np.r_[np.arange(0, n, int(np.ceil(n / max_points))), n - 1])
    return df.iloc[idx]


def _t(df: pd.DataFrame) -> np.ndarray:
    return df["t_ns"].to_numpy() * 1e-9


def layout(fig: go.Figure, title: str, **kw) -> go.Figure:
    """Apply the report's figure style (margins, height, template, horizontal legend) and
    ``title`` to ``fig``; ``kw`` overrides any of those options. Returns ``fig``."""
    opts = {"margin": dict(l=50, r=20, t=40, b=40), "height": 360, "template": "plotly_white",
            "legend": dict(orientation="h"), **kw}
    fig.update_layout(title=title, **opts)
    return fig


def path_3d(ned: pd.DataFrame) -> go.Figure | None:
    """3-D flight path from columns ``pos_n_m``, ``pos_e_m``, ``pos_d_m`` (plotted as up = −d)."""
    if ned is None or not len(ned) or not ned["pos_n_m"].notna().any():
        return None
    d = decimate(ned.dropna(subset=["pos_n_m", "pos_e_m", "pos_d_m"]))
    fig = go.Figure(go.Scatter3d(x=d["pos_e_m"], y=d["pos_n_m"], z=-d["pos_d_m"], mode="lines",
                                 line=dict(width=3, color=_t(d), colorscale="Viridis"), name="path"))
    fig.update_layout(scene=dict(xaxis_title="east [m]", yaxis_title="north [m]", zaxis_title="up [m]",
                                 aspectmode="data"))
    return layout(fig, "3-D path (local NED, up = −d)", height=480)


def _nice_length(span: float) -> float:
    """A 1/2/5 × 10^k length close to a fifth of ``span``."""
    if not np.isfinite(span) or span <= 0:
        return 1.0
    raw = span / 5
    k = 10 ** np.floor(np.log10(raw))
    return float(min((m * k for m in (1, 2, 5, 10)), key=lambda v: abs(v - raw)))


def ground_track(ned: pd.DataFrame) -> go.Figure | None:
    """Ground track north vs east in metres, equal axes, with a scale bar."""
    if ned is None or not len(ned) or not ned["pos_n_m"].notna().any():
        return None
    d = decimate(ned.dropna(subset=["pos_n_m", "pos_e_m"]))
    e, n = d["pos_e_m"].to_numpy(), d["pos_n_m"].to_numpy()
    fig = go.Figure(go.Scatter(x=e, y=n, mode="lines", name="track"))
    fig.add_trace(go.Scatter(x=e[:1], y=n[:1], mode="markers", marker=dict(size=9, color="green"), name="start"))
    fig.add_trace(go.Scatter(x=e[-1:], y=n[-1:], mode="markers", marker=dict(size=9, color="red"), name="end"))
    span = max(np.ptp(e), np.ptp(n), 1.0)
    bar = _nice_length(span)
    x0, y0 = e.min(), n.min() - 0.08 * span
    fig.add_shape(type="line", x0=x0, x1=x0 + bar, y0=y0, y1=y0, line=dict(width=4, color="black"))
    fig.add_annotation(x=x0 + bar / 2, y=y0, text=f"{bar:g} m", showarrow=False, yshift=12)
    fig.update_yaxes(scaleanchor="x", scaleratio=1, title="north [m]")
    fig.update_xaxes(title="east [m]")
    return layout(fig, "Ground track", height=480)


def altitude(series: dict[str, pd.DataFrame], calib_points: pd.DataFrame | None = None) -> go.Figure | None:
    """Altitude time series (``{name: DataFrame(t_ns, alt_m)}``) with BPM calibration points."""
    fig = go.Figure()
    for name, df in series.items():
        if df is not None and len(df) and df["alt_m"].notna().any():
            d = decimate(df)
            fig.add_trace(go.Scatter(x=_t(d), y=d["alt_m"], mode="lines", name=name))
    if calib_points is not None and len(calib_points):
        fig.add_trace(go.Scatter(x=_t(calib_points), y=calib_points["alt_m"], mode="markers",
                                 marker=dict(size=6, symbol="x"), name="calibration points"))
    if not fig.data:
        return None
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title="altitude [m, up]")
    return layout(fig, "Altitude")


def attitude(att: pd.DataFrame, euler: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> go.Figure | None:
    """Roll, pitch, yaw in degrees (ZYX, for display) against time."""
    if att is None or not len(att) or euler is None:
        return None
    fig = go.Figure()
    t = _t(att)
    for name, a in zip(("roll", "pitch", "yaw"), euler):
        d = decimate(pd.DataFrame({"t": t, "v": np.degrees(a)}))
        fig.add_trace(go.Scatter(x=d["t"], y=d["v"], mode="lines", name=name))
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title="angle [deg]")
    return layout(fig, "Attitude (ZYX Euler)")


def time_series(df: pd.DataFrame, cols: list[str], title: str, ylabel: str) -> go.Figure | None:
    """Generic multi-column time series of one stream (first instance)."""
    if df is None or not len(df):
        return None
    df = df[df["instance"] == df["instance"].min()] if "instance" in df else df
    cols = [c for c in cols if c in df and df[c].notna().any()]
    if not cols:
        return None
    d = decimate(df)
    fig = go.Figure([go.Scatter(x=_t(d), y=d[c], mode="lines", name=c) for c in cols])
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title=ylabel)
    return layout(fig, title)


def timeline(segments: pd.DataFrame | None, classified: pd.DataFrame | None = None) -> go.Figure | None:
    """Maneuver timeline: labelled segments as bars; classifier label and confidence if given."""
    fig = go.Figure()
    if segments is not None and len(segments):
        for r in segments.itertuples():
            t0, t1 = r.t_start_ns * 1e-9, r.t_end_ns * 1e-9
            fig.add_trace(go.Scatter(x=[t0, t1], y=["truth", "truth"], mode="lines", line=dict(width=14),
                                     name=str(r.label), showlegend=False, hovertext=str(r.label)))
            fig.add_annotation(x=(t0 + t1) / 2, y="truth", text=str(r.label), showarrow=False, yshift=14,
                               font=dict(size=9))
    if classified is not None and len(classified):
        d = decimate(classified)
        for lab, g in d.groupby(d["label"].astype(str), sort=True):
            fig.add_trace(go.Scatter(x=_t(g), y=["classifier"] * len(g), mode="markers", marker=dict(size=6),
                                     text=[lab] * len(g), name=f"classifier: {lab}"))
        if "confidence" in d:
            fig.add_trace(go.Scatter(x=_t(d), y=d["confidence"], mode="lines", name="confidence V", yaxis="y2"))
            fig.update_layout(yaxis2=dict(overlaying="y", side="right", title="V [log10]"))
    if not fig.data:
        return None
    fig.update_xaxes(title="t [s]")
    return layout(fig, "Maneuver timeline", height=260)


#: estimator name -> legend label of the estimate panels
ESTIMATOR_LABELS = {"ekf": "EKF", "ekf_rts": "EKF + RTS", "ekf_hmm": "EKF+HMM"}
_GROUP_UNITS = {"pos": ("position", "m"), "vel": ("velocity", "m/s"), "acc": ("acceleration", "m/s²")}


def estimate_error(errors: dict[str, pd.DataFrame], group: str, reference: str = "truth") -> go.Figure | None:
    """Norm of one state group's estimation error against time, one trace per estimator.

    ``errors``: ``{estimator: DataFrame(t_ns, pos, vel, acc)}`` (error norms per step, NaN
    where the reference has none); ``group``: ``pos``, ``vel`` or ``acc``."""
    name, unit = _GROUP_UNITS[group]
    fig = go.Figure()
    for est, df in errors.items():
        if df is None or not len(df) or not df[group].notna().any():
            continue
        d = decimate(df)
        rms = float(np.sqrt(np.nanmean(df[group].to_numpy() ** 2)))
        fig.add_trace(go.Scatter(x=_t(d), y=d[group], mode="lines",
                                 name=f"{ESTIMATOR_LABELS.get(est, est)} (RMSE {rms:.3g} {unit})"))
    if not fig.data:
        return None
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title=f"|error| [{unit}]")
    return layout(fig, f"Estimation error vs {reference}: {name}", height=300)


def mode_timeline(df: pd.DataFrame | None) -> go.Figure | None:
    """EKF+HMM mode: steps predicted with the HMM inputs (A_H/B) vs CA, and the classifier's
    label (``pred``) with its confidence ``V_best``."""
    if df is None or not len(df):
        return None
    d = decimate(df)
    fig = go.Figure()
    mode = d["mode"].astype(bool).to_numpy()
    fig.add_trace(go.Scatter(x=_t(d), y=np.where(mode, "HMM inputs", "CA"), mode="markers",
                             marker=dict(size=5, color=np.where(mode, "#d62728", "#1f77b4")),
                             name="prediction model", showlegend=False))
    for lab, g in d.groupby(d["pred"].astype(str), sort=True):
        fig.add_trace(go.Scatter(x=_t(g), y=["classifier"] * len(g), mode="markers", marker=dict(size=6),
                                 name=f"classifier: {lab}"))
    if d["V_best"].notna().any():
        fig.add_trace(go.Scatter(x=_t(d), y=d["V_best"], mode="lines", name="confidence V", yaxis="y2"))
        fig.update_layout(yaxis2=dict(overlaying="y", side="right", title="V [log10]"))
    fig.update_xaxes(title="t [s]")
    n = int(df["mode"].astype(bool).sum())
    return layout(fig, f"EKF+HMM mode ({n} of {len(df)} steps with HMM inputs)", height=280)
