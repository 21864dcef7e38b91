"""Write a simulated flight as real log files: DataFlash ``.bin``, MAVLink ``.tlog``, ROS 1 bag,
ROS 2 bag with MCAP storage — each with its ``<log>.truth.parquet`` side-car.

This module only orchestrates: it simulates the sensor streams of one flight
(:func:`pipeline.simulate.sensors.all_streams`) and hands them to the io writers, which take
canonical streams and write files:

* **DataFlash** :func:`pipeline.io.dataflash.writer.write_bin` (catalogue layout
  ``ardupilot4``), with PARM ``RADR_SN/SE/SD`` (radar site, NED m), ``RADR_TAU`` (s) and the
  frame parameters, firmware banner ``ArduCopter V4.5.0 (uavpipe simulation)``;
* **tlog** :func:`pipeline.io.tlog_writer.write_tlog_streams`;
* **ROS 1 bag / ROS 2 MCAP bag** :func:`pipeline.io.ros_writer.write_ros1`,
  :func:`pipeline.io.ros_writer.write_ros2_mcap`.

Every time derives from the configured start time ``t0_utc_ns`` (``simulate.start_time_utc``)
and the simulation clock, never the wall clock; the vehicle "boots" :data:`BOOT_US` before
t = 0. The writers are pure functions of the streams, so the same seed gives the same bytes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import pandas as pd

from ..io import schema
from ..io.dataflash.writer import write_bin
from ..io.ros_writer import write_ros1, write_ros2_mcap
from ..io.sidecar import sidecar_path, write_sidecar
from ..io.tlog_writer import write_tlog_streams
from .scenarios import run_scenario, scenario_for
from .seeds import set_rng
from .sensors import all_streams, labels_table, truth_stream

#: boot time of the simulated vehicle at the flight's t = 0 (µs)
BOOT_US = 5_000_000


# --- one flight in every format ----------------------------------------------------------

LOG_NAMES: dict[str, Callable[[str], str]] = {
    "bin": lambda s: f"{s}.bin",
    "tlog": lambda s: f"{s}.tlog",
    "bag": lambda s: f"{s}.bag",
    "mcap": lambda s: f"{s}-mcap",
}


def write_flight(out_dir: Path, stem: str, truth, sensors, params, rate_hz: float, rng, *,
                 t0_utc_ns: int, formats=("bin", "tlog", "bag", "mcap")
                 ) -> tuple[dict[str, Path], dict[str, pd.DataFrame]]:
    """Simulate run 0 of ``truth``'s sensors (one draw of ``rng``) and write it in ``formats``,
    each with its side-car. Returns ``({format: path}, streams)``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    streams = all_streams(truth, sensors, params, rate_hz, rng)
    tdf, lab = truth_stream(truth), labels_table(truth)
    o = sensors.origin
    # the frame the truth's positions are in, for formats that cannot carry it (a ROS bag has
    # no navigation origin: its reader takes the first fix, 560 m from this one on sim-M1)
    frame = {"ned_origin": {"lat_deg": float(o[0]), "lon_deg": float(o[1]), "alt_wgs84_m": float(o[2]),
                            "alt_msl_m": float(o[2]) - float(sensors.geoid_undulation_m)},
             "radar": {"site_ned_m": [float(v) for v in sensors.radar.site_ned_m],
                       "tau_rd_s": float(sensors.radar.tau_rd_s)}}
    paths = {}
    limits = (float(sensors.rangefinder["min_m"]), float(sensors.rangefinder["max_m"]))
    for fmt in formats:
        p = out_dir / LOG_NAMES[fmt](stem)
        if fmt == "bin":
            site = sensors.radar.site_ned_m
            parm = {"RADR_SN": float(site[0]), "RADR_SE": float(site[1]), "RADR_SD": float(site[2]),
                    "RADR_TAU": float(sensors.radar.tau_rd_s),
                    "FRAME_CLASS": 1.0, "FRAME_TYPE": 1.0, "RNGFND1_ORIENT": 25.0}
            write_bin(p, streams, t0_utc_ns=t0_utc_ns, boot_us=BOOT_US, params=parm,
                      message="ArduCopter V4.5.0 (uavpipe simulation)", origin=o,
                      undulation_m=sensors.geoid_undulation_m)
        elif fmt == "tlog":
            write_tlog_streams(p, streams, t0_utc_ns=t0_utc_ns, duration_s=float(truth.t_s[-1]),
                               boot_us=BOOT_US, origin=o, undulation_m=sensors.geoid_undulation_m,
                               range_limits_m=limits)
        elif fmt == "bag":
            write_ros1(p, streams, t0_utc_ns=t0_utc_ns, range_limits_m=limits)
        elif fmt == "mcap":
            write_ros2_mcap(p, streams, t0_utc_ns=t0_utc_ns, range_limits_m=limits)
        else:
            raise ValueError(f"unknown log format {fmt!r}")
        write_sidecar(sidecar_path(p), tdf, lab, t0_utc_ns=t0_utc_ns,
                      extra={"scenario": truth.meta.get("scenario"), "format": fmt, **frame})
        paths[fmt] = p
    return paths, streams


def write_flight_logs(out_dir: Path, settings, sensors, ds, seed: int, say=lambda m: None) -> list[dict]:
    """``log_flights`` padded flights per maneuver (random start/heading) + one calibration
    flight, in every configured format; writes ``out_dir/flights.tsv``. Returns manifest rows."""
    rows = []
    jobs = [("mc", m, k) for m in ds.maneuvers for k in range(ds.log_flights)] + [("calibration", None, 0)]
    for kind, man, k in jobs:
        stem = f"sim-{man}-{k:03d}" if man else "sim-calibration-000"
        rng = set_rng(seed, f"log/{stem}")
        sc = scenario_for(kind, settings, man)
        if kind == "calibration":
            tr = run_scenario(sc, settings, 1, rng, vel0_zero=True, vertical_disturbance=False)
        else:
            tr = run_scenario(sc, settings, 1, rng, min_alt_m=settings.switch_min_alt_m)
        paths, _ = write_flight(out_dir, stem, tr, sensors, settings.vehicle, settings.rate_hz, rng,
                                t0_utc_ns=ds.start_time_utc_ns, formats=ds.log_formats)
        for fmt, p in paths.items():
            rows.append({"flight_id": f"{stem}-{fmt}", "path": str(p), "vehicle": "sim-quad",
                         "role": "test", "labels": str(sidecar_path(p)), "format": "",
                         "notes": f"simulated {sc.name} ({fmt})"})
        say(f"log files {stem}: {', '.join(paths)}")
    df = pd.DataFrame(rows, columns=schema.column_names("flights"))
    out_dir.mkdir(parents=True, exist_ok=True)
    df.to_csv(out_dir / "flights.tsv", sep="\t", index=False)
    return rows
