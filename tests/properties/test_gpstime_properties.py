"""GPS <-> UTC with the leap-second table: round trips at any instant since 1980, leap
seconds never decreasing (issue 13, defect 12)."""

import calendar

from hypothesis import example, given, settings
from hypothesis import strategies as st

from helpers_time import gps_minus_utc
from pipeline.io.gpstime import (GPS_EPOCH_UNIX_S, LEAP_SECONDS_TABLE, gps_to_utc_ns, leap_seconds_at_utc,
                                 utc_to_gps_unix_us)

UTC_US = st.integers(min_value=(GPS_EPOCH_UNIX_S + 86400) * 1_000_000, max_value=1_900_000_000 * 1_000_000)

#: (UTC Unix s u of each leap step, GPS - UTC n from u on), the steps after the GPS epoch
STEPS = [(calendar.timegm(tuple(int(x) for x in d.split("-")) + (0, 0, 0, 0, 0, 0)), n)
         for d, n in LEAP_SECONDS_TABLE[1:]]


def at_every_leap_step(test):
    """Add, at each step u, the UTC instants u - 1 s, u - 1 ms, u and u + 1 ms as examples: a
    uniform draw over 1980-2030 lands within a second of one of 18 steps with odds ~1e-8."""
    for u, _ in STEPS:
        for us in ((u - 1) * 1_000_000, u * 1_000_000 - 1000, u * 1_000_000, u * 1_000_000 + 1000):
            test = example(us)(test)
    return test


@at_every_leap_step
@settings(max_examples=300, deadline=None)
@given(UTC_US)
def test_utc_gps_utc_round_trips_to_the_millisecond(utc_us):
    utc_us -= utc_us % 1000  # GPS time of week is logged in ms
    gps_ms = utc_to_gps_unix_us(utc_us) // 1000 - GPS_EPOCH_UNIX_S * 1000
    wk, tow = divmod(gps_ms, 604_800_000)
    utc_ns, leap = gps_to_utc_ns(wk, tow)
    assert utc_ns == utc_us * 1000
    assert leap == gps_minus_utc(utc_us / 1e6)


@settings(max_examples=200, deadline=None)
@given(UTC_US, UTC_US)
def test_leap_seconds_never_decrease(a, b):
    lo, hi = sorted((a, b))
    assert leap_seconds_at_utc(lo / 1e6) <= leap_seconds_at_utc(hi / 1e6)


def test_gps_to_utc_is_exact_on_both_sides_of_every_leap_step():
    # a step at UTC u happens at GPS u + n; the last GPS ms before it, u + n - 1 s - 1 ms,
    # still has n - 1 leap seconds and is UTC u - 1 ms; GPS u + n - 1 s .. u + n is the inserted
    # second 23:59:60, which Unix time cannot name
    assert len(STEPS) == 18
    for u, n in STEPS:
        for gps_s_ms, utc_ms, leap in (((u + n - 1) * 1000 - 1, u * 1000 - 1, n - 1),
                                       ((u + n) * 1000, u * 1000, n),
                                       ((u + n) * 1000 + 1, u * 1000 + 1, n)):
            wk, tow = divmod(gps_s_ms - GPS_EPOCH_UNIX_S * 1000, 604_800_000)
            assert gps_to_utc_ns(wk, tow) == (utc_ms * 1_000_000, leap), (u, n, gps_s_ms)
            assert utc_to_gps_unix_us(utc_ms * 1000) == gps_s_ms * 1000
