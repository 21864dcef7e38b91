"""FlightCoach JSON reader: ``{"parameters", "mans", "data"}`` -> canonical FlightLog.

FlightCoach (PyFlightCoach) exports an ArduPlane flight as one JSON object:

* ``data``: list of samples ``{time (µs), N, E, D (m), VN, VE, VD (m/s), roll, pitch, yaw (rad),
  r, p, yw (the same angles in degrees, not body rates), [wN, wE (wind, m/s)]}``;
* ``parameters``: the NED origin ``originLat/originLng/originAlt`` (deg, deg, m), the aerobatic
  box heading ``rotation`` (rad), pilot/centre positions, schedule;
* ``mans``: maneuvers ``{name, start, stop}`` with ``start``/``stop`` sample indices into ``data``.

Conversions:

* ``t_ns = (time - time[0]) * 1000``; ``t_boot_ns = time * 1000`` (the source log's clock);
* ``local_position``: ``pos_{n,e,d}_m = N, E, D`` and ``vel_{n,e,d}_mps = VN, VE, VD`` exactly;
* ``attitude``: :func:`pipeline.frames.rotations.euler_to_quat` of ``roll, pitch, yaw`` (ZYX);
  when ``roll/pitch/yaw`` are missing, ``r/p/yw`` in degrees are used;
* ``gps``: the NED positions back-converted about the origin with
  :func:`pipeline.frames.geodesy.ned_to_geodetic` (exact WGS-84):

  .. math:: (\\varphi, \\lambda, h) = \\mathrm{ned\\_to\\_geodetic}(N, E, D;\\ \\varphi_0, \\lambda_0, h_0)

  ``originAlt`` is the ArduPilot home altitude, i.e. **above mean sea level** (the fields of the
  real files give 0.04-5.6 m near the Severn estuary, where the WGS-84 ellipsoidal height is
  ~50 m higher; an ellipsoidal origin there could not be that low). We use it as
  ``h0`` and write the result to ``alt_msl_m``; the geoid separation is constant to well under a
  millimetre over a flying field, so the height difference is datum-independent, and the
  horizontal error from the ~50 m datum offset in ``h0`` is < 1e-5 relative. ``alt_wgs84_m``
  stays NaN and ``meta['ned_origin']['alt_wgs84_m']`` is ``None`` (``alt_msl_m`` given);
* ``labels``: one row per ``mans`` entry: ``t_start_ns = t_ns[start]``,
  ``t_end_ns = t_ns[min(stop, n - 1)]`` (consecutive maneuvers share their boundary sample),
  ``label = name``, ``source = "flightcoach_mans"``;
* ``meta['params']``: every ``parameters`` entry, plus ``box_rotation_rad``;
  the wind columns ``wN``/``wE`` are FlightCoach's wind model, not a measurement: they are kept
  out of the canonical streams and only summarised in ``meta['flightcoach']['wind']``.

Samples missing a finite ``time``/``N``/``E``/``D`` are dropped and counted in
``records_dropped['bad_sample']``; maneuvers whose indices fall outside ``data`` are dropped and
counted in ``records_dropped['bad_maneuver']``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from .lazy import pandas as pd  # imported on first use (see lazy.py)

from . import schema
from .base import FlightLog, IngestError, LogReader, Progress
from .registry import register

_KEY_HINTS = (b'"originLat"', b'"mans"', b'"parameters"')
_REQUIRED = ("time", "N", "E", "D")


@register
class FlightCoachReader(LogReader):
    """FlightCoach JSON (see the module docstring)."""

    name = "flightcoach"
    source_format = "flightcoach_json"
    version = "1"
    priority = 30

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
        if not text.startswith(b"{"):
            return None
        hints = [h.decode() for h in _KEY_HINTS if h in head]
        if (b'"data"' in head and hints) or len(hints) >= 2:
            return f"JSON object with FlightCoach keys {', '.join(hints)}"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        obj = _load(path)
        if progress:
            progress(1, 3)
        diag = schema.new_diagnostics()
        data = obj.get("data")
        if not isinstance(data, list) or not data:
            raise IngestError(path, "FlightCoach JSON has no 'data' samples (missing or empty list)")
        if not all(isinstance(r, dict) for r in data):
            raise IngestError(path, "FlightCoach 'data' must be a list of objects")
        df = pd.DataFrame.from_records(data)
        missing = [c for c in _REQUIRED if c not in df.columns]
        if missing:
            raise IngestError(path, f"FlightCoach 'data' samples lack field(s) {missing}")
        raw = df
        df = df.apply(pd.to_numeric, errors="coerce")
        n_raw = len(df)
        ok = np.isfinite(df[list(_REQUIRED)].to_numpy(dtype=np.float64)).all(axis=1)
        # a value that is not a number (text where VN should be) becomes NaN, counted per
        # column as the CSV reader counts it; the required fields' are the bad samples below
        lost = (raw.notna() & df.isna()).to_numpy()[ok]
        for c, n_bad in zip(df.columns, lost.sum(axis=0)):
            if n_bad and c not in _REQUIRED:
                diag["records_dropped"][f"bad_value:{c}"] = int(n_bad)
        # index map raw sample index -> kept row, for the maneuver indices
        kept_idx = np.flatnonzero(ok)
        if not len(kept_idx):
            raise IngestError(path, "no FlightCoach sample has finite time/N/E/D")
        if len(kept_idx) < n_raw:
            diag["records_dropped"]["bad_sample"] = int(n_raw - len(kept_idx))
        df = df.iloc[kept_idx].reset_index(drop=True)
        diag["record_counts"]["data"] = n_raw

        time_us = df["time"].to_numpy(dtype=np.float64).round().astype(np.int64)
        t_boot_ns = time_us * 1000
        t0 = int(t_boot_ns[0])
        t_ns = t_boot_ns - t0
        n = len(df)
        base = {"t_ns": t_ns, "t_boot_ns": t_boot_ns, "instance": np.zeros(n, np.uint8),
                "src": np.full(n, "flightcoach_data", dtype=object)}

        def col(name: str) -> np.ndarray:
            return df[name].to_numpy(dtype=np.float64) if name in df.columns else np.full(n, np.nan)

        pos = {"pos_n_m": col("N"), "pos_e_m": col("E"), "pos_d_m": col("D"),
               "vel_n_mps": col("VN"), "vel_e_mps": col("VE"), "vel_d_mps": col("VD")}
        streams: dict[str, pd.DataFrame] = {"local_position": pd.DataFrame({**base, **pos})}

        if all(c in df.columns for c in ("roll", "pitch", "yaw")):
            ang = [col("roll"), col("pitch"), col("yaw")]
        elif all(c in df.columns for c in ("r", "p", "yw")):
            ang = [np.radians(col("r")), np.radians(col("p")), np.radians(col("yw"))]
            diag["warnings"].append("attitude from r/p/yw (degrees): roll/pitch/yaw absent")
        else:
            ang = None
            diag["warnings"].append("no attitude angles in data")
        if ang is not None:
            from ..frames.rotations import euler_to_quat

            q = euler_to_quat(*ang)
            streams["attitude"] = pd.DataFrame({**base, **{f"q_{c}": q[:, i] for i, c in enumerate("wxyz")}})
        if progress:
            progress(2, 3)

        params = obj.get("parameters") if isinstance(obj.get("parameters"), dict) else {}
        origin = _origin(params)
        if origin is not None:
            from ..frames.geodesy import ned_to_geodetic

            lat, lon, h = ned_to_geodetic(pos["pos_n_m"], pos["pos_e_m"], pos["pos_d_m"],
                                          origin["lat_deg"], origin["lon_deg"], origin["alt_msl_m"])
            gsrc = np.full(n, "flightcoach_data(origin)", dtype=object)
            streams["gps"] = pd.DataFrame({**base, "src": gsrc, "lat_deg": lat, "lon_deg": lon,
                                           "alt_msl_m": h})
        else:
            diag["warnings"].append("parameters.originLat/originLng/originAlt missing: no gps stream")

        streams["labels"] = _labels(obj.get("mans"), kept_idx, n_raw, t_ns, diag, path)

        meta = schema.new_meta(t0_boot_ns=t0, ned_origin=origin)
        meta["params"] = {str(k): _jsonable(v) for k, v in params.items()}
        if "rotation" in params:
            meta["params"]["box_rotation_rad"] = _num(params["rotation"])
        fc = {k: _jsonable(obj[k]) for k in ("version", "name") if k in obj}
        if "wN" in df.columns or "wE" in df.columns:
            fc["wind"] = {"note": "FlightCoach wind model (wN, wE m/s); not a measurement, "
                                  "kept out of the canonical streams",
                          "mean_n_mps": _mean(col("wN")), "mean_e_mps": _mean(col("wE"))}
        meta["flightcoach"] = fc
        meta["frames"] = {"world": "NED", "body": "FRD", "gps_height": "MSL (parameters.originAlt)"}
        meta["diagnostics"] = diag
        if progress:
            progress(3, 3)
        return FlightLog.from_streams(meta, streams)


def _load(path: Path) -> dict:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise IngestError(path, f"cannot read: {exc.strerror or exc}") from None
    try:
        obj = json.loads(raw)
    except UnicodeDecodeError as exc:
        # json.loads guesses UTF-16/32 from the first bytes of a binary file and then reports
        # "truncated data" at its end: name the first byte that is not UTF-8 instead
        try:
            raw.decode("utf-8")
        except UnicodeDecodeError as exc8:
            raise IngestError(path, f"not UTF-8 text: byte 0x{raw[exc8.start]:02x} at offset {exc8.start} "
                                    "(a binary file, not FlightCoach JSON?)") from None
        # UTF-8, but NUL bytes near the start made json.loads take it for UTF-16/32
        raise IngestError(path, f"invalid JSON: a NUL byte at offset {raw.index(0) if 0 in raw else exc.start} "
                                "(a binary file, not FlightCoach JSON?)") from None
    except json.JSONDecodeError as exc:
        hint = " (file truncated?)" if exc.pos >= len(raw.rstrip()) - 1 else ""
        raise IngestError(path, f"invalid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}{hint}") from None
    except RecursionError:
        raise IngestError(path, "invalid JSON: nesting too deep") from None
    if not isinstance(obj, dict):
        raise IngestError(path, f"FlightCoach JSON must be an object, got {type(obj).__name__}")
    return obj


def _mean(x: np.ndarray) -> float | None:
    x = x[np.isfinite(x)]
    return float(x.mean()) if len(x) else None


def _num(v) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if np.isfinite(f) else None


def _jsonable(v):
    if isinstance(v, float) and not np.isfinite(v):
        return None  # JSON's NaN/Infinity extensions: meta.json is strict JSON
    if isinstance(v, (str, int, float, bool)) or v is None:
        return v
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    return str(v)


def _origin(params: dict) -> dict | None:
    lat, lon, alt = (_num(params.get(k)) for k in ("originLat", "originLng", "originAlt"))
    if lat is None or lon is None:
        return None
    return {"lat_deg": lat, "lon_deg": lon, "alt_wgs84_m": None, "alt_msl_m": alt if alt is not None else 0.0,
            "source": "flightcoach parameters.originLat/originLng/originAlt (MSL)"}


def _labels(mans, kept_idx: np.ndarray, n_raw: int, t_ns: np.ndarray, diag: dict, path: Path) -> pd.DataFrame:
    if mans is None:
        return schema.empty("labels")
    if not isinstance(mans, list):
        raise IngestError(path, f"FlightCoach 'mans' must be a list, got {type(mans).__name__}")
    # raw index -> position among kept samples (a dropped sample maps to the next kept one)
    rows, bad = [], 0
    for m in mans:
        try:
            start, stop = int(m["start"]), int(m["stop"])
            name = str(m["name"])
        except (KeyError, TypeError, ValueError):
            bad += 1
            continue
        if not (0 <= start <= stop <= n_raw):
            bad += 1
            continue
        i0 = min(int(np.searchsorted(kept_idx, start)), len(t_ns) - 1)
        i1 = min(int(np.searchsorted(kept_idx, min(stop, n_raw - 1))), len(t_ns) - 1)
        rows.append((int(t_ns[i0]), int(t_ns[i1]), name))
    if bad:
        diag["records_dropped"]["bad_maneuver"] = bad
        diag["warnings"].append(f"{bad} maneuver(s) in 'mans' with missing/out-of-range start/stop dropped")
    if not rows:
        return schema.empty("labels")
    a = np.array([r[:2] for r in rows], dtype=np.int64)
    return pd.DataFrame({"t_start_ns": a[:, 0], "t_end_ns": a[:, 1], "label": [r[2] for r in rows],
                         "source": "flightcoach_mans"})
