"""GPS positions a receiver reports without a fix, and the NED origin they must never become.

A receiver without a fix logs latitude = longitude = 0 ("Null Island", in the Gulf of Guinea)
with fix type 0 or 1. :func:`check_gps` runs on every ingested log
(:func:`pipeline.io.registry.read_log`), whatever its reader:

* gps rows at exactly lat = lon = 0 keep their row (counts still equal the source's) but
  their ``lat_deg``, ``lon_deg``, ``alt_msl_m`` and ``alt_wgs84_m`` become missing, counted in
  ``meta['diagnostics']['gps_zero_positions']`` with a warning;
* a reader's ``ned_origin`` at lat = lon = 0 is withdrawn;
* where ``ned_origin`` is null, ``meta['ned_origin_reason']`` says why (no GPS stream, or the
  GPS never got a fix: its fix types and the zero/missing coordinates), and a log whose GPS
  stream has records but never a fix gets that reason as a warning too.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from . import schema
from .base import FlightLog

_POS_COLUMNS = ("lat_deg", "lon_deg", "alt_msl_m", "alt_wgs84_m")


def _is_zero(lat, lon) -> bool:
    try:
        return float(lat) == 0.0 and float(lon) == 0.0
    except (TypeError, ValueError):
        return False


def no_fix_reason(lat: np.ndarray, lon: np.ndarray, fix: np.ndarray) -> str:
    """One line describing why GPS records give no origin (none finite and non-zero)."""
    n = len(lat)
    zero = int(np.sum((lat == 0) & (lon == 0)))
    fin = np.isfinite(fix)
    if fin.any():
        types = ", ".join(str(int(v)) for v in np.unique(fix[fin])[:6])
        kinds = f"fix type {types}"
    else:
        kinds = "no fix type"
    return (f"GPS never got a fix: {n} record(s), {kinds}, {zero} at lat = lon = 0, "
            f"{n - zero} without finite coordinates otherwise; NED origin left null")


def _col(table, name: str) -> np.ndarray:
    """A float column as NumPy with nulls as NaN (no pandas: ``info``/``ingest`` never load it)."""
    arr = table.column(name)
    v = schema.arrow_to_np(arr).astype(np.float64, copy=True)
    v[schema.arrow_nulls(arr)] = np.nan
    return v


def check_gps(log: FlightLog) -> None:
    """Null Island guard and the reason of a null NED origin (see the module docstring)."""
    meta = log.meta
    diag = meta.setdefault("diagnostics", {})
    warnings = diag.setdefault("warnings", [])
    table = log.table("gps")
    n = table.num_rows
    lat_raw = lon_raw = lat = lon = np.empty(0)
    if n:
        lat_raw, lon_raw = _col(table, "lat_deg"), _col(table, "lon_deg")
        zero = (lat_raw == 0) & (lon_raw == 0)
        lat, lon = np.where(zero, np.nan, lat_raw), np.where(zero, np.nan, lon_raw)
        if zero.any():
            for c in _POS_COLUMNS:
                i = table.schema.get_field_index(c)
                if i < 0:
                    continue
                arr = table.column(c)
                vals = schema.arrow_to_np(arr).astype(np.float64, copy=True)
                mask = schema.arrow_nulls(arr) | zero
                vals[mask] = np.nan
                table = table.set_column(i, table.schema.field(i), schema.np_to_arrow(vals, pa.float64(), mask))
            log.set_table("gps", table)
            diag["gps_zero_positions"] = int(zero.sum())
            warnings.append(f"gps: {int(zero.sum())} of {n} record(s) at lat = lon = 0 (no fix); "
                            "their positions set missing, never used")
    org = meta.get("ned_origin")
    if org and _is_zero(org.get("lat_deg"), org.get("lon_deg")):
        meta["ned_origin"] = org = None
        warnings.append("ned_origin at lat = lon = 0 (a receiver without a fix) withdrawn")
    if org:
        meta["ned_origin_reason"] = None
        return
    if meta.get("ned_origin_reason"):
        return
    if not n:
        meta["ned_origin_reason"] = "no GPS records (and no origin record) in the log"
        return
    fix = _col(table, "fix_type")
    if not (np.isfinite(lat) & np.isfinite(lon)).any():
        reason = no_fix_reason(lat_raw, lon_raw, fix)
        warnings.append(reason)
    else:
        reason = "the reader found no origin record and no GPS fix it accepts as one"
    meta["ned_origin_reason"] = reason
