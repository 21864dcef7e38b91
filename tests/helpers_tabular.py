"""The column-mapped table of the tabular reader's tests and golden file (one map, one table)."""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd

#: source column -> canonical stream/column/unit: every unit kind the map converts
COLUMNS: dict[str, dict] = {
    "lat": {"stream": "gps", "column": "lat_deg", "unit": "deg*1e7"},
    "lon": {"stream": "gps", "column": "lon_deg", "unit": "deg*1e7"},
    "alt_ft": {"stream": "gps", "column": "alt_msl_m", "unit": "ft"},
    "roll_deg": {"stream": "attitude", "column": "roll", "unit": "deg"},
    "pitch_deg": {"stream": "attitude", "column": "pitch", "unit": "deg"},
    "yaw_deg": {"stream": "attitude", "column": "yaw", "unit": "deg"},
    "p_mbar": {"stream": "baro", "column": "press_Pa", "unit": "mbar"},
    "tempK": {"stream": "baro", "column": "temp_degC", "unit": "K"},
    "gx": {"stream": "imu", "column": "gyr_x_radps", "unit": "deg/s"},
    "az": {"stream": "imu", "column": "acc_z_mps2", "unit": "g"},
    "flightmode": {"stream": "mode", "column": "mode", "values": {1: "MANUAL", 5: "FBWA"}},
}


def column_map(name: str, extra_columns: dict | None = None, **over) -> dict:
    """A column map over :data:`COLUMNS` (+ ``extra_columns``), time ``t_ms`` in ms, NED about
    the first fix; ``over`` replaces top-level keys."""
    m = {"name": name, "time": {"column": "t_ms", "unit": "ms"}, "ned_origin": "first_fix",
         "columns": copy.deepcopy({**COLUMNS, **(extra_columns or {})})}  # tests edit their copy
    m.update(over)
    return m


def table(rng: np.random.Generator, n: int) -> pd.DataFrame:
    """``n`` rows of every :data:`COLUMNS` source at 10 Hz (the mode switches at n/3, 2n/3)."""
    k = n // 3
    return pd.DataFrame({
        "t_ms": 1000.0 + 100.0 * np.arange(n),
        "lat": np.full(n, 515000000) + np.arange(n), "lon": np.full(n, -25000000) - np.arange(n),
        "alt_ft": rng.uniform(0, 300, n), "roll_deg": rng.uniform(-180, 180, n),
        "pitch_deg": rng.uniform(-89, 89, n), "yaw_deg": rng.uniform(0, 360, n),
        "p_mbar": rng.uniform(990, 1020, n), "tempK": np.full(n, 293.15) + rng.normal(0, 1, n),
        "gx": rng.normal(0, 30, n), "az": rng.normal(-1, 0.01, n),
        "flightmode": [1] * k + [5] * k + [1] * (n - 2 * k)})
