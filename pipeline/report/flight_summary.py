"""The summary table at the top of a flight page (issue 13, item 2).

One row per headline number a flight-test engineer reads first: when (UTC of ``t_ns = 0``),
what (vehicle, autopilot and firmware where logged), how long and how far, the envelope
(altitude above start, horizontal and vertical speed, tilt, body rate), GPS fix share, and the
worst warning ingest or preprocess raised. Every value is computed from the full tables, never
from the decimated display traces; a value the flight cannot give reads "–" with the reason.
"""

from __future__ import annotations

import datetime as _dt
import re
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

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


def worst_warning(meta: Mapping, preprocess: Mapping | None = None) -> str:
    """The most severe warning of ingest and preprocess, with how many others there are.

    Severity, highest first: the ingest failed (its error); data were lost (bytes skipped,
    records dropped, logger dropouts); the reader's warnings; timestamp anomalies; the
    preprocess notes. ``"none"`` when there is nothing to say."""
    diag = meta.get("diagnostics") or {}
    ranked: list[tuple[int, str]] = []
    if meta.get("status") == "failed":
        ranked.append((5, f"ingest failed: {meta.get('error') or 'unknown reason'}"))
    if diag.get("bytes_skipped"):
        ranked.append((4, f"ingest: {diag['bytes_skipped']} bytes skipped"))
    for reason, n in (diag.get("records_dropped") or {}).items():
        ranked.append((4, f"ingest: {n} records dropped ({reason})"))
    ranked += [(3, f"ingest: {w}") for w in diag.get("warnings") or []]
    ranked += [(2, f"ingest: {w}") for w in timestamp_anomalies(diag)]
    pre = preprocess or {}
    if pre.get("status") == "failed":
        ranked.append((5, f"preprocess failed: {pre.get('error') or 'unknown reason'}"))
    ranked += [(1, f"preprocess: {n}") for n in pre.get("notes") or []]
    if not ranked:
        return "none"
    top = max(r for r, _ in ranked)
    first = next(t for r, t in ranked if r == top)
    return first + (f" (+{len(ranked) - 1} more)" if len(ranked) > 1 else "")


def gps_fix_share(gps: pd.DataFrame | None) -> str:
    """Share of the first GPS instance's records with a 3-D fix (``fix_type >= 3``), or with a
    finite, non-zero position where the log has no fix type."""
    if gps is None or not len(gps):
        return f"{_NONE} (no GPS)"
    g = gps[gps["instance"] == gps["instance"].min()] if "instance" in gps else gps
    if "fix_type" in g and g["fix_type"].notna().any():
        ok = (g["fix_type"].to_numpy(np.float64) >= 3).mean()
        return f"{100 * ok:.1f} % of {len(g)} records (3-D fix or better)"
    lat, lon = g["lat_deg"].to_numpy(np.float64), g["lon_deg"].to_numpy(np.float64)
    ok = (np.isfinite(lat) & np.isfinite(lon) & ((np.abs(lat) > 1e-6) | (np.abs(lon) > 1e-6))).mean()
    return f"{100 * ok:.1f} % of {len(g)} records (finite position; no fix type logged)"


def summary_rows(meta: Mapping, *, duration_s: float, vehicle: str | None = None,
                 messages: pd.DataFrame | None = None, gps: pd.DataFrame | None = None,
                 ned: pd.DataFrame | None = None, velocity: pd.DataFrame | None = None,
                 rates: pd.DataFrame | None = None, euler: Sequence[np.ndarray] | None = None,
                 preprocess: Mapping | None = None) -> list[tuple[str, str]]:
    """The flight page's summary table as ``[(name, value)]``.

    Parameters
    ----------
    meta : mapping
        The ingest ``meta.json``.
    duration_s : float
        The log's span (``FlightLog.duration_s``).
    vehicle : str, optional
        The manifest's vehicle.
    messages, gps : DataFrame, optional
        Canonical streams.
    ned : DataFrame, optional
        Local track ``t_ns, pos_n_m, pos_e_m, pos_d_m``: distance is the horizontal path
        length ``Σ √(Δn² + Δe²)``; altitude above start is ``max(d₀ − d)`` with ``d₀`` the first
        finite down position.
    velocity : DataFrame, optional
        ``vel_{n,e,d}_mps``: max horizontal speed ``max √(v_n² + v_e²)``, max vertical ``max |v_d|``.
    rates : DataFrame, optional
        Body rates ``p, q, r`` [rad/s]: max rate ``max √(p² + q² + r²)`` in °/s.
    euler : (roll, pitch, yaw), optional
        ZYX angles [rad]: tilt ``arccos(cos φ cos θ)`` (the body z axis from the vertical).
    preprocess : mapping, optional
        The preprocess diagnostics (``notes``, ``status``).
    """
    rows = [("UTC at t = 0", utc_of_t0(meta)), ("vehicle", vehicle or _NONE),
            ("autopilot, firmware", autopilot_firmware(meta, messages)),
            ("duration", f"{duration_s:.1f} s")]
    if ned is not None and len(ned):
        p = ned[["pos_n_m", "pos_e_m"]].dropna().to_numpy(np.float64)
        rows.append(("distance (horizontal path)",
                     f"{np.sum(np.hypot(*np.diff(p, axis=0).T)):,.0f} m" if len(p) > 1 else f"{_NONE} (no track)"))
        d = _finite(ned["pos_d_m"])
        rows.append(("max altitude above start", f"{(d[0] - d).max():.1f} m" if len(d) else f"{_NONE} (no height)"))
    else:
        rows += [("distance (horizontal path)", f"{_NONE} (no track)"),
                 ("max altitude above start", f"{_NONE} (no track)")]
    if velocity is not None and len(velocity):
        rows.append(("max horizontal speed", _max(np.hypot(velocity["vel_n_mps"], velocity["vel_e_mps"]),
                                                  ".1f", "m/s", "no velocity")))
        rows.append(("max vertical speed", _max(np.abs(velocity["vel_d_mps"]), ".1f", "m/s", "no velocity")))
    else:
        rows += [("max horizontal speed", f"{_NONE} (no velocity)"), ("max vertical speed", f"{_NONE} (no velocity)")]
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
