"""Reader golden summaries: regenerate ``tests/data/golden/<fixture>.json`` (pyulog style).

Every fixture log the tests use is written at test time by the library's own writers (the demo
flight, a simulated flight in every format) or by the tests' helpers (ULog, FlightCoach JSON,
a column-mapped Parquet table), so no file under ``../shared`` is needed. Each fixture is read
with :func:`pipeline.io.registry.read_log` and summarised per stream: rows, columns, first/last
``t_ns`` and, per column, mean/min/max (numeric; 6 significant figures) or the distinct values
(text, first 10). ``tests/io/test_reader_golden.py`` compares every reader's current summary
with its golden file and prints a readable diff, so a reader change shows up as a reviewed
change of these files.

Run after an intended reader change (and review the diff)::

    PYTHONPATH=. .venv/bin/python tests/regen_golden.py [fixture ...]

Seeds are fixed here (not PIPELINE_TEST_SEED): a golden file is one fixed input.
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent))  # helpers_ulog when run as a script

import helpers_tabular  # noqa: E402
from helpers_ulog import ULogWriter  # noqa: E402

from pipeline.io import schema  # noqa: E402
from pipeline.io.registry import read_log  # noqa: E402

GOLDEN = Path(__file__).resolve().parent / "data" / "golden"
T0_UTC_NS = 1767268800 * 10 ** 9
SIG = 6  # significant figures kept in the statistics
MAX_VALUES = 10  # distinct values listed for a text column


# --- fixtures ---------------------------------------------------------------------------------

def _sim_flight(tmp: Path) -> dict[str, Path]:
    """One short simulated flight (M3, seed 5) in every format, written once per folder."""
    from pipeline.simulate.scenarios import SimSettings, run_scenario, scenario_for
    from pipeline.simulate.sensors import SensorSettings
    from pipeline.simulate.writers import LOG_NAMES, write_flight

    out = tmp / "sim"
    names = {f: out / LOG_NAMES[f]("flight") for f in ("bin", "tlog", "bag", "mcap")}
    if not all(p.exists() for p in names.values()):
        cfg = {"rate_hz": 100, "sensors": {"imu": {"rate_hz": 100}}}
        st, se = SimSettings.from_config(cfg), SensorSettings.from_config(cfg)
        rng = np.random.default_rng(5)
        tr = run_scenario(scenario_for("maneuver", st, "M3"), st, 1, rng)
        write_flight(out, "flight", tr, se, st.vehicle, st.rate_hz, rng, t0_utc_ns=T0_UTC_NS)
    return names


def demo_bin(tmp: Path) -> tuple[Path, dict]:
    from pipeline.simulate.demo import write_demo_flight

    p = tmp / "demo.bin"
    write_demo_flight(p, seed=0, duration_s=20.0)
    return p, {}


def sim_bin(tmp: Path) -> tuple[Path, dict]:
    return _sim_flight(tmp)["bin"], {}


def sim_tlog(tmp: Path) -> tuple[Path, dict]:
    return _sim_flight(tmp)["tlog"], {}


def sim_rosbag1(tmp: Path) -> tuple[Path, dict]:
    return _sim_flight(tmp)["bag"], {}


def sim_rosbag2_mcap(tmp: Path) -> tuple[Path, dict]:
    return _sim_flight(tmp)["mcap"], {}


def sim_mcap_file(tmp: Path) -> tuple[Path, dict]:
    """The ``.mcap`` file inside the ROS 2 bag, read on its own (the MCAP reader)."""
    return next(_sim_flight(tmp)["mcap"].glob("*.mcap")), {}


def ulog_synthetic(tmp: Path) -> tuple[Path, dict]:
    """A small PX4 ULog (two IMU/GPS/mag instances, airspeed, rangefinder, RC, outputs, status)."""
    rng = np.random.default_rng(7)
    F = [("uint64_t", "timestamp")]
    w = ULogWriter(start_us=5_000_000)
    w.add_info("sys_name", "PX4")
    w.add_param("SYS_AUTOSTART", 4001)
    n = 40
    ts = 5_000_000 + np.arange(n, dtype=np.uint64) * 10_000
    imu_f = F + [("uint64_t", "timestamp_sample"), ("float[3]", "delta_angle"), ("float[3]", "delta_velocity"),
                 ("uint16_t", "delta_angle_dt"), ("uint16_t", "delta_velocity_dt")]
    gps_f = F + [("uint64_t", "time_utc_usec"), ("double", "latitude_deg"), ("double", "longitude_deg"),
                 ("double", "altitude_msl_m"), ("double", "altitude_ellipsoid_m"), ("float", "eph"),
                 ("float", "epv"), ("float", "vel_n_m_s"), ("float", "vel_e_m_s"), ("float", "vel_d_m_s"),
                 ("int32_t", "timestamp_time_relative"), ("uint8_t", "fix_type"), ("uint8_t", "satellites_used")]
    mag_f = F + [("float", "x"), ("float", "y"), ("float", "z")]
    g = n // 4
    for k in (0, 1):
        w.topic("vehicle_imu", imu_f, {
            "timestamp": ts + k, "timestamp_sample": ts + k,
            "delta_angle": rng.normal(0, 0.01, (n, 3)).astype(np.float32),
            "delta_velocity": rng.normal([0, 0, -0.0981], 0.001, (n, 3)).astype(np.float32),
            "delta_angle_dt": np.full(n, 10_000, np.uint16), "delta_velocity_dt": np.full(n, 5_000, np.uint16)},
            multi_id=k)
        w.topic("sensor_gps", gps_f, {
            "timestamp": ts[::4] + k, "time_utc_usec": 1_700_000_000_000_000 + ts[::4] - 4_000_000,
            "latitude_deg": 47.0 + rng.normal(0, 1e-5, g), "longitude_deg": 8.0 + rng.normal(0, 1e-5, g),
            "altitude_msl_m": np.full(g, 400.0), "altitude_ellipsoid_m": np.full(g, 447.5),
            "eph": np.full(g, 0.8, np.float32), "epv": np.full(g, 1.2, np.float32),
            "vel_n_m_s": np.ones(g, np.float32), "vel_e_m_s": np.zeros(g, np.float32),
            "vel_d_m_s": np.zeros(g, np.float32), "timestamp_time_relative": np.zeros(g, np.int32),
            "fix_type": np.full(g, 3, np.uint8), "satellites_used": np.full(g, 12, np.uint8)}, multi_id=k)
        w.topic("sensor_mag", mag_f, {
            "timestamp": ts + k, "x": rng.normal(0.2, 0.01, n).astype(np.float32),
            "y": rng.normal(0.0, 0.01, n).astype(np.float32), "z": rng.normal(0.4, 0.01, n).astype(np.float32)},
            multi_id=k)
    w.topic("airspeed", F + [("float", "indicated_airspeed_m_s"), ("float", "true_airspeed_m_s"),
                             ("float", "air_temperature_celsius"), ("float", "confidence")], {
        "timestamp": ts, "indicated_airspeed_m_s": rng.uniform(15, 25, n).astype(np.float32),
        "true_airspeed_m_s": rng.uniform(15, 25, n).astype(np.float32),
        "air_temperature_celsius": np.full(n, 21.5, np.float32), "confidence": np.ones(n, np.float32)})
    w.topic("distance_sensor", F + [("float", "min_distance"), ("float", "max_distance"),
                                    ("float", "current_distance"), ("int8_t", "signal_quality"),
                                    ("uint8_t", "orientation")], {
        "timestamp": ts, "min_distance": np.full(n, 0.2, np.float32), "max_distance": np.full(n, 6.0, np.float32),
        "current_distance": np.array([0.1, 0.3, 2.0, 7.0, 4.0] * (n // 5), np.float32),
        "signal_quality": np.array([100, 100, 0, 100, -1] * (n // 5), np.int8),
        "orientation": np.full(n, 25, np.uint8)})
    w.topic("input_rc", F + [("uint32_t", "channel_count"), ("uint16_t[18]", "values")], {
        "timestamp": ts, "channel_count": np.full(n, 8, np.uint32),
        "values": rng.integers(1000, 2000, (n, 18)).astype(np.uint16)})
    w.topic("actuator_outputs", F + [("uint32_t", "noutputs"), ("float[16]", "output")], {
        "timestamp": ts + 2, "noutputs": np.full(n, 4, np.uint32),
        "output": rng.uniform(1000, 2000, (n, 16)).astype(np.float32)})
    w.topic("vehicle_status", F + [("uint8_t", "nav_state"), ("uint8_t", "arming_state")], {
        "timestamp": ts, "nav_state": np.repeat(np.array([0, 2, 2, 18], np.uint8), n // 4),
        "arming_state": np.array([1] * 6 + [2] * 28 + [1] * 6, np.uint8)})
    w.topic("vehicle_air_data", F + [("float", "baro_alt_meter"), ("float", "baro_temp_celcius"),
                                     ("float", "baro_pressure_pa")], {
        "timestamp": ts, "baro_alt_meter": rng.uniform(400, 410, n).astype(np.float32),
        "baro_temp_celcius": np.full(n, 30.0, np.float32),
        "baro_pressure_pa": rng.uniform(96000, 97000, n).astype(np.float32)})
    w.log("INFO", 5_000_100, "[commander] Armed by RC")
    return w.write(tmp / "synthetic.ulg"), {}


def flightcoach_json(tmp: Path) -> tuple[Path, dict]:
    """A FlightCoach export (positions, velocities, attitude in degrees, two maneuvers)."""
    n = 25
    data = [{"time": 1_000_000 + 40_000 * i, "N": float(i), "E": -2.0 * i, "D": -10.0 - 0.1 * i * i,
             "VN": 1.0, "VE": -2.0, "VD": -0.2 * i, "r": 10.0 + i, "p": 5.0, "yw": 90.0 + 2 * i}
            for i in range(n)]
    doc = {"version": "1.2", "parameters": {"rotation": 0.5, "originLat": 51.5, "originLng": -2.5,
                                            "originAlt": 5.0},
           "mans": [{"name": "tkoff", "start": 0, "stop": 8}, {"name": "loop", "start": 8, "stop": n}],
           "data": data}
    p = tmp / "flightcoach.json"
    p.write_text(json.dumps(doc))
    return p, {}


def tabular_parquet(tmp: Path) -> tuple[Path, dict]:
    """A column-mapped Parquet table (units converted by the map)."""
    df = helpers_tabular.table(np.random.default_rng(11), 30)
    cmap = helpers_tabular.column_map("goldenmap")
    p = tmp / "flight.parquet"
    df.to_parquet(p)
    return p, {"config": {"columnmaps": {"goldenmap": cmap}}}


#: fixture name -> builder(tmp folder) -> (log path, read_log keywords)
FIXTURES: dict[str, Callable[[Path], tuple[Path, dict]]] = {
    "dataflash_demo": demo_bin,
    "dataflash_sim": sim_bin,
    "tlog_sim": sim_tlog,
    "rosbag1_sim": sim_rosbag1,
    "rosbag2_mcap_sim": sim_rosbag2_mcap,
    "mcap_sim": sim_mcap_file,
    "ulog_synthetic": ulog_synthetic,
    "flightcoach_synthetic": flightcoach_json,
    "tabular_parquet": tabular_parquet,
}


# --- summaries --------------------------------------------------------------------------------

def _num(x) -> float | int | None:
    """``x`` rounded to :data:`SIG` significant figures (ints exact; NaN -> None)."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return None
    if isinstance(x, (int, np.integer)):
        return int(x)
    return float(f"{float(x):.{SIG}g}")


def summarise_frame(df: pd.DataFrame) -> dict:
    """Rows, columns, first/last ``t_ns`` and per-column statistics of one stream."""
    out: dict = {"rows": int(len(df)), "columns": [str(c) for c in df.columns]}
    if "t_ns" in df.columns and len(df):
        t = df["t_ns"].to_numpy(dtype=np.int64)
        out["t_ns_first"], out["t_ns_last"] = int(t[0]), int(t[-1])
    stats = {}
    for c in df.columns:
        s = df[c]
        if pd.api.types.is_bool_dtype(s.dtype):
            v = s.dropna().astype(bool)
            stats[c] = {"true": int(v.sum()), "false": int((~v).sum()), "na": int(s.isna().sum())}
        elif pd.api.types.is_numeric_dtype(s.dtype):
            v = s.dropna().to_numpy(dtype=np.float64)
            v = v[np.isfinite(v)]
            stats[c] = {"n": int(v.size), "mean": _num(v.mean()) if v.size else None,
                        "min": _num(v.min()) if v.size else None, "max": _num(v.max()) if v.size else None}
        else:
            vals = sorted({str(x) for x in s.dropna()})
            stats[c] = {"n": int(s.notna().sum()), "distinct": len(vals), "values": vals[:MAX_VALUES]}
    out["stats"] = stats
    return out


def summarise(path: Path, **read_kw) -> dict:
    """The golden summary of one log: reader, status and every non-empty stream.

    Streams are reached through the public ``log[name]`` DataFrame access only.
    """
    log = read_log(path, **read_kw)
    streams, empty = {}, []
    for name in schema.STREAM_NAMES:
        df = log[name]
        if len(df):
            streams[name] = summarise_frame(df)
        else:
            empty.append(name)
    return {"reader": log.meta.get("reader"), "status": log.meta.get("status"),
            "streams": streams, "empty_streams": empty}


def build(name: str, tmp: Path) -> dict:
    """Write fixture ``name`` under ``tmp`` and return its summary."""
    path, kw = FIXTURES[name](tmp)
    return summarise(path, **kw)


def golden_path(name: str) -> Path:
    return GOLDEN / f"{name}.json"


def dumps(summary: dict) -> str:
    return json.dumps(summary, indent=1, sort_keys=True, allow_nan=False) + "\n"


def diff(golden, current, where: str = "") -> list[str]:
    """Readable differences ``path: golden -> current`` between two summaries (numbers equal
    within 1e-5 relative, so a last-digit rounding flip is not a change)."""
    if isinstance(golden, dict) and isinstance(current, dict):
        out = []
        for k in sorted(set(golden) | set(current)):
            w = f"{where}/{k}" if where else str(k)
            if k not in current:
                out.append(f"{w}: {json.dumps(golden[k])[:120]} -> (missing)")
            elif k not in golden:
                out.append(f"{w}: (new) -> {json.dumps(current[k])[:120]}")
            else:
                out.extend(diff(golden[k], current[k], w))
        return out
    if isinstance(golden, float) or isinstance(current, float):
        if (isinstance(golden, (int, float)) and isinstance(current, (int, float))
                and math.isclose(golden, current, rel_tol=1e-5, abs_tol=1e-12)):
            return []
    if golden != current:
        return [f"{where}: {json.dumps(golden)[:120]} -> {json.dumps(current)[:120]}"]
    return []


def main(argv: list[str]) -> int:
    names = argv or list(FIXTURES)
    unknown = [n for n in names if n not in FIXTURES]
    if unknown:
        print(f"unknown fixture(s) {unknown}; known: {', '.join(FIXTURES)}", file=sys.stderr)
        return 2
    GOLDEN.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            summary = build(name, Path(tmp))
            p = golden_path(name)
            old = json.loads(p.read_text()) if p.exists() else None
            p.write_text(dumps(summary))
            changes = diff(old, summary) if old is not None else ["(new file)"]
            print(f"{p.relative_to(GOLDEN.parents[2])}: {len(changes)} change(s)")
            for line in changes[:40]:
                print(f"  {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
