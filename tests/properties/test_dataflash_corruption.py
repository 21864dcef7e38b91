"""Corrupt DataFlash input: every case ends within 10 s in a clear IngestError naming the file,
or in the valid records with the drops counted in ``meta['diagnostics']``.

Cases (hypothesis, modest example counts): truncation at random offsets, random bytes, garbage
spliced into (inserted into, or written over) a valid log, bit flips, an empty file, a tlog
renamed ``.bin``, records of unknown types. Sources: real logs from ../shared/realdata (read,
modified in memory, written to tmp_path only) and small logs written by pipeline.io.dataflash.writer.
For spliced garbage, >= 99 % of the oracle's records outside the splice are recovered among the
types whose FMT survived; the others appear as ``format_lost:<type id>`` drops.
"""

from __future__ import annotations

import io
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings, strategies as st

from helpers import REALDATA, TEST_SEED
from pipeline.io import dataflash as df
from pipeline.io.base import FlightLog, IngestError
from pipeline.io.dataflash.writer import DataFlashWriter
from pipeline.io.registry import detect, read_log
from pipeline.simulate.demo import write_demo_flight

# no shrinking phase: a failure is reported as found (shrinking a MB-sized case takes minutes)
SETTINGS = dict(deadline=None, derandomize=True, print_blob=True,
                phases=[Phase.explicit, Phase.reuse, Phase.generate],
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

REAL = {"small": "pymavlink_test_bin/test.BIN",
        "copter": "ap_copter_forum_crash_pool/log_0036_mechanical_failure.bin",
        "old": "ap_copter313_austin_4flights/2014-10-18_20-44-05.bin"}

_CACHE: dict[str, bytes] = {}


def source(kind: str) -> bytes:
    """Bytes of a clean log: ``demo`` (our writer, 20 s) or a real log (skip if absent)."""
    if kind not in _CACHE:
        if kind == "demo":
            buf = io.BytesIO()
            write_demo_flight(buf, seed=TEST_SEED % 1000, duration_s=20.0)
            _CACHE[kind] = buf.getvalue()
        else:
            from helpers import realdata_file

            _CACHE[kind] = realdata_file(REAL[kind]).read_bytes()
    return _CACHE[kind]


# without ../shared/realdata only the synthetic log is drawn (real cases skip, or fail under
# UAVPIPE_REQUIRE_SHARED=1, in test_real_sources_present)
_HAVE_REAL = all((REALDATA / r).exists() for r in REAL.values())
SOURCES = st.sampled_from(["demo", "small", "copter", "old"] if _HAVE_REAL else ["demo"])


def test_real_sources_present():
    from helpers import realdata_file

    for rel in REAL.values():
        assert realdata_file(rel).stat().st_size > 0


def ingest(path: Path):
    """read_log with the contract checked: <= 10 s, and FlightLog or IngestError naming the file."""
    t = time.perf_counter()
    try:
        out = read_log(path)
    except IngestError as exc:
        out = exc
        assert str(path) in str(exc) and exc.reason
    assert time.perf_counter() - t <= 10.0
    return out


def records(data: bytes, res: df.DecodeResult) -> Counter:
    """Multiset of decoded records as (type, raw bytes)."""
    c = Counter()
    for name, offs in res.offsets.items():
        ln = res.formats[name].length
        for o in offs.tolist():
            c[data[o:o + ln]] += 1
    return c


def assert_accounted(n_bytes: int, res: df.DecodeResult) -> None:
    """Every byte is in a decoded record or counted as skipped."""
    used = sum(len(o) * res.formats[k].length for k, o in res.offsets.items())
    assert used + res.diagnostics["bytes_skipped"] == n_bytes


# --------------------------------------------------------------------------------------------

@settings(max_examples=12, **SETTINGS)
@given(kind=SOURCES, frac=st.floats(0.0, 1.0, exclude_max=True))
def test_truncated_at_random_offsets(tmp_path_factory, kind, frac):
    data = source(kind)
    cut = int(frac * len(data))
    p = tmp_path_factory.mktemp("trunc") / "cut.bin"
    p.write_bytes(data[:cut])
    out = ingest(p)
    if isinstance(out, IngestError):
        if "no data: every stream is empty" in out.reason:
            # cut inside the header: only format-describing records end before it
            counts = df.decode(data[:cut]).diagnostics["record_counts"]
            assert set(counts) <= {"FMT", "FMTU", "UNIT", "MULT"}, counts
            return
        assert cut < 4096  # only when no FMT (or nothing at all) survives
        return
    assert isinstance(out, FlightLog)
    clean, cutres = df.decode(data), df.decode(data[:cut])
    assert_accounted(cut, cutres)
    # the decoded records are exactly the clean log's records that end before the cut
    for name, offs in clean.offsets.items():
        ln = clean.formats[name].length
        expect = int(np.sum(offs + ln <= cut))
        assert cutres.diagnostics["record_counts"].get(name, 0) == expect, name
    assert out.meta["diagnostics"]["record_counts"] == cutres.diagnostics["record_counts"]


@settings(max_examples=15, **SETTINGS)
@given(blob=st.binary(min_size=1, max_size=4096))
def test_random_bytes_give_a_clear_error(tmp_path_factory, blob):
    p = tmp_path_factory.mktemp("rnd") / "random.bin"
    p.write_bytes(blob)
    out = ingest(p)
    assert isinstance(out, IngestError) or out.meta["reader"] != "dataflash"
    with pytest.raises(IngestError, match="random.bin"):
        read_log(p, fmt="dataflash")


def test_empty_file(tmp_path):
    p = tmp_path / "empty.bin"
    p.write_bytes(b"")
    with pytest.raises(IngestError, match=r"empty\.bin.*empty"):
        read_log(p)
    with pytest.raises(IngestError, match=r"empty\.bin.*empty"):
        read_log(p, fmt="dataflash")


@pytest.fixture(scope="module")
def oracle_counts():
    """pymavlink's record counts on the clean sources (our clean decode must equal them, so its
    record offsets define 'the oracle's records')."""
    from pymavlink import mavutil

    out = {}
    for kind in ("demo", "small", "copter", "old"):
        try:
            data = source(kind)
        except pytest.skip.Exception:
            continue
        import tempfile

        with tempfile.NamedTemporaryFile(suffix=".bin") as fh:
            fh.write(data)
            fh.flush()
            m = mavutil.mavlink_connection(fh.name)
            c = Counter()
            while (x := m.recv_msg()) is not None:
                c[x.get_type()] += 1
            m.close()
        assert dict(c) == df.decode(data).diagnostics["record_counts"], kind
        out[kind] = c
    return out


@settings(max_examples=16, **SETTINGS)
@given(kind=SOURCES, frac=st.floats(0.0, 1.0),
       length=st.integers(1, 8000), overwrite=st.booleans(), seed=st.integers(0, 2 ** 32 - 1))
def test_garbage_spliced_into_a_valid_log(tmp_path_factory, oracle_counts, kind, frac, length,
                                          overwrite, seed):
    data = source(kind)
    assert kind in oracle_counts or not _HAVE_REAL
    garbage = np.random.default_rng(seed).integers(0, 256, length, dtype=np.uint8).tobytes()
    a = int(frac * len(data))
    b = min(a + length, len(data)) if overwrite else a
    spliced = data[:a] + garbage + data[b:]
    p = tmp_path_factory.mktemp("splice") / "spliced.bin"
    p.write_bytes(spliced)
    out = ingest(p)
    clean = df.decode(data)
    try:
        res = df.decode(spliced)
        survived = set(res.type_formats)
    except IngestError:
        res, survived = None, set()
    # the oracle's records outside the splice, split by whether their type's FMT survived
    # (FMT's own layout is fixed by the format, so it is never lost)
    lost = {f.type_id for f in clean.type_formats.values()} - survived - {df.FMT_TYPE}
    outside = Counter()
    lost_outside = Counter()
    for name, offs in clean.offsets.items():
        f = clean.formats[name]
        keep = (offs + f.length <= a) | (offs >= b)
        if f.type_id in lost:
            lost_outside[f.type_id] += int(keep.sum())
            continue
        for o in offs[keep].tolist():
            outside[data[o:o + f.length]] += 1
    if isinstance(out, IngestError):
        # only acceptable when the splice destroyed every FMT record
        assert res is None and "FMT" in out.reason
        return
    assert_accounted(len(spliced), res)
    got = records(spliced, res)
    recovered = sum(min(n, got[k]) for k, n in outside.items())
    total = sum(outside.values())
    assert recovered >= 0.99 * total, (recovered, total)
    drops = out.meta["diagnostics"]["records_dropped"]
    for t, n in lost_outside.items():
        if n:
            assert drops.get(f"format_lost:{t}", 0) >= 0.9 * n, (t, n, drops)
    if not overwrite and garbage[:2] != b"\xa3\x95":
        # inserted bytes never fit the record chain (no header), so they are counted; garbage
        # written over part of one record body is undetectable (DataFlash has no checksum)
        assert out.meta["diagnostics"]["bytes_skipped"] >= 1


@settings(max_examples=12, **SETTINGS)
@given(kind=SOURCES, data=st.data())
def test_bit_flips(tmp_path_factory, kind, data):
    clean = source(kind)
    n_flips = data.draw(st.integers(1, 24), label="n_flips")
    bits = data.draw(st.lists(st.integers(0, 8 * len(clean) - 1), min_size=n_flips, max_size=n_flips),
                     label="bits")
    buf = np.frombuffer(clean, dtype=np.uint8).copy()
    for bit in bits:
        buf[bit // 8] ^= np.uint8(1 << (bit % 8))
    p = tmp_path_factory.mktemp("flip") / "flipped.bin"
    p.write_bytes(buf.tobytes())
    out = ingest(p)
    if isinstance(out, IngestError):
        return
    res = df.decode(buf.tobytes())
    assert_accounted(len(buf), res)
    got = sum(res.diagnostics["record_counts"].values())
    want = sum(df.decode(clean).diagnostics["record_counts"].values())
    d = out.meta["diagnostics"]
    if got < want:  # every lost record shows up as skipped bytes or a counted drop
        assert d["bytes_skipped"] > 0 or d["records_dropped"]
        assert out.meta["status"] == "partial"
    # a flip destroys at most a few records, or one type's FMT: then that type's records are
    # counted as format_lost
    lost = sum(v for k, v in d["records_dropped"].items() if k.startswith("format_lost"))
    assert got + lost >= want - 40 * n_flips


def _tlog_bytes(n: int = 200) -> bytes:
    """A synthetic MAVLink v2 telemetry log: 8-byte big-endian µs UNIX time + frame."""
    from pymavlink.dialects.v20 import ardupilotmega as mav

    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    out = bytearray()
    t0 = 1_700_000_000_000_000
    for k in range(n):
        if k % 4 == 0:
            msg = m.heartbeat_encode(2, 3, 81, 5, 4)
        else:
            msg = m.attitude_encode(k * 100, 0.1, -0.2, 1.0 + k * 1e-3, 0.01, 0.0, 0.02)
        out += (t0 + k * 50_000).to_bytes(8, "big") + msg.pack(m)
    return bytes(out)


@pytest.mark.parametrize("which", ["synthetic", "real"])
def test_tlog_renamed_bin_never_reaches_the_dataflash_decoder(tmp_path, monkeypatch, which):
    if which == "synthetic":
        blob = _tlog_bytes()
    else:
        from helpers import realdata_file

        src = realdata_file("tlog_phoenix_ubc_quad/phoenix_mission1_2018-09-17_16-44-06.tlog")
        blob = src.read_bytes()[:200_000]
    p = tmp_path / "telemetry.bin"
    p.write_bytes(blob)
    assert df.DataFlashReader.sniff(p, blob[:65536]) is None

    def boom(*a, **k):  # the DataFlash decoder must never see this file
        raise AssertionError("tlog routed to the DataFlash decoder")

    monkeypatch.setattr(df, "decode", boom)
    try:
        reader, _ = detect(p)
    except IngestError as exc:
        assert "telemetry.bin" in str(exc)
        return
    assert reader.name != "dataflash"
    out = ingest(p)
    if isinstance(out, FlightLog):
        assert out.meta["reader"] == reader.name


def _with_unknown_types(seed: int) -> tuple[bytes, Counter]:
    """A small log with records of type ids that have no FMT, interleaved with known ones."""
    rng = np.random.default_rng(seed)
    buf = io.BytesIO()
    with DataFlashWriter(buf) as w:
        w.define("IMU", 131, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        w.define("BARO", 132, "Qffc", "TimeUS,Alt,Press,Temp")
    out = bytearray(buf.getvalue())
    unknown = Counter()
    imu = io.BytesIO()
    with DataFlashWriter(imu) as w2:
        w2.define("IMU", 131, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        head = len(imu.getvalue())
        for k in range(300):
            w2.write("IMU", TimeUS=1000 * k, GyrX=float(k), AccZ=-9.8)
    rec = imu.getvalue()[head:]
    ln = len(rec) // 300
    for k in range(300):
        out += rec[k * ln:(k + 1) * ln]
        if rng.random() < 0.2:
            t = int(rng.choice([7, 42, 200]))
            body = rng.integers(0, 256, int(rng.integers(5, 60)), dtype=np.uint8)
            body[body == 0xA3] = 0  # keep the unknown body free of false headers
            out += bytes([0xA3, 0x95, t]) + body.tobytes()
            unknown[t] += 1
    return bytes(out), unknown


@settings(max_examples=8, **SETTINGS)
@given(seed=st.integers(0, 2 ** 32 - 1))
def test_unknown_message_types_are_skipped_and_counted(tmp_path_factory, seed):
    blob, unknown = _with_unknown_types(seed)
    p = tmp_path_factory.mktemp("unk") / "unknown.bin"
    p.write_bytes(blob)
    out = ingest(p)
    assert isinstance(out, FlightLog)
    d = out.meta["diagnostics"]
    assert d["record_counts"]["IMU"] == 300
    assert out["imu"]["gyr_x_radps"].tolist() == [float(k) for k in range(300)]
    for t, n in unknown.items():
        assert d["records_dropped"][f"format_lost:{t}"] == n
    if unknown:
        assert d["bytes_skipped"] > 0 and out.meta["status"] == "partial"


def test_a_signalling_nan_in_a_record_is_read_as_nan_without_a_console_warning(tmp_path):
    # random bytes hold signalling NaNs (exponent all ones, quiet bit clear); their float32 ->
    # float64 cast raised NumPy's "invalid value encountered in cast" (an error under pytest)
    import struct

    buf = io.BytesIO()
    with DataFlashWriter(buf) as w:
        w.define("IMU", 131, "Qffffff", "TimeUS,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
        for k in range(50):
            w.write("IMU", TimeUS=1000 * k, GyrX=0.5, AccZ=-9.8)
    data = bytearray(buf.getvalue())
    snan = struct.pack("<I", 0x7F800001)
    at = data.index(struct.pack("<f", 0.5), len(data) // 2)
    data[at:at + 4] = snan
    p = tmp_path / "snan.bin"
    p.write_bytes(bytes(data))
    log = read_log(p)
    gx = log["imu"]["gyr_x_radps"].to_numpy()
    assert np.isnan(gx).sum() == 1 and np.count_nonzero(gx == 0.5) == 49
