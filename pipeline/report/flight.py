"""Per-flight HTML report: path, ground track, altitude (+ BPM points), attitude, sensors, timeline.

Plotly is not inlined per page: every report references one local copy of ``plotly.min.js``
(written by :func:`write_plotly_js`) by a relative URL, so the reports open offline from
``file://`` and the results folder stays small.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from ..estimate.pf_run import classifier_softmax
from ..frames.rotations import quat_to_euler
from ..io import schema
from ..io.parquet import read_flightlog, read_table, read_table_meta
from .flight_summary import (PATH_BIN_S, PATH_NOISE_K, diagnostics_text, first_instance, flight_numbers,
                             ned_track, numbers_script, plain_text, summary_rows, velocity_track, without_edges)
from .pages import count_text, figure_divs, render, vector_text, write_page
from . import plots

#: the 9 CA state columns (pos, vel, acc NED) of the state table and the truth stream
_STATE9 = tuple(f"{q}_{a}_{u}" for q, u in (("pos", "m"), ("vel", "mps"), ("acc", "mps2")) for a in "ned")


def write_plotly_js(path: str | os.PathLike) -> None:
    """Write plotly's bundled JavaScript (from the installed package, no network) to ``path``."""
    from plotly.offline import get_plotlyjs

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(get_plotlyjs())


#: frame notes of the flight page's titles: body-frame panels come from the preprocessed state
#: (mount applied); raw streams keep the frame the sensor or the autopilot logged them in
STATE_FRAME = "state: body FRD, mount-corrected"
SENSOR_FRAME = "raw, sensor frame"


def _body_rates(state: pd.DataFrame | None, imu: pd.DataFrame) -> tuple[pd.DataFrame | None, str]:
    """Body rates p, q, r and the frame they are in: the state's (mount-corrected FRD) where
    preprocessed, else the first gyro's ``gyr_{x,y,z}_radps`` as logged (sensor frame)."""
    cols = ["p_radps", "q_radps", "r_radps"]
    if state is not None and len(state) and set(cols) <= set(state.columns) and state["p_radps"].notna().any():
        return state[["t_ns", *cols]], STATE_FRAME
    g = first_instance(imu)
    if not len(g):
        return None, SENSOR_FRAME
    return pd.DataFrame({"t_ns": g["t_ns"].to_numpy(), **{c: g[f"gyr_{a}_radps"].to_numpy()
                                                          for c, a in zip(cols, "xyz")}}), SENSOR_FRAME


def attitude_source(state: pd.DataFrame | None, log) -> tuple[pd.DataFrame | None, tuple | None, str]:
    """The attitude a flight page plots: ``(rows with t_ns, (roll, pitch, yaw) [rad], frame note)``.

    The preprocessed state's ZYX angles of the mount-corrected body (FRD -> NED) where the
    flight has a state with attitude; else the ``attitude`` stream as logged, whose body may be
    the sensor's (the Husky's IMU orientation is the rotated ``imu_link``: roll ≈ +90° at rest)."""
    cols = ["roll_rad", "pitch_rad", "yaw_rad"]
    if state is not None and len(state) and set(cols) <= set(state.columns) and state["roll_rad"].notna().any():
        s = state.dropna(subset=cols)
        return s[["t_ns"]], tuple(s[c].to_numpy(np.float64) for c in cols), STATE_FRAME
    att = first_instance(log["attitude"]).dropna(subset=["q_w"])
    if not len(att):
        return None, None, SENSOR_FRAME
    return att[["t_ns"]], quat_to_euler(att[["q_w", "q_x", "q_y", "q_z"]].to_numpy()), \
        "attitude stream as logged, not mount-corrected"


#: the barometer's start datum: the median of its first second of valid samples
BARO_DATUM_S = 1.0


def baro_relative(baro: pd.DataFrame | None, track: pd.DataFrame | None = None, *,
                  ref_name: str = "the track's height") -> tuple[pd.DataFrame, str] | None:
    """The barometric altitude of the altitude panel: ``(DataFrame(t_ns, alt_m), legend name)``.

    The first instance's ``alt_rel_m`` less its start (the median of its first
    :data:`BARO_DATUM_S` of valid samples), plus the reference height ``track`` (``t_ns``,
    ``alt_m``: the calibrated height, else the track's −d) over that same second where it has
    one, so the baro shares the panel's axis with the track, the calibrated height and the
    calibration points (the legend names it by ``ref_name``). Without that term a flight whose
    NED origin is not where it starts (a simulated flight begins in the air, 20 m above its
    origin) drew its baro 20 m below everything else. The raw value's datum differs by source:
    a ULog's is the ISA pressure altitude (1013.25 hPa: hundreds of metres), a DataFlash log's
    the ground at arming; the legend names the shift. ``None`` without a valid sample."""
    b = first_instance(baro)
    if b is None or not len(b) or "alt_rel_m" not in b:
        return None
    b = b[["t_ns", "alt_rel_m"]].dropna()
    b = b[np.isfinite(b["alt_rel_m"].to_numpy(np.float64))]
    if not len(b):
        return None
    t = b["t_ns"].to_numpy(np.int64)
    v = b["alt_rel_m"].to_numpy(np.float64)
    t_end = t[0] + int(BARO_DATUM_S * 1e9)
    datum = float(np.median(v[t <= t_end]))
    start = 0.0
    if track is not None and len(track):
        tt = track["t_ns"].to_numpy(np.int64)
        h = track["alt_m"].to_numpy(np.float64)
        h = h[(tt >= t[0]) & (tt <= t_end) & np.isfinite(h)]
        start = float(np.median(h)) if len(h) else 0.0
    shift = start - datum
    name = (f"baro (raw, shifted {shift:+.1f} m to start at {ref_name})" if start
            else f"baro (raw, relative to its start: {datum:+.1f} m subtracted)")
    return pd.DataFrame({"t_ns": t, "alt_m": v + shift}), name


def altitude_panel(series: Mapping[str, pd.DataFrame], calib_pts: pd.DataFrame | None, *,
                   ground: bool = False):
    """The altitude panel (:func:`plots.altitude`); for a ground vehicle its title says that
    the heights drawn are the sensors' (husky-ros1's GPS height wanders 35 m over a 347 m
    drive), as the summary table already leaves its altitude and climb out."""
    fig = plots.altitude(dict(series), calib_pts)
    if fig is not None and ground:
        fig.update_layout(title="Altitude (a ground vehicle: the sensors' height, not a climb)")
    return fig


def _spectrogram_panel(imu: pd.DataFrame, cols: list[str], name: str, unit: str) -> tuple[str, object]:
    """``(title, figure or None)`` of one IMU spectrogram at the IMU's own rate; without a
    figure the title says why (an IMU logged too slowly for a spectrum, too few samples)."""
    title = f"{name} (raw, sensor frame)"
    fig = plots.spectrogram(imu, cols, title, unit)
    why = None if fig is not None else plots.spectrogram_absent(imu, cols)
    return (f"{name} (raw, sensor frame; {why})" if why else title), fig


def calibration_table(preprocess: Mapping | None) -> tuple[str, list[str], list[list[str]]]:
    """The barometric calibration of a flight as a page table ``(title, headers, rows)``: one
    row per region of the fitted offset (time span, offset, drift, RMS of the fit, points used),
    from the ``calibration`` diagnostics of the preprocessed state's metadata
    (:meth:`pipeline.preprocess.calibrate.Calibration.info`). The title names the method, the
    points used of the candidates and the notes; no rows when nothing was fitted."""
    c = (preprocess or {}).get("calibration") or {}
    headers = ["region", "t start [s]", "t end [s]", "offset [m]", "drift [m/s]", "RMS of fit [m]", "points used"]
    if not c:
        return "Barometric calibration (no preprocess diagnostics)", headers, []

    def num(v, spec):
        try:
            v = float(v)
        except (TypeError, ValueError):
            return "–"
        return f"{v:{spec}}" if np.isfinite(v) else "–"

    rows = [[str(r.get("region", i)), num(r.get("t_start_s"), ".1f"), num(r.get("t_end_s"), ".1f"),
             num(r.get("offset_m"), "+.3f"), num(r.get("drift_mps"), "+.5f"), num(r.get("rms_m"), ".3f"),
             str(r.get("n_points", "–"))] for i, r in enumerate(c.get("regions") or [])]
    how = {"rangefinder": "against the rangefinder", "gps": "against GPS height",
           "uncalibrated": "not calibrated", "none": "no barometer"}.get(c.get("method"), str(c.get("method")))
    parts = [how]
    if c.get("n_candidates"):
        parts.append(f"{c.get('n_used', 0)} of {count_text(c['n_candidates'], 'candidate point')} used")
    parts += [t for t in (plain_text(n) for n in c.get("notes") or []) if t != how]   # "no barometer" once
    return f"Barometric calibration ({'; '.join(parts)})", headers, rows


def _error_norms(est: pd.DataFrame, ref_t: np.ndarray, ref: np.ndarray) -> pd.DataFrame:
    """Per-step error norms of position, velocity, acceleration of an ``estimate`` table against
    a reference track (``ref`` (N, 9) at ``ref_t``, linearly interpolated; NaN outside it)."""
    t = est["t_ns"].to_numpy(np.int64)
    x = est[[f"x_{c}" for c in _STATE9]].to_numpy(np.float64)
    r = np.full_like(x, np.nan)
    inside = (t >= ref_t[0]) & (t <= ref_t[-1]) if len(ref_t) else np.zeros(len(t), bool)
    for j in range(9):
        ok = np.isfinite(ref[:, j])
        if ok.sum() >= 2:
            r[inside, j] = np.interp(t[inside], ref_t[ok], ref[ok, j])
    e = x - r
    return pd.DataFrame({"t_ns": t, **{g: np.linalg.norm(e[:, sl], axis=1)
                                        for g, sl in (("pos", slice(0, 3)), ("vel", slice(3, 6)), ("acc", slice(6, 9)))}})


def estimate_panels(estimates: Mapping[str, str | os.PathLike], *, truth: pd.DataFrame | None,
                    state: pd.DataFrame | None,
                    classified: Mapping[str, str | os.PathLike] | None = None) -> tuple[list, list]:
    """The estimate panels of a flight page and their facts: ``([(title, figure or None)],
    [(key, text)])``.

    Error norms per group (position, velocity, acceleration) for every estimator, against the
    reference its metadata names (``truth``: the ingest truth stream, ``state``: the
    preprocessed state); the EKF+HMM mode timeline; the weave classifier's AF(k) with its τ
    line (estimator ``hmpf``, issue 17). A panel without data keeps a title that says why
    (placeholder reason, no reference)."""
    estimates = dict(estimates)
    hm = estimates.pop("hmpf", None)
    if hm:
        figs, facts = estimate_panels(estimates, truth=truth, state=state)
        # the weave classifier is this flight's estimate: no "not in estimate.vehicles" line above it
        figs = [f for f in figs if f[1] is not None or not f[0].startswith(NO_EKF_TITLE)]
        wf, wfa = weave_panels(hm)
        return figs + wf, facts + wfa
    estimates = {e: p for e, p in estimates.items() if p and Path(p).exists()}
    # the particle filters (issue 17) have their own table (``pf``) and panels
    pf = {e: estimates.pop(e) for e in [e for e in estimates if e in PF_ESTIMATORS]}
    pf_figs, pf_facts = pf_panels(pf, classified)
    if not estimates:
        return [(NO_EKF_TITLE, None), *pf_figs], pf_facts
    tables, metas = {}, {}
    for e, p in estimates.items():
        metas[e] = read_table_meta(p)
        tables[e] = read_table(p)
    facts = []
    for e, m in metas.items():
        label = plots.ESTIMATOR_LABELS.get(e, e)
        if m.get("status") == "failed":
            facts.append((label, f"placeholder: {m.get('error')}"))
        else:
            facts.append((label, f"{count_text(m.get('n_steps'), 'step')} ({m.get('n_predict_only')} predict-only), radar "
                                 f"{m.get('radar')} (site {vector_text(m.get('radar_site_ned_m'), 'm NED')} from {m.get('radar_site_from')}), "
                                 f"q {m.get('q')}, reference {m.get('reference')}"))
    ok = {e: t for e, t in tables.items() if len(t)}
    ref_name = next((metas[e].get("reference") for e in ok), None)
    src = truth if ref_name == "truth" else state if ref_name == "state" else None
    figs = []
    if not ok:
        reason = next(iter(metas.values())).get("error") or "no estimates"
        figs.append((f"Estimation error (no estimates: {reason})", None))
    elif src is None or not len(src):
        figs.append(("Estimation error (no reference: no truth, and the radar is not synthesised from the state)", None))
    else:
        ref = src[list(_STATE9)].to_numpy(np.float64)
        errs = {e: _error_norms(t, src["t_ns"].to_numpy(np.int64), ref) for e, t in ok.items()}
        for g in ("pos", "vel", "acc"):
            figs.append((f"Estimation error ({g})", plots.estimate_error(errs, g, ref_name)))
    if "ekf_hmm" in metas:
        h = tables["ekf_hmm"]
        why = metas["ekf_hmm"].get("error") if metas["ekf_hmm"].get("status") == "failed" else None
        figs.append((f"EKF+HMM mode timeline ({why})" if why else "EKF+HMM mode timeline",
                     plots.mode_timeline(h) if len(h) else None))
    return figs + pf_figs, facts + pf_facts


#: the particle-filter estimators (``results/estimate/<name>/``, table ``pf``)
PF_ESTIMATORS: tuple[str, ...] = ("pf_jm",)


def pf_panels(estimates: Mapping[str, str | os.PathLike],
              classified: Mapping[str, str | os.PathLike] | None = None) -> tuple[list, list]:
    """The particle-filter panels and facts of a flight page: the weighted mode fractions per
    step beside the classifier's softmax of its ``ll_<label>`` where the flight is classified
    (the table's own ``cls_p_*`` columns, else those of the first classification that is not
    a placeholder, ``classified`` {model set: path}); a placeholder keeps a title with its reason."""
    figs, facts = [], []
    cls_set, cls_table = None, None
    for ms, cp in (classified or {}).items():
        if cp and Path(cp).exists() and read_table_meta(cp).get("status") != "failed":
            c = read_table(cp)
            if len(c):
                cls_set, cls_table = ms, c
                break
    for e, p in estimates.items():
        m, t = read_table_meta(p), read_table(p)
        if len(t) and cls_table is not None and not any(str(c).startswith("cls_p_") for c in t.columns):
            t = t.assign(**classifier_softmax(cls_table, t["t_ns"].to_numpy(np.int64)))
            m = {**m, "classifier": cls_set}
        label = plots.ESTIMATOR_LABELS.get(e, e)
        if m.get("status") == "failed" or not len(t):
            facts.append((label, f"placeholder: {m.get('error')}"))
            figs.append((f"{label} mode fractions (placeholder: {m.get('error')})", None))
            continue
        fr = m.get("mode_fraction_mean") or {}
        facts.append((label, f"{count_text(m.get('n_steps'), 'step')}, N = {m.get('n_particles')}, {m.get('n_resampled')} resampled "
                             f"({m.get('resample')}, N_eff < {float(m.get('threshold', 0)):.2f} N), "
                             f"{m.get('n_predict_only')} predict-only, {m.get('n_reinit')} re-initialised; "
                             f"mean fractions " + ", ".join(f"{k} {v:.2f}" for k, v in fr.items())
                             + (f"; classifier {m.get('classifier')}" if m.get("classifier") else "")))
        figs.append((f"{label} mode fractions", plots.pf_mode_fractions(t, label)))
    return figs, facts


def rangefinder_height(rangefinder: pd.DataFrame | None) -> pd.DataFrame | None:
    """``DataFrame(t_ns, alt_m)`` of the first rangefinder's distances for the altitude panel,
    NaN where the reading is flagged invalid; ``None`` without a valid reading.

    An out-of-range reading is logged at the sensor's limit (ArduPilot: ``RNGFND1_MAX_CM``), not
    at a height: 495 of the 600 demo-quad samples sat at 7 m."""
    rf = first_instance(rangefinder) if rangefinder is not None else None
    if rf is None or not len(rf) or "dist_m" not in rf:
        return None
    d = rf["dist_m"]
    if "valid" in rf:
        d = d.where(rf["valid"].fillna(True).astype(bool))
    return pd.DataFrame({"t_ns": rf["t_ns"], "alt_m": d}) if d.notna().any() else None


#: the estimate panel's title on a flight no EKF runs on
NO_EKF_TITLE = "Estimates (the flight's vehicle is not in estimate.vehicles)"


def weave_panels(path: str | os.PathLike) -> tuple[list, list]:
    """The hmpf (seed-003 weave classifier) panel and fact of a flight page (issue 17)."""
    if not Path(path).exists():
        return [], []
    meta, df = read_table_meta(path), read_table(path)
    if meta.get("status") == "failed" or not len(df):
        return [(f"Weave classifier (no estimate: {meta.get('reason')})", None)], \
            [("hmpf", f"placeholder: {meta.get('reason')}")]
    first = meta.get("first_detection_t_ns")
    fact = (f"{count_text(meta.get('n_steps'), 'step')} of {meta.get('dt_s')} s, δ_max {meta.get('delta_max_m', 0):.0f} m, "
            f"θ_max {meta.get('theta_max_rad', 0):.2f} rad ({meta.get('maxima_source')}), first weave "
            + (f"at {first / 1e9:.0f} s" if first is not None else "never") +
            f", flagged {100 * meta.get('fraction_flagged', 0):.0f} % of steps; "
            + (f"σ_aT/σ_aN/σ_xy {meta['sigma_at_mps2']:.2f}/{meta['sigma_an_mps2']:.2g}/{meta['sigma_axy_mps2']:.2f} m/s² "
               f"({meta.get('noise_source')}), " if "sigma_at_mps2" in meta else "")
            + f"{meta.get('n_reinit')} re-initialised")
    return [("Weave classifier AF(k)", plots.weave_af(df, meta.get("tau", 0.269), meta.get("startup_steps", 25)))], \
        [("hmpf", fact)]


# --- issue 13 item 2: the estimator-flags panel ---------------------------------------------

#: the flag columns of the ``estimator_status`` stream as the panel names them
_FLAG_WORDS = {"solution_flags": "solution", "fault_flags": "fault", "innovation_fail_flags": "rejected",
               "gps_check_flags": "GPS check failed", "timeout_flags": "timed out", "control_mode_flags": "mode"}
#: the innovation test ratios (``<x>_test_ratio``) in words
_RATIO_WORDS = {"vel": "velocity", "pos": "horizontal position", "hgt": "height", "mag": "magnetometer",
                "hdg": "heading", "tas": "true airspeed", "hagl": "height above ground"}
ESTIMATOR_FLAGS_TITLE = "Estimator flags (EKF status, XKF flags, estimator_status)"
ESTIMATOR_RATIOS_TITLE = "Estimator innovation test ratios"


def _set_intervals(t_s: np.ndarray, on: np.ndarray) -> list:
    """x values (``None``-separated segments) of the intervals where ``on`` holds: a sample
    that sets the bit starts a segment, the next sample that clears it (or the last sample) ends it."""
    xs: list = []
    k = np.flatnonzero(np.diff(np.r_[False, on, False].astype(np.int8)))
    for a, b in zip(k[::2], k[1::2]):
        xs.extend((round(float(t_s[a]), 3), round(float(t_s[min(b, len(t_s) - 1)]), 3), None))
    return xs


def estimator_flag_panels(est: pd.DataFrame | None, meta: dict | None = None) -> list[tuple[str, object]]:
    """The estimator-flags panels of a flight page from its ``estimator_status`` stream.

    One band per (lane, flag column, bit) that is ever set, drawn over the intervals where it
    is set (a bit holds from the report that sets it to the report that clears it), named by
    :mod:`pipeline.io.estimator_bits` for the row's source (``src``; ULog: the layout in
    ``meta['estimator_status']``); a lane is one EKF core / instance of one message. Then the
    innovation test ratios per lane with the gate at 1 (a ratio above it: the measurement was
    rejected; ArduPilot logs the square root of its squared ratio, PX4 the ratio, both gated at
    1); ratios that stay 0 the whole flight (not fused) are named in the title instead of drawn.

    Returns ``[(title, figure or None)]``: one ``(title, None)`` ("no data" line) when the
    stream is empty.
    """
    import plotly.graph_objects as go

    from ..io import estimator_bits

    if est is None or not len(est):
        return [(ESTIMATOR_FLAGS_TITLE, None)]
    est = est.sort_values("t_ns", kind="stable")
    lanes = [(str(s), int(i)) for s, i in est[["src", "instance"]].astype({"src": str}).drop_duplicates()
             .itertuples(index=False)]
    multi = len(lanes) > 1
    flags, rows = go.Figure(), []
    for src, inst in lanes:
        lane = est[(est["src"].astype(str) == src) & (est["instance"] == inst)]
        t_s = lane["t_ns"].to_numpy(np.int64) * 1e-9
        tag = f" ({src} {inst})" if multi else ""
        for col in estimator_bits.FLAG_COLUMNS:
            v = lane[col]
            if not v.notna().any():
                continue
            vals = v.fillna(0).astype("int64").to_numpy()
            for bit in estimator_bits.bits_set(vals):
                name = f"{_FLAG_WORDS[col]}: {estimator_bits.bit_name(src, col, bit, meta)}{tag}"
                xs = _set_intervals(t_s, (vals >> bit & 1).astype(bool))
                y = len(rows)
                rows.append(name)
                flags.add_trace(go.Scatter(x=xs, y=[None if x is None else y for x in xs],
                                           mode="lines", name=name, showlegend=False,
                                           line=dict(color=plots.colour(col), width=8),
                                           hovertemplate=f"{name}<br>t = %{{x:.1f}} s<extra></extra>"))
    out: list[tuple[str, object]] = []
    if flags.data:
        flags.update_xaxes(title="t [s]")
        flags.update_yaxes(tickmode="array", tickvals=list(range(len(rows))), ticktext=rows,
                           range=[len(rows) - 0.5, -0.5], showgrid=False)  # first row on top
        out.append((ESTIMATOR_FLAGS_TITLE, plots.layout(
            flags, f"{ESTIMATOR_FLAGS_TITLE}: each bit ever set, drawn where it is set",
            height=max(260, 22 * len(rows) + 110), margin=dict(l=260, r=20, t=40, b=40))))
    else:
        out.append((ESTIMATOR_FLAGS_TITLE, None))
    ratios, zero = go.Figure(), set()
    for n_lane, (src, inst) in enumerate(lanes):
        lane = est[(est["src"].astype(str) == src) & (est["instance"] == inst)]
        tag = f" ({src} {inst})" if multi else ""
        for r, words in _RATIO_WORDS.items():
            col = f"{r}_test_ratio"
            v = lane[col]
            if not v.notna().any():
                continue
            if not (v.fillna(0) != 0).any():
                zero.add(words)
                continue
            d = plots.decimate(lane[["t_ns", col]], max_points=1000, cols=[col], breaks=True)
            ratios.add_trace(go.Scatter(x=d["t_ns"].to_numpy() * 1e-9, y=d[col], mode="lines",
                                        name=f"{words}{tag}",
                                        line=dict(color=plots.colour(col), dash=("solid", "dot", "dash")[n_lane % 3])))
    if ratios.data:
        ratios.add_hline(y=1.0, line=dict(color="#d62728", dash="dash", width=1),
                         annotation_text="gate: above 1 rejected", annotation_position="top right")
        ratios.update_xaxes(title="t [s]")
        ratios.update_yaxes(title="innovation test ratio [1]", rangemode="tozero")
        title = "Estimator innovation test ratios (gate at 1)"
        if zero:
            title += f"; always 0: {', '.join(sorted(zero))}"
        out.append((ESTIMATOR_RATIOS_TITLE, plots.layout(ratios, title)))
    return out


def build_flight_report(ingest_dir: str | os.PathLike, out_html: str | os.PathLike, *,
                        template: str | os.PathLike, plotly_js: str, index_href: str = "../index.html",
                        state: str | os.PathLike | None = None,
                        calibration: str | os.PathLike | None = None,
                        segments: str | os.PathLike | None = None,
                        classified: Mapping[str, str | os.PathLike] | None = None,
                        estimates: Mapping[str, str | os.PathLike] | None = None,
                        vehicle: str | None = None) -> None:
    """Render one flight's report.

    Parameters
    ----------
    ingest_dir : path-like
        ``results/ingest/<flight>/``.
    out_html : path-like
        Output page.
    template : path-like
        Jinja2 template (``reports/templates/flight.html.j2``), a declared rule input.
    plotly_js : str
        URL of plotly.min.js relative to the page.
    state, calibration, segments : path-like, optional
        Derived tables from preprocess when the workflow has them.
    classified : mapping, optional
        ``{model_set: path}`` of the flight's classification tables (one timeline each).
    estimates : mapping, optional
        ``{estimator: path}`` of the flight's estimate tables (``results/estimate/<estimator>/``):
        error panels against the reference the estimates name (truth or the state) and the
        EKF+HMM mode timeline; a placeholder's panel says why in one line.
    vehicle : str, optional
        The manifest's vehicle, for the summary table.
    """
    log = read_flightlog(ingest_dir)
    meta = log.meta
    st = read_table(state) if state and Path(state).exists() else None
    state_meta = read_table_meta(state) if st is not None else {}
    pre = state_meta.get("preprocess") or {}
    seg = read_table(segments) if segments and Path(segments).exists() else None
    if seg is None and len(log["labels"]):
        seg = log["labels"]
    cal = read_table(calibration) if calibration and Path(calibration).exists() else None
    classified = {m: p for m, p in (classified or {}).items() if p and Path(p).exists()}
    timelines = {}

    failed = meta.get("status") == "failed"
    ned = ned_track(log, st)
    velocity = velocity_track(st, log)
    # a velocity differentiated from position: its run ends are extrapolations, kept out of the maxima
    edge_s = 0.5 * float(pre.get("derivative_window_s") or 1.0) \
        if st is not None and "vel_n_mps" in st and st["vel_n_mps"].notna().any() \
        and "differentiated" in str((pre.get("sources") or {}).get("velocity")) else 0.0
    numbers = flight_numbers(log, st, ned=ned, velocity=without_edges(velocity, edge_s))
    if pre.get("ground_vehicle"):   # a rover's height is GPS noise: no altitude or climb to report
        numbers.update(max_alt_m=float("nan"), max_vspeed_mps=float("nan"), ground_vehicle=True)
    alt_series = {}
    track_h = pd.DataFrame({"t_ns": ned["t_ns"], "alt_m": -ned["pos_d_m"]}) if ned is not None else None
    cal_h = pd.DataFrame({"t_ns": st["t_ns"], "alt_m": st["alt_cal_m"]}) \
        if st is not None and "alt_cal_m" in st and st["alt_cal_m"].notna().any() else None
    # the raw baro starts where the calibrated height does (the calibration points' datum), else
    # at the track's height
    baro = baro_relative(log["baro"], cal_h if cal_h is not None else track_h,
                         ref_name="the calibrated height" if cal_h is not None else "the track's height")
    if baro is not None:
        alt_series[baro[1]] = baro[0]
    if track_h is not None:
        alt_series["−d (track)"] = track_h
    if cal_h is not None:
        alt_series["calibrated"] = cal_h
    rf = rangefinder_height(log["rangefinder"])
    if rf is not None:
        alt_series["rangefinder"] = rf
    calib_pts = None
    if cal is not None and {"t_ns", "h_ref_m"} <= set(cal.columns) and len(cal):
        # the BPM reference heights the fit used (tilt-compensated range or GPS height)
        used = cal[cal["used"].fillna(False).astype(bool)] if "used" in cal else cal
        calib_pts = pd.DataFrame({"t_ns": used["t_ns"], "alt_m": used["h_ref_m"]})
    for m, p in classified.items():
        cls = read_table(p)
        if len(cls) and "pred" in cls:
            timelines[m] = pd.DataFrame({"t_ns": cls["t_ns"], "label": cls["pred"].astype(str),
                                         "confidence": cls["V_best"]})
        else:
            timelines[m] = None

    att, euler, att_frame = attitude_source(st, log)
    rates, rates_frame = _body_rates(st, log["imu"])
    # "vs setpoint" only where the log has a rate setpoint to draw
    sp = first_instance(log["setpoint"])
    has_sp = len(sp) > 0 and any(c in sp and sp[c].notna().any() for c in ("p_radps", "q_radps", "r_radps"))
    rates_title = "Body rates vs setpoint" if has_sp else "Body rates"
    imu = log["imu"]
    figs = [
        # the ground track and altitude first, the 3-D path after them: a headless or GPU-less
        # browser draws it in software WebGL, ~0.6 s in one task, which the page's first
        # screen (and the user's first scroll) need not wait for
        ("Ground track", plots.ground_track(ned)),
        ("Altitude", altitude_panel(alt_series, calib_pts, ground=bool(pre.get("ground_vehicle")))),
        ("3-D path", plots.path_3d(ned)),
        ("Attitude", plots.attitude(att, euler, log["setpoint"], frame=att_frame)),
        # in °/s, as flight-test engineers read body rates and as the summary's max body rate
        (rates_title, plots.with_setpoint(
            rates, ["p_radps", "q_radps", "r_radps"], log["setpoint"],
            ["p_radps", "q_radps", "r_radps"], f"{rates_title} ({rates_frame})", "body rate [°/s]",
            scale=180.0 / np.pi, unit="°/s")),
        ("Velocity", plots.with_setpoint(
            velocity, [f"vel_{a}_mps" for a in "ned"], log["setpoint"],
            [f"vel_{a}_mps" for a in "ned"], "Velocity (NED) and setpoint where logged", "velocity [m/s]")),
        ("RC inputs", plots.time_series(log["control"], [f"rc_{i}_us" for i in range(1, schema.N_RC + 1)],
                                        "RC inputs", "pulse width [µs]")),
        # each channel on the axis of its unit: PWM µs, PX4's normalised outputs, raw ESC commands
        ("Actuator outputs", plots.actuator_outputs(
            log["control"], [f"servo_{i}_us" for i in range(1, schema.N_SERVO + 1)], "Actuator outputs (servo/ESC)")),
        ("GPS quality (fix type, satellites, HDOP/EPH)", plots.gps_quality(log["gps"])),
        ("Vibration", plots.vibration(log["vibration"], imu)),
        *(_spectrogram_panel(imu, [f"acc_{a}_mps2" for a in "xyz"], "Accelerometer spectrogram", "m/s²"),
          _spectrogram_panel(imu, [f"gyr_{a}_radps" for a in "xyz"], "Gyroscope spectrogram", "rad/s")),
        # raw IMU: the sensor's axes (FRD by convention, before the mount correction of the state)
        ("Accelerometer", plots.time_series(imu, [f"acc_{a}_mps2" for a in "xyz"],
                                            "Accelerometer (raw, sensor frame)", "specific force [m/s²]")),
        ("Gyroscope", plots.time_series(imu, [f"gyr_{a}_radps" for a in "xyz"],
                                        "Gyroscope (raw, sensor frame)", "angular rate [rad/s]")),
        ("Battery", plots.battery(log["battery"])),
        # the estimator_status stream (DataFlash XKF4/NKF4/EKF4, tlog EKF_STATUS_REPORT, ULog
        # estimator_status); an empty stream keeps the one "no data" line
        *estimator_flag_panels(log["estimator_status"], meta),
    ]
    if len(timelines) <= 1:
        figs.append(("Maneuver timeline", plots.timeline(seg, next(iter(timelines.values()), None))))
    else:
        for m, c in timelines.items():
            fig = plots.timeline(seg, c)
            if fig is not None:
                fig.update_layout(title=f"Maneuver timeline ({m})")
            figs.append((f"Maneuver timeline ({m})", fig))
    # a failed ingest's placeholders downstream would only repeat its reason
    est_figs, est_facts = ([], []) if failed else estimate_panels(estimates or {}, truth=log["truth"], state=st,
                                                                 classified=classified)
    figs.extend(est_figs)
    # flight-mode bands behind every time panel (not the 3-D path, the ground track, a spectrum),
    # the last band ending where the flight does (an end *time*, not the duration)
    t_end = numbers["t_end_s"]
    for _, f in figs:
        if plots.is_time_panel(f):
            plots.mode_bands(f, log["mode"], t_end if np.isfinite(t_end) else None)
    divs = figure_divs(figs)
    # one linked time axis: zooming any time panel zooms them all (the template's script)
    linked = [f"plot-{i}" for i, (_, f) in enumerate(figs) if plots.is_time_panel(f)]
    tables = [("Log messages", *plots.messages_table(log["messages"])),
              ("Parameters", *plots.params_table(log["params"]))]
    if pre and not failed:
        tables.append(calibration_table(pre))

    def known(v) -> str:  # never "None"
        return "–" if v in (None, "") else str(v)

    facts = [("format", known(meta.get("source_format"))),
             ("reader", f"{meta['reader']} v{meta.get('reader_version') or '?'}" if meta.get("reader") else "–"),
             ("detected by", known(meta.get("detected_by"))), ("source", known(meta.get("source_path"))),
             ("sha256", known(meta.get("source_sha256"))), ("status", known(meta.get("status"))),
             ("time span", _span_text(log, numbers)),
             ("distance rule", _distance_rule_text(numbers)),
             ("streams", ", ".join(f"{k} ({v['rows']})" for k, v in log.summary().items()) or "none"),
             ("diagnostics", diagnostics_text(meta.get("diagnostics")))]
    summary = summary_rows(meta, vehicle=vehicle, messages=log["messages"], gps=log["gps"], rates=rates,
                           euler=euler, preprocess=pre, numbers=numbers)
    if st is not None:
        src = pre.get("sources") or {}
        cinfo = pre.get("calibration") or {}
        facts.append(("preprocess", f"{count_text(pre.get('n_samples', 0), 'sample')} @ {known(pre.get('rate_hz'))} Hz; position "
                                    f"{known(src.get('position'))}; body rates {known(src.get('body_rates'))}; BPM "
                                    f"{known(cinfo.get('method'))}" if pre else known(state_meta.get("error"))))
    for m, p in classified.items():
        cm = read_table_meta(p)
        facts.append(("classifier", f"model set {m}: {cm.get('status')}"
                                    + (f" ({cm.get('error')})" if cm.get("error") else "")))
    facts.extend(est_facts)
    facts = [(k, plain_text(v)) for k, v in facts]
    if failed:
        # the reason once (the template's line under the title), none of the numbers, reader,
        # format or diagnostics a failed ingest does not have ("duration 0.0 s", "reader: none")
        summary = [("vehicle", vehicle)] if vehicle else []
        facts = [("source", known(meta.get("source_path"))),
                 *([("sha256", meta["source_sha256"])] if meta.get("source_sha256") else []),
                 ("status", "failed (the reason is above)")]
    page = render(template,
        flight_id=meta.get("flight_id"), summary=summary, facts=facts, plots=divs, tables=tables, linked=linked, plotly_js=plotly_js,
        index_href=index_href, failed=failed, error=(meta.get("error") or "unknown reason") if failed else None)
    # the numbers ride in the page, for the index (one source: they cannot disagree)
    write_page(page.replace("</body>", numbers_script(numbers) + "\n</body>", 1), out_html)


def _span_text(log, numbers: Mapping) -> str:
    """The span the duration is taken from, the sensor streams' where it differs by more than
    0.5 s, and the streams with records from more than 0.5 s before the sensors' first (stale
    records, not counted): ``"0.1 to 79.6 s (preprocessed state); sensor streams 0.0 to 79.6 s;
    control, setpoint reach back to -46.2 s (stale records, not counted)"``."""
    t0, t1 = numbers.get("t_start_s"), numbers.get("t_end_s")
    if t0 is None or not np.isfinite(t0):
        return "– (no samples)"
    out = f"{t0:.1f} to {t1:.1f} s ({numbers.get('duration_from')})"
    lo, hi = log.span_ns(schema.SENSOR_STREAMS)
    if lo is None:
        return out
    lo_s, hi_s = lo * 1e-9, hi * 1e-9
    if numbers.get("duration_from") != "sensor streams" and (abs(lo_s - t0) > 0.5 or abs(hi_s - t1) > 0.5):
        out += f"; sensor streams {lo_s:.1f} to {hi_s:.1f} s"
    # event streams (a parameter dump at boot) may precede the sensors by design: not named
    starts = {name: log.span_ns([name])[0] for name in schema.STREAM_NAMES
              if name != "labels" and name not in schema.EVENT_STREAMS}
    early = [name for name, t in starts.items() if t is not None and t * 1e-9 < lo_s - 0.5]
    if early:
        out += (f"; {', '.join(early)} reach{'es' * (len(early) == 1)} back to "
                f"{min(starts[n] for n in early) * 1e-9:.1f} s (stale records, not counted)")
    return out


def _distance_rule_text(numbers: Mapping) -> str:
    """How the distance was measured (:func:`pipeline.report.flight_summary.path_length`)."""
    h, sig = numbers.get("path_dead_band_m"), numbers.get("path_noise_m")
    if h is None or not np.isfinite(h):
        return "– (no track)"
    return (f"path of {PATH_BIN_S:g} s position averages, a step counted once it leaves a {h:.2f} m dead band "
            f"({PATH_NOISE_K:g} × the averages' noise σ = {sig:.3f} m)")
