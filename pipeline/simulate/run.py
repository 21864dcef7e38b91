"""Workflow entry points of the simulation stage, with output names fixed by the config.

The workflow's DAG is static (no checkpoints), so the simulate rules must know every file they
write before running. :func:`planned_sets` and :func:`planned_logs` derive those names from the
``simulate`` config section exactly as :func:`pipeline.simulate.datasets.run_simulate` and
:func:`pipeline.simulate.writers.write_flight_logs` name them; :func:`run_simulate_sets` and
:func:`run_simulate_logs` run the two halves separately so the bulk sets and the log-file flights
are independent jobs (a change of a log format does not regenerate the bulk sets).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..io.sidecar import sidecar_path


def _settings(sim_cfg: dict | None):
    from .datasets import DatasetSettings
    from .scenarios import SimSettings

    return SimSettings.from_config(sim_cfg), DatasetSettings.from_config(sim_cfg)


def planned_sets(sim_cfg: dict | None) -> list[str]:
    """Set names written under ``sets/`` (``<M>_train``, ``<M>_test``, ``mc_<M>``, ``switch_<k>_<t>s``)."""
    from .maneuvers import SWITCHES

    settings, ds = _settings(sim_cfg)
    names = [f"{m}_{part}" for m in ds.maneuvers for part in ("train", "test")]
    names += [f"mc_{m}" for m in ds.maneuvers]
    names += [f"switch_{k}_{t:g}s" for k in SWITCHES for t in settings.switch_times_s]
    return names


def planned_logs(sim_cfg: dict | None) -> list[dict]:
    """The log-file flights: ``[{flight_id, log, sidecar, is_dir}]`` with paths relative to the
    logs folder (the ``mcap`` format is a ROS 2 bag *directory*)."""
    from .writers import LOG_NAMES

    _, ds = _settings(sim_cfg)
    if not ds.log_formats or ds.log_flights <= 0:
        return []
    stems = [f"sim-{m}-{k:03d}" for m in ds.maneuvers for k in range(ds.log_flights)]
    stems.append("sim-calibration-000")
    out = []
    for stem in stems:
        for fmt in ds.log_formats:
            name = LOG_NAMES[fmt](stem)
            out.append({"flight_id": f"{stem}-{fmt}", "log": name, "sidecar": sidecar_path(name).name,
                        "is_dir": fmt == "mcap"})
    return out


def run_simulate_sets(out_dir: str | os.PathLike, sim_cfg: dict | None, seed: int) -> dict:
    """Bulk sets, ``summary.parquet`` and ``index.json`` under ``out_dir`` (no log files)."""
    from .datasets import run_simulate

    sim = dict(sim_cfg or {})
    sim["datasets"] = {**(sim.get("datasets") or {}), "log_formats": []}
    return run_simulate(out_dir, sim, seed, progress=_say)


def run_simulate_logs(out_dir: str | os.PathLike, sim_cfg: dict | None, seed: int) -> list[dict]:
    """The log-file flights and their truth side-cars plus ``flights.tsv`` under ``out_dir``."""
    from .sensors import SensorSettings
    from .writers import write_flight_logs

    settings, ds = _settings(sim_cfg)
    return write_flight_logs(Path(out_dir), settings, SensorSettings.from_config(sim_cfg), ds, seed, say=_say)


def _say(msg: str) -> None:
    import sys

    print(f"uavpipe simulate: {msg}", file=sys.stderr, flush=True)
