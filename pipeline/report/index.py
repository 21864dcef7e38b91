"""The HTML index over all flights: one summary line per flight, failed flights with reasons.

Self-contained (inline CSS, no scripts fetched from anywhere) so it opens from ``file://``.
"""

from __future__ import annotations

import html
import json
import os
from collections import Counter
from pathlib import Path
from typing import Mapping

import pandas as pd

from ..io.parquet import read_flightlog
from ..io import schema
from .flight_summary import flight_numbers, loss_parts, number_texts, read_page_numbers, utc_date
from .pages import count_text, write_page


def flight_summary(flight_id: str, meta_path: str | os.PathLike, page: str | os.PathLike | None = None) -> dict:
    """One index row for a flight from its ingest directory.

    Duration, distance and speed (``numbers``) are the flight page's own
    (:func:`~pipeline.report.flight_summary.read_page_numbers` of ``page``, the flight page the
    row links): both pages show one computation,
    :func:`pipeline.report.flight_summary.flight_numbers`. Without that page (not built), the
    same function runs here on the ingest streams."""
    meta_path = Path(meta_path)
    meta = json.loads(meta_path.read_text())
    d = meta_path.parent
    row = {"flight_id": flight_id, "date": utc_date(meta), "vehicle": "",
           "status": meta.get("status", "?"), "format": meta.get("source_format") or "",
           "error": meta.get("error") or "", "duration_s": float("nan"), "distance_m": float("nan"),
           "max_speed_mps": float("nan"), "maneuvers": 0, "warnings": "", "numbers": {}}
    if row["status"] == "failed":
        return row
    numbers = read_page_numbers(page) if page is not None else None
    if numbers is None:
        numbers = flight_numbers(read_flightlog(d, list(schema.SENSOR_STREAMS)))   # gps, local_position among them
    row["numbers"] = numbers
    row["duration_s"], row["distance_m"] = numbers.get("duration_s"), numbers.get("distance_m")
    row["max_speed_mps"] = numbers.get("max_hspeed_mps")
    lab = d / "labels.parquet"
    if lab.exists():
        row["maneuvers"] = len(pd.read_parquet(lab, columns=["label"]))
    warn = loss_parts(meta.get("diagnostics"))
    row["warnings"] = "; ".join(warn[:6]) + (" …" if len(warn) > 6 else "")
    return row


#: click a column head of the flights table to sort by it, again to reverse: a number with its
#: unit ("9,502 m", "60.0 s") by value, anything else ("–", dates, names) as text, after the
#: numbers either way
SORT_JS = """(function(){const t=document.getElementById('flights');if(!t)return;
const num=s=>{const m=s.trim().replace(/,/g,'').match(/^(-?\\d+(?:\\.\\d+)?)\\s*[A-Za-z/%°²]*$/);return m?parseFloat(m[1]):null;};
t.querySelectorAll('thead th').forEach((th,i)=>{th.style.cursor='pointer';th.title='sort by this column';
th.addEventListener('click',()=>{const asc=th.dataset.dir!=='asc';
t.querySelectorAll('thead th').forEach(h=>delete h.dataset.dir);th.dataset.dir=asc?'asc':'desc';
const rows=[...t.tBodies[0].rows];rows.sort((a,b)=>{const x=a.cells[i].innerText,y=b.cells[i].innerText,kx=num(x),ky=num(y);
if(kx!==null&&ky!==null)return asc?kx-ky:ky-kx;if(kx!==null||ky!==null)return kx!==null?-1:1;
return asc?x.localeCompare(y):y.localeCompare(x);});
rows.forEach(r=>t.tBodies[0].appendChild(r));});});})();"""

_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;color:#222}
table{border-collapse:collapse;font-size:14px}
th,td{border-bottom:1px solid #ddd;padding:4px 10px;text-align:left;vertical-align:top}
th{background:#f4f4f4} td.num{text-align:right;font-variant-numeric:tabular-nums}
tr.failed td{background:#fdecea} .reason{color:#b00020} .absent{color:#777}
"""


def labelled_right(c: pd.DataFrame) -> str:
    """``" (labelled M1 samples: 100% right)"`` for a classify table whose ``truth`` names
    maneuvers the model set knows (its ``ll_<label>`` columns): the share of those samples it
    labels right. The shares over the whole flight count its take-off, cruise and landing too
    (a simulated M1 flight read "M1 54%, M4 43%" though every M1 sample was right); empty when
    the flight has no such labels."""
    if "truth" not in c or "pred" not in c:
        return ""
    known = [k[3:] for k in c.columns if k.startswith("ll_") and k != "ll_background"]
    truth = c["truth"].astype(str)
    mask = truth.isin(known).to_numpy()
    if not mask.any():
        return ""
    right = 100.0 * float((c["pred"].astype(str).to_numpy()[mask] == truth.to_numpy()[mask]).mean())
    labs = sorted(set(truth[mask]))
    what = f"labelled {labs[0]} samples" if len(labs) == 1 else f"{int(mask.sum()):,} samples of {len(labs)} known maneuvers"
    return f" ({what}: {right:.0f}% right)"


def maneuver_summary(segments: str | os.PathLike | None, classified: Mapping | None) -> str:
    """``"<n> segments; sim classifier: M1 62%, M3 20%"`` from the segments and the classify
    tables ``{model_set: path}`` (share of classified samples per predicted maneuver, the four
    largest, then the ``unknown`` share), one part per model set."""
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
            unknown = float(share.get("unknown", 0.0))
            share = share[share.index != "unknown"]
            found = ", ".join(f"{k} {100 * v:.0f}%" for k, v in share.head(4).items())
            more = " …" if len(share) > 4 else ""
            # the unknown share said, last: "background 3%" alone read as the whole flight
            rest = f", unknown {100 * unknown:.0f}%" if found and unknown > 0 else ""
            parts.append(f"{m} classifier: {found or 'unknown only'}{more}{rest}{labelled_right(c)}")
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
    here = Path(out_html).parent
    links = links or {}
    rows = [flight_summary(f, m, here / links[f] if f in links else None) for f, m in zip(flight_ids, meta_paths)]
    compare = dict(compare or {})
    for r in rows:
        r["vehicle"] = (vehicles or {}).get(r["flight_id"], "")
    for r in rows:
        found = maneuver_summary((segments or {}).get(r["flight_id"]), (classified or {}).get(r["flight_id"]))
        if found and r["status"] != "failed":
            r["maneuvers"] = found
    table = pd.DataFrame([{k: v for k, v in r.items() if k != "numbers"} for r in rows])
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
        txt = number_texts(r["numbers"])   # the texts of the flight page's summary
        body.append(
            f"<tr>{first}<td>{html.escape(r['status'])}</td><td>{html.escape(r['format'])}</td>"
            f"<td class=num>{html.escape(txt['duration'])}</td><td class=num>{html.escape(txt['distance'])}</td>"
            f"<td class=num>{html.escape(txt['max_hspeed'])}</td><td>{html.escape(str(r['maneuvers']))}</td>"
            f"<td>{html.escape(r['warnings'])}</td></tr>")
    n_failed = sum(r["status"] == "failed" for r in rows)
    model_links = "".join(f'<li><a href="{html.escape(u)}">{html.escape(m)}</a></li>'
                          for m, u in (models or {}).items())
    models_html = f"<h2>Model sets</h2><ul>{model_links}</ul>" if model_links else ""
    align_links = "".join(f'<li><a href="{html.escape(u)}">{html.escape(s)}</a></li>'
                          for s, u in (align or {}).items())
    if align_links:
        models_html += f"<h2>Trajectory learning</h2><ul>{align_links}</ul>"
    # studies are built by their own targets, not by the main job, and building one does not
    # rewrite this page: link those built when it was written, name the target of the others
    study_links = "".join(
        (f'<li><a href="{html.escape(u)}">{html.escape(s)}</a></li>' if (here / u).exists() else
         f'<li>{html.escape(s)} <span class="absent">(not built: run <code>snakemake study_{html.escape(s)}</code>'
         f')</span></li>') for s, u in (studies or {}).items())
    if study_links:
        models_html += f"<h2>Studies</h2><ul>{study_links}</ul>"
    if compare:
        # how many of the index's flights each comparison holds (a vehicle's page of one flight
        # compares nothing, and says so before it is opened)
        n_of = Counter((vehicles or {}).values())

        def flights_of(v: str) -> str:
            n = n_of[v]
            return f' <span class="absent">({count_text(n, "flight")})</span>' if n else ""
        models_html = ("<h2>Vehicles: flights compared</h2><ul>" + "".join(
            f'<li><a href="{html.escape(u)}">{html.escape(v)}</a>{flights_of(v)}</li>' for v, u in compare.items())
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
    page = f"""<!doctype html><html lang="en"><head><meta charset="utf-8"><title>uavpipe flights</title>
<style>{_CSS}</style></head><body>
<h1>uavpipe — flights</h1>
<p>{count_text(len(rows), "flight")}, {n_failed} failed{f", {count_text(len(skipped), 'manifest row')} skipped" if skipped else ""}.</p>
<table id="flights"><thead><tr><th>flight</th><th>date (UTC)</th><th>vehicle</th><th>status</th><th>format</th><th>duration</th><th>distance (horizontal path)</th>
<th>max horizontal speed</th><th>maneuvers</th><th>ingest warnings</th></tr></thead>
<tbody>{''.join(body)}</tbody></table>{skipped_html}{models_html}<script>{SORT_JS}</script></body></html>"""
    write_page(page, out_html)
    return table
