"""End-of-run summary: what the workflow made of each flight and model set, in a few lines.

The Snakefile's ``onsuccess``/``onerror`` handlers print :func:`run_summary`, so a corrupt log,
which never stops the other flights, is still visible on the console at the end of the run::

    uavpipe: 3 flight(s): 1 ok, 1 partial, 1 failed; 1 manifest row(s) skipped
      failed   broken: ingest: not a DataFlash log (bad header)
      partial  crash-0036: 120 bytes skipped
      skipped  ghost: /nonexistent/x.bin not found
      model sets: sim ok, f3a failed (no role=train flights)
      report: results/index.html

A flight is ``failed`` when its ingest or preprocess failed (the reason of the first stage that
did) or its preprocess did not finish (its job log but no ``state/<flight>.json``: a crash or
a kill, which writes no placeholder; a flight not yet preprocessed is judged by its ingest),
``partial`` when the ingest decoded only part of the log (bytes skipped, records dropped), ``ok``
otherwise, and ``not run`` when the run stopped before its ingest wrote ``meta.json``. A model
set is ``stale`` when its training data was rewritten after it was trained (a run stopped before
training again), so the ``ok`` in its ``meta.json`` is an earlier run's. An
unreadable status file is reported as the flight's reason, never raised: the summary is printed
after an error too. The report line says whether ``results/index.html`` is current (:func:`index_state`): ``(not written)``, or ``(stale:
older than <newest input>)`` when an output it is built from was rewritten after it.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..io.base import losses_text

#: flight states, in the order the summary counts and lists them
FLIGHT_STATES = ("ok", "partial", "failed", "not run")


def _read_json(path: Path) -> tuple[dict[str, Any] | None, str]:
    """``(content, "")``, ``(None, "")`` when absent, ``(None, reason)`` when unreadable."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None, ""
    except OSError as exc:
        return None, f"{path}: cannot read: {exc.strerror or exc}"
    try:
        data = json.loads(text)
    except ValueError as exc:
        return None, f"{path}: not JSON ({exc.msg})"
    if not isinstance(data, dict):
        return None, f"{path}: not a JSON object"
    return data, ""


def _partial_reason(diag: Mapping[str, Any]) -> str:
    return losses_text(diag) or "partly decoded"


def flight_status(flight: str, results_dir: str | os.PathLike = "results") -> tuple[str, str]:
    """``(state, reason)`` of one flight from its ingest ``meta.json`` and preprocess ``.json``.

    ``state`` is one of :data:`FLIGHT_STATES`; ``reason`` is empty for ``ok``.
    """
    res = Path(results_dir)
    meta, bad = _read_json(res / "ingest" / flight / "meta.json")
    if bad:
        return "failed", bad
    if meta is None:
        return "not run", "no ingest output"
    if meta.get("status") == "failed":
        return "failed", f"ingest: {meta.get('error') or 'unknown reason'}"
    pre, bad = _read_json(res / "state" / f"{flight}.json")
    if bad:
        return "failed", bad
    if pre is None and (res / "logs" / "preprocess_flight" / f"{flight}.log").exists():
        # the preprocess job started (its log is its first file) and wrote no state json, its
        # last output, which a failed preprocess writes too: it crashed or was killed
        return "failed", f"preprocess did not finish (no {res / 'state' / f'{flight}.json'})"
    # (no state json and no preprocess log: not preprocessed yet, e.g. an ingest-only target)
    if pre is not None and pre.get("status") == "failed":
        return "failed", f"preprocess: {pre.get('error') or 'unknown reason'}"
    if meta.get("status") == "partial":
        return "partial", _partial_reason(meta.get("diagnostics") or {})
    return "ok", ""


def model_set_status(model_set: str, results_dir: str | os.PathLike = "results",
                     inputs: Iterable[str | os.PathLike] = ()) -> tuple[str, str]:
    """``(status, reason)`` of one model set from ``models/<set>/meta.json``.

    ``not run`` when the file is absent; ``stale`` when one of ``inputs`` (the training data the
    ``train_model`` rule reads: bulk sets, or the training flights' state and segments) was
    rewritten after it, or is missing: the run changed the data and stopped before training
    again, so the status in the file is an earlier run's and the models do not describe this
    run's data. Otherwise the file's ``status`` (``ok``, ``failed``) and its ``error``.
    """
    path = Path(results_dir) / "models" / model_set / "meta.json"
    meta, bad = _read_json(path)
    if bad:
        return "failed", bad
    if meta is None:
        return "not run", ""
    try:
        t_meta = path.stat().st_mtime_ns
    except OSError as exc:                          # removed between the read and the stat
        return "failed", f"{path}: cannot read: {exc.strerror or exc}"
    for p in map(Path, inputs):
        try:
            if p.stat().st_mtime_ns > t_meta:
                return "stale", f"trained before {p} was rewritten"
        except OSError:
            return "stale", f"{p} missing"
    status = str(meta.get("status", "ok"))
    return status, str(meta.get("error") or "") if status != "ok" else ""


def run_summary(flights: Iterable[str], model_sets: Iterable[str],
                results_dir: str | os.PathLike = "results", *,
                skipped: Mapping[str, str] | None = None,
                model_inputs: Mapping[str, Iterable[str | os.PathLike]] | None = None) -> str:
    """The end-of-run summary (several lines, no trailing newline).

    Parameters
    ----------
    flights : iterable of str
        The planned flight ids (manifest rows whose log is available).
    model_sets : iterable of str
        The config's model set names.
    results_dir : path-like
        The workflow's ``results/`` folder.
    skipped : mapping, optional
        Manifest rows left out at start-up: flight id -> reason (e.g. ``"/x.bin not found"``).
    model_inputs : mapping, optional
        Model set -> the files its training reads; a model set trained before one of them was
        rewritten is reported ``stale`` (:func:`model_set_status`).
    """
    res = Path(results_dir)
    flights, model_sets = list(flights), list(model_sets)
    skipped = dict(skipped or {})
    states = {f: flight_status(f, res) for f in flights}
    counts = {s: sum(st == s for st, _ in states.values()) for s in FLIGHT_STATES}
    head = ", ".join(f"{counts[s]} {s}" for s in FLIGHT_STATES if counts[s] or s in ("ok", "failed"))
    lines = [f"uavpipe: {len(flights)} flight(s): {head}; {len(skipped)} manifest row(s) skipped"]
    for s in ("failed", "partial", "not run"):
        lines += [f"  {s:8s} {f}: {why}" if why else f"  {s:8s} {f}"
                  for f, (st, why) in states.items() if st == s]
    lines += [f"  skipped  {f}: {why}" for f, why in skipped.items()]
    sets = []
    for m in model_sets:
        st, why = model_set_status(m, res, (model_inputs or {}).get(m, ()))
        sets.append(f"{m} {st}" + (f" ({why})" if why else ""))
    lines.append(f"  model sets: {', '.join(sets) if sets else 'none'}")
    lines.append(f"  report: {index_state(flights, model_sets, res)}")
    return "\n".join(lines)


def index_required(flights: Iterable[str], model_sets: Iterable[str], res: Path) -> list[Path]:
    """The files the index rule reads for every planned flight and model set (``report_index``'s
    inputs): the ingest ``meta.json``, ``segments`` table and page of each flight, the page of
    each model set. One missing (a job failed and Snakemake removed its output) leaves the index
    describing an older run."""
    paths = []
    for f in flights:
        paths += [res / "ingest" / f / "meta.json", res / "segments" / f"{f}.parquet",
                  res / "report" / "flights" / f"{f}.html"]
    return paths + [res / "report" / "models" / f"{m}.html" for m in model_sets]


def index_inputs(flights: Iterable[str], model_sets: Iterable[str], res: Path) -> list[Path]:
    """The outputs the index is built from (or summarises), those that exist: per flight its
    ingest ``meta.json``, preprocess ``state/<f>.json``, ``segments`` table and page; per model
    set its ``meta.json`` and page; the comparison, trajectory-learning and bearing-replay pages.
    Study pages are linked by name, not read, and do not count."""
    flights, model_sets = list(flights), list(model_sets)
    paths = index_required(flights, model_sets, res)
    paths += [res / "state" / f"{f}.json" for f in flights] + [res / "models" / m / "meta.json" for m in model_sets]
    for kind in ("compare", "align", "bearing"):
        paths += sorted((res / "report" / kind).glob("*.html"))
    return [p for p in paths if p.is_file()]


def index_state(flights: Iterable[str], model_sets: Iterable[str],
                results_dir: str | os.PathLike = "results") -> str:
    """Where the report is and whether it is current: ``results/index.html``, ``results/index.html
    (not written)`` when absent, ``results/index.html (stale: older than <newest input>)`` when a
    flight's or model set's output (:func:`index_inputs`) is newer than it: the run rebuilt
    something after the index was last written and stopped before writing it again (a failed
    job, an interrupted run), so the index shows an older run's results; ``(stale: <input>
    missing)`` when a file it is built from (:func:`index_required`) is gone. An up-to-date run
    that had nothing to rebuild leaves the index current, and it is reported as such (the
    summary sees the files, not when the run started)."""
    flights, model_sets = list(flights), list(model_sets)
    res = Path(results_dir)
    index = res / "index.html"
    shown = str(index)
    try:
        t_index = index.stat().st_mtime_ns
    except OSError:
        return f"{shown} (not written)"
    newer = []
    for p in index_inputs(flights, model_sets, res):
        try:
            t = p.stat().st_mtime_ns
        except OSError:
            continue
        if t > t_index:
            newer.append((t, p))
    if newer:
        return f"{shown} (stale: older than {max(newer)[1]})"
    missing = next((p for p in index_required(flights, model_sets, res) if not p.is_file()), None)
    if missing is not None:
        return f"{shown} (stale: {missing} missing)"
    return shown
