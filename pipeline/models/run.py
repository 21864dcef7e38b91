"""Workflow entry points of the model stages: train one model set, classify one flight, and
evaluate a model against the seed-000 result tables.

A *model* of the workflow is one entry of the config's ``train`` section::

    sim: {data: simulated, labels: [M1, M2, M3, M4], vehicles: [sim-quad]}
    f3a: {data: flights, vehicles: [f3a-plane], exclude: [tkoff, lnd]}

``data: simulated`` trains on the simulated bulk sets ``<label>_train.parquet``; ``data:
flights`` on the labelled segments of the manifest's ``role: train`` flights of ``vehicles``
(each segment is one training run). ``vehicles`` also names the flights the model classifies.

Failures are data, not crashes: a model that cannot be trained (no data, degenerate
covariances) is written as a placeholder (``meta.json`` ``status: failed`` with the reason, an
empty ``params.npz``); classifying with it, or classifying a flight whose preprocessing failed,
writes an empty classification table whose metadata carries the status and reason.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from .. import __version__
from ..io.parquet import read_table, read_table_meta, write_json, write_table
from .base import ModelError, ModelsConfig
from .metrics import THESIS_TRUTH, per_maneuver_table, thesis_side_by_side

CLASSIFY_MIN_COLUMNS = ("run_id", "t_ns", "truth", "pred", "best", "V_best")
EVAL_COLUMNS = ("table", "split", "decision", "maneuver", "n_runs", "FA_pct", "MAoT_pct",
                "thesis_FA_pct", "thesis_MAoT_pct")
#: (split, decision) -> seed 000 table of truth-input results
THESIS_TABLES = {("train", "oneclass"): "3.1", ("train", "confidence"): "3.2",
                 ("test", "oneclass"): "3.3", ("test", "confidence"): "3.4"}


def _say(msg: str) -> None:
    print(f"uavpipe models: {msg}", file=sys.stderr, flush=True)


def _read_sets(paths: Sequence[str | os.PathLike]) -> pd.DataFrame:
    # run ids restart in every set file: make them unique per file
    frames = []
    for i, p in enumerate(paths):
        df = pd.read_parquet(p)
        df["run_id"] = [f"{Path(p).stem}:{r}" for r in df["run_id"]]
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


def flight_runs(states: Sequence, segments: Sequence) -> pd.DataFrame:
    """One training run per labelled segment of each flight (``run_id`` = ``<flight>:<segment>``)."""
    frames = []
    for sp, gp in zip(states, segments):
        st = read_table(sp)
        if not len(st):
            continue
        seg = read_table(gp)
        lab = label_state(st, seg)
        lab = lab[lab["segment_id"] >= 0]
        lab["run_id"] = [f"{Path(sp).stem}:{s}" for s in lab["segment_id"]]
        frames.append(lab.drop(columns="segment_id"))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _write_failed_model(out_dir: Path, spec: Mapping, reason: str) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    tmp = out_dir / ".params.tmp.npz"
    np.savez(tmp, failed=np.zeros(0))
    os.replace(tmp, out_dir / "params.npz")
    write_json({"status": "failed", "error": reason, "labels": [], "spec": dict(spec),
                "code_version": __version__}, out_dir / "meta.json")


def train_model(name: str, spec: Mapping, out_dir: str | os.PathLike, models_cfg: Mapping | None, *,
                seed: int = 0, sets: Sequence = (), states: Sequence = (), segments: Sequence = ()) -> dict:
    """Train model ``name`` from its inputs and write ``out_dir/{params.npz, meta.json}``.

    Parameters
    ----------
    name : str
        Model name (key of the ``train`` section).
    spec : mapping
        Its entry: ``data`` (``simulated``/``flights``), optional ``labels``, ``exclude`` and
        ``models`` (overrides of the ``models`` section for this model only).
    out_dir : path-like
        ``results/models/<name>``.
    models_cfg : mapping
        The ``models`` section (hyperparameters, seed).
    sets : paths
        Simulated ``<label>_train.parquet`` sets (``data: simulated``).
    states, segments : paths
        ``state`` and ``segments`` tables of the training flights, in the same order.

    Returns
    -------
    dict
        The written ``meta.json`` content.
    """
    from .classifier import ManeuverModelSet

    out = Path(out_dir)
    cfg = ModelsConfig.from_section(models_cfg, seed=seed, **dict(spec.get("hmm") or {}))
    try:
        df = _read_sets(sets) if spec.get("data", "simulated") == "simulated" else flight_runs(states, segments)
        if not len(df) or "label" not in df.columns:
            raise ModelError("no labelled training data (no training flights with segments?)")
        keep = df["label"].notna() & ~df["label"].isin(list(spec.get("exclude") or []))
        if spec.get("labels"):
            keep &= df["label"].isin(list(spec["labels"]))
        if not keep.any():
            raise ModelError(f"no training samples with labels {spec.get('labels')}")
        ms = ManeuverModelSet(config=cfg).fit(df[keep].reset_index(drop=True))
    except ValueError as exc:  # ModelError, numpy LinAlgError, bad tables: a placeholder model
        reason = f"training failed: {type(exc).__name__}: {exc}"
        _say(f"{name}: {reason}")
        _write_failed_model(out, spec, reason)
        return json.loads((out / "meta.json").read_text())
    ms.save(out)
    meta = json.loads((out / "meta.json").read_text())
    meta.update({"status": "ok", "name": name, "spec": dict(spec),
                 "training_inputs": [str(p) for p in (*sets, *states)]})
    write_json(meta, out / "meta.json")
    _say(f"{name}: trained {len(ms.labels_)} maneuver models {ms.labels_}")
    return meta


def model_status(model_dir: str | os.PathLike) -> tuple[str, str]:
    """``(status, error)`` of a trained model directory."""
    meta = json.loads((Path(model_dir) / "meta.json").read_text())
    return meta.get("status", "ok"), meta.get("error") or ""


def _empty_classification() -> pd.DataFrame:
    return pd.DataFrame({"run_id": pd.Series([], dtype=str), "t_ns": pd.Series([], dtype=np.int64),
                         "truth": pd.Series([], dtype=str), "pred": pd.Series([], dtype=str),
                         "best": pd.Series([], dtype=str), "V_best": pd.Series([], dtype=np.float64)})


def classify_flight(state_path, segments_path, model_dir, out_path, *, model: str = "",
                    reset_at_segments: bool = True) -> pd.DataFrame:
    """Classify one preprocessed flight with a trained model set; write ``out_path``.

    Samples inside a labelled segment carry its label in ``truth`` (``""`` elsewhere); with
    ``reset_at_segments`` the forward passes restart at every segment start, as the thesis
    classifies each maneuver from its first sample.
    """
    from .classifier import ManeuverModelSet

    extra = {"model": model, "flight_id": read_table_meta(state_path).get("flight_id")}
    m_status, m_error = model_status(model_dir)
    state = read_table(state_path)
    st_meta = read_table_meta(state_path)
    reason = ""
    if m_status == "failed":
        reason = f"model {model} failed: {m_error}"
    elif st_meta.get("status") == "failed":
        reason = st_meta.get("error") or "preprocessing failed"
    elif not len(state) or not state["pos_n_m"].notna().any():
        reason = "no position data to classify"
    if not reason:
        seg = read_table(segments_path)
        lab = label_state(state, seg)
        try:
            ms = ManeuverModelSet.load(model_dir)
            res = ms.classify(lab.drop(columns="segment_id"),
                              reset_t_ns=seg["t_start_ns"].to_numpy() if reset_at_segments and len(seg) else None)
        except ValueError as exc:  # ModelError and numerical failures on odd flights
            reason = f"classification failed: {type(exc).__name__}: {exc}"
        else:
            res["run_id"] = res["run_id"].astype(str)
            res["truth"] = res["truth"].replace({"<NA>": "", "nan": "", "None": ""})
            write_table(res, out_path, name="classification",
                        extra={**extra, "status": "ok", "labels": ms.labels_, "mode": ms.config.mode})
            _say(f"{extra['flight_id']}: {len(res)} samples classified with {model}")
            return res
    _say(f"{extra['flight_id']}: placeholder classification ({reason})")
    res = _empty_classification()
    write_table(res, out_path, name="classification", extra={**extra, "status": "failed", "error": reason})
    return res


def _runs_from_truth(df: pd.DataFrame, flight: str) -> pd.Series:
    """Run ids = maximal stretches of constant truth within a flight (one maneuver each)."""
    change = (df["truth"] != df["truth"].shift()).cumsum()
    return flight + ":" + change.astype(str)


def evaluate_model(name: str, spec: Mapping, model_dir, out_path, *, train_sets: Sequence = (),
                   test_sets: Sequence = (), classified: Sequence = ()) -> pd.DataFrame:
    """FA / MAoT per maneuver (seed 000 §5) beside the thesis values; writes ``out_path``.

    ``data: simulated``: the model classifies the simulated train and test sets with both
    decision rules, as Tables 3.1-3.4 (truth input; labels the model lacks, e.g. M5, are correct
    only as ``unknown``). ``data: flights``: the classifications of the ``role: test`` flights,
    one run per labelled segment (no thesis values).
    """
    from .classifier import ManeuverModelSet

    status, error = model_status(model_dir)
    rows = []
    if status == "ok":
        ms = ManeuverModelSet.load(model_dir)
        if spec.get("data", "simulated") == "simulated":
            for split, paths in (("train", train_sets), ("test", test_sets)):
                if not paths:
                    continue
                df = _read_sets(paths)
                for decision in ("oneclass", "confidence"):
                    res = ms.classify(df, decision=decision, gmr=False)
                    tab = per_maneuver_table(res, ms.labels_, truth_col="truth")
                    tab = thesis_side_by_side(tab, THESIS_TABLES[(split, decision)])
                    tab["split"], tab["decision"] = split, decision
                    rows.append(tab)
        else:
            parts = []
            for p in classified:
                c = read_table(p)
                if len(c) and "truth" in c:
                    c = c[c["truth"].astype(str) != ""].copy()
                    c["run_id"] = _runs_from_truth(c, Path(p).stem)
                    parts.append(c)
            if parts:
                tab = per_maneuver_table(pd.concat(parts, ignore_index=True), ms.labels_, truth_col="truth")
                tab.insert(0, "table", "flights")
                tab["thesis_FA_pct"] = np.nan
                tab["thesis_MAoT_pct"] = np.nan
                tab["split"], tab["decision"] = "test flights", ms.config.decision
                rows.append(tab)
    table = pd.concat(rows, ignore_index=True)[list(EVAL_COLUMNS)] if rows else \
        pd.DataFrame({c: pd.Series([], dtype=float if c.endswith("pct") else str) for c in EVAL_COLUMNS})
    write_table(table, out_path, name="model_evaluation",
                extra={"model": name, "status": status, "error": error,
                       "thesis_tables": sorted(THESIS_TRUTH) if spec.get("data", "simulated") == "simulated" else []})
    _say(f"{name}: evaluation with {len(table)} rows ({status})")
    return table
