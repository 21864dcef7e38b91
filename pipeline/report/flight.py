"""Per-flight HTML report: path, ground track, altitude (+ BPM points), attitude, sensors, timeline.

Plotly is not inlined per page: every report references one local copy of ``plotly.min.js``
(written by :func:`write_plotly_js`) by a relative URL, so the reports open offline from
``file://`` and the results folder stays small.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from ..estimate.pf_run import classifier_softmax
from ..frames.rotations import quat_to_euler
from ..io import schema
from ..io.parquet import read_flightlog, read_table, read_table_meta
from .pages import figure_divs, render, write_page
from . import plots

#: the 9 CA state columns (pos, vel, acc NED) of the state table and the truth stream
_STATE9 = tuple(f"{q}_{a}_{u}" for q, u in (("pos", "m"), ("vel", "mps"), ("acc", "mps2")) for a in "ned")


def write_plotly_js(path: str | os.PathLike) -> None:
    """Write plotly's bundled JavaScript (from the installed package, no network) to ``path``."""
    from plotly.offline import get_plotlyjs

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(get_plotlyjs())


def _first_instance(df: pd.DataFrame) -> pd.DataFrame:
    return df[df["instance"] == df["instance"].min()] if len(df) else df


def _ned_track(log, state: pd.DataFrame | None) -> pd.DataFrame | None:
    """Local NED track: state, else the autopilot's local_position, else GPS about the NED origin."""
    cols = ["t_ns", "pos_n_m", "pos_e_m", "pos_d_m"]
    if state is not None and len(state) and state["pos_n_m"].notna().any():
        return state[cols]
    lp = _first_instance(log["local_position"])
    if len(lp) and lp["pos_n_m"].notna().any():
        return lp[cols]
    gps = _first_instance(log["gps"]).dropna(subset=["lat_deg", "lon_deg"])
    gps = gps[(gps["lat_deg"].abs() > 1e-6) | (gps["lon_deg"].abs() > 1e-6)]
    if len(gps):
        from ..frames.geodesy import geodetic_to_ned

        o = log.meta.get("ned_origin") or {}
        lat0 = o.get("lat_deg") if o.get("lat_deg") is not None else gps["lat_deg"].iloc[0]
        lon0 = o.get("lon_deg") if o.get("lon_deg") is not None else gps["lon_deg"].iloc[0]
        # heights in one datum: ellipsoidal when the log has it, else MSL (display only)
        if gps["alt_wgs84_m"].notna().all():
            alt, h0 = gps["alt_wgs84_m"].to_numpy(), o.get("alt_wgs84_m")
        else:
            alt, h0 = gps["alt_msl_m"].fillna(0.0).to_numpy(), o.get("alt_msl_m")
        h0 = alt[0] if h0 is None else h0
        n, e, d = geodetic_to_ned(gps["lat_deg"].to_numpy(), gps["lon_deg"].to_numpy(), alt, lat0, lon0, h0)
        return pd.DataFrame({"t_ns": gps["t_ns"].to_numpy(), "pos_n_m": n, "pos_e_m": e, "pos_d_m": d})
    return None


def _body_rates(state: pd.DataFrame | None, imu: pd.DataFrame) -> pd.DataFrame | None:
    """Body rates p, q, r: the state's (mount-corrected) where preprocessed, else the first
    gyro's (``gyr_{x,y,z}_radps``, FRD convention)."""
    cols = ["p_radps", "q_radps", "r_radps"]
    if state is not None and len(state) and set(cols) <= set(state.columns) and state["p_radps"].notna().any():
        return state[["t_ns", *cols]]
    g = _first_instance(imu)
    if not len(g):
        return None
    return pd.DataFrame({"t_ns": g["t_ns"].to_numpy(), **{c: g[f"gyr_{a}_radps"].to_numpy()
                                                          for c, a in zip(cols, "xyz")}})


def _velocity(state: pd.DataFrame | None, log) -> pd.DataFrame | None:
    """NED velocity: the state's, else the autopilot's local_position, else GPS."""
    cols = [f"vel_{a}_mps" for a in "ned"]
    for df in (state, _first_instance(log["local_position"]), _first_instance(log["gps"])):
        if df is not None and len(df) and set(cols) <= set(df.columns) and df["vel_n_mps"].notna().any():
            return df[["t_ns", *cols]]
    return None


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
    preprocessed state); the EKF+HMM mode timeline. A panel without data keeps a title that
    says why (placeholder reason, no reference)."""
    estimates = {e: p for e, p in estimates.items() if p and Path(p).exists()}
    # the particle filters (issue 17) have their own table (``pf``) and panels
    pf = {e: estimates.pop(e) for e in [e for e in estimates if e in PF_ESTIMATORS]}
    pf_figs, pf_facts = pf_panels(pf, classified)
    if not estimates:
        return [("Estimates (the flight's vehicle is not in estimate.vehicles)", None), *pf_figs], pf_facts
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
            facts.append((label, f"{m.get('n_steps')} steps ({m.get('n_predict_only')} predict-only), radar "
                                 f"{m.get('radar')} (site {m.get('radar_site_ned_m')} from {m.get('radar_site_from')}), "
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
        facts.append((label, f"{m.get('n_steps')} steps, N = {m.get('n_particles')}, {m.get('n_resampled')} resampled "
                             f"({m.get('resample')}, N_eff < {float(m.get('threshold', 0)):.2f} N), "
                             f"{m.get('n_predict_only')} predict-only, {m.get('n_reinit')} re-initialised; "
                             f"mean fractions " + ", ".join(f"{k} {v:.2f}" for k, v in fr.items())
                             + (f"; classifier {m.get('classifier')}" if m.get("classifier") else "")))
        figs.append((f"{label} mode fractions", plots.pf_mode_fractions(t, label)))
    return figs, facts


def build_flight_report(ingest_dir: str | os.PathLike, out_html: str | os.PathLike, *,
                        template: str | os.PathLike, plotly_js: str, index_href: str = "../index.html",
                        state: str | os.PathLike | None = None,
                        calibration: str | os.PathLike | None = None,
                        segments: str | os.PathLike | None = None,
                        classified: Mapping[str, str | os.PathLike] | None = None,
                        estimates: Mapping[str, str | os.PathLike] | None = None) -> None:
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
    """
    log = read_flightlog(ingest_dir)
    meta = log.meta
    st = read_table(state) if state and Path(state).exists() else None
    seg = read_table(segments) if segments and Path(segments).exists() else None
    if seg is None and len(log["labels"]):
        seg = log["labels"]
    cal = read_table(calibration) if calibration and Path(calibration).exists() else None
    classified = {m: p for m, p in (classified or {}).items() if p and Path(p).exists()}
    timelines = {}

    ned = _ned_track(log, st)
    alt_series = {}
    baro = _first_instance(log["baro"])
    if len(baro):
        alt_series["baro (raw)"] = pd.DataFrame({"t_ns": baro["t_ns"], "alt_m": baro["alt_rel_m"]})
    if ned is not None:
        alt_series["−d (track)"] = pd.DataFrame({"t_ns": ned["t_ns"], "alt_m": -ned["pos_d_m"]})
    if st is not None and "alt_cal_m" in st:
        alt_series["calibrated"] = pd.DataFrame({"t_ns": st["t_ns"], "alt_m": st["alt_cal_m"]})
    rf = _first_instance(log["rangefinder"])
    if len(rf) and rf["dist_m"].notna().any():
        alt_series["rangefinder"] = pd.DataFrame({"t_ns": rf["t_ns"], "alt_m": rf["dist_m"]})
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

    att = _first_instance(log["attitude"]).dropna(subset=["q_w"])
    euler = quat_to_euler(att[["q_w", "q_x", "q_y", "q_z"]].to_numpy()) if len(att) else None
    imu = log["imu"]
    figs = [
        ("3-D path", plots.path_3d(ned)),
        ("Ground track", plots.ground_track(ned)),
        ("Altitude", plots.altitude(alt_series, calib_pts)),
        ("Attitude", plots.attitude(att, euler, log["setpoint"])),
        ("Body rates vs setpoint", plots.with_setpoint(
            _body_rates(st, imu), ["p_radps", "q_radps", "r_radps"], log["setpoint"],
            ["p_radps", "q_radps", "r_radps"], "Body rates vs setpoint (FRD)", "body rate [rad/s]")),
        ("Velocity", plots.with_setpoint(
            _velocity(st, log), [f"vel_{a}_mps" for a in "ned"], log["setpoint"],
            [f"vel_{a}_mps" for a in "ned"], "Velocity (NED) and setpoint where logged", "velocity [m/s]")),
        ("RC inputs", plots.time_series(log["control"], [f"rc_{i}_us" for i in range(1, schema.N_RC + 1)],
                                        "RC inputs", "pulse width [µs]")),
        ("Actuator outputs", plots.time_series(log["control"], [f"servo_{i}_us" for i in range(1, schema.N_SERVO + 1)],
                                               "Actuator outputs (servo/ESC)", "pulse width [µs]")),
        ("GPS quality (fix type, satellites, HDOP/EPH)", plots.gps_quality(log["gps"])),
        ("Vibration", plots.vibration(log["vibration"], imu)),
        ("Battery", plots.battery(log["battery"])),
        # raw IMU: the sensor's axes (FRD by convention, before the mount correction of the state)
        ("Accelerometer", plots.time_series(imu, [f"acc_{a}_mps2" for a in "xyz"],
                                            "Accelerometer (raw, sensor frame)", "specific force [m/s²]")),
        ("Gyroscope", plots.time_series(imu, [f"gyr_{a}_radps" for a in "xyz"],
                                        "Gyroscope (raw, sensor frame)", "angular rate [rad/s]")),
    ]
    if len(timelines) <= 1:
        figs.append(("Maneuver timeline", plots.timeline(seg, next(iter(timelines.values()), None))))
    else:
        for m, c in timelines.items():
            fig = plots.timeline(seg, c)
            if fig is not None:
                fig.update_layout(title=f"Maneuver timeline ({m})")
            figs.append((f"Maneuver timeline ({m})", fig))
    est_figs, est_facts = estimate_panels(estimates or {}, truth=log["truth"], state=st, classified=classified)
    figs.extend(est_figs)
    # flight-mode bands behind every time panel (not the 3-D path and the ground track)
    for _, f in figs[2:]:
        plots.mode_bands(f, log["mode"], log.duration_s)
    divs = figure_divs(figs)
    # one linked time axis: zooming any time panel zooms them all (the template's script)
    linked = [f"plot-{i}" for i, (_, f) in enumerate(figs) if i >= 2 and f is not None]
    tables = [("Log messages", *plots.messages_table(log["messages"])),
              ("Parameters", *plots.params_table(log["params"]))]

    def known(v) -> str:  # a failed ingest has no reader or format: say so, never "None"
        return "–" if v in (None, "") else str(v)

    reader = (f"{meta['reader']} v{meta.get('reader_version') or '?'}" if meta.get("reader")
              else "none took the file" if meta.get("status") == "failed" else "–")
    facts = [("format", known(meta.get("source_format"))), ("reader", reader),
             ("detected by", known(meta.get("detected_by"))), ("source", known(meta.get("source_path"))),
             ("sha256", known(meta.get("source_sha256"))), ("status", known(meta.get("status"))),
             *([("reason", meta.get("error") or "unknown")] if meta.get("status") == "failed" else []),
             ("duration", f"{log.duration_s:.1f} s"),
             ("streams", ", ".join(f"{k} ({v['rows']})" for k, v in log.summary().items()) or "none"),
             ("diagnostics", json.dumps({k: v for k, v in meta.get("diagnostics", {}).items()
                                         if k in ("bytes_skipped", "records_dropped", "timestamp_anomalies")}))]
    if state and Path(state).exists():
        pre = read_table_meta(state).get("preprocess") or {}
        src = pre.get("sources") or {}
        cinfo = pre.get("calibration") or {}
        facts.append(("preprocess", f"{pre.get('n_samples', 0)} samples @ {pre.get('rate_hz')} Hz; position "
                                    f"{src.get('position')}; body rates {src.get('body_rates')}; BPM "
                                    f"{cinfo.get('method')}" if pre else read_table_meta(state).get("error", "–")))
    for m, p in classified.items():
        cm = read_table_meta(p)
        facts.append(("classifier", f"model set {m}: {cm.get('status')}"
                                    + (f" ({cm.get('error')})" if cm.get("error") else "")))
    facts.extend(est_facts)
    page = render(template, 
        flight_id=meta.get("flight_id"), facts=facts, plots=divs, tables=tables, linked=linked, plotly_js=plotly_js,
        index_href=index_href, failed=meta.get("status") == "failed", error=meta.get("error"))
    write_page(page, out_html)
