"""Study ``trajectory_learning``: seed 004's learner on simulated demos with known intent and on
real F3A schedules by leave-one-out.

**Simulated part** (:func:`pipeline.studies.trajectory_sim.simulated_study`): per reference
(level flight with turns, a hover-like pull-up, a loop) and seed, M demos with known intent; the
learned trajectory's position RMSE against the truth beside the best single demo, the DBA
average and the smoothed DBA average (tables ``sim_cases``, ``sim_summary``;
``RESULT align_sim_refs_learned_best``).

**Real part** (this module): the demo sets ``align.sets`` named by ``sets`` (default P23: the
two P23 flights, whose ``hB`` is flown twice each; P21: the labelled FlightCoach flight and the
two kd0aij CSVs rigidly fitted to it), demos in the box frame (:mod:`pipeline.align.demos`). A label flown twice in a flight is two
maneuvers, one per occurrence (``repeats: split``, :func:`pipeline.align.run.by_occurrence`; ``pool``: one).
For every maneuver and every demo *k* (leave one out), the trajectory is learned from the other
demos (:class:`~pipeline.align.trajectory.TrajectoryLearner` with the ``align`` settings; the
learned μ on its whole hidden axis) and compared with the left-out demo by the RMS 3-D position
distance along their DTW path (symmetric2, box frame), both taken as curves (densified to 0.5 m,
:func:`pipeline.align.anchors.dense_dtw_rms`: on the 3 Hz samples, ~9 m apart, the pairing of
samples alone reads 3-5 m between a demo and a trajectory learned from that very demo), beside each other demo's distance to it and their DBA
average's (:func:`pipeline.align.baselines.dba_average`). Where only one other demo is left (a
maneuver with two demos) the learner is given that demo twice (it needs two; the fit is then a
smoother of that one demo on the hidden axis) — such folds are marked ``single_other``. Two
identical demos drive the ML Σ^(y) to its floor, so the fit interpolates that demo (on simulated
demos it is exactly as far from the truth as the demo); its distance to the left-out demo then
equals the other demo's within the curves' resolution (≤ 0.3 m measured), and "better" on such a
maneuver is decided by that tie.

Each comparison is made twice (``frames``): in the box frame as the demos are (the headline),
and **centred**, each demo's mean position subtracted first, so that what is compared is the
maneuver's shape rather than where in the box the pilot flew it (two flights of one schedule
are commonly flown 50–100 m apart in range, which no averaging of demos can recover).

A maneuver counts as **better** when the learned trajectory's distance to the left-out demo,
averaged over its folds, is below the averaged distance of the closest other demo;
``RESULT align_real_loo_better_pct`` is the share of maneuvers that are better in the box frame
(target ≥ 80), ``align_real_loo_better_pct_centred`` the same centred.

Seed: the simulated part draws from ``default_rng([seed, reference, i])``; the real part has no
randomness.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import plotly.graph_objects as go

from ..align.anchors import dense_dtw_rms
from ..align.baselines import dba_average
from ..align.run import fit_summary, load_demo_set, make_learner, stretchable
from ..config import ConfigError, load_config, section
from ..io.parquet import write_table
from ..report.study import build_study_page
from .base import (Progress, Results, StudyResult, input_path, md_table, output_path, say, study_settings,
                   write_text)

NAME = "trajectory_learning"
ROOT = Path(__file__).resolve().parents[2]
OUTPUT_TABLES = ("sim_cases", "sim_summary", "real_loo", "real_summary")
DEFAULTS: dict[str, Any] = {"sets": ["p23", "p21"], "skip": [], "sim": {}, "frames": ["box", "centred"],
                            "real_max_iter": 30, "real_maneuvers": 0, "repeats": "split"}
SIZES: dict[str, dict[str, Any]] = {"tiny": {"real_max_iter": 5, "real_maneuvers": 3},
                                    "small": {}, "thesis": {}}


def _path_rms(a: np.ndarray, b: np.ndarray) -> float:
    # as curves (densified to 0.5 m): on the 3 Hz samples (~9 m apart) the path's pairing error
    # alone is 3-5 m, more than most of the differences compared here
    return dense_dtw_rms(a, b)


def _centred(x: np.ndarray) -> np.ndarray:
    y = np.array(x, dtype=np.float64, copy=True)
    y[:, :3] -= y[:, :3].mean(axis=0)
    return y


def loo_maneuver(set_name: str, label: str, demos, align_cfg: Mapping, *, max_iter: int,
                 frame: str = "box") -> list[dict]:
    """One row per fold (left-out demo) of one maneuver (see the module docstring).

    ``frame``: ``box`` (the demos as they are) or ``centred`` (each demo's mean position
    subtracted first: the maneuver's shape, without where in the box it was flown).
    """
    cfg = {**dict(align_cfg), "max_iter": int(max_iter)}
    dt = float(np.median(np.concatenate([np.diff(d.t_ns) for d in demos]))) * 1e-9
    xs = [_centred(d.x) if frame == "centred" else d.x for d in demos]
    dist: dict[tuple[int, int], float] = {}

    def path_rms(i: int, j: int) -> float:
        # demo i to demo j, each ordered pair's DTW once per frame: a fold's distances to the
        # left-out demo are the other folds' distances between their training demos
        if (i, j) not in dist:
            dist[(i, j)] = _path_rms(xs[i], xs[j])
        return dist[(i, j)]

    rows = []
    for k, left in enumerate(demos):
        oi = [i for i in range(len(demos)) if i != k]
        others, ox = [demos[i] for i in oi], [xs[i] for i in oi]
        lx = xs[k]
        train = ox if len(ox) >= 2 else [ox[0], ox[0]]
        row = {"set": set_name, "maneuver": label, "frame": frame, "left_out": left.name, "n_others": len(others),
               "single_other": len(others) == 1}
        try:
            model = make_learner(cfg, dt).fit(train)
        except ValueError as exc:
            row.update(status=f"fit failed: {exc}", rms_learned_m=np.nan, rms_best_other_m=np.nan,
                       rms_worst_other_m=np.nan, rms_dba_m=np.nan)
            rows.append(row)
            continue
        mu = np.asarray(model.mean_)  # the whole hidden axis (step dt/2); compared as a curve
        d_other = [path_rms(i, k) for i in oi]
        dba = dba_average([o[:, :3] for o in ox]) if len(ox) >= 2 else ox[0][:, :3]
        # how far apart the training demos are from each other: a learned path between them can
        # beat the closest one only where the left-out demo is not already beside one of them
        between = [path_rms(i, j) for a, i in enumerate(oi) for j in oi[a + 1:]]
        row.update(status="ok", rms_learned_m=_path_rms(mu, lx), rms_best_other_m=float(min(d_other)),
                   rms_worst_other_m=float(max(d_other)), rms_dba_m=_path_rms(dba, lx),
                   closest_other=others[int(np.argmin(d_other))].name,
                   rms_between_others_m=float(np.mean(between)) if between else np.nan,
                   n_iter=int(getattr(model, "n_iter_", 0)))
        rows.append(row)
    return rows


def real_part(inputs, align_cfg: Mapping, st: Mapping, progress) -> tuple[pd.DataFrame, pd.DataFrame, list[str]]:
    """The leave-one-out folds (``real_loo``), the per-maneuver summary and the notices."""
    rows, notices = [], []
    for s in st["sets"]:
        if s not in (align_cfg.get("sets") or {}):
            raise ConfigError(f"studies.{NAME}.sets: {s!r} is not an align.sets entry "
                              f"({', '.join(align_cfg.get('sets') or {}) or 'none'})")
        if st["repeats"] not in ("split", "pool"):
            raise ConfigError(f"studies.{NAME}.repeats: {st['repeats']!r} is not 'split' or 'pool'")
        # the study's own choice, which the workflow's align stage takes from align.repeats
        ds = load_demo_set(inputs, {**align_cfg, "repeats": st["repeats"]}, s)
        notices += ds.notices
        for f, info in ds.flights.items():
            # a box-less flight's fit and the fit-free schedule check, so a poor fit can be told
            # from a flight of another schedule
            if (summary := fit_summary(info)) is not None:
                notices.append(f"set {s}: {f} fitted to the reference: {summary}")
        if not ds.maneuvers:
            notices.append(f"set {s}: no demos (its flights are not available): skipped")
            continue
        maneuvers = ds.maneuvers
        labels = list(maneuvers)
        if int(st["real_maneuvers"]) > 0:
            labels = labels[: int(st["real_maneuvers"])]
        for lab in labels:
            demos, misfits = stretchable(maneuvers[lab])
            if len(demos) < 2:
                rows += [{"set": s, "maneuver": lab, "frame": fr, "left_out": "", "n_others": len(demos) - 1,
                          "single_other": False, "status": f"skipped: {len(demos)} usable demo(s)"}
                         for fr in st["frames"]]
                continue
            t0 = time.perf_counter()
            for frame in st["frames"]:
                rows += loo_maneuver(s, lab, demos, align_cfg, max_iter=int(st["real_max_iter"]), frame=frame)
            progress(f"real {s} {lab}: {len(demos)} folds in {time.perf_counter() - t0:.1f} s"
                     + (f" ({len(misfits)} demo(s) dropped: length)" if misfits else ""))
    loo = pd.DataFrame(rows)
    if not len(loo):
        return loo, pd.DataFrame(), notices
    ok = loo[loo["status"] == "ok"]
    summ = ok.groupby(["frame", "set", "maneuver"], sort=False).agg(
        folds=("left_out", "size"), demos=("n_others", lambda v: int(v.iloc[0]) + 1),
        single_other=("single_other", "any"), rms_learned_m=("rms_learned_m", "mean"),
        rms_best_other_m=("rms_best_other_m", "mean"), rms_worst_other_m=("rms_worst_other_m", "mean"),
        rms_dba_m=("rms_dba_m", "mean")).reset_index()
    summ["better"] = summ["rms_learned_m"] < summ["rms_best_other_m"]
    summ["better_than_dba"] = summ["rms_learned_m"] < summ["rms_dba_m"]
    return loo, summ, notices


def _figure(summ: pd.DataFrame, frame: str = "box frame") -> go.Figure | None:
    """The leave-one-out distances per maneuver, three bars each; ``frame`` names the frame in
    the title (the box frame and the centred one were two panels of one title)."""
    if summ is None or not len(summ):
        return None
    x = [f"{a}:{b}" for a, b in zip(summ["set"], summ["maneuver"])]
    fig = go.Figure()
    for col, name in (("rms_learned_m", "learned from the others"), ("rms_best_other_m", "closest other demo"),
                      ("rms_dba_m", "DBA of the others")):
        fig.add_trace(go.Bar(x=x, y=summ[col], name=name))
    fig.update_layout(barmode="group", title=f"Leave one out ({frame}): RMS distance to the left-out demo after DTW",
                      template="plotly_white", height=420, yaxis_title="RMS distance [m]")
    return fig


def run_trajectory_learning(inputs: Mapping | None, outputs: Mapping, config: Mapping | None, *, seed: int,
                            align: Mapping | None = None, **_other) -> StudyResult:
    """Run the trajectory-learning study and write its tables, report, results and page.

    Parameters
    ----------
    inputs : mapping or None
        ``states``, ``segments``: the demo sets' flights' preprocessed tables (flight id = file
        stem; absent flights are skipped with a notice); optional ``template``.
    outputs : mapping
        ``report``, ``results``, ``page`` and one per table of :data:`OUTPUT_TABLES`.
    config : mapping or None
        The ``studies`` section (``size``, ``trajectory_learning``).
    seed : int
        The master seed (simulated part).
    align : mapping, optional
        The ``align`` section (default: ``datasets/config.yaml``'s).

    Returns
    -------
    StudyResult
    """
    size, st = study_settings(config, NAME, DEFAULTS, SIZES)
    skip = set(st["skip"] or ())
    if skip - {"simulated", "real"}:
        raise ConfigError(f"studies.{NAME}.skip: unknown part(s) {sorted(skip - {'simulated', 'real'})}")
    align = dict(align) if align is not None else section(load_config(), "align")
    template = input_path(inputs, "template", ROOT / "reports" / "templates" / "study.html.j2")
    paths = {k: output_path(outputs, k) for k in ("report", "results", "page", *OUTPUT_TABLES)}
    progress = Progress()
    res = Results()
    notices: list[str] = []
    sim_tables: dict[str, pd.DataFrame] = {}
    if "simulated" not in skip:
        try:
            from .trajectory_sim import SIM_SIZES, simulated_study  # noqa: PLC0415 (h15-em)
        except ImportError as exc:
            notices.append(f"simulated part not available ({exc}): skipped")
        else:
            sim_settings = {**SIM_SIZES.get(size, {}), **dict(st["sim"] or {})}
            # the demos' own settings: align.simulate, under the study's sim.simulate overrides
            sim_settings["simulate"] = {**{k: (tuple(v) if isinstance(v, list) else v)
                                           for k, v in dict(align.get("simulate") or {}).items()},
                                        **dict(sim_settings.get("simulate") or {})}
            sim_tables, sim_results = simulated_study(sim_settings, seed=int(seed), progress=progress)
            for metric, value, definition in sim_results:
                res.add(metric, value, definition)
    for k in ("sim_cases", "sim_summary"):
        write_table(sim_tables.get(k, pd.DataFrame()), paths[k], name=f"{NAME}_{k}",
                    extra={"size": size, "seed": int(seed), "skipped": k not in sim_tables})
    loo, summ, summ_all = pd.DataFrame(), pd.DataFrame(), pd.DataFrame()
    if "real" not in skip:
        loo, summ, n2 = real_part(inputs, align, st, progress)
        notices += n2
    write_table(loo, paths["real_loo"], name=f"{NAME}_real_loo", extra={"size": size, "notices": notices})
    write_table(summ, paths["real_summary"], name=f"{NAME}_real_summary", extra={"size": size})  # every frame
    for n in notices:
        say(f"uavpipe study {NAME}: {n}")
    if len(summ) and "centred" in set(summ["frame"]):
        cen = summ[summ["frame"] == "centred"]
        res.add("align_real_loo_better_pct_centred", f"{100.0 * float(cen['better'].mean()):.1f}",
                "As align_real_loo_better_pct with each demo's mean position subtracted first (the maneuver's "
                "shape, not where in the box it was flown) (%).")
        multi = cen[~cen["single_other"]]
        if len(multi):
            res.add("align_real_loo_better_pct_centred_3plus_demos", f"{100.0 * float(multi['better'].mean()):.1f}",
                    "The centred share over the maneuvers with at least 3 demos (%).")
    summ_all, summ = summ, (summ[summ["frame"] == "box"] if len(summ) else summ)
    if len(summ):
        pct = 100.0 * float(summ["better"].mean())
        res.add("align_real_loo_better_pct", f"{pct:.1f}",
                "Share of real maneuvers (P23, P21; box frame) where the trajectory learned from the other demos "
                "is closer (RMS after DTW, mean over folds) to the left-out demo than the closest other demo (%, target ≥ 80).")
        res.add("align_real_loo_better_than_dba_pct", f"{100.0 * float(summ['better_than_dba'].mean()):.1f}",
                "Share of real maneuvers where the learned trajectory is closer to the left-out demo than the others' DBA average (%).")
        multi = summ[~summ["single_other"]]
        if len(multi):
            res.add("align_real_loo_better_pct_3plus_demos", f"{100.0 * float(multi['better'].mean()):.1f}",
                    "The same share over the maneuvers with at least 3 demos (at least 2 left to learn from) (%).")
        folds = loo[(loo["status"] == "ok") & (loo["frame"] == "box") & ~loo["single_other"].astype(bool)]
        if len(folds):
            res.add("align_real_loo_folds_better_3plus_demos",
                    f"{int((folds['rms_learned_m'] < folds['rms_best_other_m']).sum())}/{len(folds)}",
                    "Box-frame folds of the maneuvers with at least 3 demos where the learned trajectory is closer "
                    "to the left-out demo than the closest other demo.")
            res.add("align_real_loo_closest_over_between_3plus_demos",
                    f"{float(np.median(folds['rms_best_other_m'] / folds['rms_between_others_m'])):.3f}",
                    "Those folds, median of (left-out demo to its closest other) / (the other demos to each other), "
                    "RMS after DTW: below 1 the left-out demo lies beside one other demo rather than among them, "
                    "where a path between the others is farther than that demo.")
        res.add("align_real_loo_maneuvers", len(summ), "Real maneuvers in the leave-one-out.")
    if len(loo):
        # the shares above are over the maneuvers with at least one scored fold: say how many were
        # left out of their denominator (too few demos, or every fold failed) and how many folds failed
        box = loo[loo["frame"] == "box"]
        st_ = box["status"].astype(str)
        keys = box[["set", "maneuver"]].apply(tuple, axis=1)
        scored = set(keys[st_ == "ok"])
        res.add("align_real_loo_maneuvers_unscored", len(set(keys) - scored),
                "Real maneuvers left out of the leave-one-out shares: fewer than 2 usable demos, or no fold fitted.")
        res.add("align_real_loo_folds_failed", int((~st_.str.startswith("skipped") & (st_ != "ok")).sum()),
                "Box-frame leave-one-out folds whose learner failed (left out of their maneuver's mean).")
    res.add("align_trajectory_learning_wall_s", f"{progress.elapsed:.0f}", "Wall time of the study (s), page excluded.")
    res.write(paths["results"])
    md = [f"# Trajectory learning ({size})", "",
          "Simulated demos with known intent (position RMSE against the truth, m) and real F3A schedules by "
          "leave one out (RMS distance to the left-out demo after DTW, box frame, m).", ""]
    if "sim_summary" in sim_tables and len(sim_tables["sim_summary"]):
        md += ["## Simulated demos", "", md_table(sim_tables["sim_summary"]), ""]
    if len(summ):
        md += ["## Real demos, leave one out (per maneuver, mean over folds; frame box, then centred)", "",
               md_table(summ_all, "{:.1f}"), ""]
    if notices:
        md += ["## Notices", "", *(f"- {n}" for n in notices), ""]
    write_text(paths["report"], "\n".join(md))
    build_study_page(NAME, paths["page"], results=paths["results"], report_md=paths["report"], template=template,
                     definitions=res.definitions, figures=[("Leave one out", _figure(summ)),
                                                               ("Leave one out, centred",
                                                                _figure(summ_all[summ_all["frame"] == "centred"] if len(summ_all) else summ_all,
                                                                        "each demo centred on its mean position"))],
                     title=f"Study: trajectory learning from repeated demonstrations ({size})",
                     facts=[("size", size), ("seed", str(seed)), ("sets", ", ".join(st["sets"])),
                            ("tables", ", ".join(f"{t}.parquet" for t in OUTPUT_TABLES))])
    return StudyResult(name=NAME, status="ok", results=dict(res.values),
                       diagnostics={"size": size, "seed": int(seed), "settings": st, "notices": notices,
                                    "wall_s": round(progress.elapsed, 1)})
