"""DataFlash message tables -> the canonical streams of :mod:`pipeline.io.schema`.

Canonical mapping (:func:`to_flightlog`; instance from an ``I``/``Instance``/``C`` field,
else the name suffix, ``IMU2`` -> 1):

==============  ===============================================================================
stream          source
==============  ===============================================================================
imu             IMU/IMU2/IMU3 ``Gyr*`` rad/s, ``Acc*`` m/s² (ArduPilot body axes are FRD), ``T``
gps             GPS/GPS2 ``Lat/Lng`` deg, ``Alt`` MSL, ``Spd``/``GCrs``/``VZ`` -> NED velocity,
                ``Status`` -> fix_type, ``NSats``, ``HDop``; GPA ``HAcc``/``VAcc``/``VDop``,
                ``Und`` -> WGS-84 height
baro            BARO/BAR2/BAR3 ``Alt``, ``Press``, ``Temp``; old logs: CTUN ``BarAlt``
mag             MAG/MAG2/MAG3 mGauss × 10⁻⁷ -> T
attitude        ATT (instance 0) and AHR2 (instance 1) ZYX Euler deg -> quaternion
local_position  XKF1/XKF6/NKF1/NKF6/EKF1 ``PN PE PD VN VE VD`` (core 0 -> instance 0); with
                no EKF message NTUN ``PosX/PosY`` (cm N/E of home) ``VelX/VelY`` (cm/s) with
                down from CTUN ``-Alt``/``-CRt``, home moved onto the origin; else POS
rangefinder     RFND ``Dist`` (m; unscaled integer fields are cm), else non-zero CTUN ``SAlt``
airspeed        ARSP/ASP2
control         RCIN/RCI2 ``C1..C16`` (old ``Chan1..8``) -> ``rc_i_us``; RCOU/RCO2/RCO3 -> servo
mode            MODE (``ModeNum``/``Mode`` -> pymavlink's mode names), EV 10/11 -> ``armed``
radar           RADR (simulation): ``Rng``, ``U``, ``V``, ``RR``, ``I``; PARM RADR_SN/SE/SD/TAU
battery         BAT/BAT2 (else CURR/CURR2) ``Volt`` V, ``Curr`` A (old integer fields 1/100),
                ``CurrTot`` mAh -> Ah, ``RemPct`` -> fraction, ``Temp``
setpoint        ATT ``DesRoll/DesPitch/DesYaw`` deg -> rad; RATE ``RDes/PDes/YDes`` deg/s ->
                rad/s; copter NTUN ``DVelX/DVelY`` cm/s -> north/east m/s, CTUN ``DCRt``
                cm/s up -> down m/s; PSCN/PSCE/PSCD ``TVN/TVE/TVD`` m/s
messages        MSG ``Message`` (no severity in DataFlash: NaN)
params          PARM ``Name``, ``Value``, every record at its time
vibration       VIBE ``VibeX/Y/Z`` m/s², ``Clip0..2`` (Copter 4: per ``IMU``, ``Clip``)
estimator_stat  XKF4 (core ``C``; before it XKF4/XKF9 = cores 0/1), NKF4/NKF9 (EKF2 cores 0/1),
                EKF4 (EKF1): ``SV SP SH SM SVT`` test ratios (EKF1 ``SMX/SMY/SMZ``: the
                largest), ``FS`` fault, ``TS`` timeout, ``SS`` solution, ``GPS`` check bits,
                ``PI`` primary core; integer ``H`` ratio fields (Copter 4.1+) × 0.01
                (stream ``estimator_status``)
==============  ===============================================================================

PARM -> also ``meta['params']``; MSG -> also ``meta['diagnostics']['messages']``; ORGN (else the first 3D
GPS fix, else POS) -> ``meta['ned_origin']``.

Time. ``t_ns = TimeUS·1000`` (``TimeMS·10⁶`` on old logs; old ``GPS`` uses its boot-time
field ``T``) minus ``t0``, the first boot time stamp of a record mapped to a canonical stream.
Untimed records take the time of the preceding timed record in file order. A record whose boot
time stamp stands out from its neighbours in file order (more than :data:`TIME_OUTLIER_US` from
the median of the ``2w + 1`` timed records around it, ``w`` = :data:`TIME_OUTLIER_HALF_WINDOW`,
all message types together) has a corrupt time field and is dropped before ``t0`` is chosen,
counted in ``records_dropped['bad_timestamp']`` (:func:`time_outliers`). UTC of ``t_ns = 0``
comes from the first GPS record with a week number:

.. math:: t_{UTC} = 315964800 + 604800\\,\\mathrm{week} + \\mathrm{tow}_{ms}/1000 - n

(the GPS epoch, 1980-01-06, in Unix seconds; ``n`` the GPS − UTC leap seconds of that date
from the full table since 1980, :mod:`pipeline.io.gpstime`: 16 s in 2014, 18 s since 2017 —
pymavlink's ``DFReader.py::_gpsTimeToTime`` subtracts a fixed 18), recorded in
``meta['leap_seconds']``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from .. import schema
from ..base import FlightLog
from ..gpstime import gps_to_utc_ns
from .decode import Columns, DecodeResult

SOURCE_FORMAT = "ardupilot_dataflash"
READER_NAME = "dataflash"
READER_VERSION = "6"  # 2: the schema 1.1 streams; 3: estimator_status (schema 1.3); 4: bad_timestamp drops; 5: NTUN home height from the median of the fixes; 6: damaged spans counted and named

GPS_EPOCH_UNIX_S = 315964800
#: pymavlink's fixed GPS − UTC (DFReader._gpsTimeToTime), true since 2017-01-01; the reader
#: uses :func:`pipeline.io.gpstime.gps_to_utc_ns` (the table by date) instead
LEAP_SECONDS = 18

#: A boot time stamp farther than this (µs) from the median of its neighbours in file order is
#: corrupt (:func:`time_outliers`). No logger holds a record back for a minute, and records
#: interleave within milliseconds; a flipped bit >= 26 of the µs counter moves a stamp by more.
TIME_OUTLIER_US = 60_000_000
#: Neighbours on each side in the window of :func:`time_outliers` (up to this many corrupt
#: stamps in a row are still outvoted).
TIME_OUTLIER_HALF_WINDOW = 4



# --------------------------------------------------------------------------------------------
# canonical mapping
# --------------------------------------------------------------------------------------------

def _instance_of(name: str, base: str, cols: dict, n: int, field_names=("I", "Instance", "C")) -> np.ndarray:
    """Sensor instance: an ``I``/``Instance``/``C`` field, else the digit suffix (IMU2 -> 1)."""
    for fn in field_names:
        if fn in cols:
            return np.asarray(cols[fn]).astype(np.uint8)
    suffix = name[len(base):]
    k = int(suffix) - 1 if suffix.isdigit() else 0
    return np.full(n, max(k, 0), dtype=np.uint8)


class _Clock:
    """Boot time (µs, int64) of every record; untimed records take the preceding timed one's.

    The file-order index of all timed records is built only when an untimed type asks (old
    logs' MODE/EV/PARM); own times are computed once per type."""

    def __init__(self, res: DecodeResult):
        self.res = res
        self._own: dict[str, np.ndarray | None] = {}
        self._index: tuple[np.ndarray, np.ndarray] | None = None

    def _build_index(self) -> tuple[np.ndarray, np.ndarray]:
        offs, times = [], []
        for name in self.res.formats:
            t = self.own_time_us(name)
            if t is not None and len(t):
                offs.append(self.res.offsets[name])
                times.append(t)
        if not offs:
            return np.empty(0, np.int64), np.empty(0, np.int64)
        o = np.concatenate(offs)
        t = np.concatenate(times)
        k = np.argsort(o, kind="stable")
        return o[k], t[k]

    def own_time_us(self, name: str) -> np.ndarray | None:
        if name in self._own:
            return self._own[name]
        f = self.res.formats[name]
        cols = self.res.tables.get(name)
        t = None
        if cols is not None:
            tf = f.time_field
            if tf == "TimeUS":
                t = cols["TimeUS"].astype(np.int64)
            elif tf == "TimeMS":
                t = cols["TimeMS"].astype(np.int64) * 1000
            elif f.name in ("GPS", "GPS2") and "T" in cols:  # old GPS: TimeMS is GPS time of week
                t = cols["T"].astype(np.int64) * 1000
        self._own[name] = t
        return t

    def time_us(self, name: str) -> np.ndarray:
        t = self.own_time_us(name)
        if t is not None:
            return t
        if self._index is None:
            self._index = self._build_index()
        idx_off, idx_t = self._index
        off = self.res.offsets[name]
        if not len(idx_off):
            return np.zeros(len(off), dtype=np.int64)
        k = np.searchsorted(idx_off, off, side="right") - 1
        return idx_t[np.maximum(k, 0)]


def time_outliers(t: np.ndarray, limit: float = TIME_OUTLIER_US,
                  half_window: int = TIME_OUTLIER_HALF_WINDOW) -> np.ndarray:
    """Mask of the stamps of ``t`` (in arrival order) that stand out from their neighbours.

    A stamp is an outlier when it lies more than ``limit`` from the median of the
    ``2 * half_window + 1`` stamps centred on it (the window is moved inward at the ends):

    .. math:: |t_k - \\operatorname{median}(t_{k-w}, \\dots, t_{k+w})| > \\Delta

    Why this rule: the running median of a non-decreasing sequence is the sequence itself, so a
    real clock is never cut, whatever pauses it has (logging stopped while disarmed, gaps of
    hours); a reboot that restarts the clock moves the median by at most ``w`` samples. A
    corrupt stamp (a flipped bit in ``TimeUS``, up to ``w`` of them in a row) departs from
    both its predecessors and its successors, which outvote it. A window around the median of
    the whole log would miss corruption inside the log's span and cut a log with long pauses.
    Only the first and last ``w`` stamps are judged against a one-sided window: a real pause of
    more than ``limit`` there costs those records. Only stamps next to a step larger than
    ``limit`` are examined, so a clean log costs one pass over its stamps.
    """
    t = np.asarray(t)
    n = len(t)
    bad = np.zeros(n, dtype=bool)
    if n < 3:
        return bad  # nothing to outvote with
    tf = t.astype(np.float64)  # int64 differences of corrupt stamps could overflow
    step = np.abs(np.diff(tf)) > limit
    if not step.any():
        return bad
    near = np.zeros(n, dtype=bool)
    near[:-1] |= step
    near[1:] |= step
    k = np.flatnonzero(near)
    m = min(2 * half_window + 1, n)
    lo = np.clip(k - half_window, 0, n - m)
    med = np.median(tf[lo[:, None] + np.arange(m)], axis=1)
    bad[k] = np.abs(tf[k] - med) > limit
    return bad


def _drop_time_outliers(res: DecodeResult, diag: dict) -> tuple[DecodeResult, _Clock]:
    """``res`` without the records whose own time stamp is corrupt (:func:`time_outliers` over
    all timed records in file order), counted in ``diag['records_dropped']['bad_timestamp']``
    with a warning naming the message types, and its clock. ``res`` itself is not changed."""
    clock = _Clock(res)
    names, offs, times = [], [], []
    for name in res.formats:
        t = clock.own_time_us(name)
        if t is not None and len(t):
            names.append(name)
            offs.append(res.offsets[name])
            times.append(t)
    if not names:
        return res, clock
    o = np.concatenate(offs)
    order = np.argsort(o, kind="stable")
    bad_sorted = time_outliers(np.concatenate(times)[order])
    if not bad_sorted.any():
        return res, clock
    bad = np.empty(len(o), dtype=bool)
    bad[order] = bad_sorted
    tables, offsets = dict(res.tables), dict(res.offsets)
    per_type = {}
    a = 0
    for name, t in zip(names, times):
        drop = bad[a:a + len(t)]
        a += len(t)
        if not drop.any():
            continue
        keep = ~drop
        per_type[name] = int(drop.sum())
        src, cols = res.tables[name], Columns()
        for col in src:
            cols.set_lazy(col, lambda src=src, col=col, keep=keep: src[col][keep])
        tables[name] = cols
        offsets[name] = res.offsets[name][keep]
    n = sum(per_type.values())
    dropped = diag["records_dropped"]
    dropped["bad_timestamp"] = dropped.get("bad_timestamp", 0) + n
    diag["warnings"].append(
        f"{n} record(s) with a corrupt time stamp dropped (more than {TIME_OUTLIER_US / 1e6:g} s from "
        f"the median of their neighbours in file order): "
        + ", ".join(f"{k} {v}" for k, v in sorted(per_type.items())))
    res = dataclasses.replace(res, tables=tables, offsets=offsets)
    return res, _Clock(res)


def _mode_names(res: DecodeResult) -> dict[int, str]:
    """Flight-mode number -> name for the vehicle type (pymavlink's mode mappings)."""
    try:
        from pymavlink import mavutil
    except ImportError:  # pragma: no cover - pymavlink is a core dependency
        return {}
    mav = mavutil.mavlink
    vtype = None
    ver = res.tables.get("VER")
    if ver is not None and "BU" in ver and len(ver["BU"]):
        vtype = {1: mav.MAV_TYPE_GROUND_ROVER, 2: mav.MAV_TYPE_QUADROTOR, 3: mav.MAV_TYPE_FIXED_WING,
                 4: mav.MAV_TYPE_ANTENNA_TRACKER, 7: mav.MAV_TYPE_SUBMARINE,
                 13: mav.MAV_TYPE_HELICOPTER}.get(int(ver["BU"][0]))
    if vtype is None:
        msgs = res.tables.get("MSG", {}).get("Message", [])
        text = " ".join(str(m) for m in list(msgs)[:50])
        if "Rover" in text:
            vtype = mav.MAV_TYPE_GROUND_ROVER
        elif "Plane" in text:
            vtype = mav.MAV_TYPE_FIXED_WING
        elif "Copter" in text:
            vtype = mav.MAV_TYPE_QUADROTOR
        elif "Sub" in text:
            vtype = mav.MAV_TYPE_SUBMARINE
    if vtype is None:
        # copter-only messages identify old copter logs that have no version text
        vtype = mav.MAV_TYPE_QUADROTOR if ("CTUN" in res.tables and "ThrIn" in res.tables["CTUN"]) \
            else mav.MAV_TYPE_FIXED_WING
    return dict(mavutil.mode_mapping_bynumber(vtype) or {})


def _rows(clock: _Clock, name: str, t0_us: int) -> dict[str, np.ndarray]:
    t_us = clock.time_us(name)
    return {"t_ns": (t_us - t0_us) * 1000, "t_boot_ns": t_us * 1000}


def _has(res: DecodeResult, name: str) -> bool:
    """``name`` was decoded and has records."""
    return name in res.tables and len(next(iter(res.tables[name].values()), [])) > 0


@dataclass
class _Ctx:
    """What every builder reads: the decoded tables, the clock, t0 and the diagnostics."""

    res: DecodeResult
    clock: _Clock
    t0_us: int
    diag: dict

    def base(self, name: str, base_name: str, inst: int | None = None) -> tuple[Part, dict]:
        """Common columns of one message's rows (``instance``: ``inst``, else from the
        message, see :func:`_instance_of`) and the message's columns."""
        cols = self.res.tables[name]
        n = len(next(iter(cols.values())))
        d = _rows(self.clock, name, self.t0_us)
        d["instance"] = _instance_of(name, base_name, cols, n) if inst is None else np.full(n, inst, np.uint8)
        d["src"] = name  # one value for all rows: schema.arrow_table dictionary-encodes it
        return d, cols


#: A builder's output: one part of a stream (columns by name; see schema.arrow_table).
Part = dict


def _imu(ctx: _Ctx, name: str, parts: list[Part]) -> Part:
    d, c = ctx.base(name, "IMU")
    for ax in "XYZ":
        d[f"gyr_{ax.lower()}_radps"] = c[f"Gyr{ax}"].astype(np.float64)
        d[f"acc_{ax.lower()}_mps2"] = c[f"Acc{ax}"].astype(np.float64)
    for tn in ("T", "Temp"):
        if tn in c:
            d["temp_degC"] = c[tn].astype(np.float64)
            break
    return d


def _match(keys_g: tuple[np.ndarray, np.ndarray], keys_s: tuple[np.ndarray, np.ndarray]) -> np.ndarray | None:
    """Row of ``keys_g`` (instance, time) equal to each row of ``keys_s``, -1 when none;
    ``None`` when ``keys_g`` is not unique (then nothing is matched)."""
    gi, gt = keys_g
    si, st = keys_s
    if len(gt) and (gt.dtype.kind not in "iu" or st.dtype.kind not in "iu" or gt.min() < 0 or st.min() < 0
                    or max(int(gt.max()), int(st.max()) if len(st) else 0) >= 1 << 55):
        look = {}
        for k, key in enumerate(zip(gi.tolist(), gt.tolist())):
            if key in look:
                return None
            look[key] = k
        return np.array([look.get(key, -1) for key in zip(si.tolist(), st.tolist())], dtype=np.int64)
    kg = (gi.astype(np.uint64) << np.uint64(56)) | gt.astype(np.uint64)
    ks = (si.astype(np.uint64) << np.uint64(56)) | st.astype(np.uint64)
    order = np.argsort(kg, kind="stable")
    sk = kg[order]
    if len(sk) > 1 and np.any(sk[1:] == sk[:-1]):
        return None
    j = np.searchsorted(sk, ks)
    jj = np.minimum(j, max(len(sk) - 1, 0))
    hit = (j < len(sk)) & (sk[jj] == ks) if len(sk) else np.zeros(len(ks), bool)
    return np.where(hit, order[jj] if len(sk) else 0, -1).astype(np.int64)


def _gps(ctx: _Ctx, name: str, parts: list[Part]) -> Part:  # GPS (+ GPA accuracies on instance and time)
    T = ctx.res.tables
    d, c = ctx.base(name, "GPS")
    d["lat_deg"] = c["Lat"]
    d["lon_deg"] = c["Lng"]
    d["alt_msl_m"] = c["Alt"].astype(np.float64)
    spd = c["Spd"].astype(np.float64)
    crs = np.deg2rad(c["GCrs"].astype(np.float64))
    d["vel_n_mps"] = spd * np.cos(crs)
    d["vel_e_mps"] = spd * np.sin(crs)
    if "VZ" in c:
        d["vel_d_mps"] = c["VZ"].astype(np.float64)  # ArduPilot logs NED velocity.z (down)
    d["fix_type"] = c["Status"].astype(np.float64)
    d["n_sats"] = c["NSats"].astype(np.float64)
    if "HDop" in c:
        d["hdop"] = c["HDop"].astype(np.float64)
    gpa_name = "GPA" if name == "GPS" else "GPA2"
    if gpa_name in T and "TimeUS" in c and "TimeUS" in T[gpa_name]:
        g = T[gpa_name]
        gi = _instance_of(gpa_name, "GPA", g, len(g["TimeUS"]))
        k = _match((gi, np.asarray(g["TimeUS"])), (d["instance"], np.asarray(c["TimeUS"])))
        if k is not None:
            ok = k >= 0
            for src_c, dst in (("HAcc", "hacc_m"), ("VAcc", "vacc_m"), ("VDop", "vdop")):
                if src_c in g:
                    v = np.full(len(k), np.nan)
                    v[ok] = g[src_c][k[ok]]
                    d[dst] = v
            if "Und" in g:
                # AP_GPS undulation = h_MSL - h_ellipsoid, so h_WGS84 = Alt - Und
                und = np.full(len(k), np.nan)
                und[ok] = g["Und"][k[ok]]
                und[und == 0] = np.nan  # 0 = receiver gave none
                d["alt_wgs84_m"] = d["alt_msl_m"] - und
    return d


def _baro(ctx: _Ctx, name: str, parts: list[Part]) -> Part:
    inst = {"BARO": 0, "BAR2": 1, "BAR3": 2}[name] if "I" not in ctx.res.tables[name] else None
    d, c = ctx.base(name, "BARO", inst)
    d["alt_rel_m"] = c["Alt"].astype(np.float64)
    if "Press" in c:
        d["press_Pa"] = c["Press"].astype(np.float64)
    if "Temp" in c:
        d["temp_degC"] = c["Temp"].astype(np.float64)
    return d


def _baro_ctun(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:  # old logs without BARO
    if parts:
        return None
    c = ctx.res.tables[name]
    key = "BarAlt" if "BarAlt" in c else ("BAlt" if "BAlt" in c else None)
    if key is None:
        return None
    d, _ = ctx.base(name, "CTUN", 0)
    d["alt_rel_m"] = c[key].astype(np.float64)
    return d


def _mag(ctx: _Ctx, name: str, parts: list[Part]) -> Part:  # mGauss -> T
    d, c = ctx.base(name, "MAG")
    for ax in "XYZ":
        d[f"mag_{ax.lower()}_T"] = c[f"Mag{ax}"].astype(np.float64) * 1e-7
    return d


def _attitude(ctx: _Ctx, name: str, parts: list[Part]) -> Part:  # ZYX Euler deg -> quaternion
    from ...frames.rotations import euler_to_quat

    d, c = ctx.base(name, name, {"ATT": 0, "AHR2": 1}[name])
    q = euler_to_quat(np.deg2rad(c["Roll"].astype(np.float64)),
                      np.deg2rad(c["Pitch"].astype(np.float64)),
                      np.deg2rad(c["Yaw"].astype(np.float64)))
    for i, comp in enumerate("wxyz"):
        d[f"q_{comp}"] = q[:, i]
    return d


def _local_position(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:  # EKF core 0 -> instance 0
    c = ctx.res.tables[name]
    if not all(k in c for k in ("PN", "PE", "PD", "VN", "VE", "VD")):
        return None
    inst = {"XKF1": 0, "XKF6": 1, "NKF1": 0, "NKF6": 1, "EKF1": 0}[name]
    d, _ = ctx.base(name, name, None if "C" in c else inst)
    for k in "NED":
        d[f"pos_{k.lower()}_m"] = c[f"P{k}"].astype(np.float64)
        d[f"vel_{k.lower()}_mps"] = c[f"V{k}"].astype(np.float64)
    return d


def _home_offset_ned(res: DecodeResult) -> tuple[np.ndarray, str]:
    """NED (m) of the vehicle's home about :func:`_origin` and how it was found.

    Home is the first ``CMD`` with ``CNum`` 0 (copter logs before the EKF, where inertial
    navigation works about home), its height the median over the 3D GPS fixes of
    ``Alt - RelAlt`` (MSL; ``RelAlt`` is the inertial height above home); without them, home is
    taken to be the origin.

    The median, not the first fix: at the first fix the inertial height is still settling (on
    the 2014 Austin logs ``RelAlt`` starts at -5.31 m and -3.80 m on the ground and reaches 0
    within 3 s), and one sample made that transient a constant offset of every ``pos_d``
    (-6.6 m and -4.1 m against GPS over the flight)."""
    from ...frames.geodesy import geodetic_to_ned

    org = _origin(res)
    cmd = res.tables.get("CMD")
    g = res.tables.get("GPS")
    if org is None or cmd is None or "CNum" not in cmd or not np.any(cmd["CNum"] == 0):
        return np.zeros(3), "home taken as the NED origin (no CMD 0 home record)"
    k = int(np.flatnonzero(cmd["CNum"] == 0)[0])
    lat, lon = float(cmd["Lat"][k]), float(cmd["Lng"][k])
    if lat == 0 and lon == 0:
        return np.zeros(3), "home taken as the NED origin (CMD 0 home at lat = lon = 0)"
    h = org["alt_msl_m"]
    how = "home from CMD 0"
    if g is not None and "RelAlt" in g and "Alt" in g and len(g["Alt"]):
        ok = np.flatnonzero((g["Status"] >= 3) & (g["Lat"] != 0)) if "Status" in g else np.arange(len(g["Alt"]))
        if len(ok):
            h = float(np.median(np.asarray(g["Alt"], np.float64)[ok] - np.asarray(g["RelAlt"], np.float64)[ok]))
            how += f", its height the median of GPS Alt - RelAlt over {len(ok)} fixes"
    n, e, d = geodetic_to_ned(lat, lon, h, org["lat_deg"], org["lon_deg"], org["alt_msl_m"])
    return np.array([float(n), float(e), float(d)]), how


def _interp_at(t: np.ndarray, ts: np.ndarray, x: np.ndarray, max_gap_us: float) -> np.ndarray:
    """``x(ts)`` linearly interpolated at ``t``; NaN outside ``ts`` and across longer steps."""
    order = np.argsort(ts, kind="stable")
    ts, x = ts[order].astype(np.float64), x[order].astype(np.float64)
    y = np.interp(t, ts, x)
    k = np.clip(np.searchsorted(ts, t, side="right"), 1, len(ts) - 1)
    step = ts[k] - ts[k - 1]
    bad = (t < ts[0]) | (t > ts[-1]) | ((step > max_gap_us) & (t != ts[k - 1]) & (t != ts[k]))
    return np.where(bad, np.nan, y)


def _local_position_ntun(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """Logs with no EKF message (ArduCopter before 3.3): inertial navigation ``NTUN``.

    ``PosX``/``PosY`` are cm north/east of home, ``VelX``/``VelY`` cm/s; down is ``-CTUN.Alt``
    (m above home) and its rate ``-CTUN.CRt`` (cm/s), interpolated at the NTUN times (missing
    across CTUN steps over 1 s). Home is moved onto the NED origin (:func:`_home_offset_ned`)."""
    if parts:
        return None
    c = ctx.res.tables[name]
    if not all(k in c for k in ("PosX", "PosY")):
        return None
    d, _ = ctx.base(name, name, 0)
    off, how = _home_offset_ned(ctx.res)
    d["pos_n_m"] = c["PosX"].astype(np.float64) * 0.01 + off[0]
    d["pos_e_m"] = c["PosY"].astype(np.float64) * 0.01 + off[1]
    if "VelX" in c and "VelY" in c:
        d["vel_n_mps"] = c["VelX"].astype(np.float64) * 0.01
        d["vel_e_mps"] = c["VelY"].astype(np.float64) * 0.01
    src = "NTUN PosX/PosY"
    if _has(ctx.res, "CTUN") and "Alt" in ctx.res.tables["CTUN"]:
        ct = ctx.res.tables["CTUN"]
        t = ctx.clock.time_us(name).astype(np.float64)
        tc = ctx.clock.time_us("CTUN")
        d["pos_d_m"] = -_interp_at(t, tc, ct["Alt"], 1e6) + off[2]
        src += ", -CTUN.Alt"
        if "CRt" in ct:
            d["vel_d_mps"] = -_interp_at(t, tc, ct["CRt"], 1e6) * 0.01
            src += ", -CTUN.CRt"
    ctx.diag["local_position_from"] = f"{src} (no EKF messages); {how}"
    return d


def _local_position_pos(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """Logs with neither EKF nor NTUN positions: ``POS`` (the AHRS position, lat/lon/MSL
    altitude) converted to NED about the origin; no velocity."""
    if parts:
        return None
    from ...frames.geodesy import geodetic_to_ned

    c = ctx.res.tables[name]
    org = _origin(ctx.res)
    if org is None or not all(k in c for k in ("Lat", "Lng", "Alt")):
        return None
    lat, lon = c["Lat"].astype(np.float64), c["Lng"].astype(np.float64)
    zero = (lat == 0) & (lon == 0)
    d, _ = ctx.base(name, name, 0)
    n, e, dd = geodetic_to_ned(lat, lon, c["Alt"].astype(np.float64), org["lat_deg"], org["lon_deg"],
                               org["alt_msl_m"])
    d["pos_n_m"] = np.where(zero, np.nan, n)
    d["pos_e_m"] = np.where(zero, np.nan, e)
    d["pos_d_m"] = np.where(zero, np.nan, dd)
    ctx.diag["local_position_from"] = "POS Lat/Lng/Alt about the NED origin (no EKF or NTUN messages)"
    return d


def _rangefinder(ctx: _Ctx, name: str, parts: list[Part]) -> list[Part]:  # RFND: Dist, or Dist1/Dist2
    c = ctx.res.tables[name]
    fmt_of = dict(zip(ctx.res.formats[name].dtype.names, ctx.res.formats[name].fmt))
    pairs = [("Dist", "Orient")] if "Dist" in c else [(f"Dist{k}", f"Orient{k}") for k in (1, 2)]
    out = []
    for k, (dn, on) in enumerate(pairs):
        if dn not in c:
            continue
        d, _ = ctx.base(name, name, None if "Instance" in c or "I" in c else k)
        dist = c[dn].astype(np.float64)
        if fmt_of[dn] in "hHiI":  # unscaled integer: centimetres (old logs)
            dist = dist * 0.01
        d["dist_m"] = dist
        if on in c:
            d["orientation"] = c[on].astype(np.float64)
        d["valid"] = c["Stat"] == 4 if "Stat" in c else dist > 0  # RangeFinder::Status::Good
        out.append(d)
    return out


def _rangefinder_ctun(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:  # CTUN.SAlt, no RFND
    if _has(ctx.res, "RFND") or "SAlt" not in ctx.res.tables[name]:
        return None
    salt = ctx.res.tables[name]["SAlt"].astype(np.float64)
    if not np.any(salt != 0):
        ctx.diag["warnings"].append("CTUN.SAlt is 0 throughout: no rangefinder data")
        return None
    d, _ = ctx.base(name, name, 0)
    d["dist_m"] = salt
    d["valid"] = salt > 0
    d["orientation"] = np.full(len(salt), 25.0)
    return d


def _airspeed(ctx: _Ctx, name: str, parts: list[Part]) -> Part:
    c = ctx.res.tables[name]
    d, _ = ctx.base(name, "ARSP", None if "I" in c else (0 if name == "ARSP" else 1))
    d["airspeed_mps"] = c["Airspeed"].astype(np.float64)
    if "DiffPress" in c:
        d["diff_press_Pa"] = c["DiffPress"].astype(np.float64)
    if "Temp" in c:
        d["temp_degC"] = c["Temp"].astype(np.float64)
    return d


_CONTROL = {"RCIN": ("rc", schema.N_RC), "RCI2": ("rc", schema.N_RC), "RCOU": ("servo", schema.N_SERVO),
            "RCO2": ("servo", schema.N_SERVO), "RCO3": ("servo", schema.N_SERVO)}


def _control(ctx: _Ctx, name: str, parts: list[Part]) -> Part:  # raw pulse widths
    prefix, lim = _CONTROL[name]
    d, c = ctx.base(name, name, 0)
    for col, v in c.items():
        for pre in ("Chan", "C"):
            if col.startswith(pre) and col[len(pre):].isdigit():
                i = int(col[len(pre):])
                if 1 <= i <= lim:
                    d[f"{prefix}_{i}_us"] = v.astype(np.float64)
    return d


def _mode(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """Mode and arming (EV 10 armed, 11 disarmed), state carried forward in file order."""
    res, T = ctx.res, ctx.res.tables
    ev = []
    if _has(res, "MODE"):
        c = T["MODE"]
        names = _mode_names(res)
        num = c["ModeNum"] if "ModeNum" in c else c["Mode"]
        labels = [names.get(int(x), str(int(x))) for x in num.tolist()]
        t = _rows(ctx.clock, "MODE", ctx.t0_us)
        for k in range(len(labels)):
            ev.append((int(res.offsets["MODE"][k]), int(t["t_ns"][k]), int(t["t_boot_ns"][k]), labels[k], None))
    if _has(res, "EV"):
        c = T["EV"]
        t = _rows(ctx.clock, "EV", ctx.t0_us)
        for k, i in enumerate(c["Id"].tolist()):
            if i in (10, 11):
                ev.append((int(res.offsets["EV"][k]), int(t["t_ns"][k]), int(t["t_boot_ns"][k]), None, i == 10))
    if not ev:
        return None
    ev.sort(key=lambda e: e[0])
    mode, armed = None, None
    modes, arms = [], []
    for _, _, _, m, a in ev:
        mode = m if m is not None else mode
        armed = a if a is not None else armed
        modes.append(mode)
        arms.append(armed)
    return {"t_ns": np.array([e[1] for e in ev], np.int64), "t_boot_ns": np.array([e[2] for e in ev], np.int64),
            "mode": np.array(modes, dtype=object), "armed": np.array(arms, dtype=object),
            "src": np.array(["MODE" if e[3] is not None else "EV" for e in ev], dtype=object),
            "instance": np.zeros(len(ev), np.uint8)}


def _radar(ctx: _Ctx, name: str, parts: list[Part]) -> Part:  # simulation message RADR
    d, c = ctx.base(name, name)
    d["range_m"] = c["Rng"].astype(np.float64)
    d["dcos_u"] = c["U"].astype(np.float64)
    d["dcos_v"] = c["V"].astype(np.float64)
    d["range_rate_mps"] = c["RR"].astype(np.float64)
    d["sensor_id"] = c["I"].astype(np.float64) if "I" in c else np.zeros(len(d["t_ns"]))
    return d


def _fmt_of(ctx: _Ctx, name: str) -> dict[str, str]:
    """Field name -> format character of message ``name``."""
    f = ctx.res.formats[name]
    return dict(zip(f.dtype.names, f.fmt))


def _battery(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """BAT/BAT2 (Copter 3.6+) or CURR/CURR2 (older): ``Volt`` V, ``Curr`` A, ``CurrTot`` mAh.

    Old logs (Copter 3.1) store ``Volt``/``Curr`` as unscaled integers in 1/100 V and 1/100 A
    (``Volt`` 1640 = 16.40 V); ``CurrTot`` is mAh in every version (FMTU ``i`` × 3.6 = A·s)."""
    if name.startswith("CURR") and any(p["src"].startswith("BAT") for p in parts):
        return None  # a log with both: BAT is the battery monitor's own record
    c = ctx.res.tables[name]
    if "Volt" not in c:
        return None
    fmt = _fmt_of(ctx, name)
    d, _ = ctx.base(name, "BAT" if name.startswith("BAT") else "CURR")
    for src_c, dst in (("Volt", "voltage_V"), ("Curr", "current_A")):
        if src_c in c:
            v = c[src_c].astype(np.float64)
            d[dst] = v * 0.01 if fmt[src_c] in "hHiI" else v
    if "CurrTot" in c:
        d["consumed_Ah"] = c["CurrTot"].astype(np.float64) * 1e-3
    if "RemPct" in c:
        d["remaining_frac"] = c["RemPct"].astype(np.float64) * 0.01
    if "Temp" in c:
        d["temp_degC"] = c["Temp"].astype(np.float64)
    return d


def _setpoint_deg(fields: tuple[tuple[str, str], ...], doc: str):
    """A builder of one setpoint message whose ``fields`` (source, column) are in degrees (or
    deg/s) and become radians; a log whose message lacks one of them gives no part."""
    def build(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
        c = ctx.res.tables[name]
        if not all(k in c for k, _ in fields):
            return None
        d, _ = ctx.base(name, name, 0)
        for k, col in fields:
            d[col] = np.deg2rad(c[k].astype(np.float64))
        return d
    build.__doc__ = doc
    return build


_setpoint_att = _setpoint_deg((("DesRoll", "roll_rad"), ("DesPitch", "pitch_rad"), ("DesYaw", "yaw_rad")),
                              "ATT ``DesRoll``/``DesPitch``/``DesYaw`` (deg) -> attitude setpoint (rad).")
_setpoint_rate = _setpoint_deg((("RDes", "p_radps"), ("PDes", "q_radps"), ("YDes", "r_radps")),
                               "RATE ``RDes``/``PDes``/``YDes`` (deg/s) -> body-rate setpoint (rad/s).")


def _setpoint_ntun(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """Copter NTUN ``DVelX``/``DVelY`` (cm/s, north/east; plane NTUN has none) -> velocity
    setpoint (m/s)."""
    c = ctx.res.tables[name]
    if not ("DVelX" in c and "DVelY" in c):
        return None
    d, _ = ctx.base(name, name, 0)
    d["vel_n_mps"] = c["DVelX"].astype(np.float64) * 0.01
    d["vel_e_mps"] = c["DVelY"].astype(np.float64) * 0.01
    return d


def _setpoint_ctun(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """Copter CTUN ``DCRt`` (desired climb rate, integer cm/s, up) -> ``vel_d_mps`` = −DCRt/100
    (plane CTUN has none; a float ``DCRt`` of unknown unit is not mapped)."""
    c = ctx.res.tables[name]
    if "DCRt" not in c or _fmt_of(ctx, name)["DCRt"] not in "hHiI":
        return None
    d, _ = ctx.base(name, name, 0)
    d["vel_d_mps"] = -c["DCRt"].astype(np.float64) * 0.01
    return d


def _setpoint_psc(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """Copter 4.1+ PSCN/PSCE/PSCD ``TVN``/``TVE``/``TVD`` (target velocity, m/s) -> one
    velocity-setpoint axis per message."""
    axis = name[-1].lower()
    c = ctx.res.tables[name]
    key = f"TV{name[-1]}"
    if key not in c:
        return None
    d, _ = ctx.base(name, name, 0)
    d[f"vel_{axis}_mps"] = c[key].astype(np.float64)
    return d


def _messages(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """MSG ``Message`` (DataFlash logs no severity: NaN)."""
    c = ctx.res.tables[name]
    if "Message" not in c:
        return None
    d, _ = ctx.base(name, name, 0)
    d["text"] = np.array([str(m) for m in c["Message"].tolist()], dtype=object)
    return d


def _params(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """PARM ``Name``/``Value``, every record (initial values and changes), at its time."""
    c = ctx.res.tables[name]
    if not ("Name" in c and "Value" in c):
        return None
    d, _ = ctx.base(name, name, 0)
    d["name"] = np.array([str(m) for m in c["Name"].tolist()], dtype=object)
    d["value"] = c["Value"].astype(np.float64)
    return d


def _vibration(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """VIBE ``VibeX/Y/Z`` (m/s², the accelerometer's high-passed RMS) and ``Clip0..2``
    (clipping counts since boot); Copter 4 logs one VIBE per IMU (``IMU`` field, one ``Clip``),
    which goes to ``clip_<IMU>``."""
    c = ctx.res.tables[name]
    if not all(f"Vibe{a}" in c for a in "XYZ"):
        return None
    d, _ = ctx.base(name, name, 0)
    if "IMU" in c:
        d["instance"] = np.asarray(c["IMU"]).astype(np.uint8)
    for a in "XYZ":
        d[f"vibe_{a.lower()}_mps2"] = c[f"Vibe{a}"].astype(np.float64)
    for i in range(3):
        if f"Clip{i}" in c:
            d[f"clip_{i}"] = c[f"Clip{i}"].astype(np.float64)
    if "Clip" in c:
        inst = d["instance"]
        for i in range(3):
            d[f"clip_{i}"] = np.where(inst == i, c["Clip"].astype(np.float64), np.nan)
    return d


#: EKF status message -> core when the message has no ``C`` field (EKF2/early EKF3 log the
#: second core as a separate message type)
_EKF4_CORE = {"XKF4": 0, "XKF9": 1, "NKF4": 0, "NKF9": 1, "EKF4": 0}


def _estimator_status(ctx: _Ctx, name: str, parts: list[Part]) -> Part | None:
    """XKF4/XKF9/NKF4/NKF9/EKF4: innovation test ratios ``SV SP SH SM SVT`` (EKF1: ``SMX SMY
    SMZ``, the largest of the three, as EKF2/3 log it) and the bit fields ``FS`` (fault),
    ``TS`` (timeout), ``SS`` (solution: nav_filter_status), ``GPS`` (failed GPS checks), ``PI``
    (primary core). The ratios are ``100 x value`` in int16 ``c`` fields (decoded as pymavlink
    does, / 100) or, from Copter 4.1, in uint16 ``H`` fields with an FMTU multiplier of 1e-2
    (applied here). ``instance`` = core: ``C``, else the message's own core."""
    c = ctx.res.tables[name]
    if not all(k in c for k in ("SV", "SP", "SH", "SS")):
        return None
    fmt = _fmt_of(ctx, name)
    d, _ = ctx.base(name, name, None if "C" in c else _EKF4_CORE.get(name, 0))

    def ratio(k: str) -> np.ndarray:
        v = c[k].astype(np.float64)
        return v * 0.01 if fmt[k] in "hHiI" else v
    for k, col in (("SV", "vel_test_ratio"), ("SP", "pos_test_ratio"), ("SH", "hgt_test_ratio"),
                   ("SVT", "tas_test_ratio")):
        if k in c:
            d[col] = ratio(k)
    if "SM" in c:
        d["mag_test_ratio"] = ratio("SM")
    elif all(f"SM{a}" in c for a in "XYZ"):
        d["mag_test_ratio"] = np.max([ratio(f"SM{a}") for a in "XYZ"], axis=0)
    for k, col in (("FS", "fault_flags"), ("TS", "timeout_flags"), ("SS", "solution_flags"),
                   ("GPS", "gps_check_flags")):
        if k in c:
            d[col] = np.asarray(c[k]).astype(np.int64)
    if "PI" in c:
        d["primary_core"] = c["PI"].astype(np.float64)
    return d


Builder = Callable[[_Ctx, str, list], "Part | list[Part] | None"]

#: The one mapping table: (stream, message, builder), in stream order and, within a stream, in
#: the order of its parts. ``builder(ctx, message, parts_so_far)`` returns a part, a list of
#: parts or ``None``; it runs only when ``message`` has records (the mode row reads MODE and EV
#: together). A fallback row looks at ``parts_so_far`` (CTUN altitude only without BARO).
STREAM_TABLE: tuple[tuple[str, str | tuple[str, ...], Builder], ...] = (
    ("imu", "IMU", _imu), ("imu", "IMU2", _imu), ("imu", "IMU3", _imu),
    ("gps", "GPS", _gps), ("gps", "GPS2", _gps),
    ("baro", "BARO", _baro), ("baro", "BAR2", _baro), ("baro", "BAR3", _baro), ("baro", "CTUN", _baro_ctun),
    ("mag", "MAG", _mag), ("mag", "MAG2", _mag), ("mag", "MAG3", _mag),
    ("attitude", "ATT", _attitude), ("attitude", "AHR2", _attitude),
    ("local_position", "XKF1", _local_position), ("local_position", "XKF6", _local_position),
    ("local_position", "NKF1", _local_position), ("local_position", "NKF6", _local_position),
    ("local_position", "EKF1", _local_position),
    ("local_position", "NTUN", _local_position_ntun), ("local_position", "POS", _local_position_pos),
    ("rangefinder", "RFND", _rangefinder), ("rangefinder", "CTUN", _rangefinder_ctun),
    ("airspeed", "ARSP", _airspeed), ("airspeed", "ASP2", _airspeed),
    ("control", "RCIN", _control), ("control", "RCI2", _control), ("control", "RCOU", _control),
    ("control", "RCO2", _control), ("control", "RCO3", _control),
    ("mode", ("MODE", "EV"), _mode),
    ("radar", "RADR", _radar),
    ("battery", "BAT", _battery), ("battery", "BAT2", _battery),
    ("battery", "CURR", _battery), ("battery", "CURR2", _battery),
    ("setpoint", "ATT", _setpoint_att), ("setpoint", "RATE", _setpoint_rate),
    ("setpoint", "NTUN", _setpoint_ntun), ("setpoint", "CTUN", _setpoint_ctun),
    ("setpoint", "PSCN", _setpoint_psc), ("setpoint", "PSCE", _setpoint_psc), ("setpoint", "PSCD", _setpoint_psc),
    ("messages", "MSG", _messages),
    ("params", "PARM", _params),
    ("vibration", "VIBE", _vibration),
    *(("estimator_status", m, _estimator_status) for m in ("XKF4", "XKF9", "NKF4", "NKF9", "EKF4")),
)

#: Stream -> message types it is built from (documentation and the "contains" checks).
STREAM_SOURCES: dict[str, tuple[str, ...]] = {}
for _stream, _msg, _ in STREAM_TABLE:
    STREAM_SOURCES.setdefault(_stream, ())
    STREAM_SOURCES[_stream] += tuple(m for m in ((_msg,) if isinstance(_msg, str) else _msg)
                                     if m not in STREAM_SOURCES[_stream])
del _stream, _msg


#: Streams whose records do not define t0 (schema 1.1 and 1.3; t0 stays the first sensor record).
_NOT_T0 = frozenset(schema.STREAMS_1_1) | frozenset(schema.STREAMS_1_3)


def iter_stream_parts(res: DecodeResult, clock: _Clock, t0_us: int,
                      diag: dict) -> Iterator[tuple[str, list[Part] | None]]:
    """Run :data:`STREAM_TABLE` one stream at a time: ``(stream, [part, ...] or None)``.

    A message lacking an expected field costs its own records (counted in
    ``records_dropped['unmapped:<name>']``, with a warning), not its stream or the log.
    Streams come one by one so that a consumer can conform each and drop its parts before the
    next is built (the peak holds one stream's loose columns, not all of them).
    """
    ctx = _Ctx(res, clock, t0_us, diag)
    by_stream: dict[str, list] = {}
    for row in STREAM_TABLE:
        by_stream.setdefault(row[0], []).append(row)
    for stream, table in by_stream.items():
        parts: list[Part] | None = []
        for _, msg, builder in table:
            present = any(_has(res, m) for m in msg) if isinstance(msg, tuple) else _has(res, msg)
            if not present:
                continue
            try:
                # random bytes decode to signalling NaNs, whose float32 -> float64 cast sets the
                # FPU's invalid flag: a RuntimeWarning on the console for a value that is NaN either way
                with np.errstate(invalid="ignore"):
                    got = builder(ctx, msg if isinstance(msg, str) else msg[0], parts)
            except (KeyError, ValueError, TypeError, IndexError) as exc:
                # only this message type is lost: an IMU3 without a field it should have kept
                # IMU and IMU2 out of the imu stream too, and the log still read 'ok'
                name = msg if isinstance(msg, str) else next((m for m in msg if _has(res, m)), msg[0])
                n = int(diag.get("record_counts", {}).get(name, 0))
                diag["records_dropped"][f"unmapped:{name}"] = n
                diag["warnings"].append(f"{stream}: {name} not mapped ({type(exc).__name__}: {exc}); its {n} "
                                        f"record(s) left out" + (", the stream's other messages kept" if parts else ""))
                continue
            for p in (got if isinstance(got, list) else [got]):
                if p is not None and len(p["t_ns"]):
                    parts.append(p)
        out, parts = parts or None, None
        yield stream, out
        del out


def stream_parts(res: DecodeResult, diag: dict | None = None) -> dict[str, list[Part] | None]:
    """The loose stream parts of a decoded log, ``{stream: [part, ...] or None}``, with the
    clock and ``t0`` :func:`to_flightlog` uses (what it conforms; tests compare it with pandas)."""
    diag = diag or schema.new_diagnostics()
    res, clock = _drop_time_outliers(res, diag)
    return dict(iter_stream_parts(res, clock, _first_time_us(res, clock), diag))


def _first_time_us(res: DecodeResult, clock: _Clock) -> int:
    """t0: boot time of the first (in file order) timed record of a canonically mapped type."""
    # the sensor streams only: the 1.1 streams (PARM, MSG, CURR, ...) do not move t0
    mapped = {n for stream, names in STREAM_SOURCES.items() if stream not in _NOT_T0 for n in names}
    best = None
    for names in (mapped, set(res.formats)):
        for name in names:
            if name not in res.tables:
                continue
            t = clock.own_time_us(name)
            if t is None or not len(t):
                continue
            off = int(res.offsets[name][0])
            if best is None or off < best[0]:
                best = (off, int(t[0]))
        if best is not None:
            return best[1]
    return 0


def _utc(res: DecodeResult, clock: _Clock, t0_us: int) -> tuple[int | None, dict | None]:
    """UTC (ns) of t_ns = 0 from the first GPS record with a week number."""
    g = res.tables.get("GPS")
    if g is None:
        return None, None
    if "GWk" in g and "GMS" in g and "TimeUS" in g:
        wk, tow, boot = g["GWk"], g["GMS"], g["TimeUS"].astype(np.int64)
    elif "Week" in g and "TimeMS" in g and "T" in g:
        wk, tow, boot = g["Week"], g["TimeMS"], g["T"].astype(np.int64) * 1000
    else:
        return None, None
    ok = np.flatnonzero((wk > 0) & (g["Status"] >= 3)) if "Status" in g else np.flatnonzero(wk > 0)
    if not len(ok):
        return None, None
    k = int(ok[0])
    utc_ns, leap = gps_to_utc_ns(int(wk[k]), int(tow[k]))
    t0_utc = utc_ns - (int(boot[k]) - t0_us) * 1000
    return t0_utc, {"gps_week": int(wk[k]), "gps_tow_ms": int(tow[k]), "boot_us": int(boot[k]),
                    "leap_seconds": leap}


def _origin(res: DecodeResult) -> dict | None:
    """NED origin: ORGN (EKF origin, type 0 first), else the first 3D GPS fix, else POS."""
    o = res.tables.get("ORGN")
    if o is not None and len(o.get("Lat", [])):
        typ = o.get("Type", np.zeros(len(o["Lat"])))
        k = np.flatnonzero(typ == 0)
        k = int(k[0]) if len(k) else 0
        return {"lat_deg": float(o["Lat"][k]), "lon_deg": float(o["Lng"][k]),
                "alt_wgs84_m": None, "alt_msl_m": float(o["Alt"][k]), "source": "ORGN"}
    g = res.tables.get("GPS")
    if g is not None and len(g.get("Lat", [])):
        good = np.flatnonzero((g["Status"] >= 3) & (g["Lat"] != 0)) if "Status" in g else np.arange(len(g["Lat"]))
        if len(good):
            k = int(good[0])
            return {"lat_deg": float(g["Lat"][k]), "lon_deg": float(g["Lng"][k]),
                    "alt_wgs84_m": None, "alt_msl_m": float(g["Alt"][k]), "source": "GPS"}
    p = res.tables.get("POS")
    if p is not None and len(p.get("Lat", [])):
        good = np.flatnonzero(p["Lat"] != 0)
        if len(good):
            k = int(good[0])
            return {"lat_deg": float(p["Lat"][k]), "lon_deg": float(p["Lng"][k]),
                    "alt_wgs84_m": None, "alt_msl_m": float(p["Alt"][k]), "source": "POS"}
    return None


def to_flightlog(res: DecodeResult) -> FlightLog:
    """Map decoded DataFlash tables to a canonical :class:`FlightLog` (see module docstring)."""
    diag = schema.new_diagnostics()
    diag["bytes_skipped"] = int(res.diagnostics["bytes_skipped"])
    diag["records_dropped"] = dict(res.diagnostics["records_dropped"])
    diag["record_counts"] = dict(res.diagnostics["record_counts"])
    diag["warnings"] = list(res.diagnostics["warnings"])
    res, clock = _drop_time_outliers(res, diag)  # before t0: a corrupt first stamp would shift every t_ns
    t0_us = _first_time_us(res, clock)

    params: dict[str, float] = {}
    parm = res.tables.get("PARM")
    if parm is not None and "Name" in parm:
        for k, v in zip(parm["Name"].tolist(), parm["Value"].tolist()):
            params[k] = float(v)
    msg = res.tables.get("MSG")
    if msg is not None and "Message" in msg:
        t = _rows(clock, "MSG", t0_us)["t_ns"]
        diag["messages"] = [{"t_ns": int(a), "text": str(b)} for a, b in
                            zip(t[:1000].tolist(), msg["Message"][:1000].tolist())]
    # meta is built before the streams (which are conformed one by one as they are built), but
    # its warnings follow the streams' ones, as they always have
    late: list[str] = []
    try:
        t0_utc, gps_fix = _utc(res, clock, t0_us)
    except (KeyError, ValueError, OverflowError) as exc:
        t0_utc, gps_fix = None, None
        late.append(f"UTC not derived from GPS ({type(exc).__name__}: {exc})")
    try:
        origin = _origin(res)
    except (KeyError, ValueError) as exc:
        origin = None
        late.append(f"NED origin not derived ({type(exc).__name__}: {exc})")
    meta = schema.new_meta(
        source_format=SOURCE_FORMAT,
        reader=READER_NAME,
        reader_version=READER_VERSION,
        t0_boot_ns=t0_us * 1000,
        t0_utc_ns=t0_utc,
        utc_source="gps" if t0_utc is not None else "none",
        leap_seconds=gps_fix.pop("leap_seconds") if gps_fix else None,
        ned_origin=origin,
        params=params,
        diagnostics=diag,
    )
    if gps_fix:
        meta["utc_gps_fix"] = gps_fix
    meta["dataflash"] = {"old_format": not any(f.time_field == "TimeUS" for f in res.formats.values()),
                         "has_fmtu": "FMTU" in res.tables}
    if any(k in params for k in ("RADR_SN", "RADR_SE", "RADR_SD", "RADR_TAU")):
        meta["radar"] = {"site_ned_m": [params.get("RADR_SN", 0.0), params.get("RADR_SE", 0.0),
                                        params.get("RADR_SD", 0.0)],
                         "tau_rd_s": params.get("RADR_TAU", 0.0)}
    log = FlightLog.from_streams(meta, iter_stream_parts(res, clock, t0_us, diag))
    log.meta["diagnostics"]["warnings"].extend(late)
    if "local_position_from" in diag:  # set while the streams were built (from_streams copied diag)
        log.meta["diagnostics"]["local_position_from"] = diag["local_position_from"]
    return log
