"""ArduPilot DataFlash writer (FMT-based), and canonical streams written as a ``.bin`` log.

:class:`DataFlashWriter` emits the byte format :mod:`pipeline.io.dataflash` and pymavlink read:
an ``FMT`` record per message type (``A3 95 80`` + ``Type:B Length:B Name:n Format:N
Columns:Z``), optionally ``FMTU`` with ``UNIT``/``MULT`` tables (modern logs), then records
``A3 95 <type> <body>``. Bodies are built as NumPy structured arrays and written with
``tobytes()``, so :meth:`DataFlashWriter.write_many` writes thousands of records per call;
:meth:`DataFlashWriter.write_merged` interleaves several types by ``TimeUS`` the way a vehicle
logs them. Output is a pure function of the calls (no clocks, no randomness): same calls, same
bytes.

Values are physical: scaled format characters are encoded as the reader decodes them
(``c C e E`` store ``round(100·v)``, ``L`` stores ``round(10⁷·v)`` degrees), char fields take
``str`` and are NUL-padded. Message definitions come from the one catalogue
(:mod:`pipeline.io.dataflash.catalogue`; :meth:`DataFlashWriter.define_layout`).

:func:`write_bin` writes canonical streams (``imu``, ``gps``, ``attitude``, ``baro``,
``rangefinder``, ``control``, ``radar``) in the catalogue's ``ardupilot4`` layout: ``GPS`` +
``GPA``, ``IMU``, ``ATT``, ``BARO``, ``RFND``, ``RCIN``, ``RCOU``, ``MODE``, ``EV``, ``PARM``,
``MSG``, ``ORGN`` and the radar ``RADR`` (TimeUS:Q, I:B, Rng:f m (ρ + τ_RD ρ̇), U:f, V:f
direction cosines, RR:f m/s). ``TimeUS`` = ``boot_us`` + stream time; GPS week/ms from the UTC
start with the leap seconds of its date (:mod:`pipeline.io.gpstime`). Quantisation: lat/lon 1e-7°, GPS alt and ATT angles 0.01 (m, °),
RFND 1 cm, BARO temperature 0.01 °C, float32 elsewhere.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, BinaryIO, Mapping

import numpy as np
from numpy.typing import ArrayLike

from ...frames.rotations import quat_to_euler
from . import catalogue as cat
from .decode import FMT_LEN, FMT_TYPE, FORMAT_CHARS, HEAD1, HEAD2, format_dtype
from ..gpstime import leap_seconds_at_utc

if TYPE_CHECKING:  # annotations only: writing a log needs no pandas import
    import pandas as pd

#: Unit and multiplier ids and the fixed type ids (from the catalogue)
UNITS, MULTS = cat.UNITS, cat.MULTS
FMTU_TYPE, UNIT_TYPE, MULT_TYPE, PARM_TYPE = cat.FMTU_TYPE, cat.UNIT_TYPE, cat.MULT_TYPE, cat.PARM_TYPE

#: The simulation radar message as :meth:`DataFlashWriter.define` keywords (``w.define(**RADR)``).
RADR: dict = cat.RADR.as_kwargs()

GPS_EPOCH_UNIX_S = 315964800  # 1980-01-06

_HEADER = np.dtype([("h1", "u1"), ("h2", "u1"), ("type", "u1")])


class DataFlashWriter:
    """Write a DataFlash log record by record or column-wise.

    Parameters
    ----------
    target : path-like or binary file object
        Output file (created/truncated) or an open binary stream (not closed on exit).

    Examples
    --------
    >>> with DataFlashWriter(path) as w:                              # doctest: +SKIP
    ...     w.define("IMU", 131, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
    ...              units="sEEEooo", mults="F000000")
    ...     w.write_many("IMU", {"TimeUS": t_us, "GyrX": gx, ...})
    """

    def __init__(self, target: str | os.PathLike | BinaryIO):
        if isinstance(target, (str, os.PathLike)):
            self._fh: BinaryIO = open(target, "wb")
            self._own = True
        else:
            self._fh = target
            self._own = False
        self._types: dict[str, tuple[int, str, list[str], np.dtype]] = {}
        self._ids: set[int] = set()
        self._units_written: set[str] = set()
        self._mults_written: set[str] = set()
        self._fmt_fmt_written = False

    # context manager -----------------------------------------------------------------------
    def __enter__(self) -> "DataFlashWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        self._fh.flush()
        if self._own:
            self._fh.close()

    # definitions ---------------------------------------------------------------------------
    def _emit(self, b: bytes) -> None:
        self._fh.write(b)

    def _fmt_record(self, type_id: int, name: str, fmt: str, labels: str, length: int) -> bytes:
        rec = np.zeros(1, dtype=np.dtype([("h", _HEADER), ("Type", "u1"), ("Length", "u1"),
                                          ("Name", "S4"), ("Format", "S16"), ("Columns", "S64")]))
        rec["h"] = (HEAD1, HEAD2, FMT_TYPE)
        rec["Type"], rec["Length"] = type_id, length
        rec["Name"], rec["Format"], rec["Columns"] = name.encode(), fmt.encode(), labels.encode()
        return rec.tobytes()

    def _ensure_fmt_fmt(self) -> None:
        if not self._fmt_fmt_written:
            self._fmt_fmt_written = True
            self._ids.add(FMT_TYPE)
            self._emit(self._fmt_record(FMT_TYPE, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns",
                                        FMT_LEN))

    def define(self, name: str, type_id: int, fmt: str, labels: str | list[str],
               units: str | None = None, mults: str | None = None) -> None:
        """Declare a message type (writes its FMT record, and FMTU when ``units`` is given).

        Parameters
        ----------
        name : str
            Message name, at most 4 ASCII characters.
        type_id : int
            Type byte 0..255 (128 is FMT itself), unique in the log.
        fmt : str
            DataFlash format characters, one per field (at most 16).
        labels : str or list of str
            Field names (comma-separated string or list), one per format character.
        units, mults : str, optional
            ArduPilot unit / multiplier id characters, one per field (see :data:`UNITS`,
            :data:`MULTS`). Given ``units``, FMTU/UNIT/MULT records are written too.
        """
        cols = labels.split(",") if isinstance(labels, str) else list(labels)
        if not (1 <= len(name) <= 4) or not name.isascii():
            raise ValueError(f"message name {name!r} must be 1-4 ASCII characters")
        if not (0 <= type_id <= 255) or type_id in self._ids:
            raise ValueError(f"type id {type_id} of {name} is out of range or already used")
        if len(fmt) > 16 or any(c not in FORMAT_CHARS for c in fmt):
            raise ValueError(f"bad format {fmt!r} for {name}")
        if len(cols) != len(fmt) or len(",".join(cols)) > 64:
            raise ValueError(f"{name}: {len(cols)} labels for {len(fmt)} format characters")
        if name in self._types:
            raise ValueError(f"message {name} already defined")
        dt = format_dtype(fmt, cols)
        if dt.itemsize + 3 > 255:
            raise ValueError(f"{name}: record of {dt.itemsize + 3} bytes exceeds 255")
        self._ensure_fmt_fmt()
        self._ids.add(type_id)
        self._types[name] = (type_id, fmt, cols, dt)
        self._emit(self._fmt_record(type_id, name, fmt, ",".join(cols), dt.itemsize + 3))
        if units is not None:
            mults = mults if mults is not None else "-" * len(fmt)
            if len(units) != len(fmt) or len(mults) != len(fmt):
                raise ValueError(f"{name}: units/mults must have one id per field")
            bad = [u for u in units if u not in UNITS] + [m for m in mults if m not in MULTS]
            if bad:
                raise ValueError(f"{name}: unknown unit/multiplier ids {bad}")
            self._ensure_unit_tables()
            for u in units:
                if u not in self._units_written:
                    self._units_written.add(u)
                    self.write("UNIT", TimeUS=0, Id=ord(u), Label=UNITS[u])
            for m in mults:
                if m not in self._mults_written:
                    self._mults_written.add(m)
                    self.write("MULT", TimeUS=0, Id=ord(m), Mult=MULTS[m])
            self.write("FMTU", TimeUS=0, FmtType=type_id, UnitIds=units, MultIds=mults)

    def _ensure_unit_tables(self) -> None:
        if "FMTU" not in self._types:
            for m in (cat.UNIT, cat.MULT, cat.FMTU):
                self.define_message(m)

    def define_message(self, m: cat.MessageDef) -> None:
        """Declare one catalogue message (:class:`pipeline.io.dataflash.catalogue.MessageDef`)."""
        self.define(m.name, m.type_id, m.fmt, m.labels, units=m.units, mults=m.mults)

    def define_layout(self, name: str) -> None:
        """Declare every message of catalogue layout ``name`` (``ardupilot4``, ``demo``), in
        the catalogue's order."""
        for m in cat.layout(name):
            self.define_message(m)

    # records -------------------------------------------------------------------------------
    def records(self, name: str, columns: dict[str, ArrayLike]) -> np.ndarray:
        """Encode ``columns`` as a structured array of whole records (header included)."""
        if name not in self._types:
            raise KeyError(f"message {name} not defined")
        type_id, fmt, cols, dt = self._types[name]
        missing = [c for c in columns if c not in dt.names]
        if missing:
            raise KeyError(f"{name} has no field(s) {missing}")
        lens = {len(v) for v in columns.values()
                if not isinstance(v, (str, bytes)) and (isinstance(v, (list, tuple)) or np.ndim(v) > 0)}
        n = max(lens) if lens else 1
        if len(lens) > 1:
            raise ValueError(f"{name}: columns of different lengths {sorted(lens)}")
        rec = np.zeros(n, dtype=np.dtype([("h", _HEADER), ("b", dt)]))
        rec["h"] = (HEAD1, HEAD2, type_id)
        body = rec["b"]
        for ch, cname in zip(fmt, dt.names):
            if cname not in columns:
                continue
            v = columns[cname]
            div = FORMAT_CHARS[ch][1]
            if ch in "nNZ":
                vals = [v] * n if isinstance(v, (str, bytes)) else list(v)
                body[cname] = [x.encode() if isinstance(x, str) else bytes(x) for x in vals]
            elif div is not None:
                body[cname] = np.rint(np.asarray(v, dtype=np.float64) * div)
            elif ch in "fdg":
                body[cname] = np.asarray(v, dtype=np.float64)
            else:
                body[cname] = np.asarray(v)
        return rec

    def write_many(self, name: str, columns: dict[str, ArrayLike]) -> int:
        """Write ``n`` records of ``name`` from column arrays (scalars broadcast); returns ``n``."""
        rec = self.records(name, columns)
        self._emit(rec.tobytes())
        return len(rec)

    def write(self, name: str, **values) -> None:
        """Write one record of ``name`` (fields by keyword; omitted fields are zero)."""
        self.write_many(name, values)

    def write_merged(self, batches: dict[str, dict[str, ArrayLike]], time_field: str = "TimeUS") -> int:
        """Write several message types interleaved by ``time_field`` (stable: ties keep the
        order of ``batches``), as a vehicle logs them. Returns the number of records."""
        blobs, starts, lens, times = [], [], [], []
        offset = 0
        for name, cols in batches.items():
            rec = self.records(name, cols)
            b = np.frombuffer(rec.tobytes(), dtype=np.uint8)
            size = rec.dtype.itemsize
            blobs.append(b)
            starts.append(offset + size * np.arange(len(rec)))
            lens.append(np.full(len(rec), size))
            times.append(np.asarray(rec["b"][time_field], dtype=np.int64))
            offset += len(b)
        if not blobs:
            return 0
        flat = np.concatenate(blobs)
        st, ln, tt = np.concatenate(starts), np.concatenate(lens), np.concatenate(times)
        order = np.argsort(tt, kind="stable")
        st, ln = st[order], ln[order]
        # gather every record's bytes in time order without a Python loop
        out_start = np.concatenate([[0], np.cumsum(ln)[:-1]])
        idx = np.repeat(st - out_start, ln) + np.arange(int(ln.sum()))
        self._emit(flat[idx].tobytes())
        return len(order)

    def write_params(self, params: dict[str, float], time_us: int = 0) -> None:
        """Write PARM records (defines ``PARM``, type 129, ``QNf`` on first use)."""
        if "PARM" not in self._types:
            self.define_message(cat.PARM)
        names = list(params)
        for n in names:
            if len(n.encode()) > 16:
                raise ValueError(f"parameter name {n!r} longer than 16 bytes")
        self.write_many("PARM", {"TimeUS": np.full(len(names), time_us, dtype=np.uint64),
                                 "Name": names, "Value": [float(params[n]) for n in names]})


# --------------------------------------------------------------------------------------------
# canonical streams -> .bin
# --------------------------------------------------------------------------------------------

def _us(t_ns) -> np.ndarray:
    return (np.asarray(t_ns, np.int64) // 1000).astype(np.int64)


def write_bin(path: str | os.PathLike, streams: Mapping[str, pd.DataFrame], *, t0_utc_ns: int,
              boot_us: int, params: Mapping[str, float], message: str, origin,
              undulation_m: float) -> str | os.PathLike:
    """Write canonical streams as an ArduPilot DataFlash log (layout ``ardupilot4``).

    Parameters
    ----------
    path : path-like
        Output ``.bin`` (created/truncated).
    streams : mapping of str to DataFrame
        Canonical ``gps``, ``imu``, ``attitude``, ``baro``, ``rangefinder``, ``control`` and
        ``radar`` streams (``t_ns`` since the flight's t = 0; ``gps`` and ``radar`` may be empty).
    t0_utc_ns : int
        UTC of ``t_ns = 0`` (GPS week and week milliseconds are derived from it).
    boot_us : int
        Vehicle boot time at ``t_ns = 0``: ``TimeUS = boot_us + t_ns / 1000``.
    params : mapping
        ``PARM`` records (name -> value, in this order) written at boot.
    message : str
        The one ``MSG`` text written at boot (the firmware banner).
    origin : (lat_deg, lon_deg, alt_wgs84_m)
        EKF origin; ``ORGN.Alt`` is its MSL altitude ``alt_wgs84_m - undulation_m``.
    undulation_m : float
        Geoid undulation (``GPA.Und`` = −undulation, as the source logs store it).

    Returns
    -------
    path-like
        ``path``.
    """
    boot = boot_us
    with DataFlashWriter(path) as w:
        w.define_layout("ardupilot4")
        w.write_params(dict(params), time_us=boot)
        w.write("MSG", TimeUS=boot, Message=message)
        w.write("ORGN", TimeUS=boot, Type=0, Lat=origin[0], Lng=origin[1], Alt=origin[2] - undulation_m)
        w.write("MODE", TimeUS=boot, Mode=0, ModeNum=0, Rsn=0)
        w.write("EV", TimeUS=boot, Id=10)

        batches: dict[str, dict] = {}
        g = streams["gps"]
        if len(g):
            t_us = _us(g["t_ns"])
            # GPS time runs ahead of UTC by the leap seconds of the flight's date
            leap_us = leap_seconds_at_utc(t0_utc_ns * 1e-9) * 1_000_000
            gps_us = t0_utc_ns // 1000 + t_us + leap_us - GPS_EPOCH_UNIX_S * 1_000_000
            wk = gps_us // (7 * 86400 * 1_000_000)
            gms = (gps_us - wk * 7 * 86400 * 1_000_000) // 1000
            vn, ve = g["vel_n_mps"].to_numpy(), g["vel_e_mps"].to_numpy()
            batches["GPS"] = {"TimeUS": boot + t_us, "I": 0, "Status": g["fix_type"].to_numpy().astype(np.uint8),
                              "GMS": gms, "GWk": wk, "NSats": g["n_sats"].to_numpy().astype(np.uint8), "HDop": 0.8,
                              "Lat": g["lat_deg"].to_numpy(), "Lng": g["lon_deg"].to_numpy(),
                              "Alt": g["alt_msl_m"].to_numpy(), "Spd": np.hypot(vn, ve),
                              "GCrs": np.mod(np.rad2deg(np.arctan2(ve, vn)), 360.0),
                              "VZ": g["vel_d_mps"].to_numpy(), "Yaw": 0.0, "U": 1}
            batches["GPA"] = {"TimeUS": boot + t_us, "I": 0, "VDop": 1.2, "HAcc": g["hacc_m"].to_numpy(),
                              "VAcc": g["vacc_m"].to_numpy(), "SAcc": 0.1, "YAcc": 0.0, "VV": 1,
                              "SMS": gms, "Delta": 100, "Und": -undulation_m + 0.0 * t_us}
        i = streams["imu"]
        batches["IMU"] = {"TimeUS": boot + _us(i["t_ns"]), "I": 0,
                          **{f"Gyr{a.upper()}": i[f"gyr_{a}_radps"].to_numpy() for a in "xyz"},
                          **{f"Acc{a.upper()}": i[f"acc_{a}_mps2"].to_numpy() for a in "xyz"},
                          "EG": 0, "EA": 0, "T": i["temp_degC"].to_numpy(), "GH": 1, "AH": 1,
                          "GHz": 200, "AHz": 200}
        a = streams["attitude"]
        q = a[["q_w", "q_x", "q_y", "q_z"]].to_numpy()
        r, p, y = (np.rad2deg(v) for v in quat_to_euler(q))
        batches["ATT"] = {"TimeUS": boot + _us(a["t_ns"]), "DesRoll": r, "Roll": r, "DesPitch": p, "Pitch": p,
                          "DesYaw": np.mod(y, 360.0), "Yaw": np.mod(y, 360.0), "ErrRP": 0.0, "ErrYaw": 0.0, "AEKF": 3}
        b = streams["baro"]
        batches["BARO"] = {"TimeUS": boot + _us(b["t_ns"]), "I": 0, "Alt": b["alt_rel_m"].to_numpy(),
                           "Press": b["press_Pa"].to_numpy(), "Temp": b["temp_degC"].to_numpy(), "CRt": 0.0,
                           "SMS": (_us(b["t_ns"]) // 1000 + boot // 1000).astype(np.uint32), "Offset": 0.0,
                           "GndTemp": b["temp_degC"].to_numpy(), "Health": 1}
        rf = streams["rangefinder"]
        batches["RFND"] = {"TimeUS": boot + _us(rf["t_ns"]), "Instance": 0, "Dist": rf["dist_m"].to_numpy(),
                           "Stat": np.where(rf["valid"].to_numpy(dtype=bool), 4, 3).astype(np.uint8),
                           "Orient": 25}
        c = streams["control"]
        tc = boot + _us(c["t_ns"])
        batches["RCIN"] = {"TimeUS": tc, **{f"C{k}": c[f"rc_{k}_us"].to_numpy() for k in range(1, 5)},
                           **{f"C{k}": 1500 for k in range(5, 9)}}
        batches["RCOU"] = {"TimeUS": tc, **{f"C{k}": c[f"servo_{k}_us"].to_numpy() for k in range(1, 5)}}
        rd = streams["radar"]
        if len(rd):
            batches["RADR"] = {"TimeUS": boot + _us(rd["t_ns"]), "I": rd["sensor_id"].to_numpy().astype(np.uint8),
                               "Rng": rd["range_m"].to_numpy(), "U": rd["dcos_u"].to_numpy(),
                               "V": rd["dcos_v"].to_numpy(), "RR": rd["range_rate_mps"].to_numpy()}
        # scalars broadcast: the writer's records() needs arrays of one length per batch
        for cols in batches.values():
            n = max(len(v) for v in cols.values() if np.ndim(v) > 0)
            for k, v in cols.items():
                if np.ndim(v) == 0:
                    cols[k] = np.full(n, v)
        w.write_merged(batches)
    return path
