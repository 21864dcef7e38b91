"""GPS time <-> UTC with the leap-second table since the GPS epoch (1980-01-06).

GPS time does not follow UTC's leap seconds: GPS − UTC was 0 s at the GPS epoch and grows by
one at each leap second inserted into UTC since (IERS Bulletin C; the ``leap-seconds.list``
that the IERS and NIST publish gives TAI − UTC, and GPS − UTC = TAI − UTC − 19 s):

.. math:: t_{UTC} = t_{GPS} - n(t_{UTC}), \\qquad
          t_{GPS} = 315964800 + 604800\\,\\mathrm{week} + \\mathrm{tow}

(``t`` in Unix seconds; 315964800 is 1980-01-06T00:00:00Z). pymavlink (and older versions
of this reader) subtract a fixed 18 s, right only from 2017-01-01: a 2014 log read that way is
2 s early. The table below ends with the leap second of 2016-12-31; the IERS has announced
none since (Bulletin C 70, 2025: none before 2026-06-28 at least), so 18 s holds after it.
"""

from __future__ import annotations

import bisect
import calendar

#: GPS epoch 1980-01-06T00:00:00Z in Unix seconds.
GPS_EPOCH_UNIX_S = 315964800

#: (UTC date from which it holds, GPS − UTC in s): every leap second since the GPS epoch.
LEAP_SECONDS_TABLE: tuple[tuple[str, int], ...] = (
    ("1980-01-06", 0),
    ("1981-07-01", 1), ("1982-07-01", 2), ("1983-07-01", 3), ("1985-07-01", 4),
    ("1988-01-01", 5), ("1990-01-01", 6), ("1991-01-01", 7), ("1992-07-01", 8),
    ("1993-07-01", 9), ("1994-07-01", 10), ("1996-01-01", 11), ("1997-07-01", 12),
    ("1999-01-01", 13), ("2006-01-01", 14), ("2009-01-01", 15), ("2012-07-01", 16),
    ("2015-07-01", 17), ("2017-01-01", 18),
)


def _unix(date: str) -> int:
    y, m, d = (int(x) for x in date.split("-"))
    return calendar.timegm((y, m, d, 0, 0, 0, 0, 0, 0))


#: the table as (UTC Unix s of each step, GPS − UTC from then on)
_STEPS_UTC = [_unix(d) for d, _ in LEAP_SECONDS_TABLE]
_LEAPS = [n for _, n in LEAP_SECONDS_TABLE]
#: the same steps on the GPS time scale (a step at UTC u happens at GPS u + n)
_STEPS_GPS = [u + n for u, n in zip(_STEPS_UTC, _LEAPS)]


def leap_seconds_at_utc(utc_s: float) -> int:
    """GPS − UTC (s) at UTC time ``utc_s`` (Unix seconds); 0 before the first leap second."""
    k = bisect.bisect_right(_STEPS_UTC, utc_s) - 1
    return _LEAPS[max(k, 0)]


def leap_seconds_at_gps(gps_unix_s: float) -> int:
    """GPS − UTC (s) at the instant whose GPS time is ``gps_unix_s`` (GPS seconds counted
    from the Unix epoch, i.e. ``315964800 + 604800 week + tow``)."""
    k = bisect.bisect_right(_STEPS_GPS, gps_unix_s) - 1
    return _LEAPS[max(k, 0)]


def gps_to_utc_ns(week: int, tow_ms: int) -> tuple[int, int]:
    """UTC (ns since the Unix epoch) of GPS ``week`` and time of week (ms), and the leap
    seconds used: ``(utc_ns, leap_s)``."""
    gps_ms = (GPS_EPOCH_UNIX_S + 604800 * int(week)) * 1000 + int(tow_ms)
    leap = leap_seconds_at_gps(gps_ms / 1000.0)
    return (gps_ms - leap * 1000) * 1_000_000, leap


def utc_to_gps_unix_us(utc_us: int) -> int:
    """GPS time (µs counted from the Unix epoch) of the UTC instant ``utc_us`` (µs)."""
    return int(utc_us) + leap_seconds_at_utc(utc_us / 1e6) * 1_000_000
