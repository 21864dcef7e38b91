"""GPS − UTC leap seconds from the full table since 1980, by date (issue 13, defect 12),
checked against the IERS/NIST ``leap-seconds.list`` (tests/helpers_time.py), not a constant."""

from __future__ import annotations

import calendar
import datetime as dt

import numpy as np
import pytest

from helpers import pymavlink_by_type, realdata_file
from helpers_time import IERS_LEAP_SECONDS_LIST, NTP_UNIX_OFFSET_S, gps_minus_utc
from pipeline.io import registry
from pipeline.io.dataflash.writer import DataFlashWriter
from pipeline.io.gpstime import (GPS_EPOCH_UNIX_S, LEAP_SECONDS_TABLE, gps_to_utc_ns, leap_seconds_at_gps,
                                 leap_seconds_at_utc, utc_to_gps_unix_us)


def _unix(date: str) -> int:
    return calendar.timegm(dt.date.fromisoformat(date).timetuple())


def test_the_table_is_the_iers_list_since_the_gps_epoch():
    iers = [(ntp - NTP_UNIX_OFFSET_S, n - 19) for ntp, n in IERS_LEAP_SECONDS_LIST if n > 19]
    ours = [(_unix(d), n) for d, n in LEAP_SECONDS_TABLE[1:]]
    assert ours == iers
    assert LEAP_SECONDS_TABLE[0] == ("1980-01-06", 0) and _unix("1980-01-06") == GPS_EPOCH_UNIX_S


@pytest.mark.parametrize("date, n", LEAP_SECONDS_TABLE[1:])
def test_each_leap_second_takes_effect_on_its_date(date, n):
    u = _unix(date)
    assert leap_seconds_at_utc(u) == n == gps_minus_utc(u)
    assert leap_seconds_at_utc(u - 1) == n - 1 == gps_minus_utc(u - 1)
    # on the GPS scale the step comes n seconds later (23:59:60 UTC is GPS u + n - 1)
    assert leap_seconds_at_gps(u + n) == n and leap_seconds_at_gps(u + n - 1) == n - 1


def test_the_dates_the_issue_names():
    assert leap_seconds_at_utc(_unix("2012-07-01")) == 16
    assert leap_seconds_at_utc(_unix("2014-10-18")) == 16
    assert leap_seconds_at_utc(_unix("2015-07-01")) == 17
    assert leap_seconds_at_utc(_unix("2017-01-01")) == 18
    assert leap_seconds_at_utc(_unix("2026-01-01")) == 18


def test_random_instants_agree_with_the_iers_list_and_round_trip(rng):
    utc_s = rng.integers(_unix("1980-01-07"), _unix("2030-01-01"), size=400)
    for u in utc_s.tolist():
        assert leap_seconds_at_utc(u) == gps_minus_utc(u)
        gps_us = utc_to_gps_unix_us(u * 1_000_000)
        wk, tow_ms = divmod(gps_us // 1000 - GPS_EPOCH_UNIX_S * 1000, 604_800_000)
        utc_ns, leap = gps_to_utc_ns(wk, tow_ms)
        assert utc_ns == u * 1_000_000_000 and leap == gps_minus_utc(u)


def test_a_2014_dataflash_log_written_and_read_back_gets_utc_with_16_leap_seconds(tmp_path):
    t0 = _unix("2014-10-19") * 10**9 + 3_723_500_000_000  # 2014-10-19 01:02:03.5 UTC
    gps_us = utc_to_gps_unix_us(t0 // 1000)
    wk, tow_ms = divmod(gps_us // 1000 - GPS_EPOCH_UNIX_S * 1000, 604_800_000)
    p = tmp_path / "2014.bin"
    with DataFlashWriter(p) as w:
        w.define_layout("ardupilot4")
        w.write("GPS", TimeUS=5_000_000, I=0, Status=3, GMS=tow_ms, GWk=wk, NSats=9, Lat=30.1, Lng=-97.9, Alt=300.0)
        w.write("IMU", TimeUS=5_000_000, I=0, AccZ=-9.8)
    g = pymavlink_by_type(p)["GPS"][0]
    assert (g.GWk, g.GMS) == (wk, tow_ms)
    log = registry.read_log(p)
    assert log.meta["leap_seconds"] == 16 and log.meta["t0_utc_ns"] == t0
    # pymavlink's fixed 18 s would put it 2 s early
    assert (GPS_EPOCH_UNIX_S + 604800 * g.GWk + g.GMS / 1000 - 18) * 1e9 == pytest.approx(t0 - 2e9)


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["2014-10-18_20-04-24", "2014-10-18_20-44-05"])
def test_the_2014_logs_start_at_the_time_their_file_names_give(name):
    """Mission Planner named these logs by their start in local time (Austin, CDT = UTC−5):
    with 16 leap seconds the UTC of t = 0 lands on that second; with 18 it would be 2 s early."""
    log = registry.read_log(realdata_file(f"ap_copter313_austin_4flights/{name}.bin"))
    assert log.meta["leap_seconds"] == 16
    local = dt.datetime.fromtimestamp(log.meta["t0_utc_ns"] * 1e-9, dt.timezone(dt.timedelta(hours=-5)))
    assert local.strftime("%Y-%m-%d_%H-%M-%S") == name
    assert np.isfinite(log.meta["t0_utc_ns"])
