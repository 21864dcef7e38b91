"""The HTML index over all flights: one summary line per flight, failed flights with reasons.

Self-contained (inline CSS, no scripts fetched from anywhere) so it opens from ``file://``.
"""

from __future__ import annotations

import html
import json
import os
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from ..frames.geodesy import geodetic_to_ned
from ..io.parquet import read_table
from ..io import schema
from .flight_summary import timestamp_anomalies, utc_date
from .pages import write_page


def _track_stats(flight_dir: Path) -> tuple[float, float]:
    """Distance flown (m, horizontal) and max speed (m/s) from local_position, else GPS."""
    lp_path = flight_dir / "local_position.parquet"
    gps_path = flight_dir / "gps.parquet"
    dist, vmax = float("nan"), float("nan")
    if lp_path.exists():
        lp = read_table(lp_path, schema.columns("local_position"))
        lp = lp[lp["instance"] == lp["instance"].min()] if len(lp) else lp
        if len(lp) > 1 and lp["pos_n_m"].notna().any():
            p = lp[["pos_n_m", "pos_e_m"]].dropna().to_numpy()
            dist = float(np.sum(np.hypot(*np.diff(p, axis=0).T)))
            v = lp[["vel_n_mps", "vel_e_mps", "vel_d_mps"]].to_numpy()
            if np.isfinite(v).any():
                vmax = float(np.nanmax(np.linalg.norm(v, axis=1)))
    if np.isnan(dist) and gps_path.exists():
        g = read_table(gps_path, schema.columns("gps"))
        g = g[(g["instance"] == g["instance"].min())] if len(g) else g
        g = g.dropna(subset=["lat_deg", "lon_deg"])
        g = g[(g["lat_deg"].abs() > 1e-6) | (g["lon_deg"].abs() > 1e-6)]
        if len(g) > 1:
            # horizontal track length in the local NED about the first fix (heights left out)
            lat, lon = g["lat_deg"].to_numpy(), g["lon_deg"].to_numpy()
            n, e, _ = geodetic_to_ned(lat, lon, np.zeros(len(g)), lat[0], lon[0], 0.0)
            dist = float(np.sum(np.hypot(np.diff(n), np.diff(e))))
        if len(g) and np.isnan(vmax):
            v = g[["vel_n_mps", "vel_e_mps", "vel_d_mps"]].to_numpy()
            if np.isfinite(v).any():
                vmax = float(np.nanmax(np.linalg.norm(np.nan_to_num(v), axis=1)))
    return dist, vmax


def flight_summary(flight_id: str, meta_path: str | os.PathLike) -> dict:
    """One index row for a flight from its ingest directory."""
    meta_path = Path(meta_path)
    meta = json.loads(meta_path.read_text())
    d = meta_path.parent
    row = {"flight_id": flight_id, "date": utc_date(meta), "vehicle": "",
           "status": meta.get("status", "?"), "format": meta.get("source_format") or "",
           "error": meta.get("error") or "", "duration_s": float("nan"), "distance_m": float("nan"),
           "max_speed_mps": float("nan"), "maneuvers": 0, "warnings": ""}
    if row["status"] == "failed":
        return row
    durs = []
    for s in schema.SENSOR_STREAMS:  # parameter dumps and messages may precede the first sample
        p = d / f"{s}.parquet"
        if p.exists():
            t = pd.read_parquet(p, columns=["t_ns"])["t_ns"]
            if len(t):
                durs.append((t.min(), t.max()))
    if durs:
        row["duration_s"] = (max(b for _, b in durs) - min(a for a, _ in durs)) * 1e-9
    row["distance_m"], row["max_speed_mps"] = _track_stats(d)
    lab = d / "labels.parquet"
    if lab.exists():
        row["maneuvers"] = len(pd.read_parquet(lab, columns=["label"]))
    diag = meta.get("diagnostics", {})
    warn = []
    if diag.get("bytes_skipped"):
        warn.append(f"{diag['bytes_skipped']} bytes skipped")
    for reason, n in (diag.get("records_dropped") or {}).items():
        warn.append(f"{n} dropped ({reason})")
    warn += timestamp_anomalies(diag)
    row["warnings"] = "; ".join(warn[:6]) + (" …" if len(warn) > 6 else "")
    return row


_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;color:#222}
table{border-collapse:collapse;font-size:14px}
th,td{border-bottom:1px solid #ddd;padding:4px 10px;text-align:left;vertical-align:top}
th{background:#f4f4f4} td.num{text-align:right;font-variant-numeric:tabular-nums}
tr.failed td{background:#fdecea} .reason{color:#b00020}
"""


def _fmt(x: float, nd: int = 1) -> str:
    return "–" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:,.{nd}f}"


def maneuver_summary(segments: str | os.PathLike | None, classified: Mapping | None) -> str:
    """``"<n> segments; sim classifier: M1 62%, M3 20%"`` from the segments and the classify
    tables ``{model_set: path}`` (share of classified samples per predicted maneuver, ``unknown``
    left out), one part per model set."""
    parts = []
    if segments and Path(segments).exists():
        seg = pd.read_parquet(segments, columns=["label"])
        parts.append(f"{len(seg)} segment{'s' if len(seg) != 1 else ''}")
    for m, p in (classified or {}).items():
        if not (p and Path(p).exists()):
            continue
        c = pd.read_parquet(p)
        if len(c) and "pred" in c:
            share = c["pred"].astype(str).value_counts(normalize=True)
            share = share[share.index != "unknown"]
            found = ", ".join(f"{k} {100 * v:.0f}%" for k, v in share.head(4).items())
            parts.append(f"{m} classifier: {found or 'unknown only'}" + (" …" if len(share) > 4 else ""))
    return "; ".join(parts)


def build_index(flight_ids: list[str], meta_paths: list[str], out_html: str | os.PathLike,
                links: dict[str, str] | None = None, *, segments: dict | None = None,
                classified: dict | None = None, models: dict[str, str] | None = None,
                studies: dict[str, str] | None = None, vehicles: Mapping[str, str] | None = None,
                compare: Mapping[str, str] | None = None,
                skipped: Mapping[str, str] | None = None,
                align: dict[str, str] | None = None,
                bearing: dict[str, str] | None = None) -> pd.DataFrame:
    """Write the index page; returns the summary table (one row per flight).

    Parameters
    ----------
    flight_ids, meta_paths : lists of equal length
        Flight ids and their ``results/ingest/<flight>/meta.json``.
    out_html : path-like
        Output HTML path.
    links : dict, optional
        ``{flight_id: relative URL}`` of per-flight reports.
    segments : dict, optional
        ``{flight_id: path}`` of the segments tables.
    classified : dict, optional
        ``{flight_id: {model_set: path}}`` of the classification tables (maneuvers found).
    models : dict, optional
        ``{model_set: relative URL}`` of the per-model-set reports.
    align : dict, optional
        ``{demo set: relative URL}`` of the trajectory-learning pages (``report/align/<set>.html``).
    studies : dict, optional
        ``{study: relative URL}`` of the study pages (``report/studies/<name>.html``); pages
        that do not exist yet are listed with the target that builds them (studies are built by
        their own targets, not by the main job).
    vehicles : mapping, optional
        ``{flight_id: vehicle}`` (the manifest's), shown per flight.
    compare : mapping, optional
        ``{vehicle: relative URL}`` of the per-vehicle comparison pages, linked from the
        vehicle column and listed under "Vehicles".
    skipped : mapping, optional
        ``{flight_id: reason}`` of the manifest rows left out (log not found), listed with the
        reason under the flights.
    bearing : dict, optional
        ``{pair: relative URL}`` of the bearing-only replay pages (``report/bearing/<pair>.html``).
    """
    rows = [flight_summary(f, m) for f, m in zip(flight_ids, meta_paths)]
    compare = dict(compare or {})
    for r in rows:
        r["vehicle"] = (vehicles or {}).get(r["flight_id"], "")
    for r in rows:
        found = maneuver_summary((segments or {}).get(r["flight_id"]), (classified or {}).get(r["flight_id"]))
        if found and r["status"] != "failed":
            r["maneuvers"] = found
    table = pd.DataFrame(rows)
    links = links or {}
    body = []
    for r in rows:
        name = html.escape(r["flight_id"])
        if r["flight_id"] in links:
            name = f'<a href="{html.escape(links[r["flight_id"]])}">{name}</a>'
        veh = html.escape(r["vehicle"])
        if r["vehicle"] in compare:
            veh = f'<a href="{html.escape(compare[r["vehicle"]])}">{veh}</a>'
        first = f"<td>{name}</td><td>{html.escape(r['date']) or '–'}</td><td>{veh or '–'}</td>"
        if r["status"] == "failed":
            body.append(f'<tr class="failed">{first}<td>failed</td><td colspan="6" class="reason">'
                        f'{html.escape(r["error"])}</td></tr>')
            continue
        body.append(
            f"<tr>{first}<td>{html.escape(r['status'])}</td><td>{html.escape(r['format'])}</td>"
            f"<td class=num>{_fmt(r['duration_s'])}</td><td class=num>{_fmt(r['distance_m'], 0)}</td>"
            f"<td class=num>{_fmt(r['max_speed_mps'])}</td><td>{html.escape(str(r['maneuvers']))}</td>"
            f"<td>{html.escape(r['warnings'])}</td></tr>")
    n_failed = sum(r["status"] == "failed" for r in rows)
    model_links = "".join(f'<li><a href="{html.escape(u)}">{html.escape(m)}</a></li>'
                          for m, u in (models or {}).items())
    models_html = f"<h2>Model sets</h2><ul>{model_links}</ul>" if model_links else ""
    align_links = "".join(f'<li><a href="{html.escape(u)}">{html.escape(s)}</a></li>'
                          for s, u in (align or {}).items())
    if align_links:
        models_html += f"<h2>Trajectory learning</h2><ul>{align_links}</ul>"
    here = Path(out_html).parent
    # studies are built by their own targets, not by the main job, and building one does not
    # rewrite this page: link each always, and say which target builds those absent now
    study_links = "".join(
        f'<li><a href="{html.escape(u)}">{html.escape(s)}</a>' + ("" if (here / u).exists() else
        f' <span class="absent">(not built when this index was written: <code>snakemake '
        f'study_{html.escape(s)}</code> builds it)</span>') + "</li>" for s, u in (studies or {}).items())
    if study_links:
        models_html += f"<h2>Studies</h2><ul>{study_links}</ul>"
    if compare:
        models_html = ("<h2>Vehicles: flights compared</h2><ul>" + "".join(
            f'<li><a href="{html.escape(u)}">{html.escape(v)}</a></li>' for v, u in compare.items())
            + "</ul>" + models_html)
    skipped_html = ""
    if skipped:
        skipped_html = ("<h2>Skipped manifest rows</h2><table><thead><tr><th>flight</th><th>reason</th></tr>"
                        "</thead><tbody>" + "".join(
                            f'<tr class="skipped"><td>{html.escape(f)}</td><td class="reason">{html.escape(why)}</td></tr>'
                            for f, why in skipped.items()) + "</tbody></table>")
    bearing_links = "".join(f'<li><a href="{html.escape(u)}">{html.escape(b)}</a></li>'
                            for b, u in (bearing or {}).items())
    if bearing_links:
        models_html += f"<h2>Bearing-only replays</h2><ul>{bearing_links}</ul>"
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>uavpipe flights</title>
<style>{_CSS}</style></head><body>
<h1>uavpipe — flights</h1>
<p>{len(rows)} flights, {n_failed} failed{f", {len(skipped)} manifest rows skipped" if skipped else ""}.</p>
<table><thead><tr><th>flight</th><th>date (UTC)</th><th>vehicle</th><th>status</th><th>format</th><th>duration [s]</th><th>distance [m]</th>
<th>max speed [m/s]</th><th>maneuvers</th><th>ingest warnings</th></tr></thead>
<tbody>{''.join(body)}</tbody></table>{skipped_html}{models_html}</body></html>"""
    write_page(page, out_html)
    return table
