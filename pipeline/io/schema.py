"""The canonical flight-log schema: the contract between ingest and every later stage.

Implements style.md §3.2. Every stream is a tidy wide table, one row per sample of one sensor
instance, with the common columns ``t_ns`` (int64 ns since the log's first sample), ``instance``
(uint8) and ``src`` (dictionary-encoded source message/topic), optionally ``t_boot_ns`` (nullable
int64, the source's own boot-time stamp). Units are in the column names (SI; degrees only in
``_deg`` columns); the world frame is NED, the body frame FRD; quaternions are Hamilton,
scalar-first, body FRD -> NED.

This module is the single place where streams, columns, dtypes, units and frames are declared,
for the canonical streams and for every derived table of every stage (``state``,
``segments``, ``calibration``, the simulated sets and summary, the flight manifest,
``classification``, ``model_evaluation``): :data:`TABLES` maps each name to its columns, and
:func:`columns`, :func:`empty`, :func:`conform` and :func:`cast` are the one way to shape a
table. Readers build loose DataFrames and call :func:`conform` (through ``FlightLog.from_streams``),
which orders and casts columns, adds every missing column (NaN / NA), sorts stably by
(``instance``, ``t_ns``) and rejects unknown columns, so a typo in a reader fails loudly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
import pyarrow as pa

SCHEMA_VERSION = "1.0.0"

#: Number of RC input / servo output channels carried by the ``control`` stream.
N_RC = 18
N_SERVO = 32


@dataclass(frozen=True)
class Column:
    """One column of a canonical stream.

    Parameters
    ----------
    name : str
        Column name, SI unit as suffix (``vel_n_mps``).
    dtype : str
        pandas dtype (``float64``, ``int64``, ``Int64`` nullable, ``uint8``, ``bool``,
        ``boolean`` nullable, ``category``, ``string``).
    unit : str
        Unit string (``m``, ``m/s``, ``rad/s``, ``1`` for dimensionless, ``""`` for labels).
    frame : str
        Reference frame (``NED``, ``FRD``, ``WGS84``, ``sensor``, ``source``) or ``""``.
    doc : str
        One-line description.
    """

    name: str
    dtype: str
    unit: str = ""
    frame: str = ""
    doc: str = ""


def _f(name: str, unit: str, frame: str = "", doc: str = "") -> Column:
    return Column(name, "float64", unit, frame, doc)


COMMON = (
    Column("t_ns", "int64", "ns", "", "time since the log's first sample (t0 in meta)"),
    Column("instance", "uint8", "1", "", "sensor instance (ArduPilot I, ULog multi_id)"),
    Column("src", "category", "", "", "source message type or topic"),
    Column("t_boot_ns", "Int64", "ns", "", "the source's own boot-time stamp, where it has one"),
)

_XYZ = ("x", "y", "z")
_NED = ("n", "e", "d")

STREAMS: dict[str, tuple[Column, ...]] = {
    "imu": (
        *(_f(f"gyr_{a}_radps", "rad/s", "FRD", "body rate, sensor axes in FRD convention") for a in _XYZ),
        *(_f(f"acc_{a}_mps2", "m/s^2", "FRD", "specific force, sensor axes in FRD convention") for a in _XYZ),
        _f("temp_degC", "degC"),
    ),
    "gps": (
        _f("lat_deg", "deg", "WGS84"),
        _f("lon_deg", "deg", "WGS84"),
        _f("alt_wgs84_m", "m", "WGS84", "ellipsoidal height"),
        _f("alt_msl_m", "m", "MSL"),
        *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
        _f("fix_type", "1", "", "0 none, 1 no fix, 2 2D, 3 3D, 4 DGPS, 5 RTK float, 6 RTK fixed"),
        _f("n_sats", "1"),
        _f("hacc_m", "m"),
        _f("vacc_m", "m"),
    ),
    "baro": (
        _f("press_Pa", "Pa"),
        _f("alt_rel_m", "m", "up", "barometric altitude above the reference (positive up)"),
        _f("temp_degC", "degC"),
    ),
    "mag": tuple(_f(f"mag_{a}_T", "T", "FRD") for a in _XYZ),
    "attitude": tuple(
        _f(f"q_{c}", "1", "FRD->NED", "Hamilton quaternion, scalar first") for c in "wxyz"
    ),
    "local_position": (
        *(_f(f"pos_{a}_m", "m", "NED", "about meta.ned_origin") for a in _NED),
        *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
    ),
    "odometry": (
        *(_f(f"pos_{a}_m", "m", "source", "in meta.frames.odometry") for a in _XYZ),
        *(_f(f"vel_{a}_mps", "m/s", "source", "twist, child frame as logged") for a in _XYZ),
        _f("yaw_rate_radps", "rad/s", "source"),
    ),
    "rangefinder": (
        _f("dist_m", "m"),
        Column("valid", "boolean", "", "", "within the sensor's valid range"),
        _f("orientation", "1", "", "MAV_SENSOR_ORIENTATION (25 = down)"),
    ),
    "airspeed": (
        _f("airspeed_mps", "m/s"),
        _f("diff_press_Pa", "Pa"),
        _f("temp_degC", "degC"),
    ),
    "control": (
        *(_f(f"rc_{i}_us", "us", "", "RC input pulse width") for i in range(1, N_RC + 1)),
        *(_f(f"servo_{i}_us", "us", "", "servo/ESC output pulse width") for i in range(1, N_SERVO + 1)),
    ),
    "mode": (
        Column("mode", "string", "", "", "flight mode name (or number when unknown)"),
        Column("armed", "boolean", "", "", "armed state where the source has it"),
    ),
    "radar": (
        _f("range_m", "m", "", "as measured: rho + tau_RD * rho_dot"),
        _f("dcos_u", "1", "NED", "direction cosine (north component)"),
        _f("dcos_v", "1", "NED", "direction cosine (east component)"),
        _f("range_rate_mps", "m/s"),
        _f("sensor_id", "1"),
    ),
    "truth": (
        *(_f(f"pos_{a}_m", "m", "NED") for a in _NED),
        *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
        *(_f(f"acc_{a}_mps2", "m/s^2", "NED") for a in _NED),
        *(_f(f"jerk_{a}_mps3", "m/s^3", "NED") for a in _NED),
        *(_f(f"q_{c}", "1", "FRD->NED") for c in "wxyz"),
        *(_f(f"gyr_{a}_radps", "rad/s", "FRD") for a in _XYZ),
        Column("label", "string", "", "", "maneuver label"),
    ),
}

#: The one stream without ``t_ns``/``instance``/``src``.
LABELS: tuple[Column, ...] = (
    Column("t_start_ns", "int64", "ns"),
    Column("t_end_ns", "int64", "ns"),
    Column("label", "string"),
    Column("source", "string", "", "", "e.g. flightcoach_mans, simulation_truth"),
)

STREAM_NAMES: tuple[str, ...] = (*STREAMS, "labels")

#: Columns of the derived ``state`` table (preprocess output; style.md §3.2).
STATE: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    *(_f(f"pos_{a}_m", "m", "NED") for a in _NED),
    *(_f(f"vel_{a}_mps", "m/s", "NED") for a in _NED),
    *(_f(f"acc_{a}_mps2", "m/s^2", "NED") for a in _NED),
    *(_f(f"jerk_{a}_mps3", "m/s^3", "NED") for a in _NED),
    *(_f(f"q_{c}", "1", "FRD->NED") for c in "wxyz"),
    _f("roll_rad", "rad", "ZYX"),
    _f("pitch_rad", "rad", "ZYX"),
    _f("yaw_rad", "rad", "ZYX"),
    _f("p_radps", "rad/s", "FRD"),
    _f("q_radps", "rad/s", "FRD"),
    _f("r_radps", "rad/s", "FRD"),
    _f("ail", "1"),
    _f("ele", "1"),
    _f("rud", "1"),
    _f("thr", "1"),
    # physical controls (seed 004 §6.8), NaN unless the vehicle config gives bench fits
    _f("delta_a_rad", "rad", "", "aileron deflection"),
    _f("delta_e_rad", "rad", "", "elevator deflection"),
    _f("delta_r_rad", "rad", "", "rudder deflection"),
    _f("thrust_N", "N", "", "propeller thrust"),
    _f("alt_cal_m", "m", "up"),
    Column("gap", "bool"),
)

#: Columns of the derived ``segments`` table.
SEGMENTS: tuple[Column, ...] = (
    Column("segment_id", "int64"),
    Column("t_start_ns", "int64", "ns"),
    Column("t_end_ns", "int64", "ns"),
    Column("label", "string"),
)

#: Columns of the per-flight calibration table (preprocess; one row per candidate reference
#: sample of the BPM calibration, :mod:`pipeline.preprocess.calibrate`).
CALIBRATION: tuple[Column, ...] = (
    Column("t_ns", "int64", "ns"),
    _f("h_ref_m", "m", "up", "reference height (tilt-compensated range, or GPS above origin)"),
    _f("h_baro_m", "m", "up", "filtered barometric altitude at t_ns"),
    _f("offset_m", "m", "up", "h_ref_m - h_baro_m"),
    Column("region", "int64", "1", "", "calibration region (-1: not used)"),
    Column("used", "bool", "", "", "point used in the fit"),
    Column("reason", "string", "", "", "ok, or why the point was rejected"),
    Column("method", "string", "", "", "rangefinder, gps"),
)

#: Columns of a simulated bulk set (simulate ``sets/<name>.parquet``): the ``state`` columns of
#: every run, so models read sets exactly as preprocessed flights, plus the run and its label.
SIM_SET: tuple[Column, ...] = (
    *STATE,
    Column("run_id", "int64", "1", "", "run number within the set"),
    Column("label", "string", "", "", "maneuver label (truth)"),
)

#: Columns of the simulation summary (simulate ``summary.parquet``): per maneuver, quantity and
#: axis, min / max / RMS over all samples of all runs at the truth rate.
SIM_SUMMARY: tuple[Column, ...] = (
    Column("maneuver", "string"),
    Column("quantity", "string", "", "", "acc (m/s^2) or jerk (m/s^3)"),
    Column("axis", "string", "", "", "n/e/d (NED), fwd/right/down (heading frame), norm"),
    Column("min", "float64"),
    Column("max", "float64"),
    Column("rms", "float64"),
    Column("n_runs", "int64"),
)

#: Columns of the simulated log flights' manifest (simulate ``logs/flights.tsv``; the layout of
#: the workflow's flight manifest).
FLIGHTS: tuple[Column, ...] = (
    Column("flight_id", "string"),
    Column("path", "string", "", "", "log file or ROS 2 bag directory"),
    Column("vehicle", "string"),
    Column("role", "string", "", "", "train, test"),
    Column("labels", "string", "", "", "labels / truth side-car path"),
    Column("format", "string", "", "", "reader name, empty: detected"),
    Column("notes", "string"),
)

#: Columns of a classification table (models ``classify``; one row per model-rate sample).
#: The first six (:data:`CLASSIFY_MIN_COLUMNS`) are the placeholder layout of a failed
#: classification. ``ll_*`` stands for one ``ll_<label>`` column per model of the set (and
#: ``ll_background``); the ``*_hmm_*`` columns are written with GMR only.
CLASSIFICATION: tuple[Column, ...] = (
    Column("run_id", "string", "", "", "run (simulated sets) or flight run id"),
    Column("t_ns", "int64", "ns"),
    Column("truth", "string", "", "", "label of the enclosing segment, '' outside"),
    Column("pred", "string", "", "", "decided label, or unknown"),
    Column("best", "string", "", "", "most likely model"),
    Column("V_best", "float64", "1", "", "online Viterbi score of best"),
    Column("oneclass_ok", "bool", "", "", "best passes its one-class threshold"),
    Column("ll_*", "float64", "1", "", "log-likelihood score per model label"),
    Column("state", "int64", "1", "", "online Viterbi state of best (-1: none)"),
    Column("change", "bool", "", "", "a maneuver change detected here"),
    Column("change_t_ns", "int64", "ns", "", "where the change began (-1: none)"),
    *(_f(f"acc_hmm_{a}_mps2", "m/s^2", "NED", "GMR acceleration estimate") for a in _NED),
    *(_f(f"jerk_hmm_{a}_mps3", "m/s^3", "NED", "GMR jerk estimate") for a in _NED),
    *(Column(f"acc_hmm_gated_{a}", "boolean", "", "", "GMR acceleration dropped by the gate") for a in _NED),
)
CLASSIFY_MIN_COLUMNS: tuple[str, ...] = ("run_id", "t_ns", "truth", "pred", "best", "V_best")

#: Columns of a model evaluation table (models ``evaluate``): FA / MAoT per maneuver beside the
#: thesis values (seed 000 §5, Tables 3.1-3.4).
MODEL_EVALUATION: tuple[Column, ...] = (
    Column("table", "string", "", "", "thesis table, or flights"),
    Column("split", "string", "", "", "train, test, test flights"),
    Column("decision", "string", "", "", "oneclass, confidence"),
    Column("maneuver", "string"),
    Column("n_runs", "int64"),
    _f("FA_pct", "%", "", "final accuracy"),
    _f("MAoT_pct", "%", "", "mean accuracy over time"),
    _f("thesis_FA_pct", "%"),
    _f("thesis_MAoT_pct", "%"),
)
EVAL_COLUMNS: tuple[str, ...] = tuple(c.name for c in MODEL_EVALUATION)

#: Every table of every stage by name: the canonical streams (common columns first), ``labels``
#: and the derived tables. :func:`columns`, :func:`empty` and :func:`conform` take these names.
TABLES: dict[str, tuple[Column, ...]] = {
    **{name: (*COMMON, *cols) for name, cols in STREAMS.items()},
    "labels": LABELS,
    "state": STATE,
    "segments": SEGMENTS,
    "calibration": CALIBRATION,
    "simulate_set": SIM_SET,
    "simulate_summary": SIM_SUMMARY,
    "flights": FLIGHTS,
    "classification": CLASSIFICATION,
    "model_evaluation": MODEL_EVALUATION,
}


class SchemaError(ValueError):
    """A DataFrame does not fit its canonical stream (unknown column, uncastable dtype)."""


def columns(table: str) -> tuple[Column, ...]:
    """All columns of ``table`` (a key of :data:`TABLES`) in canonical order (a stream's
    common columns first)."""
    if table not in TABLES:
        raise SchemaError(f"unknown table {table!r}; known: {', '.join(TABLES)}")
    return TABLES[table]


def column_names(table: str) -> list[str]:
    """Column names of ``table`` in canonical order."""
    return [c.name for c in columns(table)]


def _cols(table: str | tuple[Column, ...]) -> tuple[Column, ...]:
    return columns(table) if isinstance(table, str) else tuple(table)


def _is_wildcard(col: Column) -> bool:
    # ``ll_*``: a family of columns named at run time (one per model label)
    return col.name.endswith("*")


def _empty_series(col: Column, n: int) -> pd.Series:
    if col.dtype == "float64":
        return pd.Series(np.full(n, np.nan))
    if col.dtype in ("int64", "uint8", "bool"):
        if n:
            raise SchemaError(f"required column {col.name!r} missing")
        return pd.Series(np.empty(0, dtype=col.dtype))
    if col.dtype == "category":
        return pd.Series(pd.Categorical([None] * n, categories=[]))
    return pd.Series(pd.array([None] * n, dtype=col.dtype))


def cast(column: Column, series: pd.Series) -> pd.Series:
    """``series`` cast to the declared dtype of ``column``.

    Raises
    ------
    SchemaError
        Naming the column, when a value cannot be cast or an ``int64``/``uint8`` column has
        missing values.
    """
    col, s = column, series
    try:
        if col.dtype == "category":
            return s.astype("string").astype("category")
        if col.dtype in ("int64", "uint8"):
            if s.isna().any():
                raise SchemaError(f"column {col.name!r} ({col.dtype}) contains missing values")
            return s.astype(col.dtype)
        return s.astype(col.dtype)
    except (TypeError, ValueError, OverflowError) as exc:
        if isinstance(exc, SchemaError):
            raise
        raise SchemaError(f"column {col.name!r} cannot be cast to {col.dtype}: {exc}") from None


def empty(table: str | tuple[Column, ...]) -> pd.DataFrame:
    """An empty DataFrame with the full schema of ``table`` (a :data:`TABLES` name, or its
    columns; wildcard column families such as ``ll_*`` have no member yet and are left out)."""
    return pd.DataFrame({c.name: _empty_series(c, 0) for c in _cols(table) if not _is_wildcard(c)})


def conform(table: str | tuple[Column, ...], df: pd.DataFrame | None) -> pd.DataFrame:
    """Return ``df`` in the canonical layout of ``table`` (a :data:`TABLES` name, or columns).

    Adds missing optional columns (NaN/NA), casts dtypes and orders columns canonically
    (columns of a wildcard family such as ``ll_*`` at its place, in their given order). A
    stream also gets ``instance`` 0 where it has none, and its rows are sorted stably by
    (``instance``, ``t_ns``) (``labels``: by ``t_start_ns``); derived tables keep their row
    order. Samples are never dropped or repaired here: timestamp anomalies are counted by
    :func:`timestamp_anomalies` and repaired in preprocessing.

    Raises
    ------
    SchemaError
        On an unknown table or column, or a value that cannot be cast.
    """
    stream = table if isinstance(table, str) else ""
    if df is None or (len(df) == 0 and len(df.columns) == 0):
        return empty(table)
    cols = _cols(table)
    known = {c.name for c in cols}
    prefixes = tuple(c.name[:-1] for c in cols if _is_wildcard(c))
    unknown = [c for c in df.columns if c not in known and not (prefixes and str(c).startswith(prefixes))]
    if unknown:
        kind = "stream" if stream in STREAM_NAMES else "table"
        raise SchemaError(f"{kind} {stream or 'given'!r}: unknown column(s) {unknown}")
    n = len(df)
    if stream in STREAMS and "instance" not in df.columns:
        df = df.assign(instance=np.zeros(n, dtype=np.uint8))
    out = {}
    for c in cols:
        if _is_wildcard(c):
            for name in df.columns:
                if str(name).startswith(c.name[:-1]) and name not in known:
                    out[name] = cast(Column(name, c.dtype, c.unit, c.frame, c.doc), df[name].reset_index(drop=True))
        elif c.name in df.columns:
            out[c.name] = cast(c, df[c.name].reset_index(drop=True))
        else:
            out[c.name] = _empty_series(c, n)
    res = pd.DataFrame(out)
    keys = ["t_start_ns"] if stream == "labels" else ["instance", "t_ns"] if stream in STREAMS else []
    if keys:
        order = np.lexsort([res[k].to_numpy() for k in reversed(keys)])
        if not np.array_equal(order, np.arange(n)):
            res = res.iloc[order].reset_index(drop=True)
    return res


def timestamp_anomalies(df: pd.DataFrame, by_src: bool = True) -> dict[str, int]:
    """Count timestamp anomalies of one conformed stream, in *arrival order*.

    Must be called on the reader's rows before sorting (``FlightLog.from_streams`` does).
    Counted per (``instance``, ``src``) sequence: ``backwards`` (t[k] < t[k-1]) and
    ``duplicate`` (t[k] == t[k-1]).
    """
    if len(df) < 2 or "t_ns" not in df.columns:
        return {"backwards": 0, "duplicate": 0}
    keys = [df["instance"].to_numpy()] if "instance" in df.columns else []
    if by_src and "src" in df.columns:
        keys.append(df["src"].astype("string").fillna("").to_numpy())
    t = df["t_ns"].to_numpy(dtype=np.int64)
    if keys:
        grp = pd.DataFrame({f"k{i}": k for i, k in enumerate(keys)})
        gid = grp.groupby(list(grp.columns), sort=False).ngroup().to_numpy()
        order = np.argsort(gid, kind="stable")
        t = t[order]
        same = gid[order][1:] == gid[order][:-1]
    else:
        same = np.ones(len(t) - 1, dtype=bool)
    d = np.diff(t)
    return {"backwards": int(np.sum((d < 0) & same)), "duplicate": int(np.sum((d == 0) & same))}


def arrow_schema(table: str) -> pa.Schema:
    """pyarrow schema of ``table`` (any :data:`TABLES` name) with per-column
    ``unit``/``frame`` field metadata (wildcard families left out)."""
    return _arrow_schema(columns(table))


def arrow_schema_for(cols: tuple[Column, ...]) -> pa.Schema:
    """pyarrow schema for given columns (``STATE``, ``SEGMENTS``...)."""
    return _arrow_schema(cols)


_PA = {
    "float64": pa.float64(),
    "int64": pa.int64(),
    "Int64": pa.int64(),
    "uint8": pa.uint8(),
    "bool": pa.bool_(),
    "boolean": pa.bool_(),
    "string": pa.string(),
    "category": pa.dictionary(pa.int32(), pa.string()),
}


def _arrow_schema(cols: tuple[Column, ...]) -> pa.Schema:
    fields = [
        pa.field(
            c.name,
            _PA[c.dtype],
            nullable=c.dtype not in ("int64", "uint8", "bool"),
            metadata={"unit": c.unit, "frame": c.frame, "doc": c.doc},
        )
        for c in cols
        if not _is_wildcard(c)
    ]
    return pa.schema(fields)


def units(table: str) -> dict[str, dict[str, str]]:
    """``{column: {"unit": ..., "frame": ...}}`` for the file metadata."""
    return {c.name: {"unit": c.unit, "frame": c.frame} for c in columns(table)}


def new_meta(**kw) -> dict:
    """A ``meta`` dict with every key of style.md §3.2 present (defaults ``None``/empty).

    Keys: ``schema_version``, ``flight_id``, ``source_path``, ``source_format``,
    ``source_sha256``, ``source_size_bytes``, ``reader``, ``reader_version``, ``detected_by``,
    ``t0_boot_ns`` (source clock value at ``t_ns = 0``), ``t0_utc_ns`` (UTC of ``t_ns = 0``,
    nullable), ``utc_source`` (gps/host/none), ``leap_seconds``, ``ned_origin`` (``lat_deg``,
    ``lon_deg``, ``alt_wgs84_m`` or ``None``), ``frames`` (world/body plus per-source frames),
    ``diagnostics`` (see :func:`new_diagnostics`), ``params`` (autopilot parameters),
    ``status`` (``ok``/``partial``/``failed``) and ``error`` (reason when failed).
    """
    meta = {
        "schema_version": SCHEMA_VERSION,
        "flight_id": None,
        "source_path": None,
        "source_format": None,
        "source_sha256": None,
        "source_size_bytes": None,
        "reader": None,
        "reader_version": None,
        "detected_by": None,
        "t0_boot_ns": None,
        "t0_utc_ns": None,
        "utc_source": "none",
        "leap_seconds": None,
        "ned_origin": None,
        "frames": {"world": "NED", "body": "FRD"},
        "diagnostics": new_diagnostics(),
        "params": {},
        "status": "ok",
        "error": None,
    }
    meta.update(kw)
    return meta


def new_diagnostics() -> dict:
    """Ingest diagnostics, every counter present.

    ``bytes_skipped``: bytes not part of any decoded record (resync, garbage, truncation);
    ``records_dropped``: ``{reason: count}`` (e.g. ``bad_format``, ``truncated``, ``unknown_type``,
    ``format_lost:<TYPE>``); ``timestamp_anomalies``: ``{stream: {backwards, duplicate}}``;
    ``messages``: text messages logged by the vehicle (first 1000); ``warnings``: reader notes;
    ``record_counts``: ``{source message type: records decoded}``.
    """
    return {
        "bytes_skipped": 0,
        "records_dropped": {},
        "timestamp_anomalies": {},
        "messages": [],
        "warnings": [],
        "record_counts": {},
    }
