"""Entry point of the align stage: learn one intended trajectory per maneuver of a demo set.

:func:`run_align` reads the ``state`` and ``segments`` tables of a set's flights (``align.sets``;
:mod:`pipeline.align.demos`: demos in the box frame, box-less flights rigidly fitted to the set's
reference), fits :class:`pipeline.align.trajectory.TrajectoryLearner` (seed 004 §3: EM over a
hidden 13-D kinematic trajectory, EKF/RTS E-step, banded τ alignment, ridge-penalised bias β) to
the demos of every maneuver label and writes the four declared tables (``io.schema``
``align_learned``, ``align_alignment``, ``align_iterations``, ``align_demos``;
``results/align/<set>/{learned,alignment,iterations,demos}.parquet``), one ``maneuver`` column
each (maneuvers are rows: the DAG does not depend on the data).

**Bad input** is reported, never raised: a flight of the set that is not among the inputs is
skipped with a notice (an ``alignment`` row, status ``dropped``); so is a flight whose
preprocessing failed (its placeholder's error), whose ``state``/``segments`` file cannot be read
(the file named), whose fit to the reference fails or whose demos cannot be cut (the error on one
line), and the others go on; when that flight is the reference, the box-less flights stay in NED
with a notice. A demo with ``gap`` rows inside its segment is dropped with the reason; a maneuver
with fewer than ``align.min_demos`` usable demos is skipped, with the reason in ``alignment`` and
``iterations``; a fit that fails skips the maneuver with the error. The workflow
(``rules/align.smk``) and ``uavpipe align`` call the same function.
"""

from __future__ import annotations

import re
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..io import schema
from ..io.parquet import read_table, read_table_meta, write_table
from ..io.stage import declared, declared_list, exception_line
from .demos import DEMO_COLUMNS, Demo, Dropped, FlightDemos, fit_to_reference, flight_demos

F64 = NDArray[np.float64]

#: the declared outputs of one set, in order (``results/align/<set>/<name>.parquet``)
ALIGN_OUTPUTS: tuple[str, ...] = ("learned", "alignment", "iterations", "demos")


@dataclass(frozen=True)
class AlignResult:
    """What :func:`run_align` did.

    Attributes
    ----------
    set_name : str
    status : str
        ``ok`` (every maneuver learned), ``partial`` (some skipped) or ``failed`` (none learned;
        the four tables are empty placeholders with the reason in their metadata).
    error : str
        The reason when not ``ok``.
    diagnostics : dict
        Per flight its frame and heading, per maneuver demos and iterations; notices (run times
        are said on stderr and kept in the benchmark file, not here: same seed, same bytes).
    """

    set_name: str
    status: str
    error: str = ""
    diagnostics: dict = field(default_factory=dict)


def fit_summary(info: Mapping[str, Any]) -> str | None:
    """``heading … deg, pair RMS … m, altitude-profile RMS … m`` of a flight's diagnostics
    (:class:`~pipeline.align.demos.FlightDemos`) when it was fitted to the reference, else None."""
    if info.get("fit_rms_m") is None:
        return None
    alt = info.get("fit_altitude_rms_m")
    return (f"heading {np.degrees(info.get('heading_rad') or 0.0):.1f} deg, pair RMS {info['fit_rms_m']:.1f} m, "
            f"altitude-profile RMS {'n/a' if alt is None else f'{alt:.1f} m'}")


def _say(msg: str) -> None:
    print(f"uavpipe align: {msg}", file=sys.stderr, flush=True)


def make_learner(config: Mapping[str, Any], dt: float):
    """The :class:`~pipeline.align.trajectory.TrajectoryLearner` of the ``align`` section for
    demos sampled every ``dt`` s (the hidden step is ``dt/2``)."""
    from .trajectory import TrajectoryLearner  # noqa: PLC0415 (numba kernels compile on import)

    return TrajectoryLearner(dt=float(dt), window_C=int(config.get("window_C", 20)),
                             max_iter=int(config.get("max_iter", 30)), tol=float(config.get("tol", 1e-6)),
                             ridge=float(config.get("ridge", 1.0)),
                             dynamics=str(config.get("dynamics", "kinematic")))


# --- demo sets -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class DemoSet:
    """The demos of a set grouped by maneuver label (reference order), and what was left out."""

    name: str
    maneuvers: dict[str, list[Demo]]
    dropped: list[Dropped]
    flights: dict[str, dict]
    notices: list[str]


#: file stems that name a table's kind, not its flight (``uavpipe preprocess -o DIR`` writes
#: ``DIR/<flight>/{state,segments}.parquet``)
GENERIC_STEMS: tuple[str, ...] = ("state", "segments")


def table_flight_id(path: str | Path) -> str:
    """The flight id of a ``state`` or ``segments`` table.

    Its ``uavpipe`` metadata ``flight_id`` when it has one (preprocess writes it); else the
    folder name when the file stem is the generic ``state``/``segments`` of the CLI layout
    ``DIR/<flight>/state.parquet``; else the file stem (the workflow's
    ``results/state/<flight>.parquet``, whose metadata says the same flight). A file that cannot
    be read falls back on its name: reading it later says why it is bad.
    """
    p = Path(path)
    try:
        fid = read_table_meta(p).get("flight_id")
    except (OSError, ValueError):  # pyarrow's ArrowInvalid is a ValueError
        fid = None
    if fid:
        return str(fid)
    return p.parent.name if p.stem in GENERIC_STEMS and p.parent.name else p.stem


def _paths_by_flight(inputs) -> dict[str, tuple[str, str]]:
    states = declared_list(inputs, "states")
    segs = {table_flight_id(p): p for p in declared_list(inputs, "segments")}
    flights = [table_flight_id(p) for p in states]
    return {f: (p, segs.get(f)) for f, p in zip(flights, states)}


def occurrence(name: str) -> int:
    """The ``k`` of a demo name ``<flight>:<label>#<k>`` (1 without one)."""
    return int(str(name).rsplit("#", 1)[1]) if "#" in str(name) else 1


def by_occurrence(maneuvers: Mapping[str, list], repeated: set[str] | None = None) -> dict[str, list]:
    """The maneuvers with a label flown more than once in a flight split by occurrence: the k-th
    ``hB`` of every flight (demo name ``<flight>:hB#k``) is the maneuver ``hB#k``.

    A schedule that flies a label twice flies two different figures under it (P23's two ``hB``:
    the first at about 355 m going east, the second at about 60 m going west), so the demos of
    one intended trajectory are the same occurrence in each flight; pooled, the learned path
    sat 55–79 m from every demo. Occurrences count dropped segments too
    (:func:`~pipeline.align.demos.flight_demos`), so the pairing follows the schedule.
    ``repeated``: the labels to split (default: those with an occurrence above 1 among the demos).
    """
    if repeated is None:
        repeated = {lab for lab, demos in maneuvers.items() if any(occurrence(d.name) > 1 for d in demos)}
    out: dict[str, list] = {}
    for lab, demos in maneuvers.items():
        if lab not in repeated:
            out[lab] = list(demos)
            continue
        occ = [occurrence(d.name) for d in demos]
        for k in sorted(set(occ)):
            out[f"{lab}#{k}"] = [d for d, o in zip(demos, occ) if o == k]
    return out


def _failed_preprocess_reason(meta: Mapping[str, Any]) -> str | None:
    """Why preprocessing of a flight failed, from its ``state`` metadata, or None when it did not.

    Parameters
    ----------
    meta : mapping
        The ``uavpipe`` metadata of the flight's ``state`` table (:func:`read_table_meta`).

    Returns
    -------
    str or None
        ``preprocessing failed: <error>`` for a preprocess placeholder (``status``/``error`` at the
        top level, :mod:`pipeline.preprocess.run`) or a ``preprocess`` diagnostics block whose
        status is ``failed``; None otherwise.
    """
    pre = meta.get("preprocess") or {}
    if meta.get("status") != "failed" and pre.get("status") != "failed":
        return None
    error = str(meta.get("error") or pre.get("error") or "").strip()
    if not error:
        return "preprocessing failed"
    # the placeholder's own reason may already start so (a preprocess exception): said once
    return error if error.startswith("preprocessing failed") else f"preprocessing failed: {error}"


def _read_flight(state_path: str, segments_path: str) -> tuple[pd.DataFrame, pd.DataFrame, dict] | str:
    """The ``state`` and ``segments`` tables of one flight and the state's metadata, or the one-line
    reason it cannot be used (a preprocess placeholder; a file that cannot be read, named)."""
    try:
        meta = read_table_meta(state_path)
    except Exception as exc:  # a damaged file is this flight's problem, not the set's
        return f"cannot read {state_path}: {exception_line(exc, where=False)}"
    failed = _failed_preprocess_reason(meta)
    if failed is not None:
        return failed
    tables = []
    for p in (state_path, segments_path):
        try:
            tables.append(read_table(p))
        except Exception as exc:
            return f"cannot read {p}: {exception_line(exc, where=False)}"
    return tables[0], tables[1], meta


def load_demo_set(inputs, config: Mapping[str, Any], set_name: str) -> DemoSet:
    """Read and cut the demos of ``align.sets[set_name]`` from the declared inputs.

    ``inputs``: ``states`` and ``segments`` (lists of ``results/{state,segments}/<flight>.parquet``
    or the CLI's ``DIR/<flight>/{state,segments}.parquet``; the flight id is
    :func:`table_flight_id`'s). Flights of the set without inputs are skipped with a notice, and
    inputs of flights the set does not list are ignored with one. A flight that cannot be used
    (preprocessing failed, a file that cannot be read, a failed fit to the reference or demo
    cut) is a whole-flight :class:`~pipeline.align.demos.Dropped` (segment -1) with the one-line
    reason, and a notice; the other flights go on. Without a usable reference the box-less
    flights stay in NED (notice).
    """
    spec = (config.get("sets") or {}).get(set_name)
    if spec is None:
        raise KeyError(f"align.sets: no set {set_name!r} (sets: {', '.join(config.get('sets') or {}) or 'none'})")
    flights = list(spec["flights"])
    ref = spec.get("reference")
    paths = _paths_by_flight(inputs)
    hz = float(config.get("sample_hz", 3.0))
    exclude = tuple(config.get("exclude", ()))
    fit_cfg = dict(config.get("csv_fit") or {})
    notices: list[str] = []
    dropped: list[Dropped] = []
    loaded: dict[str, tuple[pd.DataFrame, pd.DataFrame, float | None]] = {}
    origins: dict[str, list[float] | None] = {}
    for f in sorted(set(paths) - set(flights)):  # given, but the set does not list it: said, not silent
        msg = f"set {set_name}: input flight {f} is not a flight of the set ({', '.join(flights)}): ignored"
        notices.append(msg)
        _say(msg)
    for f in flights:
        if f not in paths or paths[f][1] is None:
            msg = f"set {set_name}: flight {f} missing (no state/segments input): skipped"
            notices.append(msg)
            _say(msg)
            dropped.append(Dropped(f"{f}:", f, "", -1, "flight missing"))
            continue
        sp, gp = paths[f]
        got = _read_flight(sp, gp)
        if isinstance(got, str):
            notices.append(f"set {set_name}: flight {f}: {got}: skipped")
            dropped.append(Dropped(f"{f}:", f, "", -1, got))
            continue
        state, seg, meta = got
        box = meta.get("box_rotation_rad")
        pilot = meta.get("box_pilot_ned_m")  # the box origin (older state tables: none, NED origin)
        origins[f] = [float(v) for v in pilot] if pilot is not None else None
        loaded[f] = (state, seg, float(box) if box is not None else None)
    if ref is not None and ref not in loaded:
        notices.append(f"set {set_name}: reference {ref} not available: box-less flights stay in NED")
    ref_ok = ref is not None and ref in loaded
    done: dict[str, FlightDemos] = {}
    flight_dropped: dict[str, list[Dropped]] = {}
    # the reference first, so that when its demos cannot be cut the box-less flights are not
    # fitted to it (they stay in NED, as without a reference); the tables keep the set's order
    for f in sorted(loaded, key=lambda g: g != ref):
        state, seg, box = loaded[f]
        fit = None
        step = f"cannot cut the demos of {paths[f][0]}"
        try:
            if box is None and ref_ok and f != ref:
                step = f"fit to reference {ref} failed"
                r_state, r_seg, r_box = loaded[ref]
                fit, carried = fit_to_reference(state, r_state, r_seg, ref_heading_rad=r_box, sample_hz=hz,
                                                fit_hz=float(fit_cfg.get("sample_hz", 1.0)),
                                                headings=int(fit_cfg.get("headings", 24)),
                                                iterations=int(fit_cfg.get("iterations", 30)),
                                                ref_origin_ned_m=origins.get(ref), schedule_exclude=exclude)
                if not len(seg):
                    seg = carried
                step = f"cannot cut the demos of {paths[f][0]}"
            fd = flight_demos(state, seg, flight_id=f, heading_rad=box, fit=fit, sample_hz=hz, exclude=exclude,
                              box_origin_ned_m=origins.get(f))
        except Exception as exc:  # one bad flight never stops the others: its drop says why
            reason = f"{step}: {exception_line(exc)}"
            notices.append(f"set {set_name}: flight {f}: {reason}: skipped")
            flight_dropped[f] = [Dropped(f"{f}:", f, "", -1, reason)]
            if f == ref:
                ref_ok = False
                notices.append(f"set {set_name}: reference {ref} failed: box-less flights stay in NED")
            continue
        if fit is not None:
            _say(f"set {set_name}: {f} fitted to {ref}: {fit_summary(fd.diagnostics)}")
        done[f] = fd
        flight_dropped[f] = list(fd.dropped)
    per_flight = [done[f] for f in loaded if f in done]
    info = {f: done[f].diagnostics for f in loaded if f in done}
    for f in loaded:
        dropped.extend(flight_dropped.get(f, ()))
    order: list[str] = []
    for fd in sorted(per_flight, key=lambda d: d.flight_id != ref):  # the reference's order first
        for d in fd.demos:
            if d.label not in order:
                order.append(d.label)
    for d in dropped:
        if d.label and d.label not in order:
            order.append(d.label)
    maneuvers = {lab: [d for fd in per_flight for d in fd.demos if d.label == lab] for lab in order}
    if config.get("repeats", "split") == "split":
        # a label flown twice in a flight is two figures: one maneuver per occurrence, the
        # dropped demos filed under theirs
        rep = {d.label for demos in maneuvers.values() for d in demos if occurrence(d.name) > 1}
        rep |= {d.label for d in dropped if d.label and occurrence(d.name) > 1}
        maneuvers = by_occurrence(maneuvers, rep)
        dropped = [replace(d, label=f"{d.label}#{occurrence(d.name)}") if d.label in rep else d for d in dropped]
        for d in dropped:
            if d.label and d.label not in maneuvers:
                maneuvers[d.label] = []
    return DemoSet(set_name, maneuvers, dropped, info, notices)


def stretchable(demos: list[Demo], hidden_factor: float = 2.0) -> tuple[list[Demo], list[tuple[Demo, str]]]:
    """The demos the τ model can place on one hidden axis, and the others with the reason.

    With ``T = round(hidden_factor × mean N)`` and τ steps of 1–3 hidden steps from τ₀ = 0, a
    demo of ``N`` samples spans between ``N − 1`` and ``3 (N − 1)`` steps, so it fits only when
    ``N − 1 <= T − 1 <= 3 (N − 1)``. While some demo does not fit, the one whose length is
    furthest (in log ratio) from the median is dropped (a mis-cut segment, e.g. a box-less
    flight's segment carried badly through the DTW path), and T is recomputed.
    """
    keep = list(demos)
    out: list[tuple[Demo, str]] = []
    while len(keep) >= 2:
        n = np.array([len(d.t_ns) for d in keep], dtype=np.float64)
        T = int(round(hidden_factor * n.mean()))
        bad = (n - 1 > T - 1) | (3 * (n - 1) < T - 1)
        if not bad.any():
            break
        k = int(np.argmax(np.abs(np.log(n / np.median(n)))))
        out.append((keep[k], f"{int(n[k])} samples against a median of {np.median(n):.0f}: τ steps of 1-3 "
                             f"cannot place it on the T = {T} hidden steps of the others"))
        keep.pop(k)
    return keep, out


# --- tables ----------------------------------------------------------------------------------------

def _rows(a: Any, n: int, d: int) -> F64:
    """``a`` as ``(n, d)`` (NaN-padded at the end, ``None`` -> NaN), for β and the MPE."""
    out = np.full((n, d), np.nan)
    if a is None:
        return out
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 1 and a.size == d:
        a = np.broadcast_to(a, (n, d))
    if a.ndim != 2:
        return out
    k, m = min(n, a.shape[0]), min(d, a.shape[1])
    out[:k, :m] = a[:k, :m]
    return out


def _diag_history(a: Any, n_rows: int, d: int) -> F64:
    """Per-iteration diagonals from a learner attribute: ``(I, D, D)``, ``(I, D)`` per iteration,
    or a final ``(D, D)`` / ``(D,)`` (written at the last row)."""
    out = np.full((n_rows, d), np.nan)
    if a is None or n_rows == 0:
        return out
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 3:
        h = np.einsum("kii->ki", a)
    elif a.ndim == 2 and a.shape == (d, d):
        h = np.diag(a)[None, :]
    elif a.ndim == 2:
        h = a
    elif a.ndim == 1:
        h = a[None, :]
    else:
        return out
    h = h[-n_rows:]
    out[n_rows - len(h):, :h.shape[1]] = h[:, :d]
    return out


def _maneuver_tables(label: str, demos: list[Demo], model, dt: float, meta_of) -> dict[str, pd.DataFrame]:
    d = len(DEMO_COLUMNS)
    mean = np.asarray(model.mean_, dtype=np.float64)
    var = np.asarray(model.var_, dtype=np.float64)
    T = mean.shape[0]
    learned = pd.DataFrame({"maneuver": label, "t": np.arange(T), "t_s": np.arange(T) * dt})
    beta = _rows(getattr(model, "beta_", None), T, d)
    mpe = _rows(getattr(model, "model_error_", None), T, d)
    for k, c in enumerate(DEMO_COLUMNS):
        learned[f"mu_{c}"] = mean[:, k]
        learned[f"var_{c}"] = var[:, k]
        learned[f"beta_{c}"] = beta[:, k]
        learned[f"mpe_{c}"] = mpe[:, k]
    dd = np.asarray(model.d_, dtype=np.float64).reshape(len(demos), -1)
    al, dm = [], []
    for i, demo in enumerate(demos):
        tau = np.asarray(model.tau_[i], dtype=np.int64)
        frame, psi = meta_of(demo.flight_id)
        al.append(pd.DataFrame({
            "maneuver": label, "demo": demo.name, "flight_id": demo.flight_id, "segment_id": demo.segment_id,
            "status": "used", "reason": "", "frame": frame, "heading_rad": psi, "j": np.arange(len(tau)),
            "t_ns": demo.t_ns[:len(tau)], "tau": tau, "d_1": dd[i, 0], "d_2": dd[i, 1], "d_3": dd[i, 2]}))
        x = pd.DataFrame(demo.x[:len(tau)], columns=list(DEMO_COLUMNS))
        dm.append(pd.concat([pd.DataFrame({"maneuver": label, "demo": demo.name, "flight_id": demo.flight_id,
                                           "j": np.arange(len(tau)), "tau": tau, "t_s": tau * dt}), x], axis=1))
    ll = np.atleast_1d(np.asarray(model.loglik_, dtype=np.float64))
    it = pd.DataFrame({"maneuver": label, "iteration": np.arange(len(ll)), "loglik": ll})
    # per-iteration traces where the learner keeps them, else the final matrices at the last row
    sz = _diag_history(getattr(model, "sigma_z_trace_", getattr(model, "sigma_z_", None)), len(ll), d)
    sy = _diag_history(getattr(model, "sigma_y_trace_", getattr(model, "sigma_y_", None)), len(ll), d)
    for k, c in enumerate(DEMO_COLUMNS):
        it[f"sigma_z_{c}"] = sz[:, k]
        it[f"sigma_y_{c}"] = sy[:, k]
    it["status"], it["reason"], it["n_demos"] = "ok", "", len(demos)
    it["converged"] = bool(getattr(model, "converged_", False))
    return {"learned": learned, "alignment": pd.concat(al, ignore_index=True),
            "iterations": it, "demos": pd.concat(dm, ignore_index=True)}


def _not_used(label: str, name: str, flight: str, seg: int, status: str, reason: str, frame: str,
              psi: float) -> pd.DataFrame:
    return pd.DataFrame([{"maneuver": label, "demo": name, "flight_id": flight, "segment_id": seg,
                          "status": status, "reason": reason, "frame": frame, "heading_rad": psi,
                          "j": -1, "t_ns": -1, "tau": -1, "d_1": np.nan, "d_2": np.nan, "d_3": np.nan}])


def _skipped_iteration(label: str, reason: str, n: int) -> pd.DataFrame:
    row = {"maneuver": label, "iteration": -1, "loglik": np.nan, "status": "skipped", "reason": reason,
           "n_demos": n, "converged": False}
    row.update({f"sigma_{w}_{c}": np.nan for w in "zy" for c in DEMO_COLUMNS})
    return pd.DataFrame([row])


def _frame(cols: tuple[schema.Column, ...], parts: list[pd.DataFrame]) -> pd.DataFrame:
    parts = [p for p in parts if len(p)]
    if not parts:
        return schema.empty(cols)
    df = pd.concat(parts, ignore_index=True)
    return df[[c.name for c in cols]]


# --- entry point -----------------------------------------------------------------------------------

def _reason_kind(reason: str) -> str:
    """A drop reason without its counts (``12 gap rows inside the segment`` → ``gap rows inside
    the segment``), so one flight's drops are said in a few kinds."""
    return re.sub(r"^\d+ ", "", reason)


def run_align(inputs, outputs, config: Mapping[str, Any], *, set_name: str) -> AlignResult:
    """Learn the intended trajectory of every maneuver of one demo set and write its tables.

    Parameters
    ----------
    inputs : mapping or namedlist
        ``states``, ``segments``: the set's available flights' ``results/state/<flight>.parquet``
        and ``results/segments/<flight>.parquet`` (flight id: :func:`table_flight_id`).
    outputs : mapping or namedlist
        ``learned``, ``alignment``, ``iterations``, ``demos`` (Parquet paths).
    config : mapping
        The validated ``align`` section.
    set_name : str
        A key of ``align.sets``.

    Returns
    -------
    AlignResult
    """
    t_all = time.perf_counter()
    ds = load_demo_set(inputs, config, set_name)
    min_demos = int(config.get("min_demos", 2))
    frames = {f: (i.get("frame", "ned"), float(i.get("heading_rad", 0.0))) for f, i in ds.flights.items()}

    def meta_of(f: str) -> tuple[str, float]:
        return frames.get(f, ("", np.nan))

    parts: dict[str, list[pd.DataFrame]] = {k: [] for k in ALIGN_OUTPUTS}
    by_flight: dict[str, list] = {}
    for d in ds.dropped:
        by_flight.setdefault(d.flight_id, []).append(d)
    for f, ds_f in by_flight.items():
        # said per flight: a maneuver "skipped (1 usable demo(s))" below does not say whose
        # demos went missing or why (the alignment table keeps every one)
        kinds = len({_reason_kind(d.reason) for d in ds_f})
        _say(f"set {set_name}: {f}: {len(ds_f)} demo(s) dropped, first {ds_f[0].name}: {ds_f[0].reason}"
             + (f" ({kinds} kinds of reason, each in the alignment table)" if kinds > 1 else ""))
    for d in ds.dropped:
        fr, psi = meta_of(d.flight_id)
        parts["alignment"].append(_not_used(d.label, d.name, d.flight_id, d.segment_id, "dropped", d.reason,
                                            fr, psi))
    per_maneuver: dict[str, dict] = {}
    for label, demos in ds.maneuvers.items():
        demos, misfits = stretchable(demos)
        for d, why in misfits:
            _say(f"set {set_name}: {label}: {d.name} dropped ({why})")
            fr, psi = meta_of(d.flight_id)
            parts["alignment"].append(_not_used(label, d.name, d.flight_id, d.segment_id, "dropped", why, fr, psi))
        reason = ""
        if len(demos) < min_demos:
            reason = f"{len(demos)} usable demo(s) (< align.min_demos = {min_demos})"
        else:
            t0 = time.perf_counter()
            try:
                dt_demo = float(np.median(np.concatenate([np.diff(d.t_ns) for d in demos]))) * 1e-9
                model = make_learner(config, dt_demo).fit([d.x for d in demos])
                dt = float(getattr(model, "dt_hidden_", 0.5 * dt_demo))
                tabs = _maneuver_tables(label, demos, model, dt, meta_of)
            except Exception as exc:  # one maneuver's bad demos never stop the set: its row says why
                reason = f"fit failed: {exception_line(exc)}"
            else:
                for k, v in tabs.items():
                    parts[k].append(v)
                ll = np.atleast_1d(np.asarray(model.loglik_, dtype=np.float64))
                per_maneuver[label] = {"status": "ok", "n_demos": len(demos), "n_iter": int(getattr(model, "n_iter_", len(ll))),
                                       "converged": bool(getattr(model, "converged_", False)),
                                       "loglik_first": float(ll[0]), "loglik_last": float(ll[-1]),
                                       "T": int(np.asarray(model.mean_).shape[0]), "dt_s": dt}
                # times are said, not stored: same seed -> same bytes (the rule's benchmark
                # file keeps the job's run time)
                _say(f"set {set_name}: {label}: {len(demos)} demos, {per_maneuver[label]['n_iter']} iterations, "
                     f"{time.perf_counter() - t0:.1f} s")
        if reason:
            _say(f"set {set_name}: {label}: skipped ({reason})")
            per_maneuver[label] = {"status": "skipped", "reason": reason, "n_demos": len(demos)}
            for d in demos:
                fr, psi = meta_of(d.flight_id)
                parts["alignment"].append(_not_used(label, d.name, d.flight_id, d.segment_id, "skipped", reason,
                                                    fr, psi))
            parts["iterations"].append(_skipped_iteration(label, reason, len(demos)))
    n_ok = sum(1 for m in per_maneuver.values() if m["status"] == "ok")
    if n_ok == 0:
        status, error = "failed", ("no maneuver learned: " + "; ".join(
            f"{k}: {v.get('reason')}" for k, v in per_maneuver.items()) if per_maneuver else "no demos")
    elif n_ok < len(per_maneuver):
        status, error = "partial", f"{len(per_maneuver) - n_ok} of {len(per_maneuver)} maneuvers skipped"
    else:
        status, error = "ok", ""
    diag = {"set": set_name, "flights": ds.flights, "maneuvers": per_maneuver, "notices": ds.notices,
            "n_dropped": len(ds.dropped)}
    extra = {"set": set_name, "status": status, "error": error, "align": diag}
    cols = {"learned": schema.ALIGN_LEARNED, "alignment": schema.ALIGN_ALIGNMENT,
            "iterations": schema.ALIGN_ITERATIONS, "demos": schema.ALIGN_DEMOS}
    for k in ALIGN_OUTPUTS:
        write_table(_frame(cols[k], parts[k]), declared(outputs, k), cols[k], name=f"align_{k}", extra=extra)
    _say(f"set {set_name}: {n_ok}/{len(per_maneuver)} maneuvers learned ({status}) in {time.perf_counter() - t_all:.1f} s")
    return AlignResult(set_name, status, error, diag)
