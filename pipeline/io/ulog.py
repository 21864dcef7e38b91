"""PX4 ULog reader (through pyulog): ``*.ulg`` -> canonical :class:`~pipeline.io.base.FlightLog`.

pyulog parses the file (:class:`pyulog.ULog`); this module only selects topics, converts units
and frames, and keeps the books (diagnostics). Topic -> stream map:

=========================================  =================  ===================================
ULog topic                                 stream             conversion
=========================================  =================  ===================================
``sensor_combined`` (or ``vehicle_imu``)   ``imu``            gyro rad/s, accel m/s^2 (FRD, as
                                                              logged); ``vehicle_imu``:
                                                              ``delta_angle/delta_angle_dt``,
                                                              ``delta_velocity/delta_velocity_dt``
``vehicle_gps_position`` (or              ``gps``            lat/lon: float deg, or int 1e-7 deg
``sensor_gps``)                                               (older logs); alt: float m or int mm
``vehicle_magnetometer`` (or              ``mag``            Gauss x 1e-4 -> T
``sensor_mag``)
``vehicle_air_data`` (or ``sensor_baro``)  ``baro``           Pa (``baro_pressure_pa``; mbar x 100
                                                              for ``*_mbar`` fields);
                                                              ``alt_rel_m`` = ``baro_alt_meter``,
                                                              the ISA altitude (1013.25 hPa datum)
``vehicle_attitude``                       ``attitude``       ``q`` is FRD->NED, scalar first: as is
``vehicle_local_position``                 ``local_position`` ``x,y,z,vx,vy,vz`` NED; ``ref_lat``,
                                                              ``ref_lon``, ``ref_alt`` (AMSL) ->
                                                              ``meta['ned_origin']``; the sum of
                                                              ``xy/z/vxy/vz_reset_counter`` ->
                                                              ``reset_count``
``distance_sensor``                        ``rangefinder``    m; ``valid`` = within
                                                              [min_distance, max_distance] and
                                                              ``signal_quality != 0``
``airspeed`` / ``differential_pressure``   ``airspeed``       indicated airspeed m/s, degC / Pa
``input_rc``                               ``control``        ``values[i]`` -> ``rc_{i+1}_us``
                                                              (channels >= ``channel_count`` NaN)
``actuator_outputs``                       ``control``        ``output[i]`` -> ``servo_{i+1}_us``
                                                              (>= ``noutputs`` NaN), raw as logged
``vehicle_status``                         ``mode``           ``nav_state`` name, ``armed`` =
                                                              ``arming_state == 2``; rows on change
``battery_status``                         ``battery``        V, A, mAh -> Ah, remaining 0..1, degC
``vehicle_attitude_setpoint``              ``setpoint``       ``roll/pitch/yaw_body`` rad, else
                                                              ``q_d`` -> ZYX Euler
``vehicle_rates_setpoint``                 ``setpoint``       ``roll pitch yaw`` rad/s -> p q r
``vehicle_local_position_setpoint`` (or    ``setpoint``       ``vx vy vz`` / ``velocity[i]`` NED
``trajectory_setpoint``)
``vehicle_imu_status`` (or                 ``vibration``      accel/gyro vibration metrics,
``estimator_status`` ``vibe[2]/vibe[1]``)                     ``accel_clipping[i]`` -> ``clip_i``
logged messages (``L``, tagged ``C``)      ``messages``       ``text``, ``severity`` = syslog level
initial + changed parameters               ``params``         initial at ``t_ns = 0``, changes at
                                                              their time
(GPS topic ``hdop``/``vdop``)              ``gps``            dilutions as logged
``estimator_status``                       ``estimator_status`` ``solution_status_flags``,
                                                              ``filter_fault_flags``,
                                                              ``innovation_check_flags``,
                                                              ``gps_check_fail_flags``,
                                                              ``timeout_flags``,
                                                              ``control_mode_flags`` as logged;
                                                              ``*_test_ratio``; instance = EKF
                                                              instance (multi_id)
=========================================  =================  ===================================

``estimator_status_flags`` (PX4 1.12+, one boolean per bit, published on change) mostly repeats
``estimator_status``'s bits; where ``estimator_status`` has no ``innovation_check_flags`` (PX4
1.14+) its ``reject_*`` booleans become ``estimator_status`` rows (``src``
``estimator_status_flags``) whose ``innovation_fail_flags`` bit ``k`` is the ``k``-th
``reject_*`` field. The topic also tells which layout the log's bit fields use,
recorded in ``meta['estimator_status']['layout']`` (:mod:`pipeline.io.estimator_bits`): a log
whose ``fs_*`` fields include ``fs_bad_vel_n``, or without the topic, has the legacy 0-17
``filter_fault_flags``; otherwise the current one (bit 9 unused, 10 ``bad_acc_vertical``). Its
``reject_*`` field names, in order, name the bits of ``innovation_check_flags``
(``meta['estimator_status']['innovation_fail_flags']``).

Time. ``t_boot_ns = timestamp * 1000`` (``timestamp``: µs since boot, the publication time of
every uORB message) and ``t_ns = t_boot_ns - t0_boot_ns`` with ``t0_boot_ns`` the ULog header
timestamp (logger start). Topics published once before the logger started (a stale sample is
written at subscription) keep their true stamp and so get ``t_ns < 0``; their number is in
``meta['diagnostics']['warnings']``. ``t0_utc_ns`` comes from the GPS topic's ``time_utc_usec``:

.. math:: t_{0,\\mathrm{UTC}} = \\operatorname{median}_k\\,[u_k - (b_k + r_k)] + t_{0,\\mathrm{boot}}

with ``u`` = ``time_utc_usec``, ``b`` = ``timestamp``, ``r`` = ``timestamp_time_relative``
(samples with ``u > 0`` and a fix), ``utc_source = "gps"``.

Multi-instance topics (pyulog ``multi_id``) become the ``instance`` column; ``src`` is the topic
name. ``actuator_outputs`` are written raw: PWM µs for PWM output groups, but UAVCAN/DShot groups
log ESC command units (e.g. 0..8191); groups whose values exceed 2500 are named in a warning.
Logged text messages (``L`` and tagged ``C``) go to ``diagnostics['messages']``
(``{t_ns, level, text}``), dropouts to ``diagnostics['dropouts']`` (``count``, ``total_ms``) and
make the log ``partial``; a file cut mid-message is counted in ``bytes_skipped``.

Damage. pyulog steps over damage by the sizes it reads there, out of step with the messages,
and may end its data loop at it without a word (``motor_failure.ulg`` with 4 kB flipped
mid-file lost its second half: 53 % of the rows, the sensors ending at 24.0 s of 44.0 s, under
"count unknown"). So the messages are walked once more checking each one's form
(:class:`_Chain`): damaged spans are located (from the message before the first malformed one
up to where a chain of well-formed messages starts again), cut out, and the rest parsed again,
so the data after the damage is kept and none of the bytes read out of step becomes samples.
Each span is counted (``records_dropped['corrupt']``, its bytes in ``bytes_skipped``) with a
warning naming its byte offsets and the log times on both sides; DATA messages whose
subscription was lost to the damage are counted in ``records_dropped['no_subscription']``,
messages of a type ULog does not define in ``records_dropped['unknown_type']``, a last message
cut by the end of the file in ``records_dropped['truncated']``. A message whose header survived
but whose payload was hit cannot be told from a good one (ULog has no checksums).

Config (``ingest: ulog:``): ``imu``, ``gps``, ``mag``, ``baro``: ``auto`` (the first listed topic
present, default) or a topic name / list of topic names to take; ``rangefinder_valid_m: [lo, hi]``
narrows ``valid`` to a trusted window inside the sensor's declared range (``motor_failure.ulg``
declares 0.05-25 m, all 361 samples inside; 98 fall in 0.17-6 m).
"""

from __future__ import annotations

import contextlib
import functools
import io
import mmap
import re
import struct
from pathlib import Path

import numpy as np
from .lazy import pandas as pd  # imported on first use (see lazy.py)

from . import schema
from .base import FlightLog, IngestError, LogReader, Progress
from .registry import register
from .stage import one_line

MAGIC = b"ULog\x01\x12\x35"

#: PX4 ``vehicle_status.nav_state`` names (msg/VehicleStatus.msg; 6-9, 11 and 16 were renamed
#: or freed across releases, so their older meaning is given too).
NAV_STATES = {
    0: "MANUAL", 1: "ALTCTL", 2: "POSCTL", 3: "AUTO_MISSION", 4: "AUTO_LOITER", 5: "AUTO_RTL",
    6: "POSITION_SLOW/AUTO_RCRECOVER", 7: "AUTO_RTGS", 8: "AUTO_LANDENGFAIL",
    9: "AUTO_LANDGPSFAIL", 10: "ACRO", 11: "UNUSED", 12: "DESCEND", 13: "TERMINATION",
    14: "OFFBOARD", 15: "STAB", 16: "RATTITUDE", 17: "AUTO_TAKEOFF", 18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET", 20: "AUTO_PRECLAND", 21: "ORBIT", 22: "AUTO_VTOL_TAKEOFF",
    **{23 + i: f"EXTERNAL{i + 1}" for i in range(8)},
}
#: ``arming_state`` value meaning armed, in old (INIT/STANDBY/ARMED...) and new
#: (DISARMED=1/ARMED=2) enumerations alike.
ARMING_STATE_ARMED = 2

#: candidate topics per stream in preference order ("auto" takes the first one present)
DEFAULT_TOPICS = {
    "imu": ("sensor_combined", "vehicle_imu"),
    "gps": ("vehicle_gps_position", "sensor_gps"),
    "mag": ("vehicle_magnetometer", "sensor_mag"),
    "baro": ("vehicle_air_data", "sensor_baro"),
}

#: ``accelerometer_timestamp_relative`` value meaning "no accelerometer sample in this message"
RELATIVE_TIMESTAMP_INVALID = 0x7FFFFFFF
_VALID_MSG_TYPES = frozenset(b"BFIMPQARDLCSO")
_GAUSS_TO_T = 1e-4


@register
class ULogReader(LogReader):
    """PX4 ULog through pyulog (see the module docstring for the topic map)."""

    name = "ulog"
    source_format = "px4_ulog"
    version = "3"  # 2: the schema 1.1 streams; 3: estimator_status (schema 1.3)
    priority = 10
    magic = MAGIC

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if head[:7] == MAGIC:
            ver = head[7] if len(head) > 7 else -1
            return f"ULog magic 'ULog\\x01\\x12\\x35' (file version {ver})"
        return None

    def read(self, path: Path, *, config: dict | None = None,
             progress: Progress | None = None) -> FlightLog:
        cfg = dict((config or {}).get("ulog") or {})
        ulog, pyulog_out = _parse(path)
        chain = _check_chain(path, ulog)
        if chain.repaired is not None:
            # pyulog read on out of step after the damage (or stopped there): parse the file
            # again without the damaged spans, so the messages after them decode and no garbage does
            ulog, pyulog_out = _parse(path, chain.repaired)
        if progress:
            progress(1, 2)
        diag = schema.new_diagnostics()
        if pyulog_out.strip():
            diag["warnings"].append(f"pyulog: {one_line(pyulog_out)[:500]}")
        topics: dict[str, list] = {}
        for d in ulog.data_list:
            topics.setdefault(d.name, []).append(d)
            diag["record_counts"][f"{d.name}[{d.multi_id}]"] = int(len(d.data["timestamp"]))
        if not topics:
            if chain.spans:
                sp = chain.spans[0]
                raise IngestError(path, f"corrupt ULog: no data messages decoded (damaged from byte "
                                        f"{sp.start}; {sum(x.end - x.start for x in chain.spans)} of "
                                        f"{chain.size} bytes not decodable)")
            if ulog.file_corruption:
                raise IngestError(path, "corrupt ULog: no data messages decoded (pyulog met bytes it could "
                                        "not read: damaged, or cut before the data section)")
            raise IngestError(path, "ULog has no data messages (empty or cut before the data section)")

        t0_us = int(ulog.start_timestamp)
        conv = _Conv(t0_us)
        streams: dict[str, list[pd.DataFrame]] = {}

        def add(stream: str, df: pd.DataFrame | None) -> None:
            if df is not None and len(df):
                streams.setdefault(stream, []).append(df)

        for stream, builder in (("imu", _imu), ("gps", _gps), ("mag", _mag), ("baro", _baro)):
            choice = cfg.get(stream, "auto")
            missing = configured_topics_absent(topics, choice)
            if missing:
                # a misspelt topic would otherwise leave the stream silently empty
                diag["warnings"].append(
                    f"ingest.ulog.{stream}: topic(s) {', '.join(missing)} not in the log; logged "
                    f"candidates: {', '.join(n for n in DEFAULT_TOPICS[stream] if n in topics) or 'none'}")
            for d in _select(topics, stream, choice, path):
                add(stream, builder(d, conv))
        for d in topics.get("vehicle_attitude", []):
            add("attitude", _attitude(d, conv))
        for d in topics.get("vehicle_local_position", []):
            add("local_position", _local_position(d, conv))
        for d in topics.get("distance_sensor", []):
            add("rangefinder", _rangefinder(d, conv, cfg.get("rangefinder_valid_m")))
        for d in topics.get("airspeed", []):
            add("airspeed", _airspeed(d, conv))
        for d in topics.get("differential_pressure", []):
            add("airspeed", _diff_press(d, conv))
        for d in topics.get("input_rc", []):
            add("control", _input_rc(d, conv))
        non_pwm = []
        for d in topics.get("actuator_outputs", []):
            df = _actuator_outputs(d, conv)
            add("control", df)
            vals = df.filter(like="servo_").to_numpy()
            if np.isfinite(vals).any() and np.nanmax(vals) > 2500:
                non_pwm.append(d.multi_id)
        if non_pwm:
            diag["warnings"].append(
                f"actuator_outputs instance(s) {non_pwm} exceed 2500: not PWM µs (ESC/UAVCAN "
                "command units), written raw into servo_*_us")
        for d in topics.get("vehicle_status", []):
            add("mode", _mode(d, conv))
        # schema 1.1 streams
        for d in topics.get("battery_status", []):
            add("battery", _battery(d, conv))
        for d in topics.get("vehicle_attitude_setpoint", []):
            add("setpoint", _attitude_setpoint(d, conv))
        for d in topics.get("vehicle_rates_setpoint", []):
            add("setpoint", _rates_setpoint(d, conv))
        vel_topic = next((n for n in ("vehicle_local_position_setpoint", "trajectory_setpoint") if n in topics), None)
        for d in topics.get(vel_topic, []):
            add("setpoint", _velocity_setpoint(d, conv))
        vib_topic = next((n for n in ("vehicle_imu_status", "estimator_status") if n in topics), None)
        for d in topics.get(vib_topic, []):
            add("vibration", _vibration(d, conv))
        for d in topics.get("estimator_status", []):
            add("estimator_status", _estimator_status(d, conv))
        if not any("innovation_check_flags" in d.data for d in topics.get("estimator_status", [])):
            for d in topics.get("estimator_status_flags", []):  # PX4 1.14+: rejections only here
                add("estimator_status", _estimator_rejections(d, conv))

        out = {k: pd.concat(v, ignore_index=True) if len(v) > 1 else v[0] for k, v in streams.items()}
        if conv.n_before_start:
            diag["warnings"].append(
                f"{conv.n_before_start} sample(s) stamped before the logger start (stale topics "
                "written at subscription) have t_ns < 0")
        meta = schema.new_meta(t0_boot_ns=t0_us * 1000)
        meta["ned_origin"] = _ned_origin(topics, out.get("gps"), diag)
        if "estimator_status" in out:
            meta["estimator_status"] = _estimator_layout(topics)
        _utc(meta, topics, out, cfg, t0_us)
        streams_ev = _messages(ulog, diag, t0_us)
        if streams_ev is not None:
            out["messages"] = streams_ev
        out["params"] = _params(ulog, t0_us)
        if ulog.dropouts:
            total = int(sum(int(o.duration) for o in ulog.dropouts))
            diag["dropouts"] = {"count": len(ulog.dropouts), "total_ms": total}
            diag["warnings"].append(f"{len(ulog.dropouts)} logger dropout(s), {total} ms in total")
            meta["status"] = "partial"
        else:
            diag["dropouts"] = {"count": 0, "total_ms": 0}
        tail = chain.tail
        _report_damage(chain, t0_us, diag)
        if tail:
            diag["bytes_skipped"] += tail
            diag["records_dropped"]["truncated"] = diag["records_dropped"].get("truncated", 0) + 1
            diag["warnings"].append(f"file cut mid-message: last {tail} byte(s) not decoded")
        if ulog.file_corruption and not (chain.spans or chain.unsubscribed or chain.unknown_type):
            # damage pyulog met but the message walk did not place (it is counted above if it did)
            diag["records_dropped"]["corrupt"] = diag["records_dropped"].get("corrupt", 0) + 1
            diag["warnings"].append("pyulog detected corrupt data and resynchronised; "
                                    "some records were skipped (count unknown)")
        meta["diagnostics"] = diag
        meta["params"] = {str(k): _py(v) for k, v in ulog.initial_parameters.items()}
        meta["params_changed"] = [[int(t) * 1000 - t0_us * 1000, str(k), _py(v)]
                                  for t, k, v in ulog.changed_parameters]
        meta["source_info"] = {str(k): _py(v) for k, v in ulog.msg_info_dict.items()
                               if isinstance(v, (str, int, float, np.integer, np.floating))}
        meta["frames"] = {"world": "NED", "body": "FRD",
                          "baro_alt_rel_m": "ISA pressure altitude (1013.25 hPa datum)",
                          "control_servo": "actuator_outputs raw (PWM us for PWM groups)"}
        if progress:
            progress(2, 2)
        return FlightLog.from_streams(meta, out)


# --- parsing and bookkeeping ------------------------------------------------------------------

class _FullReadSeeks:
    """The file handle pyulog's definitions loop reads through: a relative seek right after a
    short read counts from where the read would have ended had it returned every byte asked for.

    Why: pyulog's ``_read_file_definitions`` (1.3.0) steps over a corrupt message header (type 0,
    size 0 or size > 10000) with ``read(size)`` and then ``seek(-2 - size, 1)``, meaning "one byte
    past the header". Within ``size`` bytes of the end of the file the read returns fewer bytes,
    so the seek lands up to 64 KiB *before* the header; the byte-wise rescan from there walks
    onto the same header again and the loop never ends (a ULog whose ``ADD_LOGGED`` message was
    hit, so that the definitions scan runs on into the data, hangs for good). Counting the seek
    from the full read's end restores what pyulog means (one byte on; the end-of-section seek
    back onto the header start), so every step moves forward and the scan ends at the end of
    the file. The data loop needs no help: it stops at a short read before any seek.
    """

    __slots__ = ("_fh", "_full_end")

    def __init__(self, fh):
        self._fh = fh
        self._full_end: int | None = None  # where the last read would have ended, if it was short

    def read(self, n: int = -1) -> bytes:
        start = self._fh.tell()
        data = self._fh.read(n)
        self._full_end = start + n if n is not None and len(data) < n else None
        return data

    def seek(self, offset: int, whence: int = 0) -> int:
        if whence == 1 and self._full_end is not None:
            offset, whence = self._full_end + offset, 0
        self._full_end = None
        return self._fh.seek(offset, whence)

    def tell(self) -> int:
        return self._fh.tell()

    def close(self) -> None:
        self._fh.close()


@functools.lru_cache(maxsize=1)
def _ulog_class():
    """pyulog's ``ULog`` whose definitions section is read through :class:`_FullReadSeeks`
    (the data section keeps the plain file handle: no per-read cost on the bulk of the file)."""
    from pyulog import ULog

    class _GuardedULog(ULog):
        def _read_file_definitions(self):
            raw = getattr(self, "_file_handle", None)
            if raw is None:  # a pyulog that keeps its handle elsewhere: run it unguarded
                return super()._read_file_definitions()
            self._file_handle = _FullReadSeeks(raw)
            try:
                return super()._read_file_definitions()
            finally:
                self._file_handle = raw

    return _GuardedULog


def _parse(path: Path, data: bytes | None = None):
    """Run pyulog (guarded against its end-of-file rescan loop, :class:`_FullReadSeeks`) on
    ``path``, or on ``data`` (the repaired bytes of ``path``) when given, wrapping its
    exceptions and capturing what it prints."""
    from pyulog.exceptions import ULogException

    buf = io.StringIO()
    try:
        # our own handle: pyulog leaves its file open when it raises
        with (open(path, "rb") if data is None else io.BytesIO(data)) as fh, contextlib.redirect_stdout(buf):
            ulog = _ulog_class()(fh)
    except ULogException as exc:
        raise IngestError(path, f"not a readable ULog: {exc}") from None
    except (struct.error, ValueError, IndexError, KeyError, OverflowError, UnicodeDecodeError,
            TypeError) as exc:
        raise IngestError(path, f"corrupt ULog definitions section: {type(exc).__name__}: {exc}") from None
    except OSError as exc:
        raise IngestError(path, f"cannot read: {exc.strerror or exc}") from None
    return ulog, buf.getvalue()


class _ChainCheck:
    """What :func:`_check_chain` found: ``spans`` (:class:`_Damage`), ``tail`` (bytes of a
    last message cut by the end of the file), ``unsubscribed`` (DATA messages of ids no
    ADD_LOGGED subscribed), ``unknown_type`` (messages of a type ULog does not define),
    ``size`` (file bytes) and ``repaired`` (the file without the
    damaged spans, to parse again; None when there is nothing to repair)."""

    __slots__ = ("spans", "tail", "unsubscribed", "unknown_type", "size", "repaired")

    def __init__(self, spans, tail, unsubscribed, unknown_type, size, repaired):
        self.spans, self.tail, self.unsubscribed, self.unknown_type = spans, tail, unsubscribed, unknown_type
        self.size, self.repaired = size, repaired


def _check_chain(path: Path, ulog) -> _ChainCheck:
    """Walk the messages of the file pyulog parsed (:class:`_Chain`): where their chain breaks,
    and the file without the damaged spans to parse again.

    The walk runs on every file, not only those pyulog calls corrupt: a damaged header of a
    variable-size type (LOGGING, PARAMETER) swallows the messages behind it without pyulog
    noticing, and a DATA message too short for its id ends pyulog's data loop without a word.
    It costs about half of pyulog's own parse.
    """
    size = path.stat().st_size
    if size <= 16:
        return _ChainCheck([], 0, 0, 0, size, None)
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data:
        walker = _Chain(data, ulog)
        spans, tail = walker.walk(16)
        repaired = None
        # appended data sits at absolute offsets that cutting bytes out would move
        if spans and not (ulog.has_data_appended and ulog._appended_offsets):
            keep, at = [], 0
            for sp in spans:
                keep.append(data[at:sp.start])
                at = sp.end
            keep.append(data[at:])
            repaired = b"".join(keep)
        counts = walker.unsubscribed, walker.unknown_type
        del walker  # the mapping closes only when no view of it is left
    return _ChainCheck(spans, tail, *counts, size, repaired)


def _report_damage(chain: _ChainCheck, t0_us: int, diag: dict) -> None:
    """Count the damaged spans (``bytes_skipped``, ``records_dropped['corrupt']``) and the
    DATA messages left without a subscription; one warning each, naming the byte offsets and
    the log times on both sides of the damage."""
    def at(t_us: int | None) -> str:
        return "?" if t_us is None else f"{(t_us - t0_us) * 1e-6:.3f} s"

    for sp in chain.spans:
        n = sp.end - sp.start
        diag["bytes_skipped"] += n
        diag["records_dropped"]["corrupt"] = diag["records_dropped"].get("corrupt", 0) + 1
        if sp.end < chain.size:
            diag["warnings"].append(
                f"ULog damaged from byte {sp.start} (after the record at t = {at(sp.t_before_us)}): "
                f"{n} byte(s) up to byte {sp.end} not decoded; decoding resumed there "
                f"(t = {at(sp.t_after_us)})")
        else:
            diag["warnings"].append(
                f"ULog undecodable from byte {sp.start} of {chain.size} (after the record at "
                f"t = {at(sp.t_before_us)}): the last {n} byte(s) not decoded")
    if chain.unsubscribed:
        diag["records_dropped"]["no_subscription"] = chain.unsubscribed
        diag["warnings"].append(f"{chain.unsubscribed} DATA message(s) of an id that no ADD_LOGGED "
                                "message subscribed (lost to the damage) not decoded")
    if chain.unknown_type:
        diag["records_dropped"]["unknown_type"] = chain.unknown_type
        diag["warnings"].append(f"{chain.unknown_type} message(s) of a type ULog does not define (a "
                                "later ULog version's, or a damaged type byte) skipped")


#: consecutive well-formed messages that mark an offset as a message boundary again after
#: damage (a random offset passes one header check with p < 0.05: 13 of 256 type bytes, and
#: a size that must chain on to the next header)
_RESYNC_CHAIN = 8
_SYNC_BYTES = b"\x2f\x73\x13\x20\x25\x0c\xbb\x12"
_VALID_MSG_TYPES_ORDERED = bytes(sorted(_VALID_MSG_TYPES))
_KEY = re.compile(rb"[a-z0-9_]+(\[[0-9]+\])? [A-Za-z0-9_./\[\]-]+")  # "type name" of I/P/Q/M
_FORMAT = re.compile(rb"[A-Za-z0-9_]+:")  # FORMAT: "name:type field;..."
_MAX_UNKNOWN = 10000  # pyulog skips a message of a type it does not know up to this size


class _Damage:
    """Where a ULog's message chain breaks: bytes ``[start, end)`` are not decodable (``end`` is
    the file size when no message boundary follows); ``t_before_us``/``t_after_us`` are the
    last DATA timestamp before and the first after (None when there is none)."""

    __slots__ = ("start", "end", "t_before_us", "t_after_us")

    def __init__(self, start: int, end: int, t_before_us: int | None, t_after_us: int | None):
        self.start, self.end = start, end
        self.t_before_us, self.t_after_us = t_before_us, t_after_us


class _Chain:
    """Walk a ULog's messages checking each one's form, as pyulog does not.

    pyulog (1.3) steps over a damaged header by its declared size, so after damage it reads on
    out of step with the messages (feeding garbage into topics whose id happens to match) until
    a ``struct.error`` ends its data loop without a word (``motor_failure.ulg`` with 4 kB
    flipped mid-file: 47 % of the file never decoded) or the end of the file; a damaged
    LOGGING or PARAMETER header swallows up to 64 kB behind it unnoticed. Here a message is
    well-formed when its type is a ULog type, its size fits the file, and, for the types with
    a layout, its size matches it: a DATA message of a subscribed id has the size of its
    format (pyulog's own bounds), DROPOUT 2 bytes, SYNC its magic, a key/value message a
    ``"type name"`` key inside it, and so on. Where a message is not, the damage began at the
    message before it (its declared size led here; its payload is suspect too), and decoding
    resumes at the first offset after that message's start from which :data:`_RESYNC_CHAIN`
    well-formed messages follow each other (or reach the end of the file).

    In the walk itself (``commit``) two kinds pass that a resync chain does not, both counted
    (pyulog decodes neither): a DATA message of an id no ``ADD_LOGGED`` subscribed (its
    subscription lost to the damage; :attr:`unsubscribed`) and a message of a type ULog does
    not define that a chain follows (a later ULog version's, or a damaged type byte;
    :attr:`unknown_type`).
    """

    def __init__(self, data, ulog):
        from pyulog import ULog

        self.data = data
        self.n = len(data)
        self.formats = ulog._message_formats  # pyulog's parsed FORMAT definitions
        self._add_logged = ULog._MessageAddLogged
        #: msg_id -> (min payload, max payload, timestamp offset), from the ADD_LOGGED messages
        self.subs: dict[int, tuple[int, int, int]] = {}
        self.unsubscribed = 0
        self.unknown_type = 0
        self.in_data = False  # an ADD_LOGGED or DATA message was seen: FORMAT no longer stands

    def _subscription(self, payload: bytes) -> tuple[int, tuple[int, int, int]] | None:
        try:
            a = self._add_logged(payload, None, self.formats)
        except Exception:  # noqa: BLE001 - unknown format name, garbage: not an ADD_LOGGED
            return None
        return a.msg_id, (a.dtype.itemsize, a.max_data_size, a.timestamp_offset)

    def size_ok(self, pos: int, commit: bool = False, chain_subs: dict | None = None) -> int | None:
        """End offset of the message at ``pos`` when it is well-formed, else None; with
        ``commit`` (the walk itself, see the class docstring) its subscription is recorded,
        else in ``chain_subs`` (given by :meth:`chained`: the ADD_LOGGED messages of the chain
        being checked, for the DATA messages after them)."""
        d, n = self.data, self.n
        if pos + 3 > n:
            return None
        size = d[pos] | (d[pos + 1] << 8)
        typ = d[pos + 2]
        end = pos + 3 + size
        if size == 0 or end > n:
            return None
        if typ == 0x44:  # 'D'
            sub = None
            if size >= 2:
                msg_id = d[pos + 3] | (d[pos + 4] << 8)
                sub = self.subs.get(msg_id) or (chain_subs.get(msg_id) if chain_subs else None)
            if sub is not None:
                ok = sub[0] <= size - 2 <= sub[1]
            else:
                ok = commit and size >= 10
                if ok:
                    self.unsubscribed += 1
            if ok and commit:
                self.in_data = True
            return end if ok else None
        if typ == 0x41:  # 'A'
            got = self._subscription(bytes(d[pos + 3:end])) if size > 3 else None
            if got is None:
                return None
            if commit:
                self.subs[got[0]] = got[1]
                self.in_data = True
            elif chain_subs is not None:
                chain_subs[got[0]] = got[1]
            return end
        if typ in (0x4F, 0x52):  # 'O' dropout, 'R' remove logged
            return end if size == 2 else None
        if typ == 0x53:  # 'S'
            return end if bytes(d[pos + 3:end]) == _SYNC_BYTES else None
        if typ in (0x4C, 0x43):  # 'L', 'C': log level (0-7, or the ASCII digit), [tag], time, text
            return end if size >= (9 if typ == 0x4C else 11) and (d[pos + 3] & ~0x30) <= 7 else None
        if typ in (0x49, 0x50, 0x51, 0x4D):  # 'I', 'P', 'Q', 'M': [flag,] key length, "type name", value
            off = 2 if typ in (0x51, 0x4D) else 1
            if size <= off:
                return None
            klen = d[pos + 2 + off]
            return end if off + klen <= size and _KEY.fullmatch(bytes(d[pos + 3 + off:pos + 3 + off + klen])) \
                else None
        if typ == 0x46:  # 'F' stands in the definitions section only
            return end if not self.in_data and _FORMAT.match(bytes(d[pos + 3:end])) else None
        if typ == 0x42 or typ in _VALID_MSG_TYPES:  # 'B' stands first and only once
            return None
        # a type of a later ULog version (or a damaged type byte): pyulog skips it without a
        # word; here it passes where a chain follows, counted
        if commit and size <= _MAX_UNKNOWN and self.chained(end):
            self.unknown_type += 1
            return end
        return None

    def chained(self, pos: int) -> bool:
        """:data:`_RESYNC_CHAIN` well-formed messages follow each other from ``pos`` (or reach
        the end of the file)."""
        chain_subs: dict[int, tuple[int, int, int]] = {}
        for _ in range(_RESYNC_CHAIN):
            if pos == self.n:
                return True
            nxt = self.size_ok(pos, chain_subs=chain_subs)
            if nxt is None:
                return False
            pos = nxt
        return True

    def resync(self, pos: int) -> int | None:
        """The first offset after ``pos`` where a chain of well-formed messages starts (only
        offsets whose type byte is a ULog type are tried, found 64 KiB at a time)."""
        valid = np.frombuffer(_VALID_MSG_TYPES_ORDERED, np.uint8)
        lo = pos + 1
        while lo + 3 <= self.n:
            hi = min(self.n - 2, lo + (1 << 16))  # candidate starts [lo, hi): type bytes [lo+2, hi+2)
            types = np.frombuffer(self.data, np.uint8, count=hi - lo, offset=lo + 2)
            for k in np.flatnonzero(np.isin(types, valid)):
                if self.chained(lo + int(k)):
                    return lo + int(k)
            lo = hi
        return None

    def timestamp(self, pos: int | None) -> int | None:
        """The timestamp of the DATA message at ``pos`` (of a subscribed id), else None."""
        if pos is None:
            return None
        d = self.data
        sub = self.subs.get(d[pos + 3] | (d[pos + 4] << 8))
        if d[pos + 2] != 0x44 or sub is None:
            return None
        at = pos + 5 + sub[2]
        return int.from_bytes(d[at:at + 8], "little")

    def walk(self, start: int) -> tuple[list[_Damage], int]:
        """Damaged spans from ``start`` (the first message after the header) and the bytes of a
        last message cut by the end of the file (0 when it ends on a message)."""
        d, n, subs = self.data, self.n, self.subs
        spans: list[_Damage] = []
        pos, prev = start, None
        last_d = last_d_before_prev = None  # offsets of the last DATA message, and of the one before prev
        after_pending = False  # the last span still wants the time of the first DATA message after it
        if pos + 3 <= n and d[pos + 2] == 0x42 and pos + 3 + (d[pos] | d[pos + 1] << 8) <= n:
            pos += 3 + (d[pos] | d[pos + 1] << 8)  # FLAG_BITS, the first message
        while pos < n:
            # the bulk of a log: DATA messages of a subscribed id, checked here without a call
            if pos + 5 <= n and d[pos + 2] == 0x44:
                size = d[pos] | (d[pos + 1] << 8)
                sub = subs.get(d[pos + 3] | (d[pos + 4] << 8))
                if sub is not None and sub[0] <= size - 2 <= sub[1] and pos + 3 + size <= n:
                    last_d_before_prev, last_d = last_d, pos
                    if after_pending:
                        spans[-1].t_after_us, after_pending = self.timestamp(pos), False
                    prev, pos = pos, pos + 3 + size
                    continue
            nxt = self.size_ok(pos, commit=True)
            if nxt is not None:
                last_d_before_prev = last_d
                if d[pos + 2] == 0x44 and self.timestamp(pos) is not None:
                    last_d = pos
                prev, pos = pos, nxt
                continue
            size = (d[pos] | (d[pos + 1] << 8)) if pos + 2 <= n else 0
            cut = pos + 3 > n or (d[pos + 2] in _VALID_MSG_TYPES and pos + 3 + size > n)
            # the message before led here: its size may be what is damaged, its payload suspect
            first = prev if prev is not None else pos
            again = self.resync(first)
            if again is None and cut:
                return spans, n - pos  # a file cut mid-message (or mid-header)
            before = last_d_before_prev if first == prev else last_d
            spans.append(_Damage(first, n if again is None else again, self.timestamp(before), None))
            after_pending = True
            if again is None:
                break
            pos, prev = again, None
            last_d = last_d_before_prev = before
        return spans, 0


class _Conv:
    """Shared time conversion: µs since boot -> (t_ns, t_boot_ns), counting pre-start stamps."""

    def __init__(self, t0_us: int):
        self.t0_us = t0_us
        self.n_before_start = 0

    def frame(self, d, cols: dict[str, np.ndarray] | None = None) -> pd.DataFrame:
        ts = np.asarray(d.data["timestamp"]).astype(np.int64)
        self.n_before_start += int(np.sum(ts < self.t0_us))
        base = {"t_ns": (ts - self.t0_us) * 1000, "t_boot_ns": ts * 1000,
                "instance": np.full(len(ts), d.multi_id, dtype=np.uint8),
                "src": np.full(len(ts), d.name, dtype=object)}
        return pd.DataFrame({**base, **(cols or {})})


def _topic_names(choice) -> list[str] | None:
    """The topic names a config choice gives (None for ``auto``: the candidates decide)."""
    if choice in (None, "auto"):
        return None
    return [choice] if isinstance(choice, str) else list(choice)


def configured_topics_absent(topics: dict, choice) -> list[str]:
    """The topic names a non-``auto`` config choice names that the log does not hold."""
    return [n for n in _topic_names(choice) or [] if n not in topics]


def _select(topics: dict, stream: str, choice, path: Path) -> list:
    """The datasets feeding ``stream``: ``auto`` = all instances of the first candidate present."""
    names = _topic_names(choice)
    if names is None:
        for name in DEFAULT_TOPICS[stream]:
            if name in topics:
                return topics[name]
        return []
    return [d for n in names for d in topics.get(n, [])]


def _f(d, *names: str) -> np.ndarray | None:
    """First field present among ``names``, as float64."""
    for n in names:
        if n in d.data:
            return np.asarray(d.data[n], dtype=np.float64)
    return None


def _nan(d) -> np.ndarray:
    return np.full(len(d.data["timestamp"]), np.nan)


def _vec(d, fmt: str, n: int = 3) -> list[np.ndarray] | None:
    if fmt.format(0) not in d.data:
        return None
    return [np.asarray(d.data[fmt.format(i)], dtype=np.float64) for i in range(n)]


def _py(v):
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else None  # meta.json is strict JSON
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return v


# --- topic -> stream builders -------------------------------------------------------------------

def _imu(d, conv: _Conv) -> pd.DataFrame | None:
    cols = {}
    if d.name == "vehicle_imu":
        # integrated deltas over their own dt (µs): the mean rate/specific force of the interval
        da, dv = _vec(d, "delta_angle[{}]"), _vec(d, "delta_velocity[{}]")
        dta, dtv = _f(d, "delta_angle_dt"), _f(d, "delta_velocity_dt")
        if da is None or dv is None or dta is None or dtv is None:
            return None
        with np.errstate(divide="ignore", invalid="ignore"):
            for a, x, y in zip("xyz", da, dv):
                cols[f"gyr_{a}_radps"] = np.where(dta > 0, x / (dta * 1e-6), np.nan)
                cols[f"acc_{a}_mps2"] = np.where(dtv > 0, y / (dtv * 1e-6), np.nan)
    else:
        g = _vec(d, "gyro_rad[{}]")
        acc = _vec(d, "accelerometer_m_s2[{}]")
        if g is None and acc is None:
            return None
        rel = _f(d, "accelerometer_timestamp_relative")
        ok = np.ones(len(d.data["timestamp"]), bool) if rel is None else rel != RELATIVE_TIMESTAMP_INVALID
        for i, a in enumerate("xyz"):
            cols[f"gyr_{a}_radps"] = g[i] if g is not None else _nan(d)
            cols[f"acc_{a}_mps2"] = np.where(ok, acc[i], np.nan) if acc is not None else _nan(d)
    return conv.frame(d, cols)


def _scaled_deg(d, float_name: str, int_name: str) -> np.ndarray | None:
    if float_name in d.data:
        return np.asarray(d.data[float_name], dtype=np.float64)
    if int_name in d.data:
        raw = np.asarray(d.data[int_name])
        # older logs: int32 in 1e-7 deg; a float field of the old name is already in deg
        return raw.astype(np.float64) * (1e-7 if raw.dtype.kind in "iu" else 1.0)
    return None


def _scaled_alt(d, float_name: str, int_name: str) -> np.ndarray | None:
    if float_name in d.data:
        return np.asarray(d.data[float_name], dtype=np.float64)
    if int_name in d.data:
        raw = np.asarray(d.data[int_name])
        return raw.astype(np.float64) * (1e-3 if raw.dtype.kind in "iu" else 1.0)  # int mm
    return None


def _gps(d, conv: _Conv) -> pd.DataFrame | None:
    lat = _scaled_deg(d, "latitude_deg", "lat")
    lon = _scaled_deg(d, "longitude_deg", "lon")
    if lat is None or lon is None:
        return None
    alt = _scaled_alt(d, "altitude_msl_m", "alt")
    alt_e = _scaled_alt(d, "altitude_ellipsoid_m", "alt_ellipsoid")
    cols = {"lat_deg": lat, "lon_deg": lon,
            "alt_msl_m": alt if alt is not None else _nan(d),
            "alt_wgs84_m": alt_e if alt_e is not None else _nan(d)}
    for a in "ned":
        v = _f(d, f"vel_{a}_m_s")
        cols[f"vel_{a}_mps"] = v if v is not None else _nan(d)
    for col, names in (("fix_type", ("fix_type",)), ("n_sats", ("satellites_used",)),
                       ("hacc_m", ("eph",)), ("vacc_m", ("epv",)), ("hdop", ("hdop",)),
                       ("vdop", ("vdop",))):
        v = _f(d, *names)
        cols[col] = v if v is not None else _nan(d)
    return conv.frame(d, cols)


def _mag(d, conv: _Conv) -> pd.DataFrame | None:
    m = _vec(d, "magnetometer_ga[{}]") if d.name == "vehicle_magnetometer" else None
    if m is None and all(k in d.data for k in "xyz"):
        m = [np.asarray(d.data[k], dtype=np.float64) for k in "xyz"]
    if m is None:
        return None
    return conv.frame(d, {f"mag_{a}_T": v * _GAUSS_TO_T for a, v in zip("xyz", m)})


def _baro(d, conv: _Conv) -> pd.DataFrame | None:
    p = _f(d, "baro_pressure_pa")
    if p is None:
        mbar = _f(d, "baro_pressure_mbar", "baro_pres_mbar")
        if mbar is not None:
            p = mbar * 100.0
    if p is None and d.name == "sensor_baro":
        p = _f(d, "pressure")
        # sensor_baro.pressure was mbar before PX4 1.12 and Pa since; 2000 separates them
        if p is not None and len(p) and np.nanmedian(p) < 2000:
            p = p * 100.0
    alt = _f(d, "baro_alt_meter", "altitude")
    temp = _f(d, "baro_temp_celcius", "baro_temp_celsius", "temperature")
    if p is None and alt is None:
        return None
    return conv.frame(d, {"press_Pa": p if p is not None else _nan(d),
                          "alt_rel_m": alt if alt is not None else _nan(d),
                          "temp_degC": temp if temp is not None else _nan(d)})


def _attitude(d, conv: _Conv) -> pd.DataFrame | None:
    q = _vec(d, "q[{}]", 4)
    if q is None:
        return None
    return conv.frame(d, {f"q_{c}": v for c, v in zip("wxyz", q)})


def _local_position(d, conv: _Conv) -> pd.DataFrame | None:
    cols = {}
    for src, dst in (("x", "pos_n_m"), ("y", "pos_e_m"), ("z", "pos_d_m"),
                     ("vx", "vel_n_mps"), ("vy", "vel_e_mps"), ("vz", "vel_d_mps")):
        v = _f(d, src)
        cols[dst] = v if v is not None else _nan(d)
    # the EKF's reset counters (uint8, wrapping): preprocessing breaks the track where their sum
    # changes, so the reset's step (10.9 m in z on the ekf_failure fixture) is not read as motion
    counters = [c for c in (_f(d, f"{k}_reset_counter") for k in ("xy", "z", "vxy", "vz")) if c is not None]
    cols["reset_count"] = np.sum(counters, axis=0) if counters else _nan(d)
    return conv.frame(d, cols)


def _rangefinder(d, conv: _Conv, window=None) -> pd.DataFrame | None:
    dist = _f(d, "current_distance")
    if dist is None:
        return None
    lo, hi = _f(d, "min_distance"), _f(d, "max_distance")
    valid = np.isfinite(dist)
    if lo is not None and hi is not None:
        valid &= (dist >= lo) & (dist <= hi)
    if window is not None:  # config: a tighter trusted range than the sensor declares
        valid &= (dist >= float(window[0])) & (dist <= float(window[1]))
    sq = _f(d, "signal_quality")
    if sq is not None:
        valid &= sq != 0  # 0 = invalid signal, -1 = unknown
    ori = _f(d, "orientation")
    return conv.frame(d, {"dist_m": dist, "valid": valid,
                          "orientation": ori if ori is not None else _nan(d)})


def _airspeed(d, conv: _Conv) -> pd.DataFrame | None:
    ias = _f(d, "indicated_airspeed_m_s")
    if ias is None:
        return None
    temp = _f(d, "air_temperature_celsius")
    return conv.frame(d, {"airspeed_mps": ias, "temp_degC": temp if temp is not None else _nan(d)})


def _diff_press(d, conv: _Conv) -> pd.DataFrame | None:
    dp = _f(d, "differential_pressure_pa", "differential_pressure_filtered_pa",
            "differential_pressure_raw_pa")
    if dp is None:
        return None
    temp = _f(d, "temperature")
    return conv.frame(d, {"diff_press_Pa": dp, "temp_degC": temp if temp is not None else _nan(d)})


def _channels(d, conv: _Conv, count_field: str, field_fmt: str, n_max: int, col_fmt: str) -> pd.DataFrame | None:
    """Array topic ``field_fmt.format(i)`` → ``col_fmt.format(i + 1)`` columns; channels at or
    beyond the logged ``count_field`` are NaN (unused slots, not zero pulses)."""
    n_used = _f(d, count_field)
    cols = {}
    for i in range(n_max):
        v = _f(d, field_fmt.format(i))
        if v is None:
            break
        cols[col_fmt.format(i + 1)] = np.where(n_used > i, v, np.nan) if n_used is not None else v
    return conv.frame(d, cols) if cols else None


def _input_rc(d, conv: _Conv) -> pd.DataFrame | None:
    return _channels(d, conv, "channel_count", "values[{}]", schema.N_RC, "rc_{}_us")


def _actuator_outputs(d, conv: _Conv) -> pd.DataFrame | None:
    return _channels(d, conv, "noutputs", "output[{}]", schema.N_SERVO, "servo_{}_us")


def _mode(d, conv: _Conv) -> pd.DataFrame | None:
    nav = _f(d, "nav_state")
    arm = _f(d, "arming_state")
    if nav is None:
        return None
    arm = arm if arm is not None else _nan(d)
    key = np.stack([nav, np.nan_to_num(arm, nan=-1)], axis=1)
    change = np.ones(len(nav), bool)
    change[1:] = np.any(key[1:] != key[:-1], axis=1)
    df = conv.frame(d, {"mode": [NAV_STATES.get(int(v), str(int(v))) for v in nav],
                        "armed": pd.array(np.where(np.isnan(arm), None, arm == ARMING_STATE_ARMED),
                                          dtype="boolean")})
    return df[change].reset_index(drop=True)


def _battery(d, conv: _Conv) -> pd.DataFrame | None:
    """``battery_status``: ``voltage_v`` V, ``current_a`` A, ``discharged_mah`` mAh -> Ah,
    ``remaining`` 0..1, ``temperature`` degC."""
    v = _f(d, "voltage_v")
    if v is None:
        return None
    mah = _f(d, "discharged_mah")
    cols = {"voltage_V": v, "current_A": _f(d, "current_a"),
            "consumed_Ah": None if mah is None else mah * 1e-3,
            "remaining_frac": _f(d, "remaining"), "temp_degC": _f(d, "temperature")}
    return conv.frame(d, {k: (x if x is not None else _nan(d)) for k, x in cols.items()})


def _attitude_setpoint(d, conv: _Conv) -> pd.DataFrame | None:
    """``vehicle_attitude_setpoint``: ``roll_body/pitch_body/yaw_body`` (rad, older logs), else
    the quaternion ``q_d`` (FRD -> NED, scalar first) as ZYX Euler angles."""
    from ..frames.rotations import quat_to_euler

    rpy = [_f(d, f"{a}_body") for a in ("roll", "pitch", "yaw")]
    if any(x is None for x in rpy):
        q = _vec(d, "q_d[{}]", 4)
        if q is None:
            return None
        rpy = list(quat_to_euler(np.column_stack(q)))
    return conv.frame(d, {"roll_rad": rpy[0], "pitch_rad": rpy[1], "yaw_rad": rpy[2]})


def _rates_setpoint(d, conv: _Conv) -> pd.DataFrame | None:
    """``vehicle_rates_setpoint`` ``roll/pitch/yaw`` (rad/s, body FRD)."""
    r = [_f(d, a) for a in ("roll", "pitch", "yaw")]
    if any(x is None for x in r):
        return None
    return conv.frame(d, {"p_radps": r[0], "q_radps": r[1], "r_radps": r[2]})


def _velocity_setpoint(d, conv: _Conv) -> pd.DataFrame | None:
    """``vehicle_local_position_setpoint`` (else ``trajectory_setpoint``) ``vx vy vz`` or
    ``velocity[0..2]`` (m/s, NED; NaN where the controller sets none)."""
    v = _vec(d, "velocity[{}]") or ([_f(d, a) for a in ("vx", "vy", "vz")] if "vx" in d.data else None)
    if v is None:
        return None
    return conv.frame(d, {"vel_n_mps": v[0], "vel_e_mps": v[1], "vel_d_mps": v[2]})


def _vibration(d, conv: _Conv) -> pd.DataFrame | None:
    """``vehicle_imu_status`` ``accel_vibration_metric`` (m/s²), ``gyro_vibration_metric``
    (rad/s), ``accel_clipping[0..2]`` (counts since boot); older logs ``estimator_status``
    ``vibe[2]`` (accel high-frequency vibration, m/s²) and ``vibe[1]`` (gyro, rad/s)."""
    if d.name == "estimator_status":
        acc, gyr = _f(d, "vibe[2]"), _f(d, "vibe[1]")
        if acc is None or gyr is None:
            return None
        return conv.frame(d, {"acc_vibration_mps2": acc, "gyr_vibration_radps": gyr})
    acc, gyr = _f(d, "accel_vibration_metric"), _f(d, "gyro_vibration_metric")
    if acc is None and gyr is None:
        return None
    cols = {"acc_vibration_mps2": acc if acc is not None else _nan(d),
            "gyr_vibration_radps": gyr if gyr is not None else _nan(d)}
    clip = _vec(d, "accel_clipping[{}]")
    if clip is not None:
        cols.update({f"clip_{i}": c for i, c in enumerate(clip)})
    return conv.frame(d, cols)


#: ``estimator_status`` field -> ``estimator_status`` stream column
_ESTIMATOR_FLAGS = (("solution_status_flags", "solution_flags"), ("filter_fault_flags", "fault_flags"),
                    ("innovation_check_flags", "innovation_fail_flags"), ("gps_check_fail_flags", "gps_check_flags"),
                    ("timeout_flags", "timeout_flags"), ("control_mode_flags", "control_mode_flags"))
_ESTIMATOR_RATIOS = ("vel", "pos", "hgt", "mag", "hdg", "tas", "hagl")


def _estimator_status(d, conv: _Conv) -> pd.DataFrame | None:
    """``estimator_status``: the bit fields as logged (int64; ``control_mode_flags`` is a uint64
    whose highest named bit is 44) and the ``<x>_test_ratio`` fields; a field this firmware does
    not log stays missing."""
    cols: dict[str, np.ndarray] = {}
    for src, col in _ESTIMATOR_FLAGS:
        if src in d.data:
            cols[col] = np.asarray(d.data[src]).astype(np.int64)
    for r in _ESTIMATOR_RATIOS:
        v = _f(d, f"{r}_test_ratio")
        if v is not None:
            cols[f"{r}_test_ratio"] = v
    if "solution_flags" not in cols and not any(k.endswith("_test_ratio") for k in cols):
        return None  # an estimator_status without any of them (very old PX4): vibration only
    return conv.frame(d, cols)


def _estimator_rejections(d, conv: _Conv) -> pd.DataFrame | None:
    """``estimator_status_flags`` ``reject_*`` booleans packed into ``innovation_fail_flags``,
    bit ``k`` = the ``k``-th ``reject_*`` field of the topic (the names recorded in
    ``meta['estimator_status']['innovation_fail_flags']``); one row per record (the topic is
    published on change, so a bit holds until the next record)."""
    reject = [f for f in d.data if f.startswith("reject_")]
    if not reject:
        return None
    packed = np.zeros(len(d.data["timestamp"]), np.int64)
    for k, f in enumerate(reject):
        packed |= (np.asarray(d.data[f]) != 0).astype(np.int64) << k
    return conv.frame(d, {"innovation_fail_flags": packed})


def _estimator_layout(topics: dict) -> dict:
    """Which bit layout the log's ``estimator_status`` uses (see the module docstring)."""
    flags = topics.get("estimator_status_flags", [])
    fields = list(flags[0].data) if flags else []
    fs = [f for f in fields if f.startswith("fs_")]
    out = {"layout": "px4" if fs and "fs_bad_vel_n" not in fs else "px4_legacy"}
    reject = [f for f in fields if f.startswith("reject_")]
    if reject:  # they name innovation_check_flags (PX4 1.12-1.13) or the packed estimator_status_flags rows
        out["innovation_fail_flags"] = reject
    return out


def _ned_origin(topics: dict, gps: pd.DataFrame | None, diag: dict) -> dict | None:
    """``ref_lat/ref_lon/ref_alt`` of the first globally referenced local-position sample.
    ``ref_alt`` is AMSL; the ellipsoidal height adds the GPS geoid separation
    (median ``alt_wgs84_m - alt_msl_m`` over 3D fixes) when the log has it."""
    for d in topics.get("vehicle_local_position", []):
        lat, lon, alt = _f(d, "ref_lat"), _f(d, "ref_lon"), _f(d, "ref_alt")
        if lat is None or lon is None:
            continue
        glob = _f(d, "xy_global")
        ok = np.isfinite(lat) & np.isfinite(lon) & ~((lat == 0) & (lon == 0))
        if glob is not None:
            ok &= glob != 0
        if not ok.any():
            continue
        k = int(np.argmax(ok))
        changes = np.unique(np.stack([lat[ok], lon[ok]], 1), axis=0)
        if len(changes) > 1:
            diag["warnings"].append(f"vehicle_local_position reference changed {len(changes) - 1} "
                                    "time(s); meta.ned_origin is the first one")
        origin = {"lat_deg": float(lat[k]), "lon_deg": float(lon[k]), "alt_wgs84_m": None,
                  "alt_msl_m": float(alt[k]) if alt is not None else None,
                  "source": "vehicle_local_position.ref_lat/ref_lon/ref_alt"}
        if gps is not None and origin["alt_msl_m"] is not None:
            good = (gps["fix_type"] >= 3) & gps["alt_wgs84_m"].notna() & gps["alt_msl_m"].notna()
            if good.any():
                n = float(np.median((gps["alt_wgs84_m"] - gps["alt_msl_m"])[good]))
                origin["alt_wgs84_m"] = origin["alt_msl_m"] + n
                origin["geoid_separation_m"] = n
        return origin
    return None


def _utc(meta: dict, topics: dict, out: dict, cfg: dict, t0_us: int) -> None:
    for d in _select(topics, "gps", cfg.get("gps", "auto"), Path()):
        if "time_utc_usec" not in d.data:
            continue
        utc = np.asarray(d.data["time_utc_usec"]).astype(np.int64)
        ts = np.asarray(d.data["timestamp"]).astype(np.int64)
        rel = d.data.get("timestamp_time_relative")
        rel = np.zeros_like(ts) if rel is None else np.asarray(rel).astype(np.int64)
        fix = _f(d, "fix_type")
        ok = utc > 0
        if fix is not None:
            ok &= fix >= 2
        if not ok.any():
            continue
        off = np.median(utc[ok] - (ts[ok] + rel[ok]))
        meta["t0_utc_ns"] = int(round(off)) * 1000 + t0_us * 1000
        meta["utc_source"] = "gps"
        return


def _level(m) -> float:
    """Syslog level 0 (emergency) .. 7 (debug) of a logged message (ULog stores it as the
    ASCII digit, ``'6'`` = 54)."""
    lv = int(m.log_level)
    return float(lv - 48 if lv >= 48 else lv)


def _messages(ulog, diag: dict, t0_us: int) -> pd.DataFrame | None:
    """Logged messages (``L`` and tagged ``C``): all of them as the ``messages`` stream (None
    when there are none), the first 1000 also in ``diag['messages']``."""
    msgs = [(int(m.timestamp), m.log_level_str(), str(m.message).strip(), _level(m), "logged_messages")
            for m in ulog.logged_messages]
    for lst in ulog.logged_messages_tagged.values():
        msgs += [(int(m.timestamp), m.log_level_str(), str(m.message).strip(), _level(m),
                  "logged_messages_tagged") for m in lst]
    bad = [m for m in msgs if not 0 <= m[0] < 1 << 63]
    if bad:  # a damaged LOGGING message whose header survived: no time to place it at
        msgs = [m for m in msgs if 0 <= m[0] < 1 << 63]
        diag["records_dropped"]["bad_timestamp"] = diag["records_dropped"].get("bad_timestamp", 0) + len(bad)
        diag["warnings"].append(f"{len(bad)} logged message(s) with a time stamp beyond 2^63 µs dropped")
    msgs.sort(key=lambda m: m[0])
    diag["messages"] = [{"t_ns": (t - t0_us) * 1000, "level": lvl, "text": txt}
                        for t, lvl, txt, _, _ in msgs[:1000]]
    if len(msgs) > 1000:
        diag["warnings"].append(f"{len(msgs)} logged messages, first 1000 kept")
    if not msgs:
        return None
    ts = np.array([m[0] for m in msgs], dtype=np.int64)
    return pd.DataFrame({"t_ns": (ts - t0_us) * 1000, "t_boot_ns": ts * 1000,
                         "instance": np.zeros(len(ts), np.uint8), "src": [m[4] for m in msgs],
                         "text": [m[2] for m in msgs], "severity": [m[3] for m in msgs]})


def _params(ulog, t0_us: int) -> pd.DataFrame:
    """Initial parameters (written before the data: at the logger start, ``t_ns = 0``) then
    every changed parameter at its own time. Non-numeric values are NaN."""
    def num(v) -> float:
        try:
            return float(v)
        except (TypeError, ValueError):
            return float("nan")

    init = list(ulog.initial_parameters.items())
    changed = list(ulog.changed_parameters)
    ts = np.array([t0_us] * len(init) + [int(t) for t, _, _ in changed], dtype=np.int64)
    return pd.DataFrame({
        "t_ns": (ts - t0_us) * 1000, "t_boot_ns": ts * 1000, "instance": np.zeros(len(ts), np.uint8),
        "src": ["initial_parameters"] * len(init) + ["changed_parameters"] * len(changed),
        "name": [str(k) for k, _ in init] + [str(k) for _, k, _ in changed],
        "value": np.array([num(v) for _, v in init] + [num(v) for _, _, v in changed], dtype=np.float64)})
