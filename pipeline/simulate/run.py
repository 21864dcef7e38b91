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
from dataclasses import dataclass
from pathlib import Path

from ..io.sidecar import sidecar_path
from ..io.stage import declared, declared_list


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
    from .sensors import SensorSettings, sensor_steps
    from .writers import LOG_NAMES

    settings, ds = _settings(sim_cfg)
    if not ds.log_formats or ds.log_flights <= 0:
        return []
    # the workflow plans the logs at start-up: a sensor rate the writer would refuse stops the
    # run here, in one line, not in the first simulate job
    sensor_steps(SensorSettings.from_config(sim_cfg), settings.rate_hz)
    stems = [f"sim-{m}-{k:03d}" for m in ds.maneuvers for k in range(ds.log_flights)]
    stems.append("sim-calibration-000")
    out = []
    for stem in stems:
        for fmt in ds.log_formats:
            name = LOG_NAMES[fmt](stem)
            out.append({"flight_id": f"{stem}-{fmt}", "log": name, "sidecar": sidecar_path(name).name,
                        "is_dir": fmt == "mcap"})
    return out


@dataclass(frozen=True)
class SimulateResult:
    """What a simulate entry point wrote: the paths, and the index/manifest rows."""

    paths: tuple[str, ...]
    diagnostics: dict






def _check_written(declared: list[str], written: list[str], what: str) -> None:
    # the DAG is static: the planned names must be exactly what the simulation wrote
    missing = sorted(set(map(os.path.normpath, declared)) - set(map(os.path.normpath, written)))
    if missing:
        raise RuntimeError(f"simulate {what}: declared outputs not written: {missing[:5]}"
                           f"{' …' if len(missing) > 5 else ''}")


def run_simulate_sets(inputs, outputs, config: dict | None, *, seed: int) -> SimulateResult:
    """Bulk sets, ``summary.parquet`` and ``index.json`` (no log files).

    Parameters
    ----------
    inputs : mapping
        Unused (the simulation has no inputs); kept for the one entry-point signature.
    outputs : mapping
        ``sets`` (``<dir>/sets/<name>.parquet`` for every :func:`planned_sets` name),
        ``summary`` and ``index`` (``<dir>/summary.parquet``, ``<dir>/index.json``).
    config : dict
        The ``simulate`` section.
    seed : int
        The master seed.
    """
    from .datasets import run_simulate

    out_dir = Path(declared(outputs, "index")).parent
    sim = dict(config or {})
    sim["datasets"] = {**(sim.get("datasets") or {}), "log_formats": []}
    index = run_simulate(out_dir, sim, seed, progress=_say)
    written = [str(out_dir / v["path"]) for v in index["sets"].values()]
    _check_written(declared_list(outputs, "sets"), written, "sets")
    return SimulateResult(paths=tuple(written), diagnostics=index)


def run_simulate_logs(inputs, outputs, config: dict | None, *, seed: int) -> SimulateResult:
    """The log-file flights and their truth side-cars plus ``flights.tsv``.

    ``outputs``: ``logs`` (files, and the ``mcap`` bag directories), ``sidecars`` and
    ``manifest`` (``<dir>/flights.tsv``), all in one folder; names from :func:`planned_logs`.
    """
    from .sensors import SensorSettings
    from .writers import write_flight_logs

    out_dir = Path(declared(outputs, "manifest")).parent
    settings, ds = _settings(config)
    rows = write_flight_logs(out_dir, settings, SensorSettings.from_config(config), ds, seed, say=_say)
    _check_written(declared_list(outputs, "logs") + declared_list(outputs, "sidecars"),
                   [r["path"] for r in rows] + [r["labels"] for r in rows], "logs")
    return SimulateResult(paths=tuple(r["path"] for r in rows), diagnostics={"flights": rows})


def run_demo_log(inputs, outputs, config: dict | None, *, seed: int) -> SimulateResult:
    """The demo DataFlash flight (``outputs.log``): uavpipe's own writer, always available."""
    from .demo import write_demo_flight

    path = declared(outputs, "log")
    write_demo_flight(path, seed=seed)
    return SimulateResult(paths=(str(path),), diagnostics={})


def _say(msg: str) -> None:
    import sys

    print(f"uavpipe simulate: {msg}", file=sys.stderr, flush=True)
