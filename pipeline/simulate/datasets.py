"""The seed-000 simulated data sets: bulk Parquet sets, a few log files, a summary table.

``run_simulate(out_dir, sim_cfg, seed)`` (the ``uavpipe simulate`` command and, later, the
workflow's simulate rule) writes under ``out_dir``:

* ``sets/<M>_train.parquet``, ``sets/<M>_test.parquet`` — per maneuver M1–M5, ``runs`` runs
  (thesis: 2300) split at random 70/30 (``train_fraction``), truth at ``truth_rate_hz`` (5 Hz);
* ``sets/mc_<M>.parquet`` — ``mc_runs`` padded Monte Carlo runs (same start, new disturbance);
* ``sets/switch_<A-D>_<t>s.parquet`` — ``switch_runs`` runs per change scenario and switch time;
* ``logs/`` — ``log_flights`` padded flights per maneuver plus one calibration flight, each
  written in every format of ``log_formats`` (``bin``, ``tlog``, ``bag``, ``mcap``) with its
  ``<log>.truth.parquet`` side-car, and ``logs/flights.tsv`` (manifest rows: flight_id, path,
  vehicle, role, labels, format, notes);
* ``summary.parquet`` — per maneuver and NED/heading axis: min, max and RMS of acceleration
  and jerk over all runs of the maneuver at the full truth rate (:class:`SummaryAccumulator`);
* ``index.json`` — what was written, with sizes, seeds and the config used.

Bulk sets are one Parquet file per set in the ``state`` column schema (``schema.STATE``) plus
``run_id`` (int64) and ``label`` (string), so models read them exactly as preprocessed
flights. ``alt_cal_m`` is the true altitude, ``gap`` is False, sticks come from the commands,
``thrust_N`` is the commanded (= realised) thrust; state columns with no quadcopter
counterpart (control-surface deflections) are NaN.

Sizes (``simulate.datasets``): ``size`` [small] picks a row of ``sizes``:
``small`` {runs: 60, mc_runs: 20, switch_runs: 10, log_flights: 1} (minutes on 2 cores) or
``thesis`` {runs: 2300, mc_runs: 1000, switch_runs: 243, log_flights: 3}; ``batch_runs`` [100]
runs are integrated at once; ``train_fraction`` [0.7]; ``truth_rate_hz`` [5];
``log_formats`` [[bin, tlog, bag, mcap]]; ``start_time_utc`` (top level of ``simulate``,
["2026-01-01T12:00:00Z"]) is the UTC time of every flight's t = 0 — never the wall clock.

Seeding: every set draws from ``np.random.default_rng([seed, crc32(set name), chunk])``, so a set
does not depend on which other sets were generated; same seed -> byte-identical files.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..config import ConfigError, build, cfield, default_at, validate_section
from ..io import schema
from ..io.parquet import write_json, write_table
from . import maneuvers as mv
from .quadcopter import Truth, rotate_to_heading
from .scenarios import SimSettings, run_named
from .seeds import set_rng
from .sensors import SensorSettings, sticks
from .writers import write_flight_logs

#: the columns of a bulk set and of the summary (declared with every table in io.schema)
SET_COLUMNS: tuple[schema.Column, ...] = schema.SIM_SET
SUMMARY_COLUMNS: tuple[schema.Column, ...] = schema.SIM_SUMMARY

_sim = functools.partial(cfield, "simulate")


def size_row(sim_sec: Mapping[str, Any]) -> dict[str, int]:
    """The run counts of ``simulate.datasets.size`` (a key of ``simulate.datasets.sizes``)."""
    sec = dict(sim_sec.get("datasets") or {})
    size = sec.get("size", default_at("simulate.datasets.size"))
    sizes = sec.get("sizes") or default_at("simulate.datasets.sizes")
    if size not in sizes:
        raise ConfigError(f"simulate.datasets.size: {size!r} is not one of {', '.join(sizes)}")
    return {k: int(v) for k, v in sizes[size].items()}


def _count(name: str):
    return _sim(lambda sec: size_row(sec)[name], default_path=f"simulate.datasets.sizes.small.{name}")


def utc_ns(iso: str) -> int:
    """ISO 8601 time (``Z`` or an offset; naive = UTC) -> Unix ns."""
    try:
        dt = datetime.fromisoformat(str(iso).replace("Z", "+00:00"))
    except ValueError as exc:
        raise ConfigError(f"simulate.start_time_utc: {exc}") from None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=timezone.utc)
    return int(round(dt.timestamp())) * 10 ** 9 + dt.microsecond * 1000


@dataclass(frozen=True, kw_only=True)
class DatasetSettings:
    """Sizes and formats of the simulated sets (``simulate.datasets`` and
    ``simulate.start_time_utc``); built from the whole ``simulate`` section, defaults from the
    config schema."""

    runs: int = _count("runs")
    mc_runs: int = _count("mc_runs")
    switch_runs: int = _count("switch_runs")
    log_flights: int = _count("log_flights")
    batch_runs: int = _sim("datasets.batch_runs")
    train_fraction: float = _sim("datasets.train_fraction")
    truth_rate_hz: float = _sim("datasets.truth_rate_hz")
    log_formats: tuple[str, ...] = _sim("datasets.log_formats")
    start_time_utc_ns: int = _sim("start_time_utc", convert=utc_ns)
    maneuvers: tuple[str, ...] = _sim("datasets.maneuvers")
    extra: dict = field(default_factory=dict, metadata={"config_key": None})

    @classmethod
    def from_config(cls, sim_sec: Mapping[str, Any] | None) -> "DatasetSettings":
        """Validate a ``simulate`` section against the schema and build (ConfigError if bad)."""
        return build(cls, validate_section("simulate", sim_sec))


def state_table(truth: Truth, step: int, sensors: SensorSettings, run_offset: int = 0) -> pd.DataFrame:
    """Rows of all runs (every ``step``-th sample) in :data:`SET_COLUMNS`."""
    tr = truth.subsample(step)
    n_runs, n_t = tr.pos.shape[:2]
    cols: dict[str, np.ndarray] = {"t_ns": np.tile(np.round(tr.t_s * 1e9).astype(np.int64), n_runs)}
    for name, arr, unit in (("pos", tr.pos, "m"), ("vel", tr.vel, "mps"), ("acc", tr.acc, "mps2"),
                            ("jerk", tr.jerk, "mps3")):
        for i, a in enumerate("ned"):
            cols[f"{name}_{a}_{unit}"] = arr[..., i].ravel()
    for i, c in enumerate("wxyz"):
        cols[f"q_{c}"] = tr.quat[..., i].ravel()
    for i, c in enumerate(("roll_rad", "pitch_rad", "yaw_rad")):
        cols[c] = tr.euler[..., i].ravel()
    for i, c in enumerate(("p_radps", "q_radps", "r_radps")):
        cols[c] = tr.rates[..., i].ravel()
    st = sticks(tr, sensors.control)
    for k in ("ail", "ele", "rud", "thr"):
        cols[k] = np.ascontiguousarray(st[k]).ravel()
    cols["alt_cal_m"] = -tr.pos[..., 2].ravel()
    cols["gap"] = np.zeros(n_runs * n_t, bool)
    if any(c.name == "thrust_N" for c in schema.STATE):
        cols["thrust_N"] = tr.thrust_N.ravel()
    for c in schema.STATE:  # columns without a simulated counterpart (fixed-wing deflections)
        if c.name not in cols:
            cols[c.name] = np.full(n_runs * n_t, np.nan)
    cols["run_id"] = np.repeat(np.arange(run_offset, run_offset + n_runs, dtype=np.int64), n_t)
    cols["label"] = pd.array(np.tile(tr.label.astype(str), n_runs), dtype="string")
    return pd.DataFrame(cols)


def _chunks(n: int, size: int):
    for k, lo in enumerate(range(0, n, size)):
        yield k, lo, min(n, lo + size)


def simulate_set(kind: str, name: str, n_runs: int, settings: SimSettings, ds: DatasetSettings,
                 sensors: SensorSettings, seed: int, set_name: str, t_switch: float | None = None,
                 on_truth=None) -> pd.DataFrame:
    """Integrate one set in chunks of ``batch_runs`` and return its table; ``on_truth(truth)`` sees
    each full-rate chunk (e.g. :meth:`SummaryAccumulator.add`) before it is dropped."""
    step = settings.decimation(ds.truth_rate_hz, "simulate.datasets.truth_rate_hz")
    parts = []
    for k, lo, hi in _chunks(n_runs, ds.batch_runs):
        tr = run_named(kind, settings, hi - lo, set_rng(seed, set_name, k), name, t_switch)
        parts.append(state_table(tr, step, sensors, lo))
        if on_truth is not None:
            on_truth(tr)
    return pd.concat(parts, ignore_index=True)


SUMMARY_AXES = ("n", "e", "d", "fwd", "right", "down", "norm")


class SummaryAccumulator:
    """Streaming min / max / RMS of acceleration and jerk per maneuver and axis, so a
    thesis-sized set never has to sit in memory at the full truth rate.

    Axes: NED ``n``/``e``/``d``, heading-frame ``fwd``/``right``/``down`` (the run's start
    heading) and the vector ``norm``; all samples of all runs at the truth rate.
    """

    def __init__(self) -> None:
        self._acc: dict[tuple[str, str, str], list[float]] = {}
        self._runs: dict[str, int] = {}

    def add(self, man: str, truth: Truth) -> None:
        self._runs[man] = self._runs.get(man, 0) + truth.n_runs
        for q in ("acc", "jerk"):
            arr = getattr(truth, q)
            hf = rotate_to_heading(arr, truth.yaw0)
            series = {"n": arr[..., 0], "e": arr[..., 1], "d": arr[..., 2],
                      "fwd": hf[..., 0], "right": hf[..., 1], "down": hf[..., 2],
                      "norm": np.linalg.norm(arr, axis=-1)}
            for ax, v in series.items():
                key = (man, q, ax)
                lo, hi, ss, n = self._acc.get(key, [np.inf, -np.inf, 0.0, 0])
                self._acc[key] = [min(lo, float(v.min())), max(hi, float(v.max())),
                                  ss + float(np.sum(v * v)), n + v.size]

    def table(self) -> pd.DataFrame:
        rows = [{"maneuver": m, "quantity": q, "axis": ax, "min": lo, "max": hi,
                 "rms": float(np.sqrt(ss / n)), "n_runs": int(self._runs[m])}
                for (m, q, ax), (lo, hi, ss, n) in self._acc.items()]
        return pd.DataFrame(rows, columns=[c.name for c in SUMMARY_COLUMNS])


def summary_table(truths: dict[str, list[Truth]]) -> pd.DataFrame:
    """Per maneuver, quantity (acc, jerk) and axis: min, max, RMS over all samples of all runs
    (see :class:`SummaryAccumulator`)."""
    acc = SummaryAccumulator()
    for man, trs in truths.items():
        for t in trs:
            acc.add(man, t)
    return acc.table()


def run_simulate(out_dir: str | os.PathLike, sim_cfg: dict | None, seed: int, *,
                 progress=None) -> dict:
    """Generate every set, the log files and the summary under ``out_dir`` (see module doc)."""
    out = Path(out_dir)
    settings = SimSettings.from_config(sim_cfg)
    sensors = SensorSettings.from_config(sim_cfg)
    ds = DatasetSettings.from_config(sim_cfg)
    say = progress or (lambda msg: None)
    index: dict[str, Any] = {"seed": int(seed), "sets": {}, "logs": [], "config": sim_cfg or {}}

    # per-maneuver train/test
    summary = SummaryAccumulator()
    for man in ds.maneuvers:
        df = simulate_set("maneuver", man, ds.runs, settings, ds, sensors, seed, f"maneuver/{man}",
                          on_truth=lambda tr, m=man: summary.add(m, tr))
        rng = set_rng(seed, f"split/{man}")
        perm = rng.permutation(ds.runs)
        n_train = int(round(ds.train_fraction * ds.runs))
        train_ids = np.sort(perm[:n_train])
        is_train = np.isin(df["run_id"].to_numpy(), train_ids)
        for part, mask in (("train", is_train), ("test", ~is_train)):
            p = out / "sets" / f"{man}_{part}.parquet"
            _write_set(df[mask].reset_index(drop=True), p, f"{man}_{part}", seed)
            index["sets"][f"{man}_{part}"] = {"path": str(p.relative_to(out)),
                                              "runs": int(df.loc[mask, "run_id"].nunique())}
        say(f"maneuver {man}: {ds.runs} runs")
    write_table(summary.table(), out / "summary.parquet", SUMMARY_COLUMNS, name="simulate_summary",
                extra={"seed": int(seed)})

    for man in ds.maneuvers:
        name = f"mc_{man}"
        df = simulate_set("mc", man, ds.mc_runs, settings, ds, sensors, seed, name)
        _write_set(df, out / "sets" / f"{name}.parquet", name, seed)
        index["sets"][name] = {"path": f"sets/{name}.parquet", "runs": ds.mc_runs}
        say(f"monte carlo {man}: {ds.mc_runs} runs")

    for key in mv.SWITCHES:
        for ts in settings.switch_times_s:
            name = f"switch_{key}_{ts:g}s"
            df = simulate_set("switch", key, ds.switch_runs, settings, ds, sensors, seed, name, t_switch=ts)
            _write_set(df, out / "sets" / f"{name}.parquet", name, seed)
            index["sets"][name] = {"path": f"sets/{name}.parquet", "runs": ds.switch_runs}
        say(f"switch scenario {key}: {ds.switch_runs} runs x {len(settings.switch_times_s)} times")

    if ds.log_formats and ds.log_flights > 0:
        index["logs"] = write_flight_logs(out / "logs", settings, sensors, ds, seed, say=say)
    write_json(index, out / "index.json")
    return index


def _write_set(df: pd.DataFrame, path: Path, name: str, seed: int) -> None:
    write_table(df, path, SET_COLUMNS, name="simulate_set",
                extra={"set": name, "seed": int(seed), "runs": int(df["run_id"].nunique()) if len(df) else 0})
