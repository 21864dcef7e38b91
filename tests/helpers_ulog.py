"""A minimal PX4 ULog *writer* for tests (import as ``from helpers_ulog import ...``).

Writes the ULog binary format (docs.px4.io "ULog File Format"): the 16-byte header
(``ULog\\x01\\x12\\x35``, version, uint64 start timestamp µs), then messages of
``uint16 msg_size, uint8 msg_type, payload``:

* ``B`` FLAG_BITS (8 compat + 8 incompat flag bytes + 3 uint64 appended offsets), first;
* ``F`` FORMAT ``"name:type field;type field;..."``, ``I`` INFO, ``P`` PARAMETER;
* ``A`` ADD_LOGGED (uint8 multi_id, uint16 msg_id, name);
* ``D`` DATA (uint16 msg_id + packed fields), ``L`` LOGGING (uint8 level, uint64 ts, text),
  ``O`` DROPOUT (uint16 duration ms).


Fields are packed without padding in declaration order, as pyulog reads them. Only what the
reader tests need; pyulog is the oracle that the output parses.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

_TYPES = {
    "int8_t": "b", "uint8_t": "B", "bool": "?", "char": "c",
    "int16_t": "h", "uint16_t": "H", "int32_t": "i", "uint32_t": "I",
    "int64_t": "q", "uint64_t": "Q", "float": "f", "double": "d",
}
#: PX4 writes the syslog level as an ASCII digit ('0' emergency ... '7' debug)
LOG_LEVELS = {"EMERG": 0, "ALERT": 1, "CRIT": 2, "ERR": 3, "WARNING": 4, "NOTICE": 5, "INFO": 6, "DEBUG": 7}


def _msg(kind: str, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), ord(kind)) + payload


class ULogWriter:
    """Build a ULog file in memory.

    Parameters
    ----------
    start_us : int
        Header timestamp (µs since boot) = the logger start.
    """

    def __init__(self, start_us: int = 1_000_000):
        self.start_us = int(start_us)
        self._defs: list[bytes] = []
        self._data: list[bytes] = []
        self._formats: dict[str, list[tuple[str, str, int]]] = {}
        self._ids: dict[tuple[str, int], int] = {}

    # --- definitions -----------------------------------------------------------------------
    def add_format(self, name: str, fields: list[tuple[str, str]]) -> None:
        """``fields``: ``(type, name)`` with ``type`` like ``float`` or ``float[3]``;
        the first field must be ``uint64_t timestamp``."""
        parsed = []
        for typ, fname in fields:
            n = 1
            if "[" in typ:
                typ, n = typ[:-1].split("[")
                n = int(n)
            parsed.append((typ, fname, n))
        self._formats[name] = parsed
        spec = "".join(f"{t}{f'[{n}]' if n > 1 else ''} {f};" for t, f, n in parsed)
        self._defs.append(_msg("F", f"{name}:{spec}".encode()))

    def add_info(self, key: str, value: str) -> None:
        v = value.encode()
        k = f"char[{len(v)}] {key}".encode()
        self._defs.append(_msg("I", bytes([len(k)]) + k + v))

    def add_param(self, key: str, value: float | int) -> None:
        if isinstance(value, int):
            k, v = f"int32_t {key}".encode(), struct.pack("<i", value)
        else:
            k, v = f"float {key}".encode(), struct.pack("<f", value)
        self._defs.append(_msg("P", bytes([len(k)]) + k + v))

    # --- data section --------------------------------------------------------------------------
    def add_logged(self, name: str, multi_id: int = 0) -> int:
        msg_id = len(self._ids)
        self._ids[(name, multi_id)] = msg_id
        self._data.append(_msg("A", struct.pack("<BH", multi_id, msg_id) + name.encode()))
        return msg_id

    def data(self, name: str, multi_id: int = 0, **values) -> None:
        """One DATA message; every field must be given (arrays as sequences)."""
        msg_id = self._ids[(name, multi_id)]
        buf = bytearray(struct.pack("<H", msg_id))
        for typ, fname, n in self._formats[name]:
            v = values[fname]
            code = _TYPES[typ]
            if n == 1:
                buf += struct.pack("<" + code, _py(v))
            else:
                buf += struct.pack(f"<{n}{code}", *list(v))
        self._data.append(_msg("D", bytes(buf)))

    def log(self, level: str, timestamp_us: int, text: str) -> None:
        self._data.append(_msg("L", struct.pack("<BQ", ord(str(LOG_LEVELS[level])), timestamp_us) + text.encode()))

    def dropout(self, duration_ms: int) -> None:
        self._data.append(_msg("O", struct.pack("<H", duration_ms)))

    def topic(self, name: str, fields: list[tuple[str, str]], rows: dict[str, np.ndarray],
              multi_id: int = 0) -> None:
        """Define (once), subscribe and write a whole table: ``rows[field]`` arrays of equal
        length (array fields as 2-D ``(n, k)``)."""
        if name not in self._formats:
            self.add_format(name, fields)
        self.add_logged(name, multi_id)
        n = len(rows["timestamp"])
        for i in range(n):
            self.data(name, multi_id, **{k: (v[i] if np.ndim(v) == 1 else v[i].tolist())
                                         for k, v in rows.items()})

    def to_bytes(self) -> bytes:
        header = b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", self.start_us)
        flags = _msg("B", bytes(8) + bytes(8) + struct.pack("<3Q", 0, 0, 0))
        return header + flags + b"".join(self._defs) + b"".join(self._data)

    def write(self, path: str | Path) -> Path:
        p = Path(path)
        p.write_bytes(self.to_bytes())
        return p


def _py(v):
    if isinstance(v, np.generic):
        return v.item()
    return v


#: PX4's sensor_combined fields (the IMU topic the ULog reader maps to ``imu``)
SENSOR_COMBINED = [("uint64_t", "timestamp"), ("float[3]", "gyro_rad"), ("uint32_t", "gyro_integral_dt"),
                   ("int32_t", "accelerometer_timestamp_relative"), ("float[3]", "accelerometer_m_s2"),
                   ("uint32_t", "accelerometer_integral_dt")]


def add_sensor_combined(w: "ULogWriter", n: int, rng: np.random.Generator, t0_us: int = 1_000_000) -> None:
    """``n`` sensor_combined samples at 250 Hz from ``t0_us`` on ``w``: a level vehicle at rest
    (gyro noise 0.01 rad/s, specific force (0, 0, −9.81) ± 0.05 m/s²)."""
    w.topic("sensor_combined", SENSOR_COMBINED, {
        "timestamp": t0_us + np.arange(n, dtype=np.uint64) * 4_000,
        "gyro_rad": rng.normal(0, 0.01, (n, 3)).astype(np.float32),
        "gyro_integral_dt": np.full(n, 4_000, np.uint32),
        "accelerometer_timestamp_relative": np.zeros(n, np.int32),
        "accelerometer_m_s2": rng.normal([0, 0, -9.81], 0.05, (n, 3)).astype(np.float32),
        "accelerometer_integral_dt": np.full(n, 4_000, np.uint32)})
