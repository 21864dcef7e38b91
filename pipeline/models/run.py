"""Entry points of the model stages: train one model set, classify one flight with it, and
evaluate it against the seed-000 result tables.

A *model set* is one entry of the config's ``model_sets`` section (keyed by name; results under
``results/models/<model_set>/``)::

    sim: {data: simulated, labels: [M1, M2, M3, M4], vehicles: [sim-quad]}
    f3a: {data: flights, vehicles: [f3a-plane], exclude: [tkoff, lnd], hmm: {feature_set: aero}}

``data: simulated`` trains on the simulated bulk sets ``<label>_train.parquet`` — the truth
(``input: truth``, the default: ``results/sim/sets/``) or its EKF estimates from radar
synthesised from the truth (``input: ekf``: ``results/estimate/sets/``, rule ``ekf_sets``,
:mod:`pipeline.estimate.sets`; the noise-aware models), and is evaluated on the matching test
sets (Tables 3.1–3.4, or 3.5–3.8 for EKF input); ``data:
flights`` on the labelled segments of the manifest's ``role: train`` flights of ``vehicles``
(each segment is one training run). ``vehicles`` also names the flights the set classifies
(``results/classify/<model_set>/<flight>.parquet``); two model sets may name one vehicle. The
entry's ``hmm`` block overrides the ``hmm`` hyperparameter section for that set only; the
workflow passes the merged block as ``config["hmm"]``.

Each entry point takes the declared ``inputs``/``outputs`` paths, the set's config and the
per-job values (:func:`run_train`, :func:`run_classify`, :func:`run_evaluate`); the workflow
rules and ``uavpipe train``/``uavpipe classify`` call the same functions.

Failures are data, not crashes: a model set that cannot be trained (no data, degenerate
covariances) is written as a placeholder (``meta.json`` ``status: failed`` with the reason, an
empty ``params.npz``); classifying with it, or classifying a flight whose preprocessing failed,
writes an empty classification table whose metadata carries the status and reason.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from .. import __version__
from ..io.atomic import atomic_output
from ..io import schema
from ..io.parquet import READ_ERRORS, read_table, read_table_meta, write_json, write_table
from ..config import ConfigError
from ..io.schema import CLASSIFY_MIN_COLUMNS, EVAL_COLUMNS  # noqa: F401  (declared in io.schema)
from ..io.stage import declared, declared_list, exception_line, one_line, say, source_names
from .base import ModelError, ModelsConfig
from .metrics import THESIS_CLASSIFICATION, per_maneuver_table, thesis_side_by_side

#: (split, decision) -> seed 000 table of truth-input results
THESIS_TABLES = {("train", "oneclass"): "3.1", ("train", "confidence"): "3.2",
                 ("test", "oneclass"): "3.3", ("test", "confidence"): "3.4"}
#: (split, decision) -> seed 000 table of EKF-input results (the thesis's models were
#: truth-trained; a model set with ``input: ekf`` is trained on EKF estimates too, so its rows
#: put our noise-aware models beside the thesis's truth-trained ones on the same kind of input)
THESIS_TABLES_EKF = {("train", "oneclass"): "3.5", ("train", "confidence"): "3.6",
                     ("test", "oneclass"): "3.7", ("test", "confidence"): "3.8"}
#: the values of a model set's ``input`` (simulated sets: truth, or EKF estimates of it)
INPUTS = ("truth", "ekf")


def thesis_tables_for(spec: Mapping) -> dict[tuple[str, str], str]:
    """The ``(split, decision) -> thesis table`` map of a simulated model set: 3.1–3.4 for
    ``input: truth`` (the default), 3.5–3.8 for ``input: ekf``.

    Raises
    ------
    ConfigError
        When ``input`` is neither.
    """
    inp = spec.get("input", "truth")
    if inp not in INPUTS:
        raise ConfigError(f"model_sets: input {inp!r} is not one of {', '.join(INPUTS)}")
    return THESIS_TABLES_EKF if inp == "ekf" else THESIS_TABLES


@dataclass(frozen=True)
class ModelStageResult:
    """What a model-stage entry point did: ``status`` (``ok``/``failed``), the reason, and the
    stage's diagnostics (training summary, sample counts, evaluation rows)."""

    model_set: str
    status: str
    error: str = ""
    diagnostics: dict | None = None






def model_set_config(config: Mapping, model_set: str) -> dict:
    """The entry ``config["model_sets"][model_set]`` with ``hmm`` = the ``hmm`` section merged
    with the entry's own ``hmm`` overrides (what the train/classify/evaluate entry points take).

    Raises
    ------
    ConfigError
        When the config has no such model set.
    """
    sets = config.get("model_sets") or {}
    if model_set not in sets:
        raise ConfigError(f"model_sets: no model set {model_set!r} (defined: {sorted(sets) or 'none'})")
    spec = dict(sets[model_set])
    spec["hmm"] = {**dict(config.get("hmm") or {}), **dict(spec.get("hmm") or {})}
    return spec


def check_model_set_labels(model_sets: Mapping[str, Mapping], simulated: Sequence[str],
                           known: Sequence[str]) -> None:
    """Refuse a simulated model set whose ``labels`` names a maneuver the simulator does not
    have (``known``), or none that this config simulates (``simulated``); checked by the
    workflow at start-up, so a typo such as ``M9`` is one line before any job instead of a model
    set silently trained on the other labels. Known labels the datasets size leaves out (the
    tiny test sizes simulate M1, M2) are dropped, as before.

    Raises
    ------
    ConfigError
        ``model_sets.<name>.labels: 'M9' is not a simulated maneuver (known: M1, ...)``.
    """
    for name, spec in model_sets.items():
        if spec.get("data", "simulated") != "simulated" or not spec.get("labels"):
            continue
        labels = list(spec["labels"])
        bad = [lab for lab in labels if lab not in known]
        if bad:
            raise ConfigError(f"model_sets.{name}.labels: {', '.join(map(repr, bad))} "
                              f"{'is' if len(bad) == 1 else 'are'} not a simulated maneuver "
                              f"(known: {', '.join(known)})")
        if not any(lab in simulated for lab in labels):
            raise ConfigError(f"model_sets.{name}.labels: none of {', '.join(labels)} is simulated with "
                              f"this config (simulate.datasets.maneuvers: {', '.join(simulated) or 'none'})")


def hmm_config(config: Mapping, seed: int) -> ModelsConfig:
    """The model set's hyperparameters: ``config["hmm"]`` (the ``hmm`` section merged with the
    set's overrides) and the master seed."""
    return ModelsConfig.from_section(dict(config.get("hmm") or {}), seed=int(seed))


def _say(msg: str, *, restated: bool = False) -> None:
    say("uavpipe models", msg, restated=restated)


def read_sets(paths: Sequence[str | os.PathLike]) -> pd.DataFrame:
    """The training runs of simulated sets (or single labelled tables), concatenated.

    Run ids restart in every set file, so each becomes ``<source>:<run_id>`` with
    :func:`pipeline.io.stage.source_names` (the file stem where stems differ); a table without
    ``run_id`` is one run.
    """
    frames = []
    for p, src in zip(paths, source_names(paths)):
        df = pd.read_parquet(p)
        if "run_id" not in df.columns:  # one run per file (a single labelled state table)
            df["run_id"] = 0
        df["run_id"] = [f"{src}:{r}" for r in df["run_id"]]
        frames.append(df)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def label_state(state: pd.DataFrame, segments: pd.DataFrame) -> pd.DataFrame:
    """``state`` with ``label`` and ``segment_id`` from the segments (NA outside every segment)."""
    out = state.copy()
    lab = np.full(len(out), None, dtype=object)
    sid = np.full(len(out), -1, dtype=np.int64)
    t = out["t_ns"].to_numpy()
    for r in segments.itertuples():
        m = (t >= r.t_start_ns) & (t < r.t_end_ns)
        lab[m], sid[m] = str(r.label), int(r.segment_id)
    out["label"] = pd.array(lab, dtype="string")
    out["segment_id"] = sid
    return out


def flight_runs(states: Sequence, segments: Sequence, skipped: dict | None = None) -> pd.DataFrame:
    """One training run per labelled segment of each flight.

    Parameters
    ----------
    states, segments : sequence of path
        The flights' state and segment tables, in the same order.
    skipped : dict, optional
        Filled with ``{flight: reason}`` for every flight left out: one whose files cannot be
        read (``unreadable state: ...``/``unreadable segments: ...``), or that gives no labelled
        sample; so training says so instead of passing over it in silence, and one damaged
        flight never stops the others.

    Returns
    -------
    pandas.DataFrame
        The labelled samples, ``run_id`` = ``<flight>:<segment>`` with ``<flight>`` the state
        file's :func:`pipeline.io.stage.source_names` name (its stem in the workflow); empty when
        no flight gives one.
    """
    frames = []
    skipped = {} if skipped is None else skipped
    for sp, gp, src in zip(states, segments, source_names(states)):
        # the metadata first: pyarrow reads a directory as an (empty) dataset, but not its schema
        try:
            meta = read_table_meta(sp)
            st = read_table(sp)
        except READ_ERRORS as exc:  # damaged, missing, a directory
            skipped[src] = f"unreadable state: {exception_line(exc, where=False)}"
            continue
        if not len(st):
            why = one_line(meta.get("error") or "preprocessing gave no samples")
            skipped[src] = f"no state ({why})"
            continue
        try:
            seg = read_table(gp)
        except READ_ERRORS as exc:
            skipped[src] = f"unreadable segments: {exception_line(exc, where=False)}"
            continue
        lab = label_state(st, seg)
        lab = lab[lab["segment_id"] >= 0]
        if not len(lab):
            skipped[src] = "no labelled segments" if not len(seg) else "no state sample inside its segments"
            continue
        lab["run_id"] = [f"{src}:{s}" for s in lab["segment_id"]]
        frames.append(lab.drop(columns="segment_id"))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _write_failed_model(out_dir: Path, spec: Mapping, reason: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_output(out_dir / "params.npz", suffix=".npz") as tmp:
        np.savez(tmp, failed=np.zeros(0))
    write_json({"status": "failed", "error": reason, "labels": [], "spec": dict(spec),
                "code_version": __version__}, out_dir / "meta.json")


def run_train(inputs, outputs, config: Mapping, *, model_set: str, seed: int) -> ModelStageResult:
    """Train model set ``model_set`` and write ``outputs.params`` (npz) and ``outputs.meta`` (JSON).

    Parameters
    ----------
    inputs : mapping
        ``sets``: simulated ``<label>_train.parquet`` sets (``data: simulated``); or ``states``
        and ``segments``: the training flights' tables, in the same order (``data: flights``).
    outputs : mapping
        ``params`` and ``meta``, in one folder (``results/models/<model_set>/``).
    config : mapping
        The set's entry of ``model_sets``: ``data``, optional ``labels``/``exclude``, and
        ``hmm`` (the hyperparameters with the set's overrides merged in).
    model_set : str
        Its name.
    seed : int
        The master seed (every random choice of training derives from it).

    Returns
    -------
    ModelStageResult
        ``diagnostics`` holds the written ``meta.json`` content.
    """
    from .classifier import ManeuverModelSet

    params, meta_path = Path(declared(outputs, "params")), Path(declared(outputs, "meta"))
    out = params.parent
    if meta_path.parent != out or params.name != "params.npz" or meta_path.name != "meta.json":
        raise ModelError(f"model set {model_set}: outputs must be <dir>/params.npz and <dir>/meta.json, "
                         f"got {params} and {meta_path}")
    spec = {k: v for k, v in dict(config).items() if k != "hmm"}
    sets, states, segments = declared_list(inputs, "sets"), declared_list(inputs, "states"), declared_list(inputs, "segments")
    cfg = hmm_config(config, seed)  # a bad hyperparameter is a config error, not a placeholder
    skipped: dict[str, str] = {}
    try:
        df = read_sets(sets) if spec.get("data", "simulated") == "simulated" else flight_runs(states, segments, skipped)
        if skipped:
            _say(f"{model_set}: {len(skipped)} of {len(states)} training flight(s) gave no labelled sample: "
                 + "; ".join(f"{f} ({why})" for f, why in skipped.items()))
        if not len(df) or "label" not in df.columns:
            if spec.get("data", "simulated") == "simulated":
                why = (f"no 'label' column in {', '.join(map(str, sets))}" if len(df)
                       else f"no rows in {', '.join(map(str, sets))}" if sets else "no sets given")
            else:
                why = "; ".join(f"{f}: {r}" for f, r in skipped.items()) or "no training flights with segments?"
            raise ModelError(f"no labelled training data ({why})")
        unlabelled = int(df["label"].isna().sum())
        if unlabelled and spec.get("data", "simulated") == "simulated":
            # every row of a simulated set has its run's label: a gap here is damage, not the
            # unlabelled flight time between a flight's segments
            _say(f"{model_set}: {unlabelled} of {len(df)} set row(s) without a label left out")
        keep = df["label"].notna() & ~df["label"].isin(list(spec.get("exclude") or []))
        if spec.get("labels"):
            keep &= df["label"].isin(list(spec["labels"]))
        if not keep.any():
            present = sorted(map(str, df["label"].dropna().unique()))
            raise ModelError(f"no training samples left: the data has labels {present or 'none'}, "
                             f"the model set takes {list(spec.get('labels') or []) or 'all'} "
                             f"and excludes {list(spec.get('exclude') or []) or 'none'}")
        ms = ManeuverModelSet(config=cfg).fit(df[keep].reset_index(drop=True))
        dropped = dict(ms.dropped_runs_)
        if dropped:
            _say(f"{model_set}: {len(dropped)} training run(s) dropped: "
                 + "; ".join(f"{r} ({why})" for r, why in list(dropped.items())[:5])
                 + (f"; … {len(dropped) - 5} more (meta.json training_dropped)" if len(dropped) > 5 else ""))
    except READ_ERRORS as exc:  # a bad or missing set; ModelError and LinAlgError are ValueErrors
        reason = f"training failed: {exception_line(exc, where=False)}"
        _say(f"{model_set}: {reason}")
        _write_failed_model(out, spec, reason)
        return ModelStageResult(model_set, "failed", reason, json.loads(meta_path.read_text()))
    ms.save(out)
    meta = json.loads(meta_path.read_text())
    meta.update({"status": "ok", "name": model_set, "spec": spec,
                 "training_inputs": [str(p) for p in (*sets, *states)], "training_skipped": skipped,
                 "training_dropped": dropped})
    write_json(meta, meta_path)
    _say(f"{model_set}: trained {len(ms.labels_)} maneuver models {ms.labels_}", restated=True)
    return ModelStageResult(model_set, "ok", "", meta)


def model_status(model_dir: str | os.PathLike) -> tuple[str, str]:
    """``(status, error)`` of a trained model directory."""
    meta = json.loads((Path(model_dir) / "meta.json").read_text())
    return meta.get("status", "ok"), meta.get("error") or ""


def _empty_classification() -> pd.DataFrame:
    return pd.DataFrame({"run_id": pd.Series([], dtype=str), "t_ns": pd.Series([], dtype=np.int64),
                         "truth": pd.Series([], dtype=str), "pred": pd.Series([], dtype=str),
                         "best": pd.Series([], dtype=str), "V_best": pd.Series([], dtype=np.float64)})


def run_classify(inputs, outputs, config: Mapping, *, model_set: str, mode: str | None = None,
                 decision: str | None = None) -> ModelStageResult:
    """Classify one preprocessed flight with a trained model set; write ``outputs.classification``.

    Parameters
    ----------
    inputs : mapping
        ``params``/``meta`` of the model set, ``state`` (the flight's state table) and optional
        ``segments``. Samples inside a labelled segment carry its label in ``truth`` (``""``
        elsewhere). Without segments, a table that carries its own ``run_id``/``label`` columns
        (a simulated bulk set) is classified run by run.
    outputs : mapping
        ``classification``: the per-sample Parquet table.
    config : mapping
        The set's entry of ``model_sets``; ``reset_at_segments`` (default true) restarts the
        forward passes at every segment start, as the thesis classifies each maneuver from its
        first sample.
    model_set : str
        Its name (recorded in the table metadata).
    mode, decision : str, optional
        Override the model set's classification mode / decision rule.
    """
    from .classifier import ManeuverModelSet

    model_dir = Path(declared(inputs, "params")).parent
    state_path, segments_path = declared(inputs, "state"), declared(inputs, "segments")
    out_path = declared(outputs, "classification")
    m_status, m_error = model_status(model_dir)
    try:
        st_meta = read_table_meta(state_path)
        state = read_table(state_path)
        unreadable = ""
    except READ_ERRORS as exc:  # one flight's damaged state: its placeholder
        st_meta, state = {}, pd.DataFrame()
        unreadable = f"cannot read {state_path}: {exception_line(exc, where=False)}"
    extra = {"model_set": model_set, "model": model_set, "flight_id": st_meta.get("flight_id") or Path(state_path).stem}
    reason = ""
    if unreadable:
        reason = unreadable
    elif m_status == "failed":
        reason = one_line(f"model set {model_set} failed: {m_error}")
    elif st_meta.get("status") == "failed":
        # one line: the reason goes into the log line and the placeholder's metadata
        reason = one_line(st_meta.get("error") or "preprocessing failed")
    elif not len(state) or not state["pos_n_m"].notna().any():
        reason = "no position data to classify"
    if not reason:
        try:
            seg = read_table(segments_path) if segments_path else None
            lab = label_state(state, seg).drop(columns="segment_id") if seg is not None else state
            resets = None
            if seg is not None and len(seg) and config.get("reset_at_segments", True):
                resets = seg["t_start_ns"].to_numpy()
            ms = ManeuverModelSet.load(model_dir)
            # box-frame feature sets need the aerobatic box heading (FlightCoach meta, copied to
            # the state metadata by preprocess); 0 where the log has none
            box = st_meta.get("box_rotation_rad")
            res = ms.classify(lab, mode=mode, decision=decision, reset_t_ns=resets,
                              box_heading_rad=float(box) if box is not None else 0.0)
        except Exception as exc:  # ModelError, numerical failures on odd flights, a damaged table
            reason = f"classification failed: {exception_line(exc)}"
        else:
            res["run_id"] = res["run_id"].astype(str)
            if "truth" in res:
                res["truth"] = res["truth"].replace({"<NA>": "", "nan": "", "None": ""})
            cols = schema.layout("classification", res.columns)
            write_table(res, out_path, cols, name="classification",
                        extra={**extra, "status": "ok", "labels": ms.labels_, "mode": mode or ms.config.mode})
            _say(f"{extra['flight_id']}: {len(res)} samples classified with {model_set}", restated=True)
            nodata = int(res["V_best"].isna().sum())     # samples with a NaN feature: no decision
            if nodata:
                who = extra["flight_id"] or Path(state_path).name
                _say(f"{who}: {nodata} of {len(res)} samples have a NaN or infinite feature "
                     f"(gaps in the state): unknown, not classified")
            return ModelStageResult(model_set, "ok", "", {"n_samples": len(res),
                                                          "n_unknown": int((res["pred"] == "unknown").sum()),
                                                          "n_no_features": nodata})
    _say(f"{extra['flight_id']}: placeholder classification ({reason})", restated=True)
    empty = _empty_classification()
    write_table(empty, out_path, schema.layout("classification", empty.columns), name="classification",
                extra={**extra, "status": "failed", "error": reason})
    return ModelStageResult(model_set, "failed", reason, {"n_samples": 0})


def _runs_from_truth(df: pd.DataFrame, flight: str) -> pd.Series:
    """Run ids = maximal stretches of constant truth within a flight (one maneuver each)."""
    change = (df["truth"] != df["truth"].shift()).cumsum()
    return flight + ":" + change.astype(str)


def run_evaluate(inputs, outputs, config: Mapping, *, model_set: str) -> ModelStageResult:
    """FA / MAoT per maneuver (seed 000 §5) beside the thesis values; writes ``outputs.evaluation``.

    ``data: simulated``: the model classifies the simulated ``inputs.train_sets`` and
    ``inputs.test_sets`` with both decision rules, as Tables 3.1-3.4 (``input: truth``) or
    3.5-3.8 (``input: ekf``: the sets are EKF estimates; labels the model lacks, e.g. M5, are
    correct only as ``unknown``). ``data: flights``: the
    classifications of the ``role: test`` flights (``inputs.classified``), one run per labelled
    segment (no thesis values). ``inputs.params``/``inputs.meta``: the trained set.

    Parameters
    ----------
    inputs : mapping
        ``params``/``meta`` of the model set; ``train_sets``/``test_sets`` (``data: simulated``)
        or ``classified`` (``data: flights``).
    outputs : mapping
        ``evaluation``: the Parquet table of per-maneuver rows.
    config : mapping
        The set's entry of ``model_sets``.
    model_set : str
        Its name (recorded in the table metadata).

    Returns
    -------
    ModelStageResult
        The model set's status; ``diagnostics`` holds ``n_rows`` and, for ``data: flights``,
        ``flights_used`` (the flights that counted) and ``flights_skipped`` (``{flight: reason}``
        for the others: unreadable, a failed or empty classification, no labelled sample, or a
        failed model set), also written to the table metadata.
    """
    from .classifier import ManeuverModelSet

    spec, name = config, model_set
    model_dir = Path(declared(inputs, "params")).parent
    out_path = declared(outputs, "evaluation")
    train_sets, test_sets = declared_list(inputs, "train_sets"), declared_list(inputs, "test_sets")
    classified = declared_list(inputs, "classified")
    status, error = model_status(model_dir)
    simulated = spec.get("data", "simulated") == "simulated"
    tables_of = thesis_tables_for(spec) if simulated else {}
    rows = []
    # which test flights counted and why the others did not: the evaluation's metadata says so,
    # so a table over fewer flights than classified is never a silent loss
    used: list[str] = []
    skipped: dict[str, str] = {}
    if status != "ok" and not simulated:
        skipped = {f: f"model set {name} failed" for f in source_names(classified)}
    if status == "ok":
        ms = ManeuverModelSet.load(model_dir)
        if spec.get("data", "simulated") == "simulated":
            for split, paths in (("train", train_sets), ("test", test_sets)):
                if not paths:
                    continue
                df = read_sets(paths)
                for decision in ("oneclass", "confidence"):
                    res = ms.classify(df, decision=decision, gmr=False)
                    tab = per_maneuver_table(res, ms.labels_, truth_col="truth")
                    tab = thesis_side_by_side(tab, tables_of[(split, decision)])
                    tab["split"], tab["decision"] = split, decision
                    rows.append(tab)
        else:
            parts = []
            # source_names: the stems in the workflow, told apart should two flights share one
            for p, flight in zip(classified, source_names(classified)):
                try:
                    c, c_meta = read_table(p), read_table_meta(p)
                except READ_ERRORS as exc:  # damaged, missing
                    skipped[flight] = f"unreadable classification: {exception_line(exc, where=False)}"
                    continue
                if c_meta.get("status") == "failed" or not len(c):
                    why = c_meta.get("error") or "no classified samples"
                    skipped[flight] = one_line(f"no classification ({why})")
                    continue
                if "truth" not in c:
                    skipped[flight] = "no 'truth' column (not classified with its segments)"
                    continue
                c = c[c["truth"].astype(str) != ""].copy()
                if not len(c):
                    skipped[flight] = "no classified sample inside a labelled segment"
                    continue
                c["run_id"] = _runs_from_truth(c, flight)
                parts.append(c)
                used.append(flight)
            if parts:
                tab = per_maneuver_table(pd.concat(parts, ignore_index=True), ms.labels_, truth_col="truth")
                tab.insert(0, "table", "flights")
                tab["thesis_FA_pct"] = np.nan
                tab["thesis_MAoT_pct"] = np.nan
                tab["split"], tab["decision"] = "test flights", ms.config.decision
                rows.append(tab)
    table = pd.concat(rows, ignore_index=True)[list(EVAL_COLUMNS)] if rows else \
        pd.DataFrame({c: pd.Series([], dtype=float if c.endswith("pct") else str) for c in EVAL_COLUMNS})
    flights = {} if simulated else {"flights_used": used, "flights_skipped": skipped}
    write_table(table, out_path, schema.MODEL_EVALUATION,
                name="model_evaluation",
                extra={"model_set": name, "model": name, "status": status, "error": error,
                       "input": spec.get("input", "truth") if simulated else "flights",
                       "thesis_tables": sorted(t for t in set(tables_of.values()) if t in THESIS_CLASSIFICATION),
                       **flights})
    if skipped and status == "ok":
        _say(f"{name}: {len(skipped)} of {len(classified)} test flight(s) left out of the evaluation: "
             + "; ".join(f"{f} ({why})" for f, why in skipped.items()))
    _say(f"{name}: evaluation with {len(table)} rows ({status})")
    return ModelStageResult(name, status, error, {"n_rows": len(table), **flights})
