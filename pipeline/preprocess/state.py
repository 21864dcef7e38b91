"""Per-flight preprocessing: FlightLog -> ``state``, ``segments`` and calibration tables.

:func:`preprocess_log` implements seed 004 §6 steps 2–8 (and seed 000 §10's differentiation)
in this order, every constant from the ``preprocess`` config section (:class:`PreprocessConfig`):

1. **Mount**: the vehicle's IMU (and magnetometer) mount rotation (:mod:`.mount`); with
   ``attitude_from_imu`` (ROS ``Imu.orientation``) the attitude is rotated to the body too.
2. **Time base**: one sensor instance per stream (the one with most samples); timestamps
   repaired and counted (:func:`.resample.repair_timestamps`); a uniform grid at ``rate_hz``
   over the span of the streams used; each column resampled with its declared method, never
   across a gap longer than ``gap_multiple`` source periods, or grid periods for a source
   faster than the grid (:func:`.resample.bridge_limit_ns`).
3. **Filtering**: Butterworth per configured column (``"<stream>.<column>": {order, cutoff_hz}``;
   default ``baro.alt_rel_m``: 3rd order, 1 Hz, seed 004), per gap-free segment (:mod:`.filters`).
4. **Position** source, in priority order: ``local_position`` (the autopilot EKF) if it has
   positions, else ``gps`` converted to NED about ``meta['ned_origin']`` (first 3D fix when
   absent; ``frames.geodesy``, exact WGS84 or flat Earth; fused with the fixes' measured velocity
   by a Kalman smoother, :mod:`.smoother`, ``gps_smoother``), else ``truth``. ``position_source``
   in the config forces one.
5. **Derivatives**: velocity from the source's measured velocity on each axis it measures (else
   the differentiated position on that axis: a ``GPS_RAW_INT`` fix has no climb rate; a GPS
   source's down axis from the filtered baro height, ``vertical_from_baro``), acceleration and jerk from the velocity by the configured
   differentiator (:mod:`.derivatives`), per gap-free segment.
6. **Attitude**: ``attitude`` (else ``truth``) quaternions, slerped, sign-continuous; ZYX Euler
   angles for display. **Body rates** from the gyro (``imu``, else ``truth``), else from the
   differentiated attitude (FlightCoach, CSV).
7. **Controls**: normalised sticks (and physical deflections where the vehicle gives them).
8. **BPM calibration** of the filtered barometric altitude -> ``alt_cal_m`` (:mod:`.calibrate`).
9. **Segments** from labels, simulation truth labels, configured windows or mode changes
   (:mod:`.segment`).

``gap`` is True at grid points where the position source or the attitude stream (those present)
has no sample within its gap limit, or its sample holds no value (a NaN position, a zero or NaN
quaternion), and around an estimator reset of the position source (``reset_count`` changes):
a row with ``gap`` False has a finite position, velocity and attitude. The other columns keep
their own streams' coverage whatever ``gap`` says (on phoenix-mission1, ~1 Hz telemetry, the
body rates are NaN on 404 rows with ``gap`` False), so a consumer of them checks them. Streams
that are absent give NaN columns; a log with no usable stream at all gives an empty ``state``
with the full schema. Diagnostics (timestamp
repairs, sources, filter flags, calibration summary) are returned in
:attr:`PreprocessResult.diagnostics` and written into the Parquet metadata and the JSON
diagnostics file; the ingest meta's aerobatic box heading ``params.box_rotation_rad`` (FlightCoach)
is copied there too (:func:`box_rotation_rad`). The stage entry point that reads and writes files is
:func:`pipeline.preprocess.run.run_preprocess`.
"""

from __future__ import annotations

import copy
import fnmatch
import functools
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..config import ConfigError, build, cfield, validate_section
from ..frames.geodesy import geodetic_to_ned
from ..frames.rotations import quat_continuity, quat_rotate, quat_to_euler
from ..io import schema
from ..io.base import FlightLog
from ..io.parquet import write_json, write_table
from .calibrate import CALIBRATION, BPMConfig, calibrate_baro, pressure_altitude
from .controls import PHYSICAL, check_stick, controls_from_params, controls_from_pwm
from .derivatives import Differentiator, body_rates_from_quat, differentiate
from .filters import butterworth
from .mount import apply_mount, apply_mount_attitude, mount_dcm
from .resample import bridge_limit_ns, make_grid, median_period_ns, primary_instance, repair_timestamps, resample
from .segment import build_segments
from .smoother import GpsSmoother, smooth_track

_NED = ("n", "e", "d")
POS = [f"pos_{a}_m" for a in _NED]
VEL = [f"vel_{a}_mps" for a in _NED]
QUAT = ["q_w", "q_x", "q_y", "q_z"]
GYR = ["gyr_x_radps", "gyr_y_radps", "gyr_z_radps"]
ACC = ["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]
#: standard gravity, m/s² (the accelerometer's specific force ``f = R⁻¹(a − g e₃)``)
G0 = 9.80665
#: the largest median NED acceleration (m/s², per axis) of an accelerometer the GPS smoother
#: fuses: a whole flight's median acceleration is near 0 (at most 0.07 on the simulated flights, 0.024
#: on husky-ros1 and -ros2)
ACC_CONSISTENCY_MPS2 = 1.0
POSITION_SOURCES = ("auto", "local_position", "gps", "truth")

_pre = functools.partial(cfield, "preprocess")
_veh = functools.partial(cfield, "preprocess.vehicles.*")


@dataclass(frozen=True, kw_only=True)
class PreprocessConfig:
    """The ``preprocess`` config section, resolved for one flight/vehicle (defaults from the
    config schema; :func:`resolve_config` or :meth:`from_config`).

    Parameters
    ----------
    rate_hz : float
        State grid rate.
    gap_multiple : float
        Longest bridged source step, in periods of the source or, when it is faster, of the
        grid (:func:`.resample.bridge_limit_ns`).
    clock_jump_s : float or None
        Steps longer than this are clock jumps and closed (None: never).
    methods : dict
        ``{"<stream>" or "<stream>.<column>": method}``; default ``linear``; quaternions are
        always ``slerp``.
    butterworth : dict
        ``{"<stream>.<column>": {order, cutoff_hz, causal}}``.
    causal : bool
        Default filter mode (False: zero-phase).
    derivatives : Differentiator
    velocity_source : {"measured", "differentiate"}
    vertical_from_baro : bool
        With a GPS position source whose fixes have no climb rate: down velocity, acceleration
        and jerk from the baro height (when it covers every kept row).
    position_source : {"auto", "local_position", "gps", "truth"}
    ned_method : {"wgs84", "flat"}
        GPS -> NED conversion (``frames.geodesy``): exact, or seed 004's flat Earth (5.1).
    bpm : BPMConfig
    gps_smoother : GpsSmoother
        A GPS position source fused with its measured velocity (:mod:`.smoother`).
    segments : dict
        ``source`` and ``windows`` (``{flight_id: [{start_s, end_s, label}]}``).
    vehicle : str or None
        Vehicle key used; its entry is in ``imu_mount``, ``mag_mount``, ``controls``, ``physical``.
    """

    rate_hz: float = _pre("rate_hz")
    gap_multiple: float = _pre("gap_multiple")
    clock_jump_s: float | None = _pre("clock_jump_s")
    methods: dict = _pre("methods")
    butterworth: dict = _pre("butterworth")
    causal: bool = _pre("causal")
    derivatives: Differentiator = field(default_factory=Differentiator)
    velocity_source: str = _pre("velocity_source")
    vertical_from_baro: bool = _pre("vertical_from_baro")
    position_source: str = _pre("position_source")
    ned_method: str = _pre("ned_method")
    bpm: BPMConfig = field(default_factory=BPMConfig)
    gps_smoother: GpsSmoother = field(default_factory=GpsSmoother)
    segments: dict = _pre("segments")
    # per vehicle (preprocess.vehicles.<name>), filled by resolve_config
    vehicle: str | None = field(default=None, metadata={"config_key": None})
    imu_mount: dict | None = _veh("imu_mount", metadata={"config_key": None})
    attitude_from_imu: bool = _veh("attitude_from_imu", metadata={"config_key": None})
    ground: bool = _veh("ground", metadata={"config_key": None})
    mag_mount: dict | None = field(default=None, metadata={"config_key": None})
    controls: dict = _veh("controls", metadata={"config_key": None})
    controls_from_params: bool = _veh("controls_from_params", metadata={"config_key": None})
    #: the config key the sticks come from (None: the built-in ArduPilot map), for the notes
    controls_key: str | None = field(default=None, metadata={"config_key": None})
    physical: dict = _veh("physical", metadata={"config_key": None})

    @classmethod
    def from_config(cls, cfg: Mapping | None, *, flight_id: str | None = None,
                    vehicle: str | None = None) -> "PreprocessConfig":
        """Validate the ``preprocess`` section (or a whole config with a ``preprocess`` key)
        against the schema and resolve it for one flight (:func:`resolve_config`)."""
        sec = dict(cfg or {})
        if "preprocess" in sec and isinstance(sec["preprocess"], Mapping):
            sec = dict(sec["preprocess"] or {})
        sec = validate_section("preprocess", sec)
        check_preprocess_config(sec)
        return resolve_config(sec, flight_id=flight_id, vehicle=vehicle)

    def method(self, stream: str, column: str, default: str = "linear") -> str:
        return self.methods.get(f"{stream}.{column}", self.methods.get(stream, default))



def check_preprocess_config(sec: Mapping[str, Any]) -> None:
    """What the schema cannot check in a validated ``preprocess`` section, for start-up: every
    vehicle's mounts are rotations and every stick of ``vehicles.<v>.controls`` and
    ``flights.<glob>.controls`` has its pulse widths in order.

    Raises
    ------
    ConfigError
        One line naming the key, e.g. ``preprocess.vehicles.copter.controls.ail: min_us 2000.0
        must be below max_us 1000.0``.
    """
    for v, entry in (sec.get("vehicles") or {}).items():
        entry = entry or {}
        for k in ("imu_mount", "mag_mount"):
            try:
                mount_dcm(entry.get(k))
            except ValueError as exc:
                raise ConfigError(f"preprocess.vehicles.{v}.{k}: {exc}") from None
    for where, entries in (("vehicles", sec.get("vehicles")), ("flights", sec.get("flights"))):
        for name, entry in (entries or {}).items():
            for stick, spec in ((entry or {}).get("controls") or {}).items():
                if spec is None:    # a stick the vehicle has not (a flying wing's rudder)
                    continue
                try:
                    check_stick(stick, spec)
                except ValueError as exc:
                    raise ConfigError(f"preprocess.{where}.{name}.{exc}") from None


def resolve_config(sec: Mapping[str, Any], *, flight_id: str | None = None,
                   vehicle: str | None = None) -> PreprocessConfig:
    """The validated ``preprocess`` section resolved for one flight.

    The vehicle is ``vehicle`` if given, else ``flights.<pattern>.vehicle`` for the first glob
    pattern matching ``flight_id``, else the ``default`` vehicle entry (if any); the flight's
    ``windows`` join ``segments.windows`` and its ``controls`` replace the vehicle's.

    Raises
    ------
    ConfigError
        A mount that is not a rotation (what the schema cannot check).
    """
    vehicles = sec.get("vehicles") or {}
    fl_entry: dict = {}
    fl_pat = None
    if flight_id:
        for pat, entry in (sec.get("flights") or {}).items():
            if fnmatch.fnmatchcase(flight_id, str(pat)):
                fl_entry, fl_pat = dict(entry or {}), str(pat)
                break
    vname = vehicle or fl_entry.get("vehicle")
    # the manifest also names vehicles without special settings: those get `default`
    vname_used = vname if vname in vehicles else ("default" if "default" in vehicles else None)
    ventry = dict(vehicles.get(vname_used) or {}) if vname_used else {}
    segs = dict(sec.get("segments") or {})
    windows = dict(segs.get("windows") or {})
    if fl_entry.get("windows"):
        windows[flight_id] = fl_entry["windows"]
    segs["windows"] = windows
    per_vehicle = {k: ventry[k] for k in ("imu_mount", "attitude_from_imu", "ground", "controls",
                                          "controls_from_params", "physical") if k in ventry}
    per_vehicle["controls_key"] = f"preprocess.vehicles.{vname_used}.controls" if "controls" in ventry else None
    if fl_entry.get("controls"):
        per_vehicle["controls"] = fl_entry["controls"]
        per_vehicle["controls_key"] = f"preprocess.flights.{fl_pat}.controls"
    per_vehicle["mag_mount"] = ventry.get("mag_mount", ventry.get("imu_mount"))
    try:
        mount_dcm(per_vehicle.get("imu_mount"))
        mount_dcm(per_vehicle["mag_mount"])
    except ValueError as exc:
        raise ConfigError(f"preprocess.vehicles.{vname_used}: {exc}") from None
    return build(PreprocessConfig, {**sec, "segments": segs}, vehicle=vname_used,
                 **{k: copy.deepcopy(v) for k, v in per_vehicle.items()})

# --- helpers ---------------------------------------------------------------------------------

def _prepare(df: pd.DataFrame, cfg: PreprocessConfig, name: str, diag: dict | None,
             key: str | None = None) -> pd.DataFrame:
    """Primary instance, timestamp repair (counted in ``diag`` under ``key``, default ``name``;
    not counted when ``diag`` is None)."""
    if df is None or not len(df):
        return schema.empty(name) if name in schema.STREAMS else pd.DataFrame()
    kept = primary_instance(df)
    if diag is not None and len(kept) < len(df):
        # one sensor per stream: the others' rows are not used, and the diagnostics say so
        n = df["instance"].value_counts()
        used = int(kept["instance"].iloc[0])
        diag.setdefault("instances", {})[key or name] = {
            "used": used, "rows_not_used": {str(int(i)): int(c) for i, c in n.sort_index().items() if int(i) != used}}
    df = kept
    df, d = repair_timestamps(df, clock_jump_s=cfg.clock_jump_s)
    if diag is not None and any(d.values()):
        diag["timestamp_repairs"][key or name] = d
    if diag is not None:
        df = implausible_to_nan(df, name, diag)
    return df


#: Measured velocity is used on an axis where it is finite on at least this share of the kept
#: samples (the rest filled from the differentiated position)
MEASURED_MIN_SHARE = 0.95


#: What no sensor of a small aircraft reads, by stream and column (``*`` a wildcard): beyond it
#: a value is a damaged record that still decoded (a DataFlash NTUN with 2,000 flipped bytes
#: read ``vel_e`` 1.06e11 m/s; an IMU record 2.9e38 rad/s) and would become the page's "max
#: speed". Far outside any flight envelope on purpose (2,000 °/s is a common gyro full scale,
#: 1,000 m/s thrice the fastest UAV), so no real reading is lost. Latitude/longitude and static
#: pressure have their own checks (:func:`_gps_ned`, step 8), the rangefinder its ``valid`` flag.
MAX_SPEED_MPS = 1000.0
PHYSICAL_LIMITS: dict[str, tuple[tuple[str, float, float], ...]] = {
    "imu": (("gyr_*_radps", -100.0, 100.0), ("acc_*_mps2", -2000.0, 2000.0), ("temp_degC", -100.0, 200.0)),
    "gps": (("alt_*_m", -2000.0, 100_000.0), ("vel_*_mps", -MAX_SPEED_MPS, MAX_SPEED_MPS)),
    "baro": (("alt_rel_m", -100_000.0, 100_000.0), ("temp_degC", -100.0, 200.0)),
    "local_position": (("pos_*_m", -1e7, 1e7), ("vel_*_mps", -MAX_SPEED_MPS, MAX_SPEED_MPS)),
}


#: Heights and positions checked for spikes (:func:`spikes`), by stream
SPIKE_COLUMNS: dict[str, str] = {"baro": "alt_rel_m", "gps": "alt_*_m", "local_position": "pos_*_m"}
#: :func:`spikes`: the margin added for sensor noise [m] to what :data:`MAX_SPEED_MPS` covers
SPIKE_MARGIN_M = 10.0


def spikes(t_ns: NDArray[np.int64], x: NDArray) -> NDArray[np.bool_]:
    """Samples farther from the median of themselves and their two neighbours on each side than
    anything flying at :data:`MAX_SPEED_MPS` could move in two median sample periods, plus
    :data:`SPIKE_MARGIN_M`:

    .. math:: |x_k - \\operatorname{med}(x_{k-2..k+2})| > v_{max} \\cdot 2\\,\\overline{\\Delta t} + m

    One or two damaged records (a DataFlash baro record with flipped bytes read 10.7 km in a
    10 m hover) are spikes; a step (an estimator reset) is not, since the median follows it."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) < 5:
        return np.zeros(len(x), dtype=bool)
    per = median_period_ns(np.asarray(t_ns, dtype=np.int64)) * 1e-9
    if not np.isfinite(per):
        return np.zeros(len(x), dtype=bool)
    med = pd.Series(x).rolling(5, center=True, min_periods=3).median().to_numpy()
    return np.isfinite(x) & np.isfinite(med) & (np.abs(x - med) > MAX_SPEED_MPS * 2 * per + SPIKE_MARGIN_M)


def implausible_to_nan(df: pd.DataFrame, name: str, diag: dict) -> pd.DataFrame:
    """``df`` with every value outside :data:`PHYSICAL_LIMITS`, and every spike of a height or
    position (:func:`spikes`, :data:`SPIKE_COLUMNS`), set to NaN (the row's other columns kept),
    counted in ``diag["implausible_values"][name]`` and said in the notes."""
    limits = PHYSICAL_LIMITS.get(name)
    if not limits or not len(df):
        return df
    counts: dict[str, int] = {}
    out = None
    for pat, lo, hi in limits:
        for c in (c for c in df.columns if fnmatch.fnmatchcase(c, pat)):
            x = pd.to_numeric(df[c], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
            bad = np.isfinite(x) & ((x < lo) | (x > hi)) | np.isinf(x)
            if fnmatch.fnmatchcase(c, SPIKE_COLUMNS.get(name, "")):
                bad |= spikes(df["t_ns"].to_numpy(np.int64), np.where(bad, np.nan, x))
            if bad.any():
                out = df.copy() if out is None else out
                out[c] = np.where(bad, np.nan, x)
                counts[c] = int(bad.sum())
    if not counts:
        return df
    diag.setdefault("implausible_values", {})[name] = counts
    diag["notes"].append(f"{name}: {sum(counts.values())} value(s) outside physical limits set to NaN ("
                         + ", ".join(f"{c} {n}" for c, n in counts.items()) + "): damaged records")
    return out


def _control_groups(ctrl: pd.DataFrame, cols: list[str]) -> dict[str, list[str]]:
    """The pulse-width columns of ``control`` split by the record that carries them,
    ``{"rc": [rc_* inputs], "servo": [servo_* outputs]}``, present columns only.

    Readers put RC inputs and servo outputs on rows of their own (RCIN/RCOU, rc_channels/
    actuator_outputs), so the stream interleaves rows where one group is missing: resampled
    together, every grid point between an RC row and a servo row would interpolate towards a
    missing value, and timestamp repair would drop whichever of two same-stamp rows came second.
    Each group is therefore repaired and resampled on its own rows.
    """
    groups: dict[str, list[str]] = {}
    for c in cols:
        if c in ctrl.columns and ctrl[c].notna().any():
            groups.setdefault(c.split("_", 1)[0], []).append(c)
    return groups


def _has(df: pd.DataFrame, cols) -> bool:
    return len(df) > 0 and all(c in df.columns for c in cols) and \
        bool(np.any(np.all(np.isfinite(df[list(cols)].to_numpy(dtype=np.float64, na_value=np.nan)), axis=1)))


def _resample_stream(df, name, cols, grid, cfg: PreprocessConfig, diag: dict):
    methods = {c: ("slerp" if c in QUAT else cfg.method(name, c)) for c in cols}
    res, valid = resample(df, grid, methods, gap_multiple=cfg.gap_multiple)
    fs = cfg.rate_hz
    for key, spec in cfg.butterworth.items():
        s, c = key.split(".", 1)
        if s != name or c not in res.columns:
            continue
        try:
            y, short = butterworth(res[c].to_numpy(), fs, order=int(spec.get("order", 3)),
                                   cutoff_hz=float(spec["cutoff_hz"]),
                                   causal=bool(spec.get("causal", cfg.causal)), valid=valid)
        except ValueError as exc:
            raise ConfigError(f"preprocess.butterworth.{key}: {exc}") from None
        res[c] = y
        if short.any():
            diag["filter_short_samples"][key] = int(short.sum())
    return res, valid


def _reset_steps(pos_df: pd.DataFrame, grid: NDArray[np.int64], diag: dict, name: str) -> NDArray[np.bool_]:
    """Grid points touched by an estimator reset of the position source.

    Where ``reset_count`` changes between two samples the estimate stepped (a PX4 EKF height
    reset moved ``z`` by 10.9 m in one sample on the ``ekf_failure`` fixture); the grid points
    from one grid period before the last sample ahead of it to one after the first sample behind
    it are gaps, so positions and derivatives never bridge the step. Counted in the notes."""
    out = np.zeros(len(grid), dtype=bool)
    if pos_df is None or "reset_count" not in pos_df.columns or len(grid) == 0:
        return out
    rc = pd.to_numeric(pos_df["reset_count"], errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
    t = pos_df["t_ns"].to_numpy(dtype=np.int64)
    ok = np.isfinite(rc)
    rc, t = rc[ok], t[ok]
    k = np.flatnonzero(np.diff(rc) != 0)
    if not len(k):
        return out
    period = int(grid[1] - grid[0]) if len(grid) > 1 else 0
    lo = np.searchsorted(grid, t[k] - period, side="left")
    hi = np.searchsorted(grid, t[k + 1] + period, side="right")
    prev = None
    for a, b in zip(lo, hi):
        # resets a few samples apart (z at 71.94 s, vz at 72.14 s) leave no island too short to
        # differentiate between them
        if prev is not None and a - prev < 3:
            a = prev
        out[a:b] = True
        prev = b
    at = ", ".join(f"{(x - grid[0]) * 1e-9:.2f}" for x in t[k + 1][:5]) + (" ..." if len(k) > 5 else "")
    diag["notes"].append(f"{name}: {len(k)} estimator reset(s) (reset_count changes) at {at} s after the grid "
                         f"start: {int(out.sum())} grid samples marked as gap")
    return out


#: plausible static pressure for a flying vehicle (Pa): ~16 km altitude to above the sea-level record
PRESS_MIN_PA, PRESS_MAX_PA = 1.0e4, 1.2e5


def _gps_ned(gps: pd.DataFrame, meta: dict, diag: dict, ned_method: str = "wgs84", min_fix: int = 3):
    """GPS fixes -> NED about the origin; returns (rows used, ndarray (n,3), origin)."""
    lat = gps["lat_deg"].to_numpy(dtype=np.float64, na_value=np.nan)
    lon = gps["lon_deg"].to_numpy(dtype=np.float64, na_value=np.nan)
    alt = gps["alt_wgs84_m"].to_numpy(dtype=np.float64, na_value=np.nan)
    alt_kind = "alt_wgs84_m"
    if not np.any(np.isfinite(alt)):
        alt = gps["alt_msl_m"].to_numpy(dtype=np.float64, na_value=np.nan)
        alt_kind = "alt_msl_m"
    fix = gps["fix_type"].to_numpy(dtype=np.float64, na_value=np.nan)
    has_pos = np.isfinite(lat) & np.isfinite(lon) & ~((lat == 0) & (lon == 0))
    low_fix = has_pos & ~(np.isnan(fix) | (fix >= min_fix))
    ok = has_pos & ~low_fix
    dropped = {k: int(v) for k, v in (("no_position", (~has_pos).sum()), ("low_fix", low_fix.sum())) if v}
    if dropped:
        diag["gps_fixes_dropped"] = dropped
        if low_fix.any():
            diag["notes"].append(f"gps: {int(low_fix.sum())} of {len(lat)} fixes below fix type {min_fix} "
                                 "not used (preprocess.bpm.gps_min_fix)")
    # a latitude beyond ±90° or a longitude beyond ±180° is no position (a reader's unit slip,
    # e.g. degE7 read as degrees, or a corrupt record): dropped and counted, never converted
    # into a point thousands of km away
    off_globe = ok & ((np.abs(lat) > 90.0) | (np.abs(lon) > 180.0))
    if off_globe.any():
        diag["notes"].append(f"gps: {int(off_globe.sum())} of {len(lat)} fixes dropped: latitude/longitude out "
                             f"of range (|lat| > 90 or |lon| > 180 deg)")
        ok &= ~off_globe
    if not ok.any():
        return gps.iloc[:0], np.empty((0, 3)), None
    g = gps[ok].reset_index(drop=True)
    lat, lon, alt = lat[ok], lon[ok], alt[ok]
    org = meta.get("ned_origin") or {}
    if org and org.get("lat_deg") is not None and org.get("lon_deg") is not None:
        lat0, lon0 = float(org["lat_deg"]), float(org["lon_deg"])
        # the origin's own altitude, in the datum of the GPS altitude used (a DataFlash ORGN or
        # first fix gives MSL): pos_d is "about meta.ned_origin" (schema), so zero is the origin,
        # not wherever the first fixes happen to be (a flight starting 20 m above its EKF
        # origin would otherwise read 20 m low throughout)
        h0 = org.get(alt_kind)
        other = "alt_msl_m" if alt_kind == "alt_wgs84_m" else "alt_wgs84_m"
        if h0 is None and org.get(other) is not None and other in g.columns:
            # the origin in the other datum (an ORGN gives MSL, the fixes WGS-84 too): shift it
            # by the fixes' own separation of the two (the geoid undulation where they are)
            sep = alt - g[other].to_numpy(dtype=np.float64, na_value=np.nan)
            if np.any(np.isfinite(sep)):
                off = float(np.nanmedian(sep))
                h0 = float(org[other]) + off
                diag["notes"].append(f"NED origin altitude from its {other} {off:+.2f} m (the fixes' "
                                     f"median {alt_kind} - {other})")
        if h0 is None or not np.isfinite(float(h0)):
            h0 = np.nanmedian(alt[:10]) if np.any(np.isfinite(alt[:10])) else 0.0
            diag["notes"].append(f"ned_origin has no {alt_kind}: GPS down about the median of the "
                                 "first fixes")
    else:
        lat0, lon0 = float(lat[0]), float(lon[0])
        h0 = float(alt[np.isfinite(alt)][0]) if np.any(np.isfinite(alt)) else 0.0
        diag["notes"].append("no meta ned_origin: GPS NED about the first 3D fix")
    ned = np.stack(geodetic_to_ned(lat, lon, np.where(np.isfinite(alt), alt, h0), lat0, lon0,
                                   float(h0), method=ned_method), axis=-1)
    ned[~np.isfinite(alt), 2] = np.nan
    return g, ned, {"lat_deg": lat0, "lon_deg": lon0, "alt_m": float(h0), "alt_kind": alt_kind}


def _empty_state() -> pd.DataFrame:
    return schema.empty("state")


# --- the orchestration -----------------------------------------------------------------------

@dataclass(frozen=True)
class PreprocessResult:
    """One preprocessed flight.

    Attributes
    ----------
    state : DataFrame
        ``schema.STATE`` columns on the uniform grid.
    segments : DataFrame
        ``schema.SEGMENTS`` rows.
    calibration : DataFrame
        :data:`.calibrate.CALIBRATION` rows (the BPM calibration points).
    diagnostics : dict
        Timestamp repairs, sources, filter flags, calibration summary, notes.
    """

    state: pd.DataFrame
    segments: pd.DataFrame
    calibration: pd.DataFrame
    diagnostics: dict

    @property
    def tables(self) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
        """``(state, segments, calibration)``."""
        return self.state, self.segments, self.calibration


def preprocess_log(log: FlightLog, config: Mapping | PreprocessConfig | None = None, *,
                   vehicle: str | None = None) -> PreprocessResult:
    """Preprocess one flight.

    Parameters
    ----------
    log : FlightLog
        Canonical flight (``read_log`` / ``read_flightlog`` output).
    config : mapping or PreprocessConfig, optional
        The ``preprocess`` section (or the whole dataset config); defaults throughout.
    vehicle : str, optional
        Vehicle key in ``preprocess.vehicles`` (the manifest's ``vehicle`` column).

    Returns
    -------
    PreprocessResult
        ``state``, ``segments``, ``calibration`` and the ``diagnostics`` dict.
    """
    fid = (log.meta or {}).get("flight_id")
    cfg = config if isinstance(config, PreprocessConfig) else \
        PreprocessConfig.from_config(config, flight_id=fid, vehicle=vehicle)
    diag: dict[str, Any] = {"flight_id": fid, "vehicle": cfg.vehicle, "ground_vehicle": cfg.ground,
                            "rate_hz": cfg.rate_hz,
                            "timestamp_repairs": {}, "filter_short_samples": {}, "sources": {},
                            "notes": []}
    box = box_rotation_rad(log.meta)
    if box is not None:
        diag["box_rotation_rad"] = box
    pilot = box_pilot_ned_m(log.meta)  # the box origin (issue 15: demos in the box frame)
    if pilot is not None:
        diag["box_pilot_ned_m"] = pilot
    if vehicle and vehicle != cfg.vehicle:
        diag["notes"].append(f"vehicle {vehicle!r} has no preprocess.vehicles entry: "
                             f"{cfg.vehicle or 'built-in'} defaults used")
    S = {name: log[name] for name in schema.STREAM_NAMES}
    # 1. mount
    S["imu"] = apply_mount(S["imu"], cfg.imu_mount, "imu")
    S["mag"] = apply_mount(S["mag"], cfg.mag_mount, "mag")
    if cfg.attitude_from_imu:
        S["attitude"] = apply_mount_attitude(S["attitude"], cfg.imu_mount)
    # 2. per-stream preparation
    P = {n: _prepare(S[n], cfg, n, diag) for n in
         ("imu", "gps", "baro", "attitude", "local_position", "rangefinder", "truth")}
    # the control stream as a whole only gives the span; its groups are repaired (and their
    # repairs counted) one by one in step 7, see _control_groups
    P["control"] = _prepare(S["control"], cfg, "control", None)

    # position source
    pos_src, pos_df, gps_origin = None, None, None
    choices = [cfg.position_source] if cfg.position_source != "auto" else ["local_position", "gps", "truth"]
    for src in choices:
        if src in ("local_position", "truth") and _has(P[src], POS[:2]):
            pos_src, pos_df = src, P[src]
            break
        if src == "gps" and _has(P["gps"], ["lat_deg", "lon_deg"]):
            g, ned, gps_origin = _gps_ned(P["gps"], log.meta or {}, diag, cfg.ned_method, cfg.bpm.gps_min_fix)
            if len(g):
                pos_df = pd.DataFrame({"t_ns": g["t_ns"].to_numpy(), POS[0]: ned[:, 0], POS[1]: ned[:, 1],
                                       POS[2]: ned[:, 2], **{v: g[v].to_numpy() for v in VEL},
                                       **{c: g[c].to_numpy() for c in ("hacc_m", "vacc_m") if c in g.columns}})
                pos_src = "gps"
                break
    diag["sources"]["position"] = pos_src
    att_src = "attitude" if _has(P["attitude"], QUAT) else ("truth" if _has(P["truth"], QUAT) else None)
    gyr_src = "imu" if _has(P["imu"], GYR) else ("truth" if _has(P["truth"], GYR) else None)
    diag["sources"]["attitude"] = att_src
    has_baro = _has(P["baro"], ["alt_rel_m"]) or _has(P["baro"], ["press_Pa"])
    has_ctrl = len(P["control"]) > 0

    # grid over the span of the streams used
    used = [d for d in (pos_df, P[att_src] if att_src else None, P[gyr_src] if gyr_src else None,
                        P["baro"] if has_baro else None, P["control"] if has_ctrl else None)
            if d is not None and len(d)]
    if not used:
        diag["notes"].append("no usable stream: empty state")
        st = _empty_state()
        seg = build_segments(S["labels"], S["mode"], windows=cfg.segments.get("windows", {}).get(fid),
                             source=cfg.segments.get("source", "auto"), flight_id=fid, truth=S["truth"],
                             notes=diag["notes"])
        cal = calibrate_baro(np.empty(0, np.int64), None).points
        diag["calibration"] = {"method": "none", "regions": [], "notes": ["no data"]}
        return PreprocessResult(state=st, segments=seg, calibration=cal, diagnostics=diag)
    t0 = min(int(d["t_ns"].iloc[0]) for d in used)
    t1 = max(int(d["t_ns"].iloc[-1]) for d in used)
    grid = make_grid(t0, t1, cfg.rate_hz)
    n = len(grid)
    dt = 1.0 / cfg.rate_hz
    diag["n_samples"] = n
    st: dict[str, NDArray] = {"t_ns": grid}
    gap = np.zeros(n, dtype=bool)

    baro_f = _baro_height(P["baro"], grid, cfg, diag) if has_baro else None

    # 6a. attitude on the grid first: the GPS smoother rotates the accelerometer with it
    q = np.full((n, 4), np.nan)
    qvalid = np.zeros(n, dtype=bool)
    if att_src:
        r, qvalid = _resample_stream(P[att_src], att_src, QUAT, grid, cfg, diag)
        q = r[QUAT].to_numpy().copy()
        # a zero or NaN quaternion (NaN after normalising) is no attitude: a gap
        qvalid = qvalid & np.isfinite(q).all(axis=1) & (np.abs(q).sum(axis=1) > 0)
        gap |= ~qvalid
        ok = np.all(np.isfinite(q), axis=1)
        if ok.any():
            q[ok] = quat_continuity(q[ok])

    # 4-5. position and derivatives
    if pos_src:
        cols = POS + [v for v in VEL if v in pos_df.columns]
        r, pvalid = _resample_stream(pos_df, pos_src if pos_src != "gps" else "gps", cols, grid, cfg, diag)
        pos = r[POS].to_numpy().copy()
        # a sample in time but with no value (a NaN position row) is a gap too: consumers that
        # keep ~gap rows must not meet NaN
        pvalid = pvalid & np.isfinite(pos).all(axis=1)
        pvalid &= ~_reset_steps(pos_df, grid, diag, pos_src)
        gap |= ~pvalid
        fused = None
        if pos_src == "gps" and cfg.gps_smoother.enabled and pvalid.any():
            acc_ned = _imu_acc_ned(P["imu"], q, qvalid, grid, cfg, diag) if cfg.gps_smoother.imu else None
            pos, fused = _smoothed_gps(pos_df, grid, pos, pvalid, cfg, diag, acc_ned)
        vel_meas = np.column_stack([r[v].to_numpy() if v in r.columns else np.full(n, np.nan) for v in VEL])
        # per axis: a GPS_RAW_INT fix carries ground speed and course but no climb rate, and its
        # measured horizontal velocity (0.05 m/s RMS on the simulated tlog) beats the
        # differentiated position (0.75 m/s) by an order of magnitude. An axis is measured where
        # the source measures it on nearly every kept row (MEASURED_MIN_SHARE): a damaged
        # record's NaN (or a stationary fix without a course) is filled from the differentiated
        # position, not the whole axis given up
        meas_ax = np.array([cfg.velocity_source == "measured" and pvalid.any()
                            and np.isfinite(vel_meas[pvalid, i]).mean() >= MEASURED_MIN_SHARE for i in range(3)])
        # the window counts the source's samples, not the grid's interpolation between them
        src_period_s = median_period_ns(pos_df["t_ns"].to_numpy(np.int64)) * 1e-9
        der = cfg.derivatives.for_source(src_period_s)
        if der is not cfg.derivatives:
            diag["notes"].append(f"derivative window {der.window_s:.2f} s: {der.min_source_samples} samples of the "
                                 f"{1 / src_period_s:.1f} Hz position source (derivatives.min_source_samples)")
        diag["derivative_window_s"] = der.window_s
        vel = np.full((n, 3), np.nan)
        acc, jerk = vel.copy(), vel.copy()
        if meas_ax.any():
            m = meas_ax
            vm = vel_meas[:, m].copy()
            holes = pvalid[:, None] & ~np.isfinite(vm)
            if holes.any():
                vm = np.where(holes, differentiate(pos[:, m], dt, 1, der, valid=pvalid), vm)
                diag["notes"].append(f"measured velocity missing on {int(holes.any(axis=1).sum())} of "
                                     f"{int(pvalid.sum())} kept samples: the differentiated position there")
            vel[:, m] = vm
            acc[:, m] = differentiate(vm, dt, 1, der, valid=pvalid)
            jerk[:, m] = differentiate(vm, dt, 2, der, valid=pvalid)
        how = ["measured" if x else "differentiated position" for x in meas_ax]
        if (not meas_ax[2] and pos_src == "gps" and cfg.vertical_from_baro and baro_f is not None
                and cfg.velocity_source == "measured"):
            # a GPS height is ~5x noisier than a barometer (simulated tlog: down velocity 1.46
            # m/s RMS from the fixes, 0.09 from the baro): the climb rate comes from the baro
            # height, as an autopilot's own height estimate does, when it covers every kept
            # row; pos_d stays the GPS's (the baro has an unknown offset and drift, step 8)
            bvalid = pvalid & np.isfinite(baro_f)
            bder = cfg.derivatives.for_source(median_period_ns(P["baro"]["t_ns"].to_numpy(np.int64)) * 1e-9)
            vb = -differentiate(baro_f, dt, 1, bder, valid=bvalid)
            if np.isfinite(vb[pvalid]).all():
                vel[:, 2] = np.where(pvalid, vb, np.nan)
                acc[:, 2] = np.where(pvalid, -differentiate(baro_f, dt, 2, bder, valid=bvalid), np.nan)
                jerk[:, 2] = np.where(pvalid, -differentiate(baro_f, dt, 3, bder, valid=bvalid), np.nan)
                how[2] = "baro height"
            else:
                diag["notes"].append(f"down velocity differentiated from the GPS height: the baro misses "
                                     f"{int((~np.isfinite(vb[pvalid])).sum())} of the position's "
                                     f"{int(pvalid.sum())} samples")
        d = np.array([h == "differentiated position" for h in how])
        if d.any():
            vel[:, d] = differentiate(pos[:, d], dt, 1, der, valid=pvalid)
            acc[:, d] = differentiate(pos[:, d], dt, 2, der, valid=pvalid)
            jerk[:, d] = differentiate(pos[:, d], dt, 3, der, valid=pvalid)
        if fused is not None and cfg.velocity_source == "measured":
            # (velocity_source: differentiate asks for every axis from the position, and gets it)
            # the smoother's own velocity and acceleration where it read the accelerometer: its
            # acceleration is measured, not a second difference of 0.3 m fixes (simulated ROS
            # bag: velocity RMS 0.21 -> see datasets/README.md#preprocess)
            ok = pvalid[:, None] & np.isfinite(fused[:, :, 1])
            for i in range(3):
                if ok[:, i].any():
                    vel[:, i] = np.where(ok[:, i], fused[:, i, 1], np.nan)
                    acc[:, i] = np.where(ok[:, i], fused[:, i, 2], np.nan)
                    jerk[:, i] = differentiate(acc[:, i:i + 1], dt, 1, der, valid=ok[:, i])[:, 0]
                    how[i] = "GPS + accelerometer smoother"
        diag["sources"]["velocity"] = velocity_source_text(how)
    else:
        pos = vel = acc = jerk = np.full((n, 3), np.nan)
    for i, a in enumerate(_NED):
        st[f"pos_{a}_m"] = pos[:, i]
        st[f"vel_{a}_mps"] = vel[:, i]
        st[f"acc_{a}_mps2"] = acc[:, i]
        st[f"jerk_{a}_mps3"] = jerk[:, i]

    # 6. attitude and body rates
    for i, c in enumerate(QUAT):
        st[c] = q[:, i]
    roll, pitch, yaw = quat_to_euler(np.where(np.isfinite(q), q, 1.0))
    bad = ~np.all(np.isfinite(q), axis=1)
    roll, pitch, yaw = (np.where(bad, np.nan, x) for x in (roll, pitch, yaw))
    st["roll_rad"], st["pitch_rad"], st["yaw_rad"] = roll, pitch, yaw
    if gyr_src:
        r, _ = _resample_stream(P[gyr_src], gyr_src, GYR, grid, cfg, diag)
        w = r[GYR].to_numpy().copy()
        diag["sources"]["body_rates"] = f"gyro ({gyr_src})"
    elif att_src:
        w = body_rates_from_quat(q, dt, cfg.derivatives, valid=qvalid)
        diag["sources"]["body_rates"] = "differentiated attitude"
    else:
        w = np.full((n, 3), np.nan)
        diag["sources"]["body_rates"] = None
    st["p_radps"], st["q_radps"], st["r_radps"] = w[:, 0], w[:, 1], w[:, 2]

    # 7. controls
    ctrl_cols = [c for c in P["control"].columns if c.endswith("_us")]
    if has_ctrl:
        r = pd.DataFrame(index=pd.RangeIndex(n))
        for group, cols in _control_groups(S["control"], ctrl_cols).items():
            rows = _prepare(S["control"].dropna(subset=cols, how="all"), cfg, "control", diag,
                            f"control.{group}")
            r[cols] = _resample_stream(rows, "control", cols, grid, cfg, diag)[0]
        sticks, said = cfg.controls, []
        if cfg.controls_from_params:
            sticks, said = controls_from_params(S["params"], cfg.controls)
            diag["notes"] += said
        diag["sources"]["controls"] = "log parameters" if said else (cfg.controls_key or "built-in ArduPilot map")
        cdf = controls_from_pwm(r, sticks, cfg.physical)
    else:
        cdf = controls_from_pwm(pd.DataFrame(index=pd.RangeIndex(n)), cfg.controls, cfg.physical)
    for c in ("ail", "ele", "rud", "thr"):
        st[c] = cdf[c].to_numpy()
    for c in PHYSICAL:
        st[c] = cdf[c].to_numpy() if c in cdf.columns else np.full(n, np.nan)

    # 8. BPM calibration (the baro height itself is on the grid since step 4-5)
    gps_t = gps_up = None
    if cfg.bpm.gps_fallback and pos_src == "gps":   # the fixes in NED are the position source's
        gps_t, gps_up = pos_df["t_ns"].to_numpy(dtype=np.int64), -pos_df[POS[2]].to_numpy()
    elif cfg.bpm.gps_fallback and _has(P["gps"], ["lat_deg", "lon_deg"]):
        g, ned, _ = _gps_ned(P["gps"], log.meta or {}, {"notes": []}, cfg.ned_method, cfg.bpm.gps_min_fix)
        if len(g):
            gps_t, gps_up = g["t_ns"].to_numpy(dtype=np.int64), -ned[:, 2]
    rf = P["rangefinder"]
    cal = calibrate_baro(grid, baro_f, rangefinder=rf if len(rf) else None,
                         roll_rad=roll if att_src else None, pitch_rad=pitch if att_src else None,
                         gps_t_ns=gps_t, gps_up_m=gps_up, cfg=cfg.bpm)
    st["alt_cal_m"] = cal.alt_cal_m
    diag["calibration"] = cal.info()
    st["gap"] = gap

    state = pd.DataFrame({c.name: st[c.name] for c in schema.STATE})
    state = pd.DataFrame({c.name: schema.cast(c, state[c.name]) for c in schema.STATE})
    diag["gap_fraction"] = float(gap.mean()) if n else 0.0

    # 9. segments
    seg = build_segments(S["labels"], S["mode"], windows=cfg.segments.get("windows", {}).get(fid),
                         source=cfg.segments.get("source", "auto"), t_end_ns=int(grid[-1]), flight_id=fid,
                         truth=S["truth"], notes=diag["notes"])
    return PreprocessResult(state=state, segments=seg, calibration=cal.points, diagnostics=diag)


def _imu_acc_ned(imu: pd.DataFrame, q: NDArray, qvalid: NDArray[np.bool_], grid: NDArray[np.int64],
                 cfg: PreprocessConfig, diag: dict) -> NDArray | None:
    """The accelerometer as an NED acceleration on the grid, ``a = R(q) f + g e₃`` (``f`` the
    mount-corrected specific force, FRD; ``R`` body to NED; ``g`` = 9.80665 m/s², NED down);
    ``None`` where the log has no accelerometer or no attitude, NaN on rows without either.
    At rest ``f = −g e₃`` in the body's level frame, so ``a = 0``. The specific force is
    averaged over each grid cell (resample method ``mean``)."""
    if not (_has(imu, ACC) and qvalid.any()):
        return None
    # the cell mean (a boxcar anti-alias filter): a 100-400 Hz accelerometer's vibration would
    # alias onto the grid through point samples
    r, valid = resample(imu, grid, {c: "mean" for c in ACC}, gap_multiple=cfg.gap_multiple)
    f = r[ACC].to_numpy(dtype=np.float64)
    ok = valid & qvalid & np.isfinite(f).all(axis=1)
    out = np.full((len(grid), 3), np.nan)
    out[ok] = quat_rotate(q[ok], f[ok]) + np.array([0.0, 0.0, G0])
    if ok.any():
        # a flight's mean acceleration is ~0 (it starts and ends at rest, or near it); an
        # accelerometer whose mount, axes or time base disagree with the attitude leaves a
        # part of g (a 90° mount error: the whole 9.8 m/s²) and would steer the track
        med = np.median(out[ok], axis=0)
        if np.abs(med).max() > ACC_CONSISTENCY_MPS2:
            diag["notes"].append(f"accelerometer not fused into the GPS track: its NED acceleration "
                                 f"R(q) f + g has a median of ({', '.join(f'{x:.2f}' for x in med)}) m/s² "
                                 f"(more than {ACC_CONSISTENCY_MPS2:g} on an axis): mount, axes or "
                                 "attitude disagree")
            return None
    return out


def _smoothed_gps(fixes: pd.DataFrame, grid: NDArray[np.int64], pos: NDArray, pvalid: NDArray[np.bool_],
                  cfg: PreprocessConfig, diag: dict, acc_ned: NDArray | None = None) -> tuple[NDArray, NDArray | None]:
    """The GPS fixes fused with their measured velocity on the grid (:mod:`.smoother`), and with
    the accelerometer's NED acceleration ``acc_ned`` when given; the rows the interpolation
    called gaps stay as they were (NaN-free rows only change). Returns the positions and, with
    ``acc_ned``, the smoother's (n, 3, 3) position, velocity and acceleration (else ``None``)."""
    g = cfg.gps_smoother

    def col(c):
        return fixes[c].to_numpy(dtype=np.float64, na_value=np.nan) if c in fixes.columns \
            else np.full(len(fixes), np.nan)

    def sigma(c, default):
        x = col(c)
        # a fix that reports no accuracy (or zero, a reader's placeholder) gets the config's
        return np.where(np.isfinite(x) & (x > 0), x, default)

    t = fixes["t_ns"].to_numpy(np.int64)
    z = fixes[POS].to_numpy(dtype=np.float64)
    v = np.column_stack([col(c) for c in VEL])
    sh, sv = sigma("hacc_m", g.sigma_h_m), sigma("vacc_m", g.sigma_v_m)
    sig_acc = None
    if acc_ned is not None:
        # the config's sigma is a floor: where the accelerometer is noisier on the grid it is
        # weighted by its own local noise, the RMS of its first differences / sqrt 2 over a
        # centred second (a vehicle's true acceleration hardly moves in one grid period;
        # vibration does: husky-ros1 on rough ground swings +-5 m/s^2 between 30 Hz samples)
        d2 = np.diff(acc_ned, axis=0) ** 2 / 2.0
        d2 = np.vstack([d2[:1], d2]) if len(d2) else np.full_like(acc_ned, np.nan)
        win = max(3, int(round(cfg.rate_hz)))
        local = pd.DataFrame(d2).rolling(win, center=True, min_periods=1).mean().to_numpy()
        sig_acc = np.maximum(g.sigma_acc_mps2, np.sqrt(np.where(np.isfinite(local), local, 0.0)))
    full = smooth_track(t, z, v, np.column_stack([sh, sh, sv]), grid, g,
                        max_gap_ns=bridge_limit_ns(t, grid, cfg.gap_multiple), causal=cfg.causal,
                        acc=acc_ned, sigma_acc=sig_acc, full=True)
    out = full[:, :, 0]
    ok = pvalid & np.isfinite(out).all(axis=1)
    res = pos.copy()
    res[ok] = out[ok]
    with_vel = [a for i, a in enumerate(_NED) if np.isfinite(v[:, i]).any()]
    n_acc = int(np.isfinite(acc_ned).all(axis=1).sum()) if acc_ned is not None else 0
    diag["gps_smoother"] = {"jerk_psd": g.jerk_psd, "causal": cfg.causal, "velocity_axes": with_vel,
                            "accelerometer_samples": n_acc,
                            "sigma_acc_median_mps2": [round(float(np.median(x)), 4) for x in sig_acc.T] if n_acc else None,
                            "sigma_acc_max_mps2": [round(float(np.max(x)), 4) for x in sig_acc.T] if n_acc else None,
                            "median_sigma_h_m": float(np.median(sh)), "median_sigma_v_m": float(np.median(sv)),
                            "rms_change_m": float(np.sqrt(np.mean((res[ok] - pos[ok]) ** 2))) if ok.any() else 0.0}
    diag["notes"].append(f"gps positions smoothed (white-jerk RTS{' forward only' if cfg.causal else ''}, "
                         f"q {g.jerk_psd:g} m²/s⁵, with the fixes' velocity on "
                         f"{', '.join(with_vel) or 'no axis'}"
                         + (f", and the accelerometer on {n_acc} of {len(grid)} grid samples" if n_acc else "")
                         + f"): {diag['gps_smoother']['rms_change_m']:.3f} m RMS "
                         "from the interpolated fixes (preprocess.gps_smoother)")
    return res, (full if n_acc else None)


def _baro_height(b: pd.DataFrame, grid: NDArray[np.int64], cfg: PreprocessConfig, diag: dict) -> NDArray:
    """The (Butterworth-filtered) barometric height on the grid, m: ``alt_rel_m``, else from the
    pressure by the international barometric formula (out-of-range pressures dropped, counted)."""
    if not _has(b, ["alt_rel_m"]):
        p = b["press_Pa"].to_numpy(dtype=np.float64, na_value=np.nan)
        # a static pressure outside 10-120 kPa (above ~16 km, or above any sea-level record)
        # is no reading but a unit slip (hPa/mbar read as Pa) or a corrupt record: dropped
        # and counted, never turned into an altitude tens of km off
        bad = np.isfinite(p) & ((p < PRESS_MIN_PA) | (p > PRESS_MAX_PA))
        if bad.any():
            med = float(np.nanmedian(p[bad]))
            hint = " (looks like hPa: the reader must convert to Pa)" if 100.0 <= med <= 1200.0 else ""
            diag["notes"].append(f"baro: {int(bad.sum())} of {len(p)} pressures dropped: outside "
                                 f"{PRESS_MIN_PA:.0f}-{PRESS_MAX_PA:.0f} Pa (median of those {med:.6g}){hint}")
            p = np.where(bad, np.nan, p)
        b = b.assign(alt_rel_m=pressure_altitude(p, cfg.bpm.p0_Pa))
        diag["notes"].append("baro altitude from pressure (international barometric formula)")
    r, _ = _resample_stream(b, "baro", ["alt_rel_m"], grid, cfg, diag)
    return r["alt_rel_m"].to_numpy().copy()


def velocity_source_text(how: list[str]) -> str:
    """The ``sources.velocity`` diagnostic from each axis's source (n, e, d): the one source when
    they agree (``"measured"``), else each with its axes, e.g. ``"measured (n, e); baro height
    (d)"``, in order of first appearance."""
    kinds = list(dict.fromkeys(how))
    if len(kinds) == 1:
        return kinds[0]
    return "; ".join(f"{k} ({', '.join(a for a, h in zip(_NED, how) if h == k)})" for k in kinds)


def box_rotation_rad(meta: Mapping | None) -> float | None:
    """The aerobatic box heading of a flight, ``meta['params']['box_rotation_rad']`` (rad).

    Set by the FlightCoach reader (``parameters.rotation``); ``None`` when the ingest meta has
    none or it is not a finite number. Preprocessing copies it into the diagnostics and the
    ``state`` table's metadata (``box_rotation_rad``), where the box-frame features
    (``state9box``, ``box``) and trajectory learning read it.
    """
    v = ((meta or {}).get("params") or {}).get("box_rotation_rad")
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if np.isfinite(v) else None


def box_pilot_ned_m(meta: Mapping | None) -> list[float] | None:
    """The aerobatic box origin of a FlightCoach flight, the pilot's position, in the flight's NED
    frame (m): ``params.pilotLat/pilotLng/pilotAlt`` about ``params.originLat/originLng/originAlt``.

    FlightCoach's N/E/D are about ``originLat/Lng/Alt``, but its box is centred on the pilot
    (FlightAnalysis ``Box.from_fcjson_parmameters``: the box from ``pilotLat/Lng`` towards
    ``centerLat/Lng``, ``gps_to_point``: ``gps - pilot_position``); the two differ by 17-44 m in
    the P23 flights. ``None`` when any of the six values is absent or not finite.
    """
    p = (meta or {}).get("params") or {}
    try:
        v = [float(p[k]) for k in ("pilotLat", "pilotLng", "pilotAlt", "originLat", "originLng", "originAlt")]
    except (KeyError, TypeError, ValueError):
        return None
    if not np.all(np.isfinite(v)):
        return None
    n, e, d = geodetic_to_ned(v[0], v[1], v[2], v[3], v[4], v[5])
    return [float(n), float(e), float(d)]


# --- files -------------------------------------------------------------------------------------

def write_outputs(result: PreprocessResult, *, state_path, segments_path, calibration_path=None,
                  info_path=None) -> None:
    """Write one flight's outputs (ZSTD Parquet with units/frames; diagnostics as JSON).

    The diagnostics ride in the ``state`` table's metadata (``preprocess``) and in ``info_path``;
    a flight with a box rotation (:func:`box_rotation_rad`) also gets it as the top-level
    ``box_rotation_rad`` key of the ``state`` metadata.
    """
    diag = result.diagnostics
    extra = {"flight_id": diag.get("flight_id"), "preprocess": diag}
    if diag.get("box_rotation_rad") is not None:
        extra["box_rotation_rad"] = float(diag["box_rotation_rad"])
    if diag.get("box_pilot_ned_m") is not None:
        extra["box_pilot_ned_m"] = [float(v) for v in diag["box_pilot_ned_m"]]
    write_table(result.state, state_path, schema.STATE, name="state", extra=extra)
    write_table(result.segments, segments_path, schema.SEGMENTS, name="segments",
                extra={"flight_id": diag.get("flight_id")})
    if calibration_path is not None:
        write_table(result.calibration, calibration_path, CALIBRATION, name="calibration",
                    extra={"flight_id": diag.get("flight_id"), "calibration": diag.get("calibration")})
    if info_path is not None:
        write_json(diag, info_path)


def summary_line(diag: dict) -> str:
    c = diag.get("calibration") or {}
    return (f"{diag.get('n_samples', 0)} samples @ {diag.get('rate_hz')} Hz, position "
            f"{diag['sources'].get('position')}, rates {diag['sources'].get('body_rates')}, "
            f"BPM {c.get('method')}, gap {100 * diag.get('gap_fraction', 0):.1f}%")
