"""Corrupt tlogs (hypothesis): truncation, random bytes, spliced garbage, bit flips, empty and
foreign files. Built from a record-aligned prefix of the real tlog and from small synthetic
tlogs written with pymavlink's encoder (nothing is committed). Every case must end within
10 s in either an IngestError naming the file and the reason, or the valid records with the
losses counted in ``meta['diagnostics']``; never another exception."""

from __future__ import annotations

import functools
import os
import time
from collections import Counter

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import pymavlink_messages, realdata_file
from pipeline.io import registry
from pipeline.io.base import IngestError
from pipeline.io.tlog import TlogReader, encode_tlog

REAL_TLOG = "tlog_phoenix_ubc_quad/phoenix_mission1_2018-09-17_16-44-06.tlog"
REAL_PREFIX_BYTES = 16_000
T0_US = 1_650_000_000_000_000
CASE_LIMIT_S = 10.0

#: examples per (property, base); raise it for a one-off soak: UAVPIPE_FUZZ_EXAMPLES=500
N_EXAMPLES = int(os.environ.get("UAVPIPE_FUZZ_EXAMPLES", "8"))
SETTINGS = settings(max_examples=N_EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _oracle(data: bytes, tmp) -> list:
    """pymavlink's own tlog loop over ``data``: the messages and their framing times."""
    path = tmp / "oracle.tlog"
    path.write_bytes(data)
    return pymavlink_messages(path)


def _synthetic(mavlink1: bool) -> bytes:
    from pymavlink.dialects.v20 import ardupilotmega as v2

    m = v2.MAVLink(None)
    recs = []
    for k in range(12):
        t = T0_US + 100_000 * k
        recs += [
            (t, m.heartbeat_encode(2, 3, 1 | (128 if k > 5 else 0), k // 4, 4)),
            (t + 1, m.heartbeat_encode(6, 8, 0, 0, 4), 255, 190),
            (t + 2, m.attitude_encode(1000 + k, 0.01 * k, -0.02 * k, 0.1 * k, 0, 0, 0)),
            (t + 3, m.gps_raw_int_encode(10**6 + k, 3, 473977420 + k, 85455940 - k, 488000 + k,
                                         120, 180, 250 + k, 9000, 11, 536000, 800, 1200, 0, 0, 0)),
            (t + 4, m.scaled_imu_encode(1000 + k, k, -k, -1000, 2 * k, 0, -k, 200, -50, 420, 4100)),
            (t + 5, m.scaled_pressure_encode(1000 + k, 1013.25 - k, 0.0, 2100, 0)),
            (t + 6, m.servo_output_raw_encode(10**6 + k, 0, 1100 + k, 1200, 1300, 1400, 0, 0, 0, 0,
                                              0, 0, 0, 0, 0, 0, 0, 0)),
        ]
    return encode_tlog(recs, mavlink1=mavlink1)


@functools.lru_cache(maxsize=None)
def _real_prefix(path) -> bytes:
    """The first records of the real tlog up to ~16 kB, cut at a record boundary (found by
    walking the framing: 8-byte time + v1/v2 frame length)."""
    data = path.read_bytes()
    off = 0
    while off < REAL_PREFIX_BYTES:
        plen = data[off + 9]
        if data[off + 8] == 0xFE:
            off += 8 + 8 + plen
        else:
            off += 8 + 12 + plen + (13 if data[off + 10] & 1 else 0)
    return data[:off]


class Base(tuple):
    """(clean tlog bytes, record end offsets, per-type counts) with a short repr (hypothesis
    prints the arguments of a failing example)."""

    name = ""

    def __repr__(self):
        return f"<{self.name}: {len(self[0])} bytes, {len(self[1])} records>"


@pytest.fixture(params=["synth_v2", "synth_v1", "real"])
def base(request, tmp_path_factory):
    """(clean tlog bytes, record end offsets, per-type counts) from pymavlink's loop."""
    if request.param == "real":
        data = _real_prefix(realdata_file(REAL_TLOG))
    else:
        data = _synthetic(mavlink1=request.param == "synth_v1")
    msgs = _oracle(data, tmp_path_factory.mktemp("oracle"))
    assert msgs and not any(m.get_type() == "BAD_DATA" for m in msgs)
    ends, off = [], 0
    for m in msgs:
        off += 8 + len(m.get_msgbuf())
        ends.append(off)
    assert off == len(data)
    out = Base((data, ends, Counter(m.get_type() for m in msgs)))
    out.name = request.param
    return out


@functools.lru_cache(maxsize=None)
def _clean_log(name: str, data: bytes):
    """The base file's FlightLog, read once per base."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / f"{name}.tlog"
        path.write_bytes(data)
        return TlogReader().read(path)


def run_case(tmp_path, data: bytes, name: str = "case.tlog"):
    """Read ``data`` with the tlog reader; returns the FlightLog or the IngestError, after
    checking the invariants every outcome must satisfy."""
    path = tmp_path / name
    path.write_bytes(data)
    t = time.perf_counter()
    try:
        out = TlogReader().read(path)
    except IngestError as exc:
        out = exc
    elapsed = time.perf_counter() - t
    assert elapsed < CASE_LIMIT_S, f"{elapsed:.1f} s"
    if isinstance(out, IngestError):
        assert str(path) in str(out) and out.reason
        return out
    d = out.meta["diagnostics"]
    assert d["bytes_skipped"] + out.meta["mavlink"]["bytes_decoded"] == len(data)
    assert all(isinstance(v, int) and v > 0 for v in d["records_dropped"].values())
    assert sum(d["record_counts"].values()) >= 1
    if d["bytes_skipped"]:
        assert d["records_dropped"] or d["bytes_skipped"] < len(data)
    return out


# ---- truncation ---------------------------------------------------------------------------

@SETTINGS
@given(frac=st.floats(0.0, 1.0))
def test_truncated_at_random_offset(base, tmp_path, frac):
    data, ends, _ = base
    cut = round(frac * len(data))
    out = run_case(tmp_path, data[:cut])
    complete = sum(1 for e in ends if e <= cut)
    if complete == 0:
        assert isinstance(out, IngestError)
        assert ("empty file" if cut == 0 else "no valid MAVLink tlog record") in out.reason
        return
    d = out.meta["diagnostics"]
    assert sum(d["record_counts"].values()) == complete
    boundary = max(e for e in ends if e <= cut)
    if boundary == cut:
        assert d["records_dropped"] == {} and d["bytes_skipped"] == 0
    else:
        assert d["records_dropped"] == {"truncated": 1}
        assert d["bytes_skipped"] == cut - boundary
        assert out.meta["status"] == "ok"  # read_log turns it into "partial"


def test_truncated_counts_equal_pymavlink(base, tmp_path):
    """At a fixed mid-record cut, per-type counts equal pymavlink's on the same bytes."""
    data, ends, _ = base
    cut = (ends[len(ends) // 2] + ends[len(ends) // 2 + 1]) // 2
    out = run_case(tmp_path, data[:cut])
    oracle = Counter(m.get_type() for m in _oracle(data[:cut], tmp_path))
    oracle.pop("BAD_DATA", None)
    assert out.meta["diagnostics"]["record_counts"] == dict(oracle)


# ---- random bytes and foreign files -------------------------------------------------------

@settings(max_examples=3 * N_EXAMPLES, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(blob=st.binary(min_size=0, max_size=4096),
       prefix=st.sampled_from([b"", b"\xa3\x95", b"ULog\x01\x12\x35"]))
def test_random_bytes(tmp_path, blob, prefix):
    data = prefix + blob
    assert TlogReader.sniff(tmp_path / "x.tlog", data[:65536]) is None
    out = run_case(tmp_path, data)
    assert isinstance(out, IngestError)
    if not data:
        assert "empty file" in out.reason
    elif prefix == b"\xa3\x95":
        assert "DataFlash" in out.reason


def test_foreign_and_empty_files_through_registry(tmp_path):
    """read_log on junk: an IngestError naming the file and the reason, never a library traceback."""
    cases = {"empty.tlog": (b"", "empty file (0 bytes)"),
             "junk.tlog": (bytes(range(256)) * 8, "unrecognised log format (file starting 00 01 02"),
             "df.tlog": (b"\xa3\x95\x80\x80" + bytes(200), "not a DataFlash log: no valid FMT record")}
    for name, (data, reason) in cases.items():
        p = tmp_path / name
        p.write_bytes(data)
        t = time.perf_counter()
        with pytest.raises(IngestError) as exc:
            registry.read_log(p)
        assert str(exc.value).startswith(f"{p}: {reason}"), exc.value
        assert time.perf_counter() - t < CASE_LIMIT_S


# ---- garbage spliced into a valid tlog ----------------------------------------------------

@SETTINGS
@given(frac=st.floats(0.0, 1.0), garbage=st.binary(min_size=1, max_size=600))
def test_garbage_spliced(base, tmp_path, frac, garbage):
    data, ends, counts = base
    at = round(frac * len(data))
    out = run_case(tmp_path, data[:at] + garbage + data[at:])
    assert not isinstance(out, IngestError)
    d = out.meta["diagnostics"]
    starts = [0, *ends[:-1]]
    hit = [i for i, (s, e) in enumerate(zip(starts, ends)) if s < at < e]  # record split by it
    n = len(ends)
    got = sum(d["record_counts"].values())
    assert n - len(hit) <= got <= n
    assert d["bytes_skipped"] >= len(garbage)
    clean = _clean_log(base.name, data)
    if not hit:  # spliced between records: every sample comes back unchanged
        assert d["bytes_skipped"] == len(garbage)
        assert d["record_counts"] == dict(counts)
        for s in ("gps", "imu", "attitude", "control", "mode"):
            pd.testing.assert_frame_equal(out[s], clean[s])
    else:  # at most the one sample of the split record is missing
        for s in ("gps", "imu", "attitude", "control"):
            assert len(clean[s]) - 1 <= len(out[s]) <= len(clean[s])


# ---- bit flips ----------------------------------------------------------------------------

@SETTINGS
@given(data=st.data())
def test_bit_flips(base, tmp_path, data):
    clean, ends, counts = base
    k = data.draw(st.integers(1, 4), label="n_flips")
    bits = data.draw(st.lists(st.integers(0, 8 * len(clean) - 1), min_size=k, max_size=k,
                              unique=True), label="bits")
    buf = bytearray(clean)
    for b in bits:
        buf[b // 8] ^= 1 << (b % 8)
    out = run_case(tmp_path, bytes(buf))
    n = len(ends)
    if isinstance(out, IngestError):  # only possible when every record was hit
        assert n <= k
        return
    d = out.meta["diagnostics"]
    got = sum(d["record_counts"].values())
    assert n - k <= got <= n  # each flip costs at most the one record it lands in
    hit = {next(i for i, e in enumerate(ends) if b // 8 < e) for b in bits}
    lost = n - got
    assert lost <= len(hit)
    if lost:
        assert d["bytes_skipped"] > 0
    if lost and k == 1:
        # one flip leaves either the framing time plausible or the frame CRC-valid, so the
        # damaged record is recognised and counted by reason (several flips in one record,
        # e.g. time and start byte, can leave nothing but skipped bytes)
        assert sum(d["records_dropped"].values()) == 1


def test_flipped_high_timestamp_bit_is_dropped_not_t0(tmp_path, base):
    """A flipped high bit in the first record's time (still 2000-2100) must not become t0."""
    clean, ends, _ = base
    buf = bytearray(clean)
    buf[2] ^= 0x10  # bit 44 of the first framing time: +/- 203 days, still 2000-2100
    out = run_case(tmp_path, bytes(buf))
    d = out.meta["diagnostics"]
    assert d["records_dropped"] == {"bad_timestamp": 1}
    assert d["bytes_skipped"] == ends[0]
    assert out.meta["t0_utc_ns"] == int.from_bytes(clean[ends[0]:ends[0] + 8], "big") * 1000
    assert sum(d["record_counts"].values()) == len(ends)  # decoded, then dropped for its time
