"""ArduPilot DataFlash writer (FMT-based) and the tiny demo flight of the default dataset.

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
``str`` and are NUL-padded. :func:`write_demo_flight` writes a < 1 MB quadcopter flight
(take-off, a circle, landing) from a smooth analytic trajectory.
"""

from __future__ import annotations

import os
from typing import BinaryIO

import numpy as np
from numpy.typing import ArrayLike

from .dataflash import FMT_LEN, FMT_TYPE, FORMAT_CHARS, HEAD1, HEAD2, _format_dtype

#: ArduPilot's standard unit ids (AP_Logger/LogStructure.h) used by FMTU/UNIT
UNITS: dict[str, str] = {
    "-": "", "#": "instance", "?": "UNKNOWN", "A": "A", "a": "Ah", "d": "deg", "b": "B",
    "k": "deg/s", "D": "deglatitude", "e": "deg/s/s", "E": "rad/s", "G": "Gauss",
    "h": "degheading", "i": "A.s", "J": "W.s", "l": "l", "L": "rad/s/s", "m": "m", "n": "m/s",
    "o": "m/s/s", "O": "degC", "%": "%", "S": "satellites", "s": "s", "q": "rpm", "r": "rad",
    "U": "deglongitude", "u": "ppm", "v": "V", "P": "Pa", "w": "Ohm", "W": "Watt", "X": "W.h",
    "Y": "us", "z": "Hz",
}
#: ArduPilot's standard multiplier ids
MULTS: dict[str, float] = {
    "-": 0.0, "?": 1.0, "2": 1e2, "1": 1.0, "0": 1.0, "A": 1e-1, "B": 1e-2, "C": 1e-3,
    "D": 1e-4, "E": 1e-5, "F": 1e-6, "G": 1e-7, "I": 1e-9, "!": 3.6, "/": 3600.0,
}

FMTU_TYPE, UNIT_TYPE, MULT_TYPE, PARM_TYPE = 253, 252, 251, 129

#: The simulation radar message (see pipeline.io.dataflash, stream ``radar``):
#: range as measured (ρ + τ·ρ̇), direction cosines u, v, range rate.
RADR = dict(name="RADR", type_id=120, fmt="QBffff", labels="TimeUS,I,Rng,U,V,RR",
            units="s#m--n", mults="F-0000")

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
        dt = _format_dtype(fmt, cols)
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
            self.define("UNIT", UNIT_TYPE, "QbZ", "TimeUS,Id,Label")
            self.define("MULT", MULT_TYPE, "Qbd", "TimeUS,Id,Mult")
            self.define("FMTU", FMTU_TYPE, "QBNN", "TimeUS,FmtType,UnitIds,MultIds")

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
            self.define("PARM", PARM_TYPE, "QNf", "TimeUS,Name,Value", units="s--", mults="F--")
        names = list(params)
        for n in names:
            if len(n.encode()) > 16:
                raise ValueError(f"parameter name {n!r} longer than 16 bytes")
        self.write_many("PARM", {"TimeUS": np.full(len(names), time_us, dtype=np.uint64),
                                 "Name": names, "Value": [float(params[n]) for n in names]})


# --------------------------------------------------------------------------------------------
# demo flight
# --------------------------------------------------------------------------------------------

G = 9.80665
#: demo origin: a field near Austin, TX (where the real copter logs were flown)
DEMO_ORIGIN = (30.1557, -97.9575, 270.0)


def _smoothstep(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic 0→1 step s(x) = 10x³ − 15x⁴ + 6x⁵ and its first two derivatives (x clipped)."""
    x = np.clip(x, 0.0, 1.0)
    s = x ** 3 * (10 - 15 * x + 6 * x * x)
    ds = 30 * x * x * (1 - x) ** 2
    dds = 60 * x * (1 - x) * (1 - 2 * x)
    return s, ds, dds


def demo_trajectory(t: np.ndarray, duration_s: float = 60.0, *, alt_m: float = 20.0,
                    radius_m: float = 25.0) -> dict[str, np.ndarray]:
    """Smooth analytic quadcopter path in NED about the home point.

    Take-off to ``alt_m`` over the first 15 % of the flight, a circle of ``radius_m`` entered
    and left with a smooth angular-rate ramp in the middle 65 %, landing in the last 20 %:

    .. math::

        p(t) = r\\,(\\cos\\theta(t) - 1,\\; \\sin\\theta(t),\\; 0) + (0, 0, -h\\,s_{up}(t) + h\\,s_{dn}(t))

    with quintic steps ``s`` (continuous acceleration). Returns position, velocity and
    acceleration (NED, m, m/s, m/s²) and the heading (rad; the nose turns with θ).
    """
    t = np.asarray(t, dtype=np.float64)
    T = float(duration_s)
    t_up, t_c0, t_c1, t_dn = 0.15 * T, 0.18 * T, 0.78 * T, 0.80 * T
    su, dsu, ddsu = _smoothstep((t - 0.02 * T) / (t_up - 0.02 * T))
    sd, dsd, ddsd = _smoothstep((t - t_dn) / (0.97 * T - t_dn))
    k_up, k_dn = 1 / (t_up - 0.02 * T), 1 / (0.97 * T - t_dn)
    d = -alt_m * su + alt_m * sd
    vd = -alt_m * dsu * k_up + alt_m * dsd * k_dn
    ad = -alt_m * ddsu * k_up ** 2 + alt_m * ddsd * k_dn ** 2
    # angle θ(t): integral of a smooth rate ramp, one full turn between t_c0 and t_c1
    sc, dsc, ddsc = _smoothstep((t - t_c0) / (t_c1 - t_c0))
    kc = 1 / (t_c1 - t_c0)
    th = 2 * np.pi * sc
    w = 2 * np.pi * dsc * kc
    wd = 2 * np.pi * ddsc * kc * kc
    c, s = np.cos(th), np.sin(th)
    n = radius_m * (c - 1)
    e = radius_m * s
    vn, ve = -radius_m * s * w, radius_m * c * w
    an = -radius_m * (c * w * w + s * wd)
    ae = radius_m * (-s * w * w + c * wd)
    # the nose turns with the circle angle (smooth, one full turn): yaw = θ
    return {"pos": np.stack([n, e, d], -1), "vel": np.stack([vn, ve, vd], -1),
            "acc": np.stack([an, ae, ad], -1), "yaw": th}


def _attitude(acc_ned: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Body->NED rotation of a multirotor: thrust axis (−z body) along a − g, heading ``yaw``."""
    f = acc_ned - np.array([0.0, 0.0, G])  # specific force, NED
    zb = -f / np.linalg.norm(f, axis=-1, keepdims=True)
    xc = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], -1)
    yb = np.cross(zb, xc)
    yb /= np.linalg.norm(yb, axis=-1, keepdims=True)
    xb = np.cross(yb, zb)
    return np.stack([xb, yb, zb], axis=-1)  # columns are body axes in NED


def write_demo_flight(path: str | os.PathLike | BinaryIO, *, seed: int = 0,
                      duration_s: float = 60.0) -> dict:
    """Write a tiny, physically consistent quadcopter DataFlash log (< 1 MB).

    Take-off to 20 m, one 25 m circle, landing, from :func:`demo_trajectory`. Rates: IMU 50 Hz,
    GPS 5 Hz, ATT/BARO/MAG/RCIN/RCOU/RFND/XKF1 10 Hz; MODE changes (STABILIZE → LOITER →
    CIRCLE → LAND), EV arm/disarm, PARM, MSG and ORGN records; modern format with
    FMTU/UNIT/MULT. The geoid is taken as the ellipsoid (GPS ``Alt`` = WGS-84 height), and
    latitude/longitude come from the exact WGS-84 NED->geodetic conversion
    (:func:`pipeline.frames.geodesy.ned_to_geodetic`) about :data:`DEMO_ORIGIN`.

    Sensor noise (seeded through ``np.random.default_rng(seed)``): gyro 0.005 rad/s, accel
    0.05 m/s², baro 0.1 m, GPS 0.3 m horizontal, mag 2 mGauss.

    Returns
    -------
    dict
        Summary: ``duration_s``, ``records`` (per type), ``origin`` and ``seed``.
    """
    from ..frames.geodesy import ned_to_geodetic
    from ..frames.rotations import dcm_to_euler, dcm_to_quat, quat_conj, quat_multiply

    rng = np.random.default_rng(seed)
    T = float(duration_s)
    boot_us = 2_000_000  # log starts 2 s after boot, like a real vehicle
    lat0, lon0, h0 = DEMO_ORIGIN

    def grid(rate):
        t = np.arange(0.0, T, 1.0 / rate)
        return t, (boot_us + np.rint(t * 1e6)).astype(np.uint64)

    counts: dict[str, int] = {}
    with DataFlashWriter(path) as w:
        w.define("PARM", PARM_TYPE, "QNf", "TimeUS,Name,Value", units="s--", mults="F--")
        w.define("MSG", 130, "QZ", "TimeUS,Message", units="s-", mults="F-")
        w.define("GPS", 131, "QBIHBcLLefffB", "TimeUS,Status,GMS,GWk,NSats,HDop,Lat,Lng,Alt,Spd,GCrs,VZ,U",
                 units="s---SmDUmnhn-", mults="F---0BGGB000-")
        w.define("IMU", 132, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ",
                 units="sEEEooo", mults="F000000")
        w.define("ATT", 133, "QccccCC", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw",
                 units="sddddhh", mults="FBBBBBB")
        w.define("BARO", 134, "QffcB", "TimeUS,Alt,Press,Temp,Health", units="smPO-", mults="F00B-")
        w.define("MAG", 135, "Qhhh", "TimeUS,MagX,MagY,MagZ", units="sGGG", mults="FCCC")
        w.define("RCIN", 136, "QHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8",
                 units="sYYYYYYYY", mults="F00000000")
        w.define("RCOU", 137, "QHHHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8",
                 units="sYYYYYYYY", mults="F00000000")
        w.define("MODE", 138, "QMBB", "TimeUS,Mode,ModeNum,Rsn", units="s---", mults="F---")
        w.define("EV", 139, "QB", "TimeUS,Id", units="s-", mults="F-")
        w.define("RFND", 140, "QBCBB", "TimeUS,Instance,Dist,Stat,Orient", units="s#m--", mults="F-B--")
        w.define("XKF1", 141, "QBccCffffff", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,PN,PE,PD",
                 units="s#ddhnnnmmm", mults="F-BBB000000")
        w.define("ORGN", 142, "QBLLe", "TimeUS,Type,Lat,Lng,Alt", units="s#DUm", mults="F-GGB")

        params = {"INS_ACCEL_FILTER": 20.0, "INS_GYRO_FILTER": 20.0, "RNGFND1_MIN_CM": 20.0,
                  "RNGFND1_MAX_CM": 700.0, "RNGFND1_ORIENT": 25.0, "FRAME_CLASS": 1.0,
                  "DEMO_SEED": float(seed)}
        w.write_params(params, time_us=boot_us)
        w.write("MSG", TimeUS=boot_us, Message="ArduCopter V4.5.0 (uavpipe demo flight)")
        w.write("MSG", TimeUS=boot_us, Message="Frame: QUAD/X")
        w.write("ORGN", TimeUS=boot_us, Type=0, Lat=lat0, Lng=lon0, Alt=h0)
        counts["PARM"] = len(params)
        counts["MSG"] = 2
        counts["ORGN"] = 1

        # IMU from the exact trajectory; gyro from the attitude's finite rotation per step
        t_i, us_i = grid(50)
        tr = demo_trajectory(t_i, T)
        R = _attitude(tr["acc"], tr["yaw"])
        q = dcm_to_quat(R)
        dq = quat_multiply(quat_conj(q[:-1]), q[1:])
        dq *= np.sign(dq[:, :1] + (dq[:, :1] == 0))
        omega = 2 * dq[:, 1:] * 50.0
        omega = np.vstack([omega, omega[-1:]])
        f_body = np.einsum("nji,nj->ni", R, tr["acc"] - np.array([0.0, 0.0, G]))
        gyr = omega + rng.normal(0, 0.005, omega.shape)
        acc = f_body + rng.normal(0, 0.05, f_body.shape)
        imu = {"TimeUS": us_i, "GyrX": gyr[:, 0], "GyrY": gyr[:, 1], "GyrZ": gyr[:, 2],
               "AccX": acc[:, 0], "AccY": acc[:, 1], "AccZ": acc[:, 2]}

        # 10 Hz streams
        t10, us10 = grid(10)
        tr10 = demo_trajectory(t10, T)
        R10 = _attitude(tr10["acc"], tr10["yaw"])
        roll, pitch, yaw = dcm_to_euler(R10)
        roll_d, pitch_d = np.rad2deg(roll), np.rad2deg(pitch)
        yaw_d = np.mod(np.rad2deg(yaw), 360.0)
        att = {"TimeUS": us10, "DesRoll": roll_d, "Roll": roll_d, "DesPitch": pitch_d,
               "Pitch": pitch_d, "DesYaw": yaw_d, "Yaw": yaw_d}
        alt = -tr10["pos"][:, 2]
        press = 101325.0 * (1 - 2.25577e-5 * (h0 + alt)) ** 5.25588
        baro = {"TimeUS": us10, "Alt": alt + rng.normal(0, 0.1, len(alt)), "Press": press,
                "Temp": np.full(len(alt), 31.5), "Health": np.ones(len(alt), np.uint8)}
        b_ned = np.array([280.0, 45.0, 430.0])  # mGauss, mid-latitude field
        m_body = np.einsum("nji,j->ni", R10, b_ned) + rng.normal(0, 2.0, (len(t10), 3))
        mag = {"TimeUS": us10, "MagX": np.rint(m_body[:, 0]), "MagY": np.rint(m_body[:, 1]),
               "MagZ": np.rint(m_body[:, 2])}
        thr = np.clip(1100 + 400 * np.linalg.norm(tr10["acc"] - [0, 0, G], axis=1) / G, 1000, 2000)
        armed = (t10 >= 0.01 * T) & (t10 < 0.985 * T)
        thr = np.where(armed, thr, 1000.0)
        rc = {"TimeUS": us10, "C1": np.rint(1500 + 500 * roll_d / 45).astype(np.uint16),
              "C2": np.rint(1500 - 500 * pitch_d / 45).astype(np.uint16),
              "C3": np.rint(thr).astype(np.uint16), "C4": np.full(len(t10), 1500, np.uint16)}
        for k in range(5, 9):
            rc[f"C{k}"] = np.full(len(t10), 1500 if k != 5 else 1165, np.uint16)
        mot = np.rint(np.clip(thr[:, None] + np.array([1, -1, 1, -1]) * 20 * roll_d[:, None] / 45, 1000, 2000))
        rcou = {"TimeUS": us10, **{f"C{k + 1}": mot[:, k].astype(np.uint16) for k in range(4)},
                **{f"C{k}": np.zeros(len(t10), np.uint16) for k in range(5, 9)}}
        agl = alt + 0.1  # sensor 10 cm above the skids
        rng_ok = (agl >= 0.2) & (agl <= 7.0)
        rfnd = {"TimeUS": us10, "Instance": np.zeros(len(t10), np.uint8),
                "Dist": np.where(rng_ok, agl + rng.normal(0, 0.02, len(agl)), np.where(agl < 0.2, 0.0, 7.0)),
                "Stat": np.where(rng_ok, 4, np.where(agl < 0.2, 2, 3)).astype(np.uint8),
                "Orient": np.full(len(t10), 25, np.uint8)}
        xkf = {"TimeUS": us10, "C": np.zeros(len(t10), np.uint8), "Roll": roll_d, "Pitch": pitch_d,
               "Yaw": yaw_d, "VN": tr10["vel"][:, 0], "VE": tr10["vel"][:, 1], "VD": tr10["vel"][:, 2],
               "PN": tr10["pos"][:, 0], "PE": tr10["pos"][:, 1], "PD": tr10["pos"][:, 2]}

        # GPS 5 Hz
        t5, us5 = grid(5)
        tr5 = demo_trajectory(t5, T)
        pn = tr5["pos"] + np.column_stack([rng.normal(0, 0.3, (len(t5), 2)), rng.normal(0, 0.5, len(t5))])
        lat, lon, h = ned_to_geodetic(pn[:, 0], pn[:, 1], pn[:, 2], lat0, lon0, h0)
        vn, ve, vd = tr5["vel"].T
        gps_week, gms0 = 2345, 302_400_000
        gps = {"TimeUS": us5, "Status": np.full(len(t5), 3, np.uint8),
               "GMS": (gms0 + np.rint(t5 * 1000)).astype(np.uint32),
               "GWk": np.full(len(t5), gps_week, np.uint16), "NSats": np.full(len(t5), 14, np.uint8),
               "HDop": np.full(len(t5), 0.7), "Lat": lat, "Lng": lon, "Alt": h,
               "Spd": np.hypot(vn, ve), "GCrs": np.mod(np.rad2deg(np.arctan2(ve, vn)), 360.0),
               "VZ": vd, "U": np.ones(len(t5), np.uint8)}

        # modes and arming
        mode_t = np.array([0.0, 0.16 * T, 0.18 * T, 0.80 * T])
        mode_n = np.array([0, 5, 7, 9])
        mode = {"TimeUS": (boot_us + np.rint(mode_t * 1e6)).astype(np.uint64), "Mode": mode_n.astype(np.int8),
                "ModeNum": mode_n.astype(np.uint8), "Rsn": np.ones(4, np.uint8)}
        ev = {"TimeUS": (boot_us + np.rint(np.array([0.01, 0.985]) * T * 1e6)).astype(np.uint64),
              "Id": np.array([10, 11], np.uint8)}
        batches = {"MODE": mode, "EV": ev, "IMU": imu, "ATT": att, "BARO": baro, "MAG": mag,
                   "RCIN": rc, "RCOU": rcou, "RFND": rfnd, "XKF1": xkf, "GPS": gps}
        w.write_merged(batches)
        counts.update({k: len(v["TimeUS"]) for k, v in batches.items()})
    return {"duration_s": T, "records": counts, "origin": {"lat_deg": lat0, "lon_deg": lon0,
                                                          "alt_wgs84_m": h0}, "seed": seed}
