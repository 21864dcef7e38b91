"""Shared plumbing of the studies: sizes, output paths, ``results.txt``, markdown tables, the page,
and :func:`run_calls` (independent runs on worker processes).

A study is a stage like the others (entry point ``run_<study>(inputs, outputs, config, *, seed,
...)``), run by its own Snakemake target (``rules/studies.smk``), never by ``all``. Each one
writes ``results/studies/<name>/`` (Parquet tables, ``report.md``, ``results.txt`` with its
headline figures as ``RESULT <metric> <value>`` lines, also printed to stderr, the rule's log)
and an offline page ``results/report/studies/<name>.html``.

``config`` is the ``studies`` section of the dataset config::

    studies:
      size: small                    # tiny (tests, seconds) | small (minutes) | thesis
      <study name>:
        <setting>: <value>           # the study's own settings (every size)
        sizes:                       # per-size settings, overriding the above
          tiny: {...}
          small: {...}
          thesis: {...}
"""

from __future__ import annotations

import copy
import dataclasses
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..config import ROOT, ConfigError
from ..io.atomic import write_text_atomic

#: the study sizes, smallest first
SIZES = ("tiny", "small", "thesis")
DEFAULT_SIZE = "small"

#: the Parquet tables each study writes (``results/studies/<name>/<table>.parquet``); kept here,
#: beside the output layout, so the rules need not import the studies themselves
STUDY_TABLES: dict[str, tuple[str, ...]] = {
    "seed000_classification": ("tables_3_1_3_4", "confusion", "switch_tables", "switch_shift",
                               "gmr_error", "gmr_rmse", "ekf_tables", "ekf_switch_tables"),
    "flightcoach_classification": ("p23_segments", "p23_timeline", "f23_segments", "oneclass_slack_sweep"),
    "flightcoach_ekf_hmm": ("maneuvers", "train_maneuvers", "tuning", "timeline"),
    "seed000_ekf": ("q_tuning", "mc_time", "mc_rmse", "q2_tuning", "scenarios", "hmm_rmse", "hmm_time"),
    "pf": ("hmpf_runs", "hmpf_timeline", "geo_summary", "geo_series", "geo_config", "geo_timing"),
    "trajectory_learning": ("sim_cases", "sim_summary", "real_loo", "real_summary"),
    "bearing_only": ("curves", "runs", "trends", "crlb", "study3"),
}
#: the FlightCoach study's flights: ``{input name: file under <realdata_dir>/<FLIGHTCOACH_DIR>}``
FLIGHTCOACH_DIR = "flightcoach_f3a_json"
FLIGHTCOACH_FILES = {
    "train": "manual_F3A_P23_22_02_18_00000036.json",
    "test_p23": "manual_F3A_P23_22_05_31_00000350.json",
    "test_f23": "manual_F3A_F23_22_02_18_00000035.json",
    "calib": "UK_England_Bristol_AMARC2002_F3A_P21_21_08_12_00000026.json",
}
#: the FlightCoach EKF+HMM study's flights (train on P23 #36, test on P23 #350)
FLIGHTCOACH_EKF_HMM_FILES = {"train": FLIGHTCOACH_FILES["train"], "test": FLIGHTCOACH_FILES["test_p23"]}


class StudyError(ValueError):
    """A study cannot run (missing input data, bad setting); the message names the file or key."""


@dataclass(frozen=True, kw_only=True)
class StudyResult:
    """What a study returns: ``status`` (``ok``), its headline figures and diagnostics.

    Attributes
    ----------
    name : str
        Study name (``seed000_classification``, ...).
    status : str
        ``ok`` when every output was written.
    results : dict
        ``{metric: value}`` as written to ``results.txt`` (values are the printed strings).
    diagnostics : dict
        Size, seed, wall time and the settings used.
    """

    name: str
    status: str
    results: dict[str, str] = field(default_factory=dict)
    diagnostics: dict[str, Any] = field(default_factory=dict)


def run_calls(fn: Callable[..., Any], calls: Sequence[Mapping[str, Any]], workers: int = 1, *,
              cost: Callable[[int], float] | None = None) -> Iterator[Any]:
    """Yield ``fn(**kw)`` for each ``kw`` of ``calls``, in their order.

    With ``workers`` > 1 (and more than one call) the calls run on that many worker processes,
    all submitted at once (the largest ``cost(i)`` first, so a long call does not start last and
    finish alone), and each result is yielded in the planned order once it is ready, then
    dropped: a caller that keeps only what it needs holds little. Otherwise they run here, one
    at a time, as they are asked for. Each call must depend on its arguments alone (its own
    seed), so the results are the same for any worker count. Calls not yet started are cancelled
    when the caller stops early or a call raises (use ``contextlib.closing`` to stop at once).
    """
    calls = list(calls)
    if workers <= 1 or len(calls) <= 1:
        for kw in calls:
            yield fn(**kw)
        return
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(max_workers=int(workers))
    try:
        order = sorted(range(len(calls)), key=lambda i: -cost(i)) if cost else range(len(calls))
        futs = {i: pool.submit(fn, **calls[i]) for i in order}
        for i in range(len(calls)):
            yield futs.pop(i).result()
    finally:
        pool.shutdown(cancel_futures=True)


def study_settings(config: Mapping | None, name: str, defaults: Mapping[str, Any],
                   sizes: Mapping[str, Mapping[str, Any]]) -> tuple[str, dict[str, Any]]:
    """The size and the merged settings of one study.

    Parameters
    ----------
    config : mapping or None
        The ``studies`` config section.
    name : str
        Study name: its settings are ``config[name]``.
    defaults : mapping
        The study's default settings (every size).
    sizes : mapping
        The study's default per-size settings, ``{size: {setting: value}}``.

    Returns
    -------
    size : str
        ``config['size']`` (default ``small``).
    settings : dict
        ``defaults``, overridden by ``config[name]``, overridden by the size's entry of
        ``sizes`` and then of ``config[name]['sizes']``.
    """
    config = dict(config or {})
    size = config.get("size", DEFAULT_SIZE)
    if size not in SIZES:
        raise ConfigError(f"studies.size: {size!r} is not one of {', '.join(SIZES)}")
    own = dict(config.get(name) or {})
    own_sizes = dict(own.pop("sizes", None) or {})
    bad = sorted(set(own) - set(defaults))
    if bad:
        raise ConfigError(f"studies.{name}: unknown key(s) {bad}; known: {sorted(defaults)}, sizes")
    bad = sorted(set(own_sizes) - set(SIZES))
    if bad:
        raise ConfigError(f"studies.{name}.sizes: unknown size(s) {bad}; known: {', '.join(SIZES)}")
    per_size = {**dict(sizes.get(size) or {}), **dict(own_sizes.get(size) or {})}
    bad = sorted(set(per_size) - set(defaults))
    if bad:
        raise ConfigError(f"studies.{name}.sizes.{size}: unknown key(s) {bad}; known: {sorted(defaults)}")
    return size, {**dict(defaults), **own, **per_size}


def study_outputs(name: str, *, results_dir: str | os.PathLike = "results",
                  models: bool = True) -> dict[str, str]:
    """The declared output paths of one study, ``{output name: path}``.

    ``report``, ``results``, ``page``, one entry per Parquet table of :data:`STUDY_TABLES`
    (``<table>.parquet``) and, with ``models``, ``model_params``/``model_meta`` (the trained
    set under ``models/``). The rules in ``rules/studies.smk`` and the tests both take their
    paths from here.
    """
    try:
        tables = STUDY_TABLES[name]
    except KeyError:
        raise StudyError(f"unknown study {name!r}; known: {', '.join(STUDY_TABLES)}") from None
    d = Path(results_dir) / "studies" / name
    out = {"report": str(d / "report.md"), "results": str(d / "results.txt"),
           "page": str(Path(results_dir) / "report" / "studies" / f"{name}.html")}
    out.update({t: str(d / f"{t}.parquet") for t in tables})
    if models:
        out.update(model_params=str(d / "models" / "params.npz"), model_meta=str(d / "models" / "meta.json"))
    return out


def flightcoach_inputs(realdata_dir: str | os.PathLike, files: Mapping[str, str] | None = None, *,
                       study: str = "flightcoach_classification") -> dict[str, str]:
    """A FlightCoach study's flights under ``realdata_dir``; a missing one is a
    :class:`StudyError` naming it (one line: the study is not part of the main job).

    ``files`` maps input names to file names under :data:`FLIGHTCOACH_DIR` (default
    :data:`FLIGHTCOACH_FILES`, the classification study's four); ``study`` names the study in
    the message."""
    d = Path(realdata_dir) / FLIGHTCOACH_DIR
    files = {k: str(d / f) for k, f in (FLIGHTCOACH_FILES if files is None else files).items()}
    for k, p in files.items():
        if not Path(p).is_file():
            raise StudyError(f"{p}: FlightCoach file not found (input {k!r} of the {study} "
                             f"study; it needs the real logs of ../shared/realdata: set realdata_dir)")
    return files


def flightcoach_defaults(files: Mapping[str, str], realdata_dir: str | os.PathLike | None = None) -> dict[str, str]:
    """``{input name: path}`` of a FlightCoach study's ``files`` under ``realdata_dir`` (default
    ``$UAVPIPE_REALDATA``, else ``../shared/realdata`` beside the repository)/:data:`FLIGHTCOACH_DIR`."""
    d = Path(realdata_dir or os.environ.get("UAVPIPE_REALDATA", ROOT.parent / "shared" / "realdata"))
    return {k: str(d / FLIGHTCOACH_DIR / f) for k, f in files.items()}


def flightcoach_paths(inputs: Mapping | None, files: Mapping[str, str], study: str) -> dict[str, Path]:
    """A FlightCoach study's declared flights, each defaulting to its file under
    ``$UAVPIPE_REALDATA`` (or ``../shared/realdata`` beside the repository)/:data:`FLIGHTCOACH_DIR`;
    a missing one is a :class:`StudyError` naming it (one line)."""
    dflt = flightcoach_defaults(files)
    paths = {k: input_path(inputs, k, dflt[k]) for k in files}
    for k, p in paths.items():
        if not p.is_file():
            raise StudyError(f"{p}: FlightCoach file not found (input {k!r}; the {study} study needs "
                             f"../shared/realdata/{FLIGHTCOACH_DIR}, set realdata_dir or UAVPIPE_REALDATA)")
    return paths


#: FlightCoach segments the studies leave out: take-off and landing are no schedule maneuvers
FLIGHTCOACH_SKIP = ("tkOf", "tkoff", "lnd")


def flightcoach_labelled(state: pd.DataFrame, seg: pd.DataFrame, skip=FLIGHTCOACH_SKIP) -> pd.DataFrame:
    """Rows of every labelled segment except take-off/landing, ``run_id`` = segment id."""
    parts = []
    for _, s in seg.iterrows():
        if s["label"] in skip:
            continue
        g = state[(state["t_ns"] >= s["t_start_ns"]) & (state["t_ns"] < s["t_end_ns"])]
        parts.append(g.assign(run_id=int(s["segment_id"]), label=str(s["label"])))
    return pd.concat(parts, ignore_index=True)


def model_dir(paths: Mapping[str, Path]) -> Path:
    """The folder of a study's trained set: its ``model_params``/``model_meta`` outputs must be
    ``<dir>/params.npz`` and ``<dir>/meta.json`` (the layout :meth:`ManeuverModelSet.save` writes)."""
    mdir = paths["model_params"].parent
    if paths["model_meta"].parent != mdir or (paths["model_params"].name, paths["model_meta"].name) != (
            "params.npz", "meta.json"):
        raise ValueError(f"study outputs: model_params/model_meta must be <dir>/params.npz and <dir>/meta.json, "
                         f"got {paths['model_params']} and {paths['model_meta']}")
    return mdir


def output_path(outputs: Mapping, key: str) -> Path:
    """One declared output (Snakemake namedlist or dict), its folder created."""
    try:
        p = Path(outputs[key])
    except (KeyError, AttributeError):
        raise StudyError(f"study outputs: {key!r} is not declared (declared: {sorted(_keys(outputs))})") from None
    p.parent.mkdir(parents=True, exist_ok=True)
    return p


def _keys(m: Mapping) -> list[str]:
    keys = getattr(m, "keys", None)
    return list(keys()) if callable(keys) else []


class Progress:
    """Stage lines on stderr (the rule's log) with the seconds since the study started."""

    def __init__(self) -> None:
        self.t0 = time.perf_counter()

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def __call__(self, msg: str) -> None:
        print(f"[{self.elapsed:6.0f} s] {msg}", file=sys.stderr, flush=True)


def say(msg: str) -> None:
    """One informational line (tables, training summary) on stderr, the rule's log."""
    print(msg, file=sys.stderr, flush=True)


class Results:
    """The headline figures of a study, in order, each with a one-sentence definition."""

    def __init__(self) -> None:
        self.values: dict[str, str] = {}
        self.definitions: dict[str, str] = {}

    def add(self, metric: str, value: Any, definition: str) -> None:
        """Record ``RESULT <metric> <value>`` (``value`` already formatted as printed)."""
        self.values[metric] = str(value)
        self.definitions[metric] = definition

    def lines(self) -> list[str]:
        return [f"RESULT {k} {v}" for k, v in self.values.items()]

    def write(self, path: str | os.PathLike) -> None:
        """Write ``results.txt`` atomically and print the lines on stderr."""
        text = "\n".join(self.lines()) + "\n"
        write_text(path, text)
        sys.stderr.write(text)
        sys.stderr.flush()


def write_text(path: str | os.PathLike, text: str) -> None:
    """Atomic text write (:func:`pipeline.io.atomic.write_text_atomic`)."""
    write_text_atomic(path, text)


def md_table(df: pd.DataFrame, fmt: str = "{:.2f}") -> str:
    """A GitHub-markdown table (no extra dependency); non-finite floats print as ``–``, flags
    as ``yes``/``no`` (as on the report pages' tables, never Python's ``True``/``False``)."""
    def cell(v):
        if isinstance(v, (bool, np.bool_)):
            return "yes" if v else "no"
        return fmt.format(v) if isinstance(v, (float, np.floating)) and np.isfinite(v) else (
            "–" if isinstance(v, (float, np.floating)) else str(v))
    head = "| " + " | ".join(map(str, df.columns)) + " |"
    rule = "|" + "---|" * len(df.columns)
    rows = ["| " + " | ".join(cell(v) for v in r) + " |" for r in df.itertuples(index=False)]
    return "\n".join([head, rule, *rows])


def input_path(inputs: Mapping | None, key: str, default: str | os.PathLike | None = None) -> Path | None:
    """An optional declared input (Snakemake namedlist or dict), else ``default``."""
    v = None
    if inputs is not None:
        get = getattr(inputs, "get", None)
        v = get(key) if callable(get) else None
    if v is None or (isinstance(v, (list, tuple)) and not v):
        return Path(default) if default is not None else None
    return Path(v[0] if isinstance(v, (list, tuple)) else v)


def model_variant(ms, **cfg):
    """A shallow copy of a trained model set with config fields replaced (``gmr_input``,
    ``gmr_align``, ``gate_mps2``: what the GMR and the gate do at classification; the HMMs are
    unchanged)."""
    out = copy.copy(ms)
    out.config = dataclasses.replace(ms.config, **cfg)
    return out
