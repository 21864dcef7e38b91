"""The IERS/NIST ``leap-seconds.list`` (TAI − UTC from each NTP timestamp), as published:
the oracle the GPS − UTC table of :mod:`pipeline.io.gpstime` is checked against
(GPS − UTC = TAI − UTC − 19 s: GPS time was set to UTC on 1980-01-06, when TAI − UTC was 19 s)."""

from __future__ import annotations

NTP_UNIX_OFFSET_S = 2208988800  # 1900-01-01 to 1970-01-01

#: (NTP seconds, TAI − UTC in s), the lines of leap-seconds.list
IERS_LEAP_SECONDS_LIST: tuple[tuple[int, int], ...] = (
    (2272060800, 10), (2287785600, 11), (2303683200, 12), (2335219200, 13), (2366755200, 14),
    (2398291200, 15), (2429913600, 16), (2461449600, 17), (2492985600, 18), (2524521600, 19),
    (2571782400, 20), (2603318400, 21), (2634854400, 22), (2698012800, 23), (2776982400, 24),
    (2840140800, 25), (2871676800, 26), (2918937600, 27), (2950473600, 28), (2982009600, 29),
    (3029443200, 30), (3076704000, 31), (3124137600, 32), (3345062400, 33), (3439756800, 34),
    (3550089600, 35), (3644697600, 36), (3692217600, 37),
)


def gps_minus_utc(unix_s: float) -> int:
    """GPS − UTC (s) at UTC ``unix_s`` from the IERS list (0 before the first step after 1980)."""
    tai_utc = 10
    for ntp, n in IERS_LEAP_SECONDS_LIST:
        if unix_s >= ntp - NTP_UNIX_OFFSET_S:
            tai_utc = n
    return max(tai_utc - 19, 0)
