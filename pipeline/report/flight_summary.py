"""The summary table at the top of a flight page (issue 13, item 2).

One row per headline number a flight-test engineer reads first: when (UTC of ``t_ns = 0``),
what (vehicle, autopilot and firmware where logged), how long and how far, the envelope
(altitude above start, horizontal and vertical speed, tilt, body rate), GPS fix share, and the
worst warning ingest or preprocess raised. Every value is computed from the full tables, never
from the decimated display traces; a value the flight cannot give reads "–" with the reason.

The flight's headline numbers (duration, distance, speeds, altitude) come from one function,
:func:`flight_numbers`, which the flight page and the index both use (the index reads them from
the flight page it links, :func:`read_page_numbers`), so the two pages cannot disagree.

**Duration** is the time span of the preprocessed state where the flight has one, else of the
sensor streams (:data:`pipeline.io.schema.SENSOR_STREAMS`): pilot inputs, setpoints, modes and
events may carry stale samples from before the log started (PX4 logs the last ``control`` and
``setpoint`` of the previous flight: ``t = −46 s`` in ``ekf_failure.ulg``), and they do not make
a flight longer.

**Distance** (:func:`path_length`) is the horizontal path length of a smoothed, thresholded
track, never the sum of the raw steps: white position noise of σ adds about σ·√π per step in 2-D
whether the vehicle moves or not (a 70 s hover logged at 25 Hz with σ = 0.25 m "flies" 340 m).
The rule: (1) average the positions in consecutive :data:`PATH_BIN_S` bins (1 Hz); (2) estimate
the noise σ of those averages from their second differences (robust: MAD per axis, ÷ √6, as
``p[k+1] − 2 p[k] + p[k−1]`` of white noise has variance 6σ², and the vehicle's own acceleration
over 1 s is mostly far below it); (3) walk the averages with a dead band: a step is counted,
and the anchor moved, only when the position is more than ``h =`` :data:`PATH_NOISE_K` · σ from
the anchor (a pair of noise-only averages exceeds that with probability ``exp(−k²/4) ≈ 10⁻⁴``);
the last anchor to the last average closes the path. Along-track errors telescope, so a
straight line or a wide circle reads within a few per cent of its length whatever the noise;
motion that never leaves a circle of radius ``h`` (a hover's wander below the noise) is not
counted, and a turn tighter than the 1 s bins is cut short (chord error ``(vΔt/R)²/24``).
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import re
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from ..io import schema
from ..io.base import grouped_drops
from ..io.parquet import json_safe
from .pages import count_text

#: MAV_AUTOPILOT enum values that name an autopilot (MAVLink common.xml)
MAV_AUTOPILOT = {0: "generic", 3: "ArduPilot", 4: "OpenPilot", 8: "none (not a flight controller)",
                 12: "PX4", 13: "SMACCMPilot", 14: "AutoQuad", 15: "Armazila", 16: "Aerob", 17: "ASLUAV",
                 18: "SmartAP", 19: "AirRails", 20: "ReflexFMS"}
#: a firmware banner in a log message: "ArduCopter V3.1.3 (...)", "ArduPlane V4.2.3", "PX4 v1.14.0"
_BANNER = re.compile(r"\b(Ardu\w+|APM:\w+|PX4\w*|Rover|Blimp)\s+[vV]?(\d+\.\d+(?:\.\d+)?\S*)")
_NONE = "–"


def utc_of_t0(meta: Mapping) -> str:
    """``"2015-05-21 19:11:37.989 UTC (host clock)"`` from ``meta["t0_utc_ns"]``; ``"–"``
    with the reason when the log has no UTC."""
    t0 = meta.get("t0_utc_ns")
    if t0 is None:
        return f"{_NONE} (no UTC in the log)"
    ts = _dt.datetime.fromtimestamp(int(t0) // 10**9, tz=_dt.timezone.utc)
    ms = (int(t0) % 10**9) // 10**6
    src = meta.get("utc_source") or "unknown"
    return f"{ts:%Y-%m-%d %H:%M:%S}.{ms:03d} UTC ({src} clock)"


def utc_date(meta: Mapping) -> str:
    """The UTC date ``YYYY-MM-DD`` of ``t_ns = 0`` (``""`` when the log has no UTC)."""
    t0 = meta.get("t0_utc_ns")
    if t0 is None:
        return ""
    return f"{_dt.datetime.fromtimestamp(int(t0) // 10**9, tz=_dt.timezone.utc):%Y-%m-%d}"


def _px4_release(v) -> str | None:
    """PX4's ``ver_sw_release`` (0xMMmmpptt: major, minor, patch, type; 255 = release)."""
    try:
        v = int(v)
    except (TypeError, ValueError):
        return None
    if v <= 0:
        return None
    major, minor, patch, kind = (v >> 24) & 0xFF, (v >> 16) & 0xFF, (v >> 8) & 0xFF, v & 0xFF
    return f"v{major}.{minor}.{patch}" + ("" if kind == 255 else f" (type {kind})")


def autopilot_firmware(meta: Mapping, messages: pd.DataFrame | None = None) -> str:
    """Autopilot and firmware as the log states them, ``"–"`` where it does not.

    Sources, first found wins per part: a ULog's info messages (``sys_name``,
    ``ver_sw_release``, ``ver_sw``, ``ver_hw``); a tlog's HEARTBEAT autopilot (MAV_AUTOPILOT);
    the firmware banner in the log's text messages (DataFlash ``MSG``, MAVLink STATUSTEXT:
    ``ArduCopter V3.1.3 ...``)."""
    parts: list[str] = []
    info = meta.get("source_info") or {}
    if info.get("sys_name"):
        rel = _px4_release(info.get("ver_sw_release"))
        sw = str(info.get("ver_sw") or "")[:8]
        parts.append(" ".join(p for p in (str(info["sys_name"]), rel, f"({sw})" if sw else "") if p))
        if info.get("ver_hw"):
            parts.append(f"hardware {info['ver_hw']}")
    banner = None
    if messages is not None and len(messages) and "text" in messages:
        for text in messages.sort_values("t_ns", kind="stable")["text"].astype(str):
            m = _BANNER.search(text)
            if m:
                banner = f"{m.group(1)} {m.group(2)}"
                break
    mav = (meta.get("mavlink") or {}).get("autopilot")
    if mav is not None and not parts:
        parts.append(MAV_AUTOPILOT.get(int(mav), f"MAV_AUTOPILOT {int(mav)}"))
    if banner and not info.get("sys_name"):
        parts.append(banner)
    return ", ".join(parts) if parts else f"{_NONE} (not logged)"


def _finite(a) -> np.ndarray:
    a = np.asarray(a, np.float64)
    return a[np.isfinite(a)]


def _max(a, fmt: str, unit: str, why: str) -> str:
    a = _finite(a)
    return f"{a.max():{fmt}} {unit}" if len(a) else f"{_NONE} ({why})"


def timestamp_anomalies(diag: Mapping) -> list[str]:
    """One phrase per stream with timestamp anomalies in the ingest diagnostics, naming only the
    non-zero counts: ``"gps: 2 duplicate timestamps"``, ``"imu: 1 backwards, 3 duplicate timestamps"``."""
    out = []
    for stream, a in (diag.get("timestamp_anomalies") or {}).items():
        parts = [f"{a[k]} {word}{'s' * (k == 'duplicate' and a[k] != 1)}"
                 for k, word in (("backwards", "backwards"), ("duplicate", "duplicate timestamp")) if a.get(k)]
        if parts:
            out.append(f"{stream}: {', '.join(parts)}")
    return out


_ITEM = r"""(?:'[^'\[\]]*'|"[^"\[\]]*"|[-+]?\d[\d.eE+-]*|None|True|False)"""
#: a Python list or tuple repr of strings/numbers inside a message: ``['a', 'b']``, ``[0.0, 1.5]``
_QUOTED = r"""(?:'[^'\[\]]*'|"[^"\[\]]*")"""
#: (one item only when quoted: ``[1]``, ``(2)`` stay as they are)
_SEQ_REPR = re.compile(r"[\[(](?:" + _ITEM + r"(?:, " + _ITEM + r")+,?|" + _QUOTED + r",?)[\])]")


def plain_text(text: str) -> str:
    """``text`` with the Python list/tuple reprs a message may hold written as plain text:
    strings comma-separated without quotes (``['a', 'b']`` → ``a, b``), numbers as a tuple
    (``[0.0, 1.5]`` → ``(0.0, 1.5)``). Anything that does not parse is left as it is."""
    import ast

    def one(m: re.Match) -> str:
        try:
            v = ast.literal_eval(m.group(0))
        except (ValueError, SyntaxError):
            return m.group(0)
        v = list(v) if isinstance(v, (list, tuple)) else [v]
        if v and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return "(" + ", ".join(f"{x:g}" for x in v) + ")"
        return ", ".join("–" if x is None else str(x) for x in v)

    return _SEQ_REPR.sub(one, str(text))


def diagnostics_text(diag: Mapping | None) -> str:
    """The ingest diagnostics in words: ``"3 bytes skipped; 1 record dropped (truncated);
    gps: 2 duplicate timestamps"``, ``"nothing lost, no timestamp anomalies"``."""
    return "; ".join(loss_parts(diag)) or "nothing lost, no timestamp anomalies"


def loss_parts(diag: Mapping | None) -> list[str]:
    """What decoding lost and the timestamp anomalies, one phrase each (the flight page's
    diagnostics and the index's warnings)."""
    diag = diag or {}
    parts = []
    if diag.get("bytes_skipped"):
        parts.append(f"{diag['bytes_skipped']} byte{'s' * (diag['bytes_skipped'] != 1)} skipped")
    for reason, n in grouped_drops(diag.get("records_dropped")):
        parts.append(f"{n} record{'s' * (n != 1)} dropped ({reason})")
    return parts + timestamp_anomalies(diag)


def worst_warning(meta: Mapping, preprocess: Mapping | None = None) -> str:
    """The most severe warning of ingest and preprocess, with how many other warnings there are.

    Severity, highest first: the ingest or the preprocess failed (its error); data were lost
    (bytes skipped, records dropped, logger dropouts); the reader's warnings
    (``diagnostics.warnings`` of the ingest ``meta.json``); timestamp anomalies. The preprocess
    ``notes`` are information, not warnings (which source was used, how positions were smoothed,
    the datum: ``baro altitude from pressure``), and are never ranked here. ``"none"`` when
    there is no warning, notes or not."""
    diag = meta.get("diagnostics") or {}
    ranked: list[tuple[int, str]] = []
    if meta.get("status") == "failed":
        ranked.append((5, f"ingest failed: {meta.get('error') or 'unknown reason'}"))
    if diag.get("bytes_skipped"):
        ranked.append((4, f"ingest: {count_text(diag['bytes_skipped'], 'byte')} skipped"))
    for reason, n in grouped_drops(diag.get("records_dropped")):
        ranked.append((4, f"ingest: {count_text(n, 'record')} dropped ({reason})"))
    ranked += [(3, f"ingest: {w}") for w in diag.get("warnings") or []]
    ranked += [(2, f"ingest: {w}") for w in timestamp_anomalies(diag)]
    pre = preprocess or {}
    if pre.get("status") == "failed":
        ranked.append((5, f"preprocess failed: {pre.get('error') or 'unknown reason'}"))
    # the preprocess info JSON keeps one list, "notes", of what it did: none of it is a warning
    # (a flight whose only note was "baro altitude from pressure" showed it as its worst warning)
    if not ranked:
        return "none"
    top = max(r for r, _ in ranked)
    first = plain_text(next(t for r, t in ranked if r == top))
    return first + (f" (+{len(ranked) - 1} more)" if len(ranked) > 1 else "")


def gps_fix_share(gps: pd.DataFrame | None) -> str:
    """Share of the first GPS instance's records with a 3-D fix (``fix_type >= 3``), or with a
    finite, non-zero position where the log has no fix type."""
    if gps is None or not len(gps):
        return f"{_NONE} (no GPS)"
    g = gps[gps["instance"] == gps["instance"].min()] if "instance" in gps else gps
    if "fix_type" in g and g["fix_type"].notna().any():
        ok = (g["fix_type"].to_numpy(np.float64) >= 3).mean()
        return f"{100 * ok:.1f} % of {count_text(len(g), 'record')} (3-D fix or better)"
    lat, lon = g["lat_deg"].to_numpy(np.float64), g["lon_deg"].to_numpy(np.float64)
    ok = (np.isfinite(lat) & np.isfinite(lon) & ((np.abs(lat) > 1e-6) | (np.abs(lon) > 1e-6))).mean()
    return f"{100 * ok:.1f} % of {count_text(len(g), 'record')} (finite position; no fix type logged)"


# --- the headline numbers: one function for the flight page and the index ----------------------

#: the bin width of the path-length rule [s] (positions averaged per bin: ~1 Hz)
PATH_BIN_S = 1.0
#: the dead band of the path-length rule, in noise σ of the bin averages
PATH_NOISE_K = 6.0


def first_instance(df: pd.DataFrame | None) -> pd.DataFrame | None:
    """The rows of the lowest ``instance`` of a canonical stream (the frame itself when empty)."""
    if df is None or not len(df) or "instance" not in df:
        return df
    return df[df["instance"] == df["instance"].min()]


def ned_track(log, state: pd.DataFrame | None) -> pd.DataFrame | None:
    """Local NED track ``t_ns, pos_n_m, pos_e_m, pos_d_m``: the preprocessed state, else the
    autopilot's local_position, else GPS about the NED origin; None when the flight has none."""
    cols = ["t_ns", "pos_n_m", "pos_e_m", "pos_d_m"]
    if state is not None and len(state) and state["pos_n_m"].notna().any():
        return state[cols]
    lp = first_instance(log["local_position"])
    if len(lp) and lp["pos_n_m"].notna().any():
        return lp[cols]
    gps = first_instance(log["gps"]).dropna(subset=["lat_deg", "lon_deg"])
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


def velocity_track(state: pd.DataFrame | None, log) -> pd.DataFrame | None:
    """NED velocity ``t_ns, vel_{n,e,d}_mps``: the state's, else the autopilot's local_position,
    else GPS; None when the flight has none."""
    cols = [f"vel_{a}_mps" for a in "ned"]
    for df in (state, first_instance(log["local_position"]), first_instance(log["gps"])):
        if df is not None and len(df) and set(cols) <= set(df.columns) and df["vel_n_mps"].notna().any():
            return df[["t_ns", *cols]]
    return None


def without_edges(velocity: pd.DataFrame | None, edge_s: float) -> pd.DataFrame | None:
    """``velocity`` with NaN within ``edge_s`` of the ends of each run of finite samples.

    A Savitzky–Golay derivative at the end of a run is the window's polynomial evaluated off its
    centre, with several times the interior's noise (cubic, 1 s at 25 Hz: 3.7×): on the simulated
    tlog flight (GPS at 10 Hz) the last sample read −9.4 m/s in a 1.5 m/s climb and made the
    page's "max vertical speed". The headline maxima leave those half-windows out; the plots do
    not."""
    if velocity is None or not len(velocity) or not edge_s or edge_s <= 0:
        return velocity
    t = velocity["t_ns"].to_numpy(np.int64)
    ok = velocity[[c for c in velocity.columns if c != "t_ns"]].notna().all(axis=1).to_numpy()
    keep = ok.copy()
    edges = np.flatnonzero(np.diff(np.r_[False, ok, False].astype(np.int8)))
    for a, b in zip(edges[::2], edges[1::2]):       # runs [a, b) of finite samples
        run = np.arange(a, b)
        near = (t[run] - t[a] < edge_s * 1e9) | (t[b - 1] - t[run] < edge_s * 1e9)
        keep[run[near]] = False
    out = velocity.copy()
    out.loc[~keep, [c for c in velocity.columns if c != "t_ns"]] = np.nan
    return out


def flight_span(log, state: pd.DataFrame | None = None) -> tuple[float | None, float | None, str]:
    """``(t_start_s, t_end_s, source)`` of the flight: the preprocessed state's span where given,
    else the sensor streams' (stale control, setpoint, mode or event records from before the
    log started do not stretch it), else every stream's; ``(None, None, "no samples")``."""
    if state is not None and len(state) and "t_ns" in state:
        t = state["t_ns"].to_numpy(np.int64)
        return float(t.min()) * 1e-9, float(t.max()) * 1e-9, "preprocessed state"
    for streams, source in ((schema.SENSOR_STREAMS, "sensor streams"), (None, "all streams")):
        lo, hi = log.span_ns(streams)
        if lo is not None:
            return lo * 1e-9, hi * 1e-9, source
    return None, None, "no samples"


def path_length(t_ns, north_m, east_m, *, bin_s: float = PATH_BIN_S,
                k: float = PATH_NOISE_K) -> tuple[float, float, float]:
    """Horizontal path length of a noisy track: ``(length_m, noise_m, dead_band_m)``.

    The rule of the module docstring: positions averaged per ``bin_s`` bin, their noise σ from
    the robust spread of their second differences, a step counted only once the track is more
    than ``k·σ`` from the last counted point (then the last point closes the path). NaN when
    fewer than two finite positions."""
    t = np.asarray(t_ns, np.int64)
    n, e = np.asarray(north_m, np.float64), np.asarray(east_m, np.float64)
    ok = np.isfinite(n) & np.isfinite(e)
    t, n, e = t[ok], n[ok], e[ok]
    if len(t) < 2:
        return float("nan"), float("nan"), float("nan")
    order = np.argsort(t, kind="stable")
    t, n, e = t[order], n[order], e[order]
    _, inv, cnt = np.unique((t - t[0]) // max(1, int(round(bin_s * 1e9))), return_inverse=True, return_counts=True)
    p = np.c_[np.bincount(inv, n) / cnt, np.bincount(inv, e) / cnt]
    sigma = 0.0
    if len(p) >= 3:
        d2 = p[2:] - 2.0 * p[1:-1] + p[:-2]
        mad = 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
        sigma = float(np.sqrt(np.mean(mad ** 2) / 6.0))
    h = k * sigma
    length, anchor = 0.0, p[0]
    for q in p[1:]:
        step = math.hypot(q[0] - anchor[0], q[1] - anchor[1])
        if step > h:
            length += step
            anchor = q
    length += math.hypot(p[-1][0] - anchor[0], p[-1][1] - anchor[1])
    return float(length), sigma, h


def track_numbers(ned: pd.DataFrame | None, velocity: pd.DataFrame | None) -> dict:
    """Distance (:func:`path_length`), max altitude above start (``max(d₀ − d)``, ``d₀`` the
    first finite down position), max horizontal ``max √(v_n² + v_e²)`` and vertical ``max |v_d|``
    speed of a track; NaN where the track cannot give one."""
    nan = float("nan")
    out = {"distance_m": nan, "path_noise_m": nan, "path_dead_band_m": nan, "max_alt_m": nan,
           "max_hspeed_mps": nan, "max_vspeed_mps": nan}
    if ned is not None and len(ned):
        out["distance_m"], out["path_noise_m"], out["path_dead_band_m"] = path_length(
            ned["t_ns"], ned["pos_n_m"], ned["pos_e_m"])
        d = _finite(ned["pos_d_m"])
        if len(d):
            out["max_alt_m"] = float((d[0] - d).max())
    if velocity is not None and len(velocity):
        h = _finite(np.hypot(velocity["vel_n_mps"], velocity["vel_e_mps"]))
        v = _finite(np.abs(velocity["vel_d_mps"]))
        out["max_hspeed_mps"] = float(h.max()) if len(h) else nan
        out["max_vspeed_mps"] = float(v.max()) if len(v) else nan
    return out


def flight_numbers(log, state: pd.DataFrame | None = None, *, ned: pd.DataFrame | None = None,
                   velocity: pd.DataFrame | None = None) -> dict:
    """The flight's headline numbers, the one source of the flight page's summary and the
    index's columns: ``duration_s``, ``t_start_s``, ``t_end_s``, ``duration_from``
    (:func:`flight_span`) and :func:`track_numbers` of the track (``ned``, ``velocity``, default
    :func:`ned_track`, :func:`velocity_track` of ``log`` and ``state``). Values are floats, NaN
    where the flight cannot give one (JSON: null)."""
    ned = ned_track(log, state) if ned is None else ned
    velocity = velocity_track(state, log) if velocity is None else velocity
    t0, t1, src = flight_span(log, state)
    return {"duration_s": float("nan") if t0 is None else t1 - t0,
            "t_start_s": float("nan") if t0 is None else t0, "t_end_s": float("nan") if t1 is None else t1,
            "duration_from": src, **track_numbers(ned, velocity)}


def _num(x) -> float:
    try:
        x = float(x)
    except (TypeError, ValueError):
        return float("nan")
    return x if math.isfinite(x) else float("nan")


def number_texts(numbers: Mapping) -> dict[str, str]:
    """The display text of the headline numbers, as the flight page's summary and the index
    show them: ``{"duration", "distance", "max_alt", "max_hspeed", "max_vspeed"}``."""
    def fmt(key, spec, unit, why):
        v = _num(numbers.get(key))
        return f"{v:{spec}} {unit}" if v == v else f"{_NONE} ({why})"

    ground = bool(numbers.get("ground_vehicle"))

    return {"duration": fmt("duration_s", ",.1f", "s", "no samples"),
            "distance": fmt("distance_m", ",.0f", "m", "no track"),
            "max_alt": fmt("max_alt_m", ".1f", "m", "ground vehicle" if ground else "no height"),
            "max_hspeed": fmt("max_hspeed_mps", ".1f", "m/s", "no velocity"),
            "max_vspeed": fmt("max_vspeed_mps", ".1f", "m/s", "ground vehicle" if ground else "no velocity")}


#: the id of the ``<script type="application/json">`` that carries a flight page's numbers
NUMBERS_ID = "uavpipe-flight-numbers"
_NUMBERS_RE = re.compile(r'<script type="application/json" id="' + NUMBERS_ID + r'">(.*?)</script>', re.S)


def numbers_script(numbers: Mapping) -> str:
    """The flight page's numbers as a JSON ``<script>`` the index reads back (NaN as null;
    ``</`` escaped so the JSON cannot end the script)."""
    return (f'<script type="application/json" id="{NUMBERS_ID}">'
            + json.dumps(json_safe(dict(numbers)), sort_keys=True).replace("</", "<\\/") + "</script>")


def read_page_numbers(page) -> dict | None:
    """The numbers a flight page carries (:func:`numbers_script`); None when the page is absent
    or has none (a page written before they were)."""
    p = Path(page)
    if not p.is_file():
        return None
    m = _NUMBERS_RE.search(p.read_text(encoding="utf-8", errors="replace"))
    if not m:
        return None
    try:
        d = json.loads(m.group(1))
    except ValueError:
        return None
    return {k: (float("nan") if v is None else v) for k, v in d.items()}


def summary_rows(meta: Mapping, *, duration_s: float | None = None, vehicle: str | None = None,
                 messages: pd.DataFrame | None = None, gps: pd.DataFrame | None = None,
                 ned: pd.DataFrame | None = None, velocity: pd.DataFrame | None = None,
                 rates: pd.DataFrame | None = None, euler: Sequence[np.ndarray] | None = None,
                 preprocess: Mapping | None = None, numbers: Mapping | None = None) -> list[tuple[str, str]]:
    """The flight page's summary table as ``[(name, value)]``.

    Parameters
    ----------
    meta : mapping
        The ingest ``meta.json``.
    duration_s : float, optional
        The flight's duration (:func:`flight_span`), when ``numbers`` is not given.
    vehicle : str, optional
        The manifest's vehicle.
    messages, gps : DataFrame, optional
        Canonical streams.
    ned, velocity : DataFrame, optional
        Local track ``t_ns, pos_n_m, pos_e_m, pos_d_m`` and ``vel_{n,e,d}_mps``, for
        :func:`track_numbers` (distance, altitude, speeds) when ``numbers`` is not given.
    rates : DataFrame, optional
        Body rates ``p, q, r`` [rad/s]: max rate ``max √(p² + q² + r²)`` in °/s.
    euler : (roll, pitch, yaw), optional
        ZYX angles [rad]: tilt ``arccos(cos φ cos θ)`` (the body z axis from the vertical).
    preprocess : mapping, optional
        The preprocess diagnostics (``status``, ``error``; its ``notes`` are information, not
        warnings).
    numbers : mapping, optional
        :func:`flight_numbers` of the flight: duration, distance, altitude and speeds as the
        index shows them (:func:`number_texts`).
    """
    if numbers is None:
        numbers = {"duration_s": float("nan") if duration_s is None else float(duration_s),
                   **track_numbers(ned, velocity)}
    txt = number_texts(numbers)
    rows = [("UTC at t = 0", utc_of_t0(meta)), ("vehicle", vehicle or _NONE),
            ("autopilot, firmware", autopilot_firmware(meta, messages)),
            ("duration", txt["duration"]), ("distance (horizontal path)", txt["distance"]),
            ("max altitude above start", txt["max_alt"]), ("max horizontal speed", txt["max_hspeed"]),
            ("max vertical speed", txt["max_vspeed"])]
    if euler is not None:
        tilt = np.degrees(np.arccos(np.clip(np.cos(euler[0]) * np.cos(euler[1]), -1.0, 1.0)))
        rows.append(("max tilt", _max(tilt, ".1f", "°", "no attitude")))
    else:
        rows.append(("max tilt", f"{_NONE} (no attitude)"))
    if rates is not None and len(rates):
        w = np.degrees(np.linalg.norm(rates[["p_radps", "q_radps", "r_radps"]].to_numpy(np.float64), axis=1))
        rows.append(("max body rate", _max(w, ".0f", "°/s", "no body rates")))
    else:
        rows.append(("max body rate", f"{_NONE} (no body rates)"))
    rows.append(("GPS fix share", gps_fix_share(gps)))
    rows.append(("worst warning", worst_warning(meta, preprocess)))
    return rows
