"""Corrupt input at ingest: bit-flipped DataFlash time stamps, a ULog whose definitions scan runs
off the end of the file, a CSV with a block of NUL bytes. Each gives a partial log with its drops
counted, or one IngestError line naming the file, in seconds (project rule on bad input).

The corruption patterns are fixed (``random.Random`` / ``default_rng`` with constant seeds): what
is tested is a particular damaged file, not a distribution of them.
"""

from __future__ import annotations

import contextlib
import random
import signal
import struct
import time

import numpy as np
import pytest

import helpers_tabular
from helpers import realdata_file
from helpers_ulog import ULogWriter, add_sensor_combined
from pipeline.io import registry
from pipeline.io.base import IngestError, losses_text
from pipeline.io.dataflash.streams import TIME_OUTLIER_US, time_outliers
from pipeline.io.tlog import write_tlog
from pipeline.simulate.demo import write_demo_flight

DEMO_S = 60.0  # the demo flight's length (s); its log starts 2 s after boot


class _Hung(BaseException):
    """Raised by :func:`deadline`; a BaseException so no reader's catch-all turns it into an
    IngestError."""


@contextlib.contextmanager
def deadline(seconds: float):
    """Fail the test instead of hanging when the body runs longer than ``seconds``."""
    def fire(signum, frame):
        raise _Hung()

    old = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    t = time.perf_counter()
    try:
        yield
    except _Hung:
        pytest.fail(f"still running after {time.perf_counter() - t:.1f} s (hang)")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


# --- DataFlash: flipped bits in TimeUS -------------------------------------------------------

def _bit_flipped_demo(path, *, start=20_000, step=997, seed=1):
    """The demo DataFlash log (~230 kB) with one bit flipped every ``step`` bytes from ``start``."""
    write_demo_flight(path, seed=0, duration_s=DEMO_S)
    data = bytearray(path.read_bytes())
    r = random.Random(seed)
    for i in range(start, len(data), step):
        data[i] ^= 1 << r.randrange(8)
    path.write_bytes(bytes(data))
    return path


def test_a_bit_flipped_dataflash_log_drops_and_counts_its_corrupt_time_stamps(tmp_path):
    log = registry.read_log(_bit_flipped_demo(tmp_path / "flipped.bin"))
    diag = log.meta["diagnostics"]
    assert log.meta["status"] == "partial"
    assert diag["records_dropped"]["bad_timestamp"] == 35  # this fixed pattern (seed 1, step 997) hits 35 stamps
    assert "bad_timestamp" in losses_text(diag)
    assert any("corrupt time stamp" in w for w in diag["warnings"])
    # what is left lies in the flight: no stamp more than a minute outside it (was -9.2e18 ns)
    lo, hi = log.span_ns()
    assert -TIME_OUTLIER_US * 1000 <= lo and hi <= (DEMO_S * 1e6 + TIME_OUTLIER_US) * 1000
    assert log.meta["t0_boot_ns"] == 2_000_000_000  # t0 from an intact first record
    assert log.n_rows()["imu"] > 0.95 * DEMO_S * 50  # 50 Hz IMU: the bulk is kept


def test_a_clean_dataflash_log_loses_no_record_to_the_time_stamp_check(tmp_path):
    p = tmp_path / "clean.bin"
    write_demo_flight(p, seed=0, duration_s=DEMO_S)
    log = registry.read_log(p)
    assert log.meta["status"] == "ok"
    assert "bad_timestamp" not in log.meta["diagnostics"]["records_dropped"]


def test_the_time_stamp_check_keeps_pauses_and_reboots_and_cuts_isolated_stamps():
    s = 1_000_000  # µs
    clean = np.concatenate([np.arange(0, 20 * s, s // 50),           # 20 s at 50 Hz
                            np.arange(3600 * s, 3610 * s, s // 50),  # an hour's pause in logging
                            np.arange(0, 5 * s, s // 50)])           # a reboot: the clock restarts
    assert not time_outliers(clean).any()
    t = clean.copy()
    hit = [100, 101, 1500, len(t) - 1]  # two in a row, one inside, the very last
    t[100] = -(1 << 62)
    t[101] = 1 << 60
    t[1500] += 1 << 36  # bit 36 of the µs counter: +19 h
    t[-1] = 1 << 45
    bad = time_outliers(t)
    assert sorted(np.flatnonzero(bad).tolist()) == hit
    assert not time_outliers(np.array([0, 1 << 62])).any()  # two stamps: nothing to outvote with


def test_a_csv_row_stamped_centuries_away_is_dropped_by_the_common_ingest_path(tmp_path):
    rng = np.random.default_rng(3)
    df = helpers_tabular.table(rng, 30)
    df.loc[17, "t_ms"] = 1e12  # 31.7 years after the others: a valid int64 ns stamp
    df.loc[23, "t_ms"] = 1e15  # 31 700 years: beyond int64 ns, no time at all
    p = tmp_path / "far.csv"
    df.to_csv(p, index=False)
    log = registry.read_log(p, config={"columnmaps": {"m": helpers_tabular.column_map("m")}})
    d = log.meta["diagnostics"]
    # the row's samples in the four streams it feeds (gps, attitude, baro, imu) are dropped
    assert d["records_dropped"] == {"bad_time": 1, "bad_timestamp": 4} and log.meta["status"] == "partial"
    assert any("absurd time stamp" in w and "gps 1" in w for w in d["warnings"])
    assert log.span_ns() == (0, 29 * 100_000_000)  # 10 Hz rows: the flight is 2.9 s
    assert len(log["gps"]) == 28


# --- DataFlash and tlog: a block of random bytes inside the file -----------------------------

def _overwrite(path, at, n, seed=7):
    """``path`` with ``n`` random bytes written over it from byte ``at``; returns the bytes."""
    data = bytearray(path.read_bytes())
    data[at:at + n] = np.random.default_rng(seed).integers(0, 256, n, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    return data


def test_a_dataflash_log_with_a_damaged_block_counts_the_span_and_says_where_and_how_much(tmp_path):
    clean = tmp_path / "clean.bin"
    write_demo_flight(clean, seed=0, duration_s=DEMO_S)
    size = clean.stat().st_size
    hit = tmp_path / "hit.bin"
    hit.write_bytes(clean.read_bytes())
    _overwrite(hit, size // 2, 1024)
    a, b = registry.read_log(clean), registry.read_log(hit)
    diag = b.meta["diagnostics"]
    assert a.meta["status"] == "ok" and not a.meta["diagnostics"]["warnings"]
    assert b.meta["status"] == "partial" and diag["records_dropped"]["damaged"] == 1
    assert "damaged" in losses_text(diag)
    (w,) = [w for w in diag["warnings"] if w.startswith("DataFlash damaged at bytes")]
    first, resume = map(int, w.split()[4].rstrip(":").split("-"))
    # the span starts and ends within one record (FMT Length: a byte) of the overwritten block:
    # a record whose header survived keeps its place in the chain (DataFlash has no checksum)
    at = size // 2
    assert abs(first - at) < 255 and abs(resume - (at + 1024)) < 255
    assert diag["bytes_skipped"] == resume - first
    # the estimate in the warning is the records really lost, to within a factor of two
    lost = sum(a.n_rows().values()) - sum(b.n_rows().values())
    est = int(w.split("about ")[1].split()[0])
    assert lost > 0 and lost / 2 <= est <= 2 * lost


def _attitude_tlog(path, n=400):
    """A tlog of one vehicle: a heartbeat, then ``n`` ATTITUDE records at 10 Hz."""
    from pymavlink.dialects.v20 import ardupilotmega as v2

    m = v2.MAVLink(None)
    t0 = 1_700_000_000_000_000
    recs = [(t0, m.heartbeat_encode(2, 3, v2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0, 4))]
    recs += [(t0 + 100_000 * (k + 1), m.attitude_encode(100 * (k + 1), 0.01 * k, 0.0, 0.1, 0, 0, 0))
             for k in range(n)]
    return write_tlog(path, recs)


def test_a_tlog_with_a_damaged_block_says_where_and_about_how_many_records_it_held(tmp_path):
    clean = _attitude_tlog(tmp_path / "clean.tlog")
    size = clean.stat().st_size
    hit = tmp_path / "hit.tlog"
    hit.write_bytes(clean.read_bytes())
    _overwrite(hit, size // 2, 512)
    a, b = registry.read_log(clean), registry.read_log(hit)
    assert a.meta["status"] == "ok" and not any("damaged" in w for w in a.meta["diagnostics"]["warnings"])
    diag = b.meta["diagnostics"]
    assert b.meta["status"] == "partial" and sum(diag["records_dropped"].values()) >= 1
    (w,) = [w for w in diag["warnings"] if w.startswith("tlog damaged at bytes")]
    first, resume = map(int, w.split()[4].rstrip(":").split("-"))
    assert first <= size // 2 and resume >= size // 2 + 512 and diag["bytes_skipped"] == resume - first
    lost = len(a["attitude"]) - len(b["attitude"])
    est = int(w.split("about ")[1].split()[0])
    assert lost > 0 and lost / 2 <= est <= 2 * lost
    # the records either side are named by their time from the log start (10 Hz records)
    t_before, t_after = (float(x) for x in w.split("t = ")[1].split(";")[0].replace(" s", "").split(" and "))
    assert 0 < t_before < t_after and t_after - t_before == pytest.approx(0.1 * (lost + 1), abs=1e-6)


def test_a_tlog_cut_inside_a_record_says_so_in_a_warning(tmp_path):
    p = _attitude_tlog(tmp_path / "cut.tlog")
    p.write_bytes(p.read_bytes()[:-20])
    diag = registry.read_log(p).meta["diagnostics"]
    assert diag["records_dropped"] == {"truncated": 1}
    assert any(w.startswith("tlog undecodable from byte") and "cut short" in w for w in diag["warnings"])


def test_the_ingest_line_of_a_partial_log_says_what_was_lost(tmp_path, capsys):
    from pipeline.io.ingest import outputs_for, run_ingest

    p = tmp_path / "cut.bin"
    write_demo_flight(p, seed=0, duration_s=DEMO_S)
    p.write_bytes(p.read_bytes()[:-5])
    res = run_ingest({"log": p}, outputs_for(tmp_path / "out"), None, flight_id="cut")
    line = [x for x in capsys.readouterr().err.splitlines() if " -> " in x][0]
    assert res.status == "partial" and line.endswith("partial: " + losses_text(res.diagnostics) + ")")
    assert "truncated" in line


# --- ULog: the definitions scan runs into the end of the file ------------------------------

def _ulog_definitions_never_end(path):
    """A small ULog (3000 sensor_combined samples, ~150 kB) damaged in two places: its one
    ADD_LOGGED message has a corrupt type byte, so pyulog's definitions scan never meets the
    data section and steps over every data message to the end of the file; there the last
    message header claims 0xFFFF bytes of type 0, more than the file holds."""
    rng = np.random.default_rng(0)
    n = 3000
    w = ULogWriter(start_us=1_000_000)
    w.add_info("sys_name", "PX4")
    w.add_param("SYS_AUTOSTART", 4001)
    add_sensor_combined(w, n, rng)
    raw = bytearray(w.to_bytes())
    add = raw.find(b"A" + struct.pack("<BH", 0, 0) + b"sensor_combined") - 2
    assert add > 0
    raw[add + 2] = ord("z")
    pos, last = 16, 16
    while pos + 3 <= len(raw):  # the last message's header
        last = pos
        pos += 3 + (raw[pos] | raw[pos + 1] << 8)
    raw[last:last + 3] = b"\xff\xff\x00"
    path.write_bytes(bytes(raw))
    return path


def test_a_ulog_whose_definitions_never_end_fails_in_one_line_within_seconds(tmp_path):
    p = _ulog_definitions_never_end(tmp_path / "no_data_section.ulg")
    t = time.perf_counter()
    with deadline(10.0), pytest.raises(IngestError) as err:
        registry.read_log(p)
    assert time.perf_counter() - t < 5.0
    msg = str(err.value)
    assert msg.startswith(f"{p}: corrupt ULog") and "\n" not in msg


def test_the_motor_failure_ulog_with_310_overwritten_bytes_no_longer_hangs(tmp_path):
    src = realdata_file("ulg_px4_flight_review_fixtures/motor_failure.ulg")
    data = bytearray(src.read_bytes())
    r = random.Random(25)  # of seeds 0-39, the one whose damage hung pyulog for good
    for _ in range(310):
        data[16 + int(r.random() * (len(data) - 16))] = r.getrandbits(8)
    p = tmp_path / "motor_failure_damaged.ulg"
    p.write_bytes(bytes(data))
    with deadline(10.0):
        try:
            log = registry.read_log(p)
        except IngestError as exc:
            assert str(exc).startswith(f"{p}: ") and "\n" not in str(exc)
        else:
            assert log.meta["status"] == "partial"


# --- CSV: a block of NUL bytes -----------------------------------------------------------------

def test_a_csv_with_a_block_of_nul_bytes_counts_the_rows_it_loses(tmp_path):
    rng = np.random.default_rng(7)
    n = 400
    df = helpers_tabular.table(rng, n)
    raw = bytearray(df.to_csv(index=False).encode())
    mid = len(raw) // 2
    raw[mid:mid + 4096] = bytes(4096)
    p = tmp_path / "zeroed.csv"
    p.write_bytes(bytes(raw))
    log = registry.read_log(p, config={"columnmaps": {"m": helpers_tabular.column_map("m")}})
    d = log.meta["diagnostics"]
    got = log["gps"]
    assert log.meta["status"] == "partial"
    assert d["records_dropped"]["unparseable_row"] == n - len(got)  # every lost row counted
    assert 4096 <= d["bytes_skipped"] < 4096 + 2 * 200  # the block and the two cut rows
    assert "unparseable_row" in losses_text(d)
    # no row glued from the head of one record and the tail of another
    t_src = (df["t_ms"].to_numpy() - df["t_ms"].iloc[0]) * 1e6
    k = np.searchsorted(t_src, got["t_ns"].to_numpy())
    np.testing.assert_array_equal(t_src[k], got["t_ns"].to_numpy())
    np.testing.assert_allclose(got["alt_msl_m"].to_numpy(), df["alt_ft"].to_numpy()[k] * 0.3048, rtol=1e-12)


def test_a_csv_whose_header_line_holds_nul_bytes_is_one_error_line(tmp_path):
    rng = np.random.default_rng(7)
    raw = bytearray(helpers_tabular.table(rng, 20).to_csv(index=False).encode())
    raw[3:6] = bytes(3)
    p = tmp_path / "bad_header.csv"
    p.write_bytes(bytes(raw))
    with pytest.raises(IngestError, match="bad_header.csv: ") as err:
        registry.read_log(p, fmt="tabular",
                          config={"columnmaps": {"m": helpers_tabular.column_map("m")}})
    assert "\n" not in str(err.value)


def test_a_csv_with_garbled_non_utf8_lines_keeps_the_others_and_counts_the_lost_rows(tmp_path):
    # before: the whole file failed ("CSV is not UTF-8 text: invalid start byte at byte 0")
    rng = np.random.default_rng(8)
    n = 200
    df = helpers_tabular.table(rng, n)
    lines = df.to_csv(index=False).encode().split(b"\n")
    for k in (50, 51, 120):  # three records garbled on the card: bytes no text encoding has
        lines[k] = lines[k][:5] + b"\xff\xfe\x80" + lines[k][8:]
    p = tmp_path / "garbled.csv"
    p.write_bytes(b"\n".join(lines))
    log = registry.read_log(p, config={"columnmaps": {"m": helpers_tabular.column_map("m")}})
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial" and len(log["gps"]) == n - 3
    assert d["records_dropped"]["unparseable_row"] == 3 and d["bytes_skipped"] > 0
    assert any("3 line(s) that are not UTF-8 text dropped" in w for w in d["warnings"])
    # a garbled header is still one error line
    p.write_bytes(b"\xff" + b"\n".join(lines))
    with pytest.raises(IngestError, match="garbled.csv: CSV is not UTF-8 text: the header line is not UTF-8"):
        registry.read_log(p, fmt="tabular", config={"columnmaps": {"m": helpers_tabular.column_map("m")}})


def test_a_csv_row_cut_short_is_dropped_and_counted_not_kept_with_its_missing_cells_as_nan(tmp_path):
    # before: pandas filled the missing cells with NaN and the row's other columns passed as
    # good data, with status ok and nothing counted
    rng = np.random.default_rng(9)
    n = 100
    df = helpers_tabular.table(rng, n)
    lines = df.to_csv(index=False).encode().split(b"\n")
    lines[30] = b",".join(lines[30].split(b",")[:3])      # a record that lost its tail
    p = tmp_path / "short.csv"
    p.write_bytes(b"\n".join(lines).rstrip(b"\n")[:-7])  # and the file ends mid-line
    log = registry.read_log(p, config={"columnmaps": {"m": helpers_tabular.column_map("m")}})
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial" and len(log["gps"]) == n - 2
    assert d["records_dropped"]["unparseable_row"] == 2
    fields = len(lines[0].split(b","))
    assert any(w.startswith(f"2 line(s) with fewer fields than the header ({fields}) dropped") and
               "first line 31 with 3 field(s)" in w for w in d["warnings"]), d["warnings"]
    # trailing empty cells are fields too: such a row is whole, and blank lines are no rows
    lines[30] = b",".join([lines[31].split(b",")[0]] + [b""] * (fields - 1))
    p.write_bytes(b"\n".join(lines) + b"\n\n")
    log = registry.read_log(p, config={"columnmaps": {"m": helpers_tabular.column_map("m")}})
    assert "unparseable_row" not in log.meta["diagnostics"]["records_dropped"]


def test_a_csv_with_a_quoted_header_still_drops_and_counts_a_row_cut_short(tmp_path):
    # before: a quote in the header skipped the check, so the short row was kept with NaN cells
    import csv

    rng = np.random.default_rng(10)
    n = 60
    df = helpers_tabular.table(rng, n)
    df["note"] = ["gps ok, baro ok"] * n       # a quoted separator in a data line adds fields
    cmap = {"columnmaps": {"m": helpers_tabular.column_map("m")}}
    lines = df.to_csv(index=False, quoting=csv.QUOTE_NONNUMERIC).encode().split(b"\n")
    assert lines[0].startswith(b'"t_ms","lat"')
    p = tmp_path / "quoted.csv"
    p.write_bytes(b"\n".join(lines))
    log = registry.read_log(p, config=cmap)
    assert log.meta["status"] == "ok" and len(log["gps"]) == n
    assert "unparseable_row" not in log.meta["diagnostics"]["records_dropped"]
    lines[20] = b",".join(lines[20].split(b",")[:4])
    p.write_bytes(b"\n".join(lines))
    log = registry.read_log(p, config=cmap)
    d = log.meta["diagnostics"]
    assert log.meta["status"] == "partial" and len(log["gps"]) == n - 1
    assert d["records_dropped"]["unparseable_row"] == 1
    assert any(w.startswith(f"1 line(s) with fewer fields than the header ({len(df.columns)}) dropped")
               and "first line 21 with 4 field(s)" in w for w in d["warnings"]), d["warnings"]


def test_the_short_line_check_parses_the_header_and_leaves_a_quoted_field_across_lines_alone():
    from pipeline.io.tabular import drop_short_lines

    # a column name holding the separator: the header has 2 fields, not 3
    kept, lost = drop_short_lines(b'"t_ms","alt, m"\n1,2\n3\n5,6\n', ",")
    assert kept == b'"t_ms","alt, m"\n1,2\n5,6\n' and lost.lines == 1
    assert "fewer fields than the header (2)" in lost.text and "first line 3 with 1 field(s)" in lost.text
    # a quoted field over two lines: the parser joins its pieces, so nothing is dropped
    data = b't_ms,note\n1,"first\nsecond"\n2,x\n'
    assert drop_short_lines(data, ",") == (data, None)


def test_the_many_kinds_of_one_drop_reason_fold_into_one_phrase():
    from pipeline.io.base import grouped_drops, losses_text

    dropped = {"bad_timestamp": 116, "truncated": 1, **{f"format_lost:{t}": n for t, n in
                                                       ((162, 9), (178, 7), (225, 5), (3, 1), (4, 1))}}
    assert grouped_drops(dropped) == [("bad_timestamp", 116), ("truncated", 1),
                                      ("format_lost, 5 kinds: 162, 178, 225, ...", 23)]
    assert losses_text({"bytes_skipped": 10, "records_dropped": dropped}) == (
        "10 bytes skipped, 140 records dropped (bad_timestamp; format_lost, 5 kinds: 162, 178, 225, ...; truncated)")
    # a few kinds are each said
    assert grouped_drops({"format_lost:7": 2, "format_lost:42": 1}) == [("format_lost:7", 2), ("format_lost:42", 1)]
