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

from .pages import count_text

MAX_POINTS = 4000


#: a display line is broken where two consecutive samples lie more than this many times the
#: trace's median step apart (or the rows between them hold no value): a telemetry outage or a
#: state ``gap`` is drawn as a hole, never as a straight line across it
GAP_FACTOR = 5.0


def _value_cols(df: pd.DataFrame) -> list[str]:
    return [c for c in df.columns if c not in ("t_ns", "t_s", "instance", "t_boot_ns")
            and pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c])]


def _extreme_rows(df: pd.DataFrame, max_points: int, cols: list[str]) -> np.ndarray:
    """Positions of the rows :func:`decimate` keeps (all of them when ``df`` is short enough)."""
    n = len(df)
    if n <= max_points:
        return np.arange(n)
    if not cols:  # nothing to keep extremes of: evenly spaced rows
        return np.unique(np.r_[np.linspace(0, n - 1, max_points).astype(np.int64), n - 1])
    n_b = max(1, max_points // (2 * len(cols)))
    bucket = np.arange(n, dtype=np.int64) * n_b // n
    starts = np.searchsorted(bucket, np.arange(n_b))
    keep = [np.array([0, n - 1])]
    for c in cols:
        v = pd.to_numeric(df[c], errors="coerce").to_numpy(np.float64)
        # lexsort: by bucket, then value; NaN sorts last, so a bucket's first row is its minimum
        # (of -v: its maximum) whenever the bucket has a finite value
        for w in (v, -v):
            order = np.lexsort((w, bucket))
            keep.append(order[starts])
    return np.unique(np.concatenate(keep))


def decimate(df: pd.DataFrame, max_points: int = MAX_POINTS, cols: list[str] | None = None, *,
             breaks: bool = False) -> pd.DataFrame:
    """Rows of ``df`` for display: the minimum and maximum of every numeric column per bucket.

    The rows are cut into ``B`` consecutive buckets of equal row count; per bucket and column
    the rows holding the minimum and the maximum are kept (with the first and last row), so a
    spike survives the decimation, as it would not under every-k-th-row. ``B`` is
    ``max_points // (2 · n_columns)``, so at most about ``max_points`` rows remain. For display
    only: analysis always uses the full table.

    Parameters
    ----------
    df : DataFrame
        Rows in plotting order (usually by ``t_ns``).
    max_points : int
        Upper bound of the rows kept (plus the first and last).
    cols : list of str, optional
        The columns whose extremes are kept; default every numeric column except ``t_ns``,
        ``t_s``, ``instance`` and ``t_boot_ns``.
    breaks : bool
        For a line trace: drop the rows where every one of ``cols`` is NaN, keep both rows
        around every gap of the time column (``t_ns``, else ``t_s``) longer than
        :data:`GAP_FACTOR` times its median step, and put a row with only the time (its
        midpoint) in each such gap, so that plotly, which breaks a line at a missing value,
        draws the gap as a hole. Nothing is computed on the result but the picture: the
        inserted rows are NaN.
    """
    if cols is None:
        cols = _value_cols(df)
    if not breaks:
        n = len(df)
        return df if n <= max_points else df.iloc[_extreme_rows(df, max_points, cols)]
    t_col = "t_ns" if "t_ns" in df else "t_s"
    if cols:
        df = df[df[cols].notna().any(axis=1).to_numpy()]
    t = df[t_col].to_numpy(np.float64)
    dt = np.diff(t)
    step = dt[dt > 0]
    gaps = (np.flatnonzero(dt > GAP_FACTOR * float(np.median(step))) if len(step)
            else np.zeros(0, np.int64))
    out = df.iloc[np.union1d(_extreme_rows(df, max_points, cols), np.r_[gaps, gaps + 1])]
    if not len(gaps):
        return out
    mid = t[gaps] + 0.5 * dt[gaps]
    holes = pd.DataFrame({t_col: mid.astype(df[t_col].dtype) if t_col == "t_ns" else mid})
    both = pd.concat([out, holes], ignore_index=True)
    return both.iloc[np.argsort(both[t_col].to_numpy(np.float64), kind="stable")].reset_index(drop=True)


#: unit suffix of a canonical column name -> the unit as displayed ("" dimensionless)
UNITS = {"m": "m", "mps": "m/s", "mps2": "m/s²", "mps3": "m/s³", "rad": "rad", "radps": "rad/s",
         "deg": "°", "Pa": "Pa", "degC": "°C", "V": "V", "A": "A", "Ah": "A·h", "T": "T", "us": "µs",
         "ns": "ns", "s": "s", "Hz": "Hz", "frac": "", "pct": "%"}
#: name tokens -> words (quantities, components, qualifiers)
WORDS = {"acc": "acceleration", "gyr": "angular rate", "vel": "velocity", "pos": "position",
         "jerk": "jerk", "mag": "magnetic field", "alt": "altitude", "press": "pressure",
         "temp": "temperature", "voltage": "voltage", "current": "current", "consumed": "charge drawn",
         "remaining": "remaining capacity", "vibe": "vibration", "vibration": "vibration",
         "rc": "RC input", "servo": "servo output", "dist": "distance", "airspeed": "airspeed",
         "diff": "differential", "lat": "latitude", "lon": "longitude", "hacc": "horizontal accuracy",
         "vacc": "vertical accuracy", "hdop": "HDOP", "vdop": "VDOP", "fix": "fix", "type": "type",
         "sats": "satellites", "clip": "clipping events", "range": "range", "rate": "rate",
         "n": "north", "e": "east", "d": "down", "x": "x", "y": "y", "z": "z",
         "wgs84": "(WGS-84)", "msl": "(MSL)", "rel": "(relative)", "cal": "(calibrated)",
         "roll": "roll", "pitch": "pitch", "yaw": "yaw", "hmm": "HMM", "gated": "gated",
         "dcos": "direction cosine", "u": "u", "v": "v"}
#: whole names that read better spelled out
NAMES = {"n_sats": "satellites", "fix_type": "fix type", "p_radps": "roll rate [rad/s]",
         "q_radps": "pitch rate [rad/s]", "r_radps": "yaw rate [rad/s]",
         "acc_vibration_mps2": "accelerometer vibration [m/s²]",
         "gyr_vibration_radps": "gyro vibration [rad/s]", "remaining_frac": "remaining capacity [0..1]",
         "t_ns": "t [ns]", "t_s": "t [s]", "q_w": "quaternion w", "q_x": "quaternion x",
         "q_y": "quaternion y", "q_z": "quaternion z"}


def label(col: str) -> str:
    """Display label with unit of a canonical column name: ``acc_x_mps2`` -> ``acceleration x [m/s²]``.

    The schema puts the SI unit in the name's last token (``_m``, ``_mps``, ``_mps2``,
    ``_rad``, ``_radps``, ``_deg``, ``_Pa``, ``_degC``, ``_V``, ``_A``, ...); the other tokens
    become words (:data:`WORDS`), unknown tokens stay as they are, a dimensionless name gets
    no brackets. ``x_`` (an estimate column) reads "estimated".
    """
    if col in NAMES:
        return NAMES[col]
    prefix = ""
    if col.startswith("x_") and len(col) > 2 and col[2:] not in NAMES:
        prefix, col = "estimated ", col[2:]
    toks = col.split("_")
    unit = None
    if len(toks) > 1 and toks[-1] in UNITS:
        unit = UNITS[toks.pop()]
    if toks and toks[-1].isdigit() and toks[0] in ("rc", "servo", "clip"):
        toks[-1] = str(int(toks[-1]) + (1 if toks[0] == "clip" else 0))
    words = " ".join(WORDS.get(t, t) for t in toks)
    return prefix + (f"{words} [{unit}]" if unit else words)


#: one colour per component, so x/north/roll (and their setpoints) look alike on every panel
PALETTE = {"x": "#1f77b4", "y": "#ff7f0e", "z": "#2ca02c", "n": "#1f77b4", "e": "#ff7f0e", "d": "#2ca02c",
           "roll": "#1f77b4", "pitch": "#ff7f0e", "yaw": "#2ca02c", "p": "#1f77b4", "q": "#ff7f0e",
           "r": "#2ca02c", "voltage": "#d62728", "current": "#9467bd", "remaining": "#8c564b",
           "consumed": "#7f7f7f", "fix": "#1f77b4", "sats": "#ff7f0e", "hdop": "#2ca02c",
           "vdop": "#17becf", "hacc": "#d62728", "vacc": "#9467bd", "baro": "#1f77b4",
           "track": "#ff7f0e", "calibrated": "#2ca02c", "rangefinder": "#9467bd", "gps": "#8c564b"}
_CYCLE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
          "#bcbd22", "#17becf")


def colour(key: str) -> str:
    """The colour of a quantity or component (:data:`PALETTE`), the same on every panel: the
    first token of ``key`` found there, checked from the component (``acc_x_mps2`` -> ``x``);
    otherwise a stable pick from the cycle by the name (never by trace order)."""
    toks = [t for t in str(key).replace(" ", "_").split("_") if t]
    if len(toks) > 1 and toks[1].isdigit():  # numbered channels (rc_3_us, servo_3_us): by number
        return _CYCLE[(int(toks[1]) - 1) % len(_CYCLE)]
    for t in (*toks[1:], *toks[:1]):
        if t in PALETTE:
            return PALETTE[t]
    import zlib

    return _CYCLE[zlib.crc32(str(key).encode()) % len(_CYCLE)]


def _t(df: pd.DataFrame) -> np.ndarray:
    return df["t_ns"].to_numpy() * 1e-9


def right_axis(title: str | None = None, **kw) -> dict:
    """A y axis on the right, over ``y``, with ticks of its own (and ``title``, when given).

    plotly.js 4 defaults an overlaying axis to ``tickmode="sync"``: its ticks land on the left
    axis's grid lines, at values such as −0.01, 8.69, 17.39 clipping events; ``auto`` gives round
    numbers of its own unit, and no second grid."""
    ax = dict(overlaying="y", side="right", tickmode="auto", showgrid=False, zeroline=False, **kw)
    return ax if title is None else {**ax, "title": title}


#: the legend's top below the plot area (px): under the tick labels and the x-axis title
LEGEND_BELOW_PX = 62.0


def layout(fig: go.Figure, title: str, **kw) -> go.Figure:
    """Apply the report's figure style (margins, height, template, horizontal legend) and
    ``title`` to ``fig``; ``kw`` overrides any of those options. Returns ``fig``."""
    # the horizontal legend sits below the x-axis title, never on it: 62 px under the plot area
    # whatever the figure's height (a fixed -0.22 of a 260 px timeline put it on the title)
    opts = {"margin": dict(l=50, r=20, t=40, b=40), "height": 360, "template": "plotly_white", **kw}
    m = {"t": 40, "b": 40, **(opts["margin"] or {})}
    plot_h = max(float(opts["height"] or 360) - m["t"] - m["b"], 60.0)
    opts.setdefault("legend", dict(orientation="h", yanchor="top", y=-LEGEND_BELOW_PX / plot_h))
    fig.update_layout(title=title, **opts)
    # plain numbers on every axis: no SI-prefixed "−0.38k" ticks on confidence or log axes
    fig.update_xaxes(exponentformat="none")
    fig.update_yaxes(exponentformat="none")
    return compact(fig)


def compact(fig: go.Figure) -> go.Figure:
    """The time (x) arrays of ``fig``'s traces as float32 (plotly writes arrays as base64 typed
    arrays): a quarter of a flight page's bytes saved, 7 significant digits (1 ms at t = 10⁴ s)
    for where a point is drawn; the values (y) keep every digit for the hover. Returns ``fig``."""
    for tr in fig.data:
        for a in ("x",):
            v = getattr(tr, a, None)
            if isinstance(v, np.ndarray) and v.dtype == np.float64:
                setattr(tr, a, v.astype(np.float32))
    return fig


def path_3d(ned: pd.DataFrame) -> go.Figure | None:
    """3-D flight path from columns ``pos_n_m``, ``pos_e_m``, ``pos_d_m`` (plotted as up = −d)."""
    if ned is None or not len(ned) or not ned["pos_n_m"].notna().any():
        return None
    d = decimate(ned.dropna(subset=["pos_n_m", "pos_e_m", "pos_d_m"]), breaks=True)
    fig = go.Figure(go.Scatter3d(x=d["pos_e_m"], y=d["pos_n_m"], z=-d["pos_d_m"], mode="lines",
                                 line=dict(width=3, color=_t(d), colorscale="Viridis", showscale=True,
                                           colorbar=dict(title="t [s]")), name="path"))
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
    d = decimate(ned.dropna(subset=["pos_n_m", "pos_e_m"]), breaks=True)
    e, n = d["pos_e_m"].to_numpy(), d["pos_n_m"].to_numpy()
    fig = go.Figure(go.Scatter(x=e, y=n, mode="lines", name="track"))
    fig.add_trace(go.Scatter(x=e[:1], y=n[:1], mode="markers", marker=dict(size=9, color="green"), name="start"))
    fig.add_trace(go.Scatter(x=e[-1:], y=n[-1:], mode="markers", marker=dict(size=9, color="red"), name="end"))
    # the gap rows decimate puts in the line are NaN
    span = max(np.nanmax(e) - np.nanmin(e), np.nanmax(n) - np.nanmin(n), 1.0)
    bar = _nice_length(span)
    x0, y0 = np.nanmin(e), np.nanmin(n) - 0.08 * span
    fig.add_shape(type="line", x0=x0, x1=x0 + bar, y0=y0, y1=y0, line=dict(width=4, color="black"))
    fig.add_annotation(x=x0 + bar / 2, y=y0, text=f"{bar:g} m", showarrow=False, yshift=12)
    fig.update_yaxes(scaleanchor="x", scaleratio=1, title="north [m]")
    fig.update_xaxes(title="east [m]")
    return layout(fig, "Ground track", height=480)


#: at most this many calibration markers on the altitude panel
MAX_MARKERS = 200


def altitude(series: dict[str, pd.DataFrame], calib_points: pd.DataFrame | None = None) -> go.Figure | None:
    """Altitude time series (``{name: DataFrame(t_ns, alt_m)}``) with BPM calibration points."""
    fig = go.Figure()
    for name, df in series.items():
        if df is not None and len(df) and df["alt_m"].notna().any():
            d = decimate(df[["t_ns", "alt_m"]], cols=["alt_m"], breaks=True)
            fig.add_trace(go.Scatter(x=_t(d), y=d["alt_m"], mode="lines", name=name, line=dict(color=colour(name))))
    if calib_points is not None and len(calib_points):
        # every k-th point, small and half see-through: a 10 Hz GPS reference as full markers
        # is a solid band that hides the track and calibrated lines it lies on
        n = len(calib_points)
        k = max(1, -(-n // MAX_MARKERS))
        pts = calib_points.iloc[::k]
        name = "calibration points" + (f" ({len(pts)} of {n} shown)" if k > 1 else "")
        fig.add_trace(go.Scatter(x=_t(pts), y=pts["alt_m"], mode="markers", opacity=0.6,
                                 marker=dict(size=4, symbol="x"), name=name))
    if not fig.data:
        return None
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title="altitude [m, up]")
    return layout(fig, "Altitude")


def break_wraps(d: pd.DataFrame, col: str = "v", limit: float = 180.0) -> pd.DataFrame:
    """``d`` (rows in time order, a time column ``t_ns`` or ``t_s`` and an angle column ``col``
    in degrees) with a hole (a row of only the midpoint time) between consecutive rows whose
    angle steps by more than ``limit``: the angle wrapped (roll through ±180° inverted), so the
    line is broken there instead of drawn as a vertical stroke across the panel. For display
    only."""
    v = d[col].to_numpy(np.float64)
    jump = np.flatnonzero(np.abs(np.diff(v)) > limit)    # NaN steps compare False
    if not len(jump):
        return d
    t_col = "t_ns" if "t_ns" in d else "t_s"
    t = d[t_col].to_numpy()
    mid = t[jump] + (t[jump + 1] - t[jump]) // 2 if t_col == "t_ns" else 0.5 * (t[jump] + t[jump + 1])
    holes = pd.DataFrame({t_col: mid})
    both = pd.concat([d, holes], ignore_index=True)
    order = np.argsort(np.r_[2 * np.arange(len(d)), 2 * jump + 1], kind="stable")
    return both.iloc[order].reset_index(drop=True)


def attitude(att: pd.DataFrame, euler: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
             setpoint: pd.DataFrame | None = None, frame: str = "") -> go.Figure | None:
    """Roll, pitch, yaw in degrees (ZYX, for display; yaw unwrapped) against time, with the
    ``setpoint`` stream's attitude (dashed, same colour per angle) where it has one; ``frame``
    (e.g. "state: body FRD, mount-corrected") goes into the title."""
    if att is None or not len(att) or euler is None:
        return None
    fig = go.Figure()
    yaw_deg = None
    for name, a in zip(("roll", "pitch", "yaw"), euler):
        v = np.degrees(np.unwrap(a) if name == "yaw" else a)
        if name == "yaw":
            yaw_deg = v
        d = break_wraps(decimate(pd.DataFrame({"t_ns": att["t_ns"].to_numpy(), "v": v}), breaks=True))
        fig.add_trace(go.Scatter(x=_t(d), y=d["v"], mode="lines", name=f"{name} [°]",
                                 line=dict(color=colour(name))))
    sp = _first(setpoint)
    if sp is not None:
        for name in ("roll", "pitch", "yaw"):
            c = f"{name}_rad"
            ok = sp.dropna(subset=[c]) if c in sp else sp.iloc[:0]
            if not len(ok):
                continue
            a = ok[c].to_numpy(np.float64)
            v = np.degrees(np.unwrap(a) if name == "yaw" else a)
            fin = np.isfinite(yaw_deg) if name == "yaw" and yaw_deg is not None else np.zeros(0, bool)
            if fin.any():
                # each setpoint sample on the measured yaw's turn (within ±180° of it): unwrapped
                # on their own, the two drift whole turns apart across a telemetry outage or a
                # fast spin, and a 1000° offset hides a 10° tracking error
                y = np.interp(ok["t_ns"].to_numpy(np.float64), att["t_ns"].to_numpy(np.float64)[fin], yaw_deg[fin])
                v = y + (np.degrees(a) - y + 180.0) % 360.0 - 180.0
            d = break_wraps(decimate(pd.DataFrame({"t_ns": ok["t_ns"].to_numpy(), "v": v}), breaks=True))
            fig.add_trace(go.Scatter(x=_t(d), y=d["v"], mode="lines", name=f"{name} setpoint [°]",
                                     line=dict(color=colour(name), dash="dash")))
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title="angle [°]")
    where = f"{frame}; " if frame else ""
    return layout(fig, f"Attitude vs setpoint ({where}ZYX Euler, yaw unwrapped)" if len(fig.data) > 3
                  else f"Attitude ({where}ZYX Euler, yaw unwrapped)")


def _first(df: pd.DataFrame | None) -> pd.DataFrame | None:
    """The first instance of a stream, ``None`` when it has no rows."""
    if df is None or not len(df):
        return None
    return df[df["instance"] == df["instance"].min()] if "instance" in df else df


def with_setpoint(df: pd.DataFrame | None, cols: list[str], setpoint: pd.DataFrame | None,
                  sp_cols: list[str], title: str, ylabel: str, *, scale: float = 1.0,
                  unit: str | None = None) -> go.Figure | None:
    """Measured ``cols`` of ``df`` (solid) and the matching ``sp_cols`` of ``setpoint`` (dashed,
    same colour per component) against time; ``None`` when neither has data.

    ``scale`` multiplies every value drawn (measured and setpoint alike) and ``unit`` replaces
    the unit in the trace names: the SI columns shown in a display unit, such as body rates in
    rad/s drawn in °/s (``scale=180/π, unit="°/s"``). ``ylabel`` names the displayed unit."""
    fig = go.Figure()
    for frame, cs, dash, suffix in ((_first(df), cols, None, ""), (_first(setpoint), sp_cols, "dash", " setpoint")):
        if frame is None:
            continue
        for c in cs:
            if c not in frame or not frame[c].notna().any():
                continue
            d = decimate(frame[["t_ns", c]], cols=[c], breaks=True)
            lab = label(c)
            if unit is not None and " [" in lab:
                lab = f"{lab[:lab.index(' [')]} [{unit}]"
            name = lab.replace(" [", f"{suffix} [") if "[" in lab else lab + suffix
            fig.add_trace(go.Scatter(x=_t(d), y=d[c] * scale, mode="lines", name=name,
                                     line=dict(color=colour(c), dash=dash)))
    if not fig.data:
        return None
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title=ylabel)
    return layout(fig, title)


def gps_quality(gps: pd.DataFrame | None) -> go.Figure | None:
    """GPS quality: fix type, satellites, HDOP/VDOP (left axis) and the receiver's horizontal /
    vertical accuracy in metres (right axis); ``None`` when the stream has none of them."""
    g = _first(gps)
    if g is None:
        return None
    fig = go.Figure()
    left = []
    for c in ("fix_type", "n_sats", "hdop", "vdop"):
        if c in g and g[c].notna().any():
            d = decimate(g[["t_ns", c]], cols=[c], breaks=True)
            fig.add_trace(go.Scatter(x=_t(d), y=d[c], mode="lines", name=label(c), line=dict(color=colour(c))))
            left.append(c)
    right = False
    for c in ("hacc_m", "vacc_m"):
        if c in g and g[c].notna().any():
            d = decimate(g[["t_ns", c]], cols=[c], breaks=True)
            fig.add_trace(go.Scatter(x=_t(d), y=d[c], mode="lines", name=label(c), yaxis="y2",
                                     line=dict(color=colour(c), dash="dot")))
            right = True
    if not fig.data:
        return None
    if right:
        fig.update_layout(yaxis2=right_axis("accuracy [m]"))
    fig.update_xaxes(title="t [s]")
    # the left axis names what it holds: a log with satellites alone read "fix type, satellites, DOP"
    words = {"fix_type": "fix type (3 = 3-D)", "n_sats": "satellites", "hdop": "DOP", "vdop": "DOP"}
    fig.layout.yaxis.title = ", ".join(dict.fromkeys(words[c] for c in left))
    return layout(fig, "GPS quality")


def accel_rms(imu: pd.DataFrame | None, window_s: float = 1.0) -> pd.DataFrame | None:
    """Accelerometer RMS about the window mean (the vibration part) in ``window_s`` windows.

    Returns ``DataFrame(t_ns (window centre), acc_x_mps2, acc_y_mps2, acc_z_mps2)`` of the
    first instance, ``None`` without accelerometer data. Per axis
    ``rms = sqrt(mean((a - mean(a))²))`` over the samples of each window (the population
    standard deviation), so gravity and slow manoeuvres drop out."""
    i = _first(imu)
    cols = [f"acc_{a}_mps2" for a in "xyz"]
    if i is None or not all(c in i for c in cols):
        return None
    i = i.dropna(subset=cols)
    if not len(i):
        return None
    w = int(window_s * 1e9)
    key = i["t_ns"].to_numpy(np.int64) // w
    g = i[cols].groupby(key)
    out = g.std(ddof=0)
    out = out[g.size() >= 2]
    if not len(out):
        return None
    return pd.DataFrame({"t_ns": out.index.to_numpy(np.int64) * w + w // 2,
                         **{c: out[c].to_numpy() for c in cols}})


def vibration(vib: pd.DataFrame | None, imu: pd.DataFrame | None = None) -> go.Figure | None:
    """Vibration: the autopilot's metric (``vibration`` stream: VIBE x/y/z, PX4's one-number
    metrics, clipping counts) where logged, else the accelerometer RMS in 1 s windows
    (:func:`accel_rms`); ``None`` when neither exists.

    Each unit has an axis of its own (:func:`unit_axes`): the accelerometer metrics in m/s² on
    the left, PX4's gyro metric in rad/s and the clipping counts on the right, each axis titled
    with its unit. A gyro metric of 0.05 rad/s beside an accelerometer metric of 5 m/s² on one
    m/s² axis read as a flat line in the wrong unit.
    """
    v = _first(vib)
    fig = go.Figure()
    if v is not None:
        # (axis title, columns, line style) per unit: left axis first, then the right ones
        groups = (("vibration [m/s²]", ("vibe_x_mps2", "vibe_y_mps2", "vibe_z_mps2", "acc_vibration_mps2"), None),
                  ("gyro vibration [rad/s]", ("gyr_vibration_radps",), "dash"),
                  ("clipping events", ("clip_0", "clip_1", "clip_2"), "dot"))
        titles = []
        for title, cols, dash in groups:
            cols = [c for c in cols if c in v and v[c].notna().any()]
            if not cols:
                continue
            axis = "y" if not titles else f"y{len(titles) + 1}"
            titles.append(title)
            for c in cols:
                d = decimate(v[["t_ns", c]], cols=[c], breaks=True)
                fig.add_trace(go.Scatter(x=_t(d), y=d[c], mode="lines", name=label(c), yaxis=axis,
                                         # a clipping count is no component: the default cycle, as before
                                         line=dict(color=None if c.startswith("clip") else colour(c), dash=dash)))
        if fig.data:
            extra = unit_axes(fig, titles)
            if "clipping events" in titles:
                # a count from 0: all zero (no clipping) autoscaled to -1..1 read as negative counts
                k = titles.index("clipping events")
                fig.layout["yaxis" if k == 0 else f"yaxis{k + 1}"].rangemode = "tozero"
            fig.update_xaxes(title="t [s]")
            return layout(fig, "Vibration (autopilot's metric)", **extra)
    r = accel_rms(imu)
    if r is None:
        return None
    for c in ("acc_x_mps2", "acc_y_mps2", "acc_z_mps2"):
        fig.add_trace(go.Scatter(x=_t(r), y=r[c], mode="lines", name=label(c).replace(" [", " RMS ["),
                                 line=dict(color=colour(c))))
    fig.update_xaxes(title="t [s]")
    fig.layout.yaxis.title = "RMS [m/s²]"
    return layout(fig, "Vibration (accelerometer RMS about the mean, 1 s windows; raw, sensor frame)")


#: below this IMU rate a spectrogram shows nothing of the vibration (Nyquist under 10 Hz): a
#: telemetry log's RAW_IMU at 1-4 Hz, a ULog whose sensor_combined was logged at 10 Hz
MIN_SPECTROGRAM_RATE_HZ = 20.0
#: the spectrogram's window length (s) at the IMU's own rate: 128 samples at 200 Hz
SPECTROGRAM_WINDOW_S = 0.64


def imu_rate_hz(imu: pd.DataFrame | None, cols: list[str] | None = None) -> float | None:
    """The sample rate of the first instance of ``imu`` as logged: 1 / the median step between
    successive distinct timestamps of the rows with ``cols`` (sensor logs jitter; a repeated
    timestamp is not a step). ``None`` without two such rows."""
    i = _first(imu)
    if i is None:
        return None
    if cols:
        cols = [c for c in cols if c in i]
        if not cols:
            return None
        i = i.dropna(subset=cols)
    t = np.unique(i["t_ns"].to_numpy(np.int64))
    if len(t) < 2:
        return None
    dt = float(np.median(np.diff(t))) * 1e-9
    return 1.0 / dt if dt > 0 else None


def spectrogram_nperseg(fs_hz: float) -> int:
    """Samples per window at ``fs_hz``: the power of two nearest :data:`SPECTROGRAM_WINDOW_S`
    of samples, at least 128 (enough frequency bins at low rates: 6.4 s at 20 Hz) and at most
    4096 (a 1 kHz IMU gets 512-sample windows, 2 Hz bins; a fixed 128 would give 8 Hz)."""
    n = 2 ** int(np.round(np.log2(max(fs_hz * SPECTROGRAM_WINDOW_S, 1.0))))
    return int(min(max(n, 128), 4096))


def spectrogram_absent(imu: pd.DataFrame | None, cols: list[str]) -> str | None:
    """Why :func:`spectrogram` draws nothing for ``cols`` of ``imu`` (for the panel's title), or
    ``None`` when it draws: no samples, too few for one window, or an IMU logged below
    :data:`MIN_SPECTROGRAM_RATE_HZ`."""
    fs = imu_rate_hz(imu, cols)
    if fs is None:
        return "no IMU samples"
    if fs < MIN_SPECTROGRAM_RATE_HZ:
        return f"IMU logged at {fs:.3g} Hz, below the {MIN_SPECTROGRAM_RATE_HZ:g} Hz a vibration spectrum needs"
    n = spectrogram_nperseg(fs)
    i = _first(imu).dropna(subset=[c for c in cols if c in imu])
    if len(i) < n:
        return f"{count_text(len(i), 'IMU sample')}, fewer than one {n}-sample window"
    return None


def spectrogram(imu: pd.DataFrame | None, cols: list[str], title: str, unit: str, *,
                nperseg: int | None = None, max_columns: int = 200) -> go.Figure | None:
    """Spectrogram of the vector ``cols`` of the first instance of ``imu`` against flight time.

    :func:`scipy.signal.spectrogram` (Hann windows of ``nperseg`` samples, half overlap, mean
    removed per window) per axis at the IMU's own rate; the vector's PSD is the sum over the
    axes (the trace of the cross-spectral matrix), shown in dB, ``10 log10(Σ PSD)``. For
    display, consecutive windows are averaged into at most ``max_columns`` time columns
    (Welch's estimate per column), so a long log keeps every sample in the estimate but a
    bounded page. The sample rate is the raw IMU rate (:func:`imu_rate_hz`: the median step;
    sensor logs jitter); ``nperseg`` defaults to :func:`spectrogram_nperseg` of it (about
    0.64 s, at least 128 samples). ``None`` below :data:`MIN_SPECTROGRAM_RATE_HZ` (a 1 Hz
    telemetry IMU holds no vibration to show: :func:`spectrogram_absent` says so) and with
    fewer than ``nperseg`` samples."""
    from scipy.signal import spectrogram as _spectrogram

    i = _first(imu)
    cols = [c for c in cols if i is not None and c in i and i[c].notna().any()]
    if not cols:
        return None
    i = i.dropna(subset=cols)
    fs = imu_rate_hz(i, cols)
    if fs is None or not np.isfinite(fs) or fs < MIN_SPECTROGRAM_RATE_HZ:
        return None
    nperseg = int(nperseg or spectrogram_nperseg(fs))
    if len(i) < nperseg:
        return None
    t_ns = i["t_ns"].to_numpy(np.int64)
    total = None
    for c in cols:
        f, tc, sxx = _spectrogram(i[c].to_numpy(np.float64), fs=fs, window="hann", nperseg=nperseg,
                                   noverlap=nperseg // 2)
        total = sxx if total is None else total + sxx
    k = -(-total.shape[1] // max_columns)           # windows per column (ceil)
    n_col = -(-total.shape[1] // k)
    cols_psd = np.stack([total[:, j * k:(j + 1) * k].mean(axis=1) for j in range(n_col)], axis=1)
    t_col = np.array([tc[j * k:(j + 1) * k].mean() for j in range(n_col)]) + t_ns[0] * 1e-9
    z = (10.0 * np.log10(np.maximum(cols_psd, 1e-30))).astype(np.float32)
    fig = go.Figure(go.Heatmap(x=t_col, y=f, z=z, colorscale="Viridis", name="PSD",
                               colorbar=dict(title=f"dB re ({unit})²/Hz")))
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title="frequency [Hz]")
    return layout(fig, f"{title} (Σ over axes, {nperseg}-sample windows = {nperseg / fs:.2g} s, "
                       f"fs = {fs:.0f} Hz, {fs / nperseg:.2g} Hz bins)", height=320)


def is_time_panel(fig: go.Figure | None) -> bool:
    """Whether ``fig`` is drawn against flight time (its x axis is ``t [s]``): time panels get
    the flight-mode bands and share the page's linked time axis; a 3-D path, a ground track or a
    spectrum do not."""
    if fig is None:
        return False
    t = fig.layout.xaxis.title.text
    return t == "t [s]"


def unit_axes(fig: go.Figure, titles: list[str], colours: list[str | None] | None = None) -> dict:
    """Give each of ``titles`` (one per unit, left to right) its own y axis: the first on the
    left (``y``), the second on the right (``y2``), a third further right (``y3``, the plot
    narrowed to leave it room). A trace goes on axis ``i`` by ``yaxis="y<i+1>"``. ``colours``
    colour each axis's title and ticks like its trace (one trace per axis). Returns the extra
    :func:`layout` options (the right margin the axes need)."""
    colours = list(colours or []) + [None] * len(titles)
    axes = {}
    for k, (title, c) in enumerate(zip(titles, colours)):
        ax = dict(title=dict(text=title, font=dict(color=c) if c else None), tickfont=dict(color=c) if c else None)
        if k:
            ax.update(right_axis())
        if k == 2:
            ax.update(anchor="free", position=1.0)
        axes["yaxis" if k == 0 else f"yaxis{k + 1}"] = ax
    if len(titles) > 2:
        axes["xaxis"] = dict(domain=[0.0, 0.86])
        axes["yaxis2"]["anchor"] = "x"
    fig.update_layout(**axes)
    return {"margin": dict(l=50, r=70 if len(titles) > 1 else 20, t=40, b=40)}


def battery(bat: pd.DataFrame | None) -> go.Figure | None:
    """Battery voltage [V] (left axis), current [A] and remaining capacity [%] each on its own
    right axis: three units, three scales, never two on one axis. A remaining capacity that
    never changes (PX4 logs 100 % throughout when it has no estimate) is named in the title,
    not drawn: its third axis would narrow the panel out of line with the others for a flat
    line."""
    b = _first(bat)
    if b is None:
        return None
    fig = go.Figure()
    titles, colours = [], []
    title = "Battery"
    rem = b["remaining_frac"].dropna().to_numpy(np.float64) if "remaining_frac" in b else np.array([])
    if len(rem) and np.ptp(rem) == 0:
        title += f" (remaining capacity {100 * rem[0]:.0f} % throughout, not drawn)"
        b = b.drop(columns="remaining_frac")
    for c, scale, name in (("voltage_V", 1.0, label("voltage_V")), ("current_A", 1.0, label("current_A")),
                           ("remaining_frac", 100.0, "remaining capacity [%]")):
        if c in b and b[c].notna().any():
            d = decimate(b[["t_ns", c]], cols=[c], breaks=True)
            k = len(titles)
            fig.add_trace(go.Scatter(x=_t(d), y=d[c] * scale, mode="lines", name=name,
                                     yaxis="y" if k == 0 else f"y{k + 1}", line=dict(color=colour(c))))
            titles.append(name)
            colours.append(colour(c))
    if not fig.data:
        return None
    extra = unit_axes(fig, titles, colours)
    fig.update_xaxes(title="t [s]")
    return layout(fig, title, **extra)


#: how an actuator output column reads (:func:`output_kind`) -> (axis title, unit in a trace
#: name, words in the panel's title)
OUTPUT_KINDS = {"pwm": ("pulse width [µs]", "µs", "PWM µs"),
                "normalised": ("normalised output [−1…1]", "−1…1", "normalised −1…1"),
                "normalised01": ("normalised output [0…1]", "0…1", "normalised 0…1"),
                "raw": ("output [raw command units, not µs]", "raw units", "raw command units")}
#: PWM pulse widths lie in this band (µs; 0 = output off); a channel outside it is not PWM
PWM_RANGE_US = (400.0, 2600.0)


def output_kind(values) -> str | None:
    """What an actuator output channel holds, from its values: ``pwm`` (every non-zero value
    within :data:`PWM_RANGE_US`), ``normalised`` (|v| ≤ 1 with a negative value: PX4's
    [−1, 1] outputs), ``normalised01`` (0 ≤ v ≤ 1), ``raw`` (anything else: ESC/UAVCAN command
    units, a simulator's 0…1000); ``None`` when the channel never leaves 0 (nothing to tell).

    The schema's ``servo_<i>_us`` holds what the autopilot logged: PWM µs for ArduPilot and
    PX4's PWM groups, other units for PX4's other outputs (the ULog reader writes them raw)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    nz = v[v != 0]
    if not len(nz):
        return None
    if np.abs(nz).max() <= 1.0:
        return "normalised" if nz.min() < 0 else "normalised01"
    if nz.min() >= PWM_RANGE_US[0] and nz.max() <= PWM_RANGE_US[1]:
        return "pwm"
    return "raw"


def actuator_outputs(control: pd.DataFrame | None, cols: list[str], title: str = "Actuator outputs (servo/ESC)"
                     ) -> go.Figure | None:
    """The actuator outputs ``cols`` (``servo_<i>_us``) of every instance of the ``control``
    stream that logs them, each channel on the axis of its unit (:func:`output_kind`): PWM in
    µs, normalised outputs and raw command units on axes of their own (dotted, dashed lines), so
    a PX4 log's [−1, 1] outputs are never labelled µs. Trace names carry the unit; an instance
    is named when more than one logs outputs (PX4 logs one per output group)."""
    if control is None or not len(control):
        return None
    cols = [c for c in cols if c in control]
    insts = sorted(control["instance"].dropna().unique()) if "instance" in control else [None]
    chans = []                                           # (instance, column, rows, kind)
    for inst in insts:
        rows = control if inst is None else control[control["instance"] == inst]
        for c in cols:
            if rows[c].notna().sum() >= 1:
                chans.append((inst, c, rows[["t_ns", c]].dropna(), output_kind(rows[c].to_numpy(np.float64))))
    if not chans:
        return None
    def commonest(ks: list) -> str | None:  # ties: in OUTPUT_KINDS order (never by set order)
        return max((k for k in OUTPUT_KINDS if k in ks), key=ks.count, default=None)

    kinds = [k for _, _, _, k in chans if k is not None]
    main = commonest(kinds)
    order = [k for k in OUTPUT_KINDS if k in kinds] or [None]
    if main in order:                                    # the commonest unit on the left axis
        order.remove(main)
        order.insert(0, main)
    many = len({i for i, _, _, _ in chans}) > 1
    mp = max(1000, 3 * MAX_POINTS // len(chans))
    fig = go.Figure()
    # an all-zero channel (an unused output) reads like the rest of its output group (instance)
    group = {inst: commonest([k for i, _, _, k in chans if i == inst and k is not None]) or order[0]
             for inst, _, _, _ in chans}
    for inst, c, rows, k in chans:
        k = k or group[inst]
        d = decimate(rows, mp, cols=[c], breaks=True)
        words = label(c).split(" [")[0] + (f" (instance {int(inst)})" if many else "")
        unit = OUTPUT_KINDS[k][1] if k else "as logged"
        ax = order.index(k)
        # a channel keeps its colour on every axis; the line style tells the axes apart
        fig.add_trace(go.Scatter(x=_t(d), y=d[c], mode="lines", name=f"{words} [{unit}]",
                                 yaxis="y" if ax == 0 else f"y{ax + 1}",
                                 line=dict(color=colour(c), dash=(None, "dot", "dash")[min(ax, 2)])))
    titles = [OUTPUT_KINDS[k][0] if k else "output [as logged]" for k in order]
    extra = unit_axes(fig, titles)
    fig.update_xaxes(title="t [s]")
    kinds_text = ", ".join(OUTPUT_KINDS[k][2] for k in order if k)
    return layout(fig, f"{title}: {kinds_text}" if kinds_text else title, **extra)


#: MAV_SEVERITY / syslog levels
SEVERITY = ("emergency", "alert", "critical", "error", "warning", "notice", "info", "debug")


def messages_table(msgs: pd.DataFrame | None) -> tuple[list[str], list[list[str]]]:
    """The log's text messages as ``(headers, rows)``: time [s], severity, text (time order)."""
    headers = ["t [s]", "severity", "text"]
    if msgs is None or not len(msgs):
        return headers, []
    m = msgs.sort_values("t_ns", kind="stable")
    rows = []
    for t, sev, text in zip(m["t_ns"].to_numpy(), m["severity"].to_numpy(np.float64, na_value=np.nan),
                            m["text"].astype(object).to_numpy()):
        s = SEVERITY[int(sev)] if np.isfinite(sev) and 0 <= sev < len(SEVERITY) else "–"
        rows.append([f"{t * 1e-9:.3f}", s, "" if text is None or text is pd.NA else str(text)])
    return headers, rows


def param_text(v) -> str:
    """A parameter value as text that never hides a digit: an integer as an integer
    (``20261120``, not ``2.026112e+07``); a value a float32 holds exactly (the autopilots store
    parameters as float32) as the shortest text that reads back to that float32 (``0.15``, not
    ``0.15000000596046448``); any other float as Python's shortest round-trip ``repr``. Two
    float32 values give two texts, as do two float64 values; :func:`param_texts` keeps a row of
    mixed ones apart."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        return "–" if v is None else str(v)
    if not np.isfinite(x):
        return "NaN" if np.isnan(x) else ("∞" if x > 0 else "−∞")
    if x.is_integer() and abs(x) < 2.0 ** 53:
        return str(int(x))
    x32 = np.float32(x)
    if np.isfinite(x32) and float(x32) == x:
        return np.format_float_positional(x32, unique=True, trim="-") if 1e-5 <= abs(x) < 1e16 \
            else np.format_float_scientific(x32, unique=True, trim="-")
    return repr(x)


def param_texts(values) -> list[str]:
    """:func:`param_text` of each value, except that values which differ always read
    differently (a float32's short text can equal another float64's ``repr``: then every
    non-integer value of the row is written as its float64 ``repr``)."""
    out = [param_text(v) for v in values]
    seen: dict[str, float] = {}
    for v, t in zip(values, out):
        try:
            x = float(v)
        except (TypeError, ValueError):
            continue
        if t in seen and seen[t] != x and not (np.isnan(x) and np.isnan(seen[t])):
            return [t if t in ("–", "NaN") or t.lstrip("-").isdigit() else repr(float(v))
                    for v, t in zip(values, out)]
        seen[t] = x
    return out


def params_table(params: pd.DataFrame | None) -> tuple[list[str], list[list[str]]]:
    """The parameters as ``(headers, rows)``: name, last value, time of that value [s], and
    how many times it was set (sorted by name)."""
    headers = ["name", "value", "t [s]", "times set"]
    if params is None or not len(params):
        return headers, []
    p = params.dropna(subset=["name"]).sort_values("t_ns", kind="stable")
    rows = []
    for name, g in p.groupby(p["name"].astype(str), sort=True):
        last = g.iloc[-1]
        rows.append([name, param_text(last["value"]), f"{int(last['t_ns']) * 1e-9:.3f}", str(len(g))])
    return headers, rows


def time_series(df: pd.DataFrame, cols: list[str], title: str, ylabel: str) -> go.Figure | None:
    """Generic multi-column time series of one stream (first instance)."""
    if df is None or not len(df):
        return None
    df = df[df["instance"] == df["instance"].min()] if "instance" in df else df
    cols = [c for c in cols if c in df and df[c].notna().any()]
    if not cols:
        return None
    # each trace keeps its own extremes; many channels (RC, servos) share one panel's budget
    # (at least 1000 points each), so a 32-output log does not make a 30 MB page
    mp = max(1000, 3 * MAX_POINTS // len(cols))
    fig = go.Figure()
    for c in cols:
        d = decimate(df[["t_ns", c]], mp, cols=[c], breaks=True)
        fig.add_trace(go.Scatter(x=_t(d), y=d[c], mode="lines", name=label(c), line=dict(color=colour(c))))
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title=ylabel)
    return layout(fig, title)


#: maneuver-label colours: plotly's Dark24 without its near-black (the confidence line's colour)
#: and its two pinks closest to the unknown grey and each other; F3A schedules hold ~17 maneuvers,
#: which 10 colours (the default cycle) could not tell apart
LABEL_PALETTE = ("#2E91E5", "#E15F99", "#1CA71C", "#FB0D0D", "#DA16FF", "#B68100", "#750D86", "#EB663B",
                 "#511CFB", "#00A08B", "#FB00D1", "#FC0080", "#B2828D", "#6C7C32", "#778AAE", "#862A16",
                 "#A777F1", "#620042", "#1616A7", "#DA60CA", "#6C4516", "#0D2A63", "#AF0038")
#: the classifier's confidence line, apart from every label colour
CONFIDENCE_COLOUR = "#222222"


def label_colour(lab: str) -> str:
    """The colour of one maneuver label alone (its hash into :data:`LABEL_PALETTE`; ``unknown``:
    grey). A panel of several labels takes :func:`label_colours`, which keeps them apart."""
    import zlib

    if str(lab) == "unknown":
        return "#999999"
    return LABEL_PALETTE[zlib.crc32(str(lab).encode()) % len(LABEL_PALETTE)]


def label_colours(labels) -> dict[str, str]:
    """``{label: colour}`` for the labels of one panel, no two alike while the palette lasts.

    Each label (in sorted order) takes its :func:`label_colour`, or on a clash the next free
    colour of the palette: a label has the same colour on every panel of the same label set
    (a flight's segments and its classifier, a schedule's pages), and on any panel where its own
    colour is free. ``unknown`` stays grey."""
    out: dict[str, str] = {}
    taken: set[str] = set()
    n = len(LABEL_PALETTE)
    for lab in sorted({str(x) for x in labels}):
        if lab == "unknown":
            out[lab] = label_colour(lab)   # grey
            continue
        k = LABEL_PALETTE.index(label_colour(lab))
        for j in range(n):
            c = LABEL_PALETTE[(k + j) % n]
            if c not in taken or len(taken) >= n:
                break
        out[lab] = c
        taken.add(c)
    return out


#: the width of one character of a 9 pt band name, and the least space between two names, as
#: fractions of a panel's span (a 1000 px plot area: ~5.8 px a character, 10 px apart)
LABEL_CHAR = 0.0058
LABEL_PAD = 0.01


def spaced_labels(at: np.ndarray, width: np.ndarray, span: float, texts, *, align: str = "centre") -> np.ndarray:
    """Which of the names ``texts`` placed at ``at`` (centred on it, or starting there with
    ``align="left"``) on a panel ``span`` wide to write so that no two written ones overlap
    (:data:`LABEL_CHAR` a character, :data:`LABEL_PAD` apart): the widest bands (``width``)
    first, a band of zero or negative width never. Returns a boolean mask in the order of
    ``at``. A band left unnamed keeps its colour and its hover text."""
    at, width = np.asarray(at, np.float64), np.asarray(width, np.float64)
    n_chars = np.array([len(str(t)) for t in texts], dtype=np.float64)
    span = max(float(span), 1e-9)
    say = np.zeros(len(at), dtype=bool)
    for i in np.argsort(-width, kind="stable"):
        if width[i] <= 0:
            continue
        j = np.flatnonzero(say)
        if align == "left":    # the name written first along the axis must end before the next starts
            first = np.where(at[j] <= at[i], n_chars[j], n_chars[i])
            room = first * LABEL_CHAR * span
        else:
            room = 0.5 * (n_chars[j] + n_chars[i]) * LABEL_CHAR * span
        if not (np.abs(at[j] - at[i]) < room + LABEL_PAD * span).any():
            say[i] = True
    return say


def mode_bands(fig: go.Figure, mode: pd.DataFrame | None, t_end_s: float | None = None) -> go.Figure:
    """Shade the flight-mode intervals of ``mode`` (the canonical ``mode`` stream) behind a time
    panel, one colour per mode name, the name written at the top of each band. Returns ``fig``."""
    m = _first(mode)
    if fig is None or m is None or "mode" not in m:
        return fig
    m = m.dropna(subset=["mode"]).sort_values("t_ns", kind="stable")
    if not len(m):
        return fig
    t = m["t_ns"].to_numpy() * 1e-9
    names = m["mode"].astype(str).to_numpy()
    keep = np.r_[True, names[1:] != names[:-1]]    # a repeated record continues its band
    t, names = t[keep], names[keep]
    end = np.r_[t[1:], max(t_end_s if t_end_s is not None else t[-1], t[-1])]
    # a name is written only where it does not run into another, the longest bands first:
    # modes switched within seconds (STABILIZE, LOITER at take-off) printed their names over
    # each other; the segments timeline's bars carry every name as hover text
    named = spaced_labels(t, end - t, float(end[-1] - t[0]), names, align="left")
    shown = end > t
    t0s, t1s, ns = t[shown], end[shown], names[shown]
    colours = [label_colour(f"mode {n}") for n in ns]
    for t0, t1, name, colour, say in zip(t0s, t1s, ns, colours, named[shown]):
        note = dict(annotation_text=name, annotation_position="top left", annotation_font_size=9) if say else {}
        fig.add_vrect(x0=t0, x1=t1, fillcolor=colour, opacity=0.08, line_width=0, layer="below", **note)
    if len(t0s):
        # a shape has no hover text, and the bands too short for their name were nameless:
        # one marker at the top edge of each band names its mode and times on hover. It sits
        # on an axis of its own, fixed at [0, 1] and hidden, so the panel's y range and its
        # unit axes (y, y2, y3) stay as they were
        axis = _free_yaxis(fig)
        fig.add_trace(go.Scatter(
            x=0.5 * (t0s + t1s), y=np.ones(len(t0s)), yaxis=f"y{axis}", mode="markers",
            marker=dict(symbol="triangle-down", size=7, color=colours),
            cliponaxis=False, showlegend=False, name="flight mode", hoverinfo="text",
            hovertext=[f"mode {n}<br>{a:.1f}–{b:.1f} s ({b - a:.1f} s)" for n, a, b in zip(ns, t0s, t1s)]))
        fig.update_layout({f"yaxis{axis}": dict(overlaying="y", range=[0, 1], visible=False, fixedrange=True)})
    return fig


def _free_yaxis(fig: go.Figure) -> int:
    """The smallest y-axis number (≥ 2) that no axis of ``fig``'s layout uses."""
    used = {1}
    for key in fig.layout.to_plotly_json():
        if key.startswith("yaxis"):
            used.add(int(key[5:] or 1))
    return next(i for i in range(2, len(used) + 2) if i not in used)


#: the timeline rows of the segments table (``pipeline.preprocess.segment``): flight-mode runs
#: (labels ``mode:<name>``) and the labelled maneuvers (labels stream, simulation truth, windows)
MODE_SEGMENTS_ROW = "segments: flight mode"
LABEL_SEGMENTS_ROW = "segments: maneuvers"


def timeline(segments: pd.DataFrame | None, classified: pd.DataFrame | None = None) -> go.Figure | None:
    """Maneuver timeline: the segments as bars, flight-mode runs (``mode:<name>``) on their own
    row apart from the labelled maneuvers; the classifier's label and confidence if given."""
    fig = go.Figure()
    colours = label_colours([*(segments["label"].astype(str) if segments is not None and len(segments) else []),
                             *(classified["label"].astype(str).unique() if classified is not None and len(classified) else [])])
    if segments is not None and len(segments):
        t0s = segments["t_start_ns"].to_numpy(np.float64) * 1e-9
        t1s = segments["t_end_ns"].to_numpy(np.float64) * 1e-9
        labs = segments["label"].astype(str).to_numpy()
        is_mode = np.char.startswith(labs.astype(str), "mode:")
        texts = np.array([lab[len("mode:"):] if m else lab for lab, m in zip(labs, is_mode)], dtype=object)
        # each row's names apart from each other (a 2 s LOITER between two modes wrote its name
        # over theirs); every bar keeps its hover text
        say = np.zeros(len(labs), dtype=bool)
        span = float(np.nanmax(t1s) - np.nanmin(t0s)) if len(labs) else 0.0
        for row_mask in (is_mode, ~is_mode):
            idx = np.flatnonzero(row_mask)
            say[idx] = spaced_labels(0.5 * (t0s[idx] + t1s[idx]), t1s[idx] - t0s[idx], span, texts[idx])
        for t0, t1, lab, text, mode_row, named in zip(t0s, t1s, labs, texts, is_mode, say):
            row = MODE_SEGMENTS_ROW if mode_row else LABEL_SEGMENTS_ROW
            fig.add_trace(go.Scatter(x=[t0, t1], y=[row, row], mode="lines",
                                     line=dict(width=14, color=colours[lab]),
                                     name=lab, showlegend=False, hovertext=lab))
            if named:
                fig.add_annotation(x=(t0 + t1) / 2, y=row, text=text, showarrow=False, yshift=14,
                                   font=dict(size=9))
    if classified is not None and len(classified):
        d = decimate(classified)
        for lab, g in d.groupby(d["label"].astype(str), sort=True):
            fig.add_trace(go.Scatter(x=_t(g), y=["classifier"] * len(g), mode="markers",
                                     marker=dict(size=6, color=colours[lab]),
                                     text=[lab] * len(g), name=f"classifier: {lab}"))
        if "confidence" in d:
            fig.add_trace(go.Scatter(x=_t(d), y=d["confidence"], mode="lines", name="confidence V", yaxis="y2",
                                     line=dict(color=CONFIDENCE_COLOUR, width=1)))
            fig.update_layout(yaxis2=right_axis("V [log10]"))
    if not fig.data:
        return None
    fig.update_xaxes(title="t [s]")
    return layout(fig, "Maneuver timeline", height=260)


#: estimator name -> legend label of the estimate panels
ESTIMATOR_LABELS = {"ekf": "EKF", "ekf_rts": "EKF + RTS", "ekf_hmm": "EKF+HMM", "pf_jm": "jump-Markov PF"}
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
        d = decimate(df, breaks=True)
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
    colours = label_colours(d["pred"].astype(str).unique())
    for lab, g in d.groupby(d["pred"].astype(str), sort=True):
        fig.add_trace(go.Scatter(x=_t(g), y=["classifier"] * len(g), mode="markers",
                                 marker=dict(size=6, color=colours[lab]), name=f"classifier: {lab}"))
    if d["V_best"].notna().any():
        fig.add_trace(go.Scatter(x=_t(d), y=d["V_best"], mode="lines", name="confidence V", yaxis="y2",
                                 line=dict(color=CONFIDENCE_COLOUR, width=1)))
        fig.update_layout(yaxis2=right_axis("V [log10]"))
    fig.update_xaxes(title="t [s]")
    n = int(df["mode"].astype(bool).sum())
    return layout(fig, f"EKF+HMM mode ({n} of {count_text(len(df), 'step')} with HMM inputs)", height=280)


#: colours of the particle-filter motion modes (issue 17)
PF_MODE_COLOURS = {"cv": "#1f77b4", "ca": "#ff7f0e", "ct": "#2ca02c", "stop": "#7f7f7f"}


def pf_mode_fractions(df: pd.DataFrame | None, name: str = "PF") -> go.Figure | None:
    """Particle-filter mode fractions ``mode_p_<mode>`` stacked to 1 (left axis) and, where the
    flight is classified, the classifier's softmax ``cls_p_<label>`` as dotted lines on the right
    axis (a different class set: maneuvers, not motion modes)."""
    if df is None or not len(df):
        return None
    modes = [c for c in df.columns if str(c).startswith("mode_p_")]
    if not modes:
        return None
    cls = [c for c in df.columns if str(c).startswith("cls_p_") and df[c].notna().any()]
    d = decimate(df[["t_ns", *modes, *cls]], cols=[*modes, *cls])
    fig = go.Figure()
    for c in modes:
        m = c[len("mode_p_"):]
        fig.add_trace(go.Scatter(x=_t(d), y=d[c], mode="lines", stackgroup="modes", name=f"{name}: {m.upper()}",
                                 line=dict(width=0.5, color=PF_MODE_COLOURS.get(m))))
    cls_colours = label_colours(c[len("cls_p_"):] for c in cls)
    for c in cls:
        lab = c[len("cls_p_"):]
        fig.add_trace(go.Scatter(x=_t(d), y=d[c], mode="lines", name=f"classifier: {lab}", yaxis="y2",
                                 line=dict(dash="dot", color=cls_colours[lab])))
    if cls:
        fig.update_layout(yaxis2=right_axis("classifier softmax", range=[0, 1]))
    fig.update_xaxes(title="t [s]")
    fig.update_layout(yaxis=dict(range=[0, 1], title="mode fraction"))
    return layout(fig, f"{name} mode fractions" + (" beside the classifier" if cls else ""), height=300)


# -- issue 17: seed-003 weave classifier (hmpf) ---------------------------------------------------

def weave_af(df: pd.DataFrame | None, tau: float = 0.269, startup_steps: int = 25) -> go.Figure | None:
    """hmpf detector: the windowed weave fraction AF(k) with the τ line (start-up steps blanked),
    the per-step weave fraction F(k) and the flagged steps."""
    if df is None or not len(df):
        return None
    t = _t(df)
    k = np.arange(len(df))
    af = np.where(k >= startup_steps, df["af"].to_numpy(np.float64), np.nan)
    fig = go.Figure()
    fig.add_trace(go.Scatter(x=t, y=df["mode_p_W"], mode="lines", line=dict(width=1, color="#bbbbbb"),
                             name="weave fraction F(k)"))
    fig.add_trace(go.Scatter(x=t, y=af, mode="lines", line=dict(color="#d62728"), name="AF(k)"))
    flag = df["weave_detected"].astype(bool).to_numpy()
    if flag.any():
        fig.add_trace(go.Scatter(x=t[flag], y=np.full(int(flag.sum()), 1.02), mode="markers",
                                 marker=dict(size=4, color="#d62728"), name="weave declared"))
    fig.add_hline(y=tau, line_dash="dash", annotation_text=f"τ = {tau:g}")
    fig.update_xaxes(title="t [s]")
    fig.update_yaxes(title="fraction", range=[0, 1.05])
    return layout(fig, f"Weave classifier (hmpf): AF(k) ≥ τ on {100 * flag.mean():.0f} % of steps", height=280)
