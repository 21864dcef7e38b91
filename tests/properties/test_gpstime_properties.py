"""GPS <-> UTC with the leap-second table: round trips at any instant since 1980, leap
seconds never decreasing (issue 13, defect 12)."""

from hypothesis import given, settings
from hypothesis import strategies as st

from helpers_time import gps_minus_utc
from pipeline.io.gpstime import GPS_EPOCH_UNIX_S, gps_to_utc_ns, leap_seconds_at_utc, utc_to_gps_unix_us

UTC_US = st.integers(min_value=(GPS_EPOCH_UNIX_S + 86400) * 1_000_000, max_value=1_900_000_000 * 1_000_000)


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
