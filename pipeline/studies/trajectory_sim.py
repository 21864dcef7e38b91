"""The simulated part of ``study_trajectory_learning`` (issue 15, Acceptance "Simulated demos";
seed 004 §10 item 2): the trajectory learner against the baselines on demos with a known intent.

Seed 004 §10 item 2: "Check that learned-vs-truth error is below demo-vs-truth error; this makes
'straighter than any demo' quantitative."

For each reference (:data:`~pipeline.simulate.demos.REFERENCES`) and seed, M demos are simulated
(:func:`~pipeline.simulate.demos.simulate_demos`) and every candidate's **position RMSE (m)
against the true intended trajectory** is taken sample by sample, each demo sample ``j`` of demo
``k`` standing for the intended point ``x[τ_j^k]`` at its true hidden index:

* ``learned``: the learned ``μ`` at the learned index ``τ̂_j^k`` (:class:`TrajectoryLearner`);
* ``best_demo`` / ``mean_demo``: the demo sample itself (the best demo, the demos' mean RMSE);
* ``dba``: the DBA average of the demos' positions (:func:`~pipeline.align.baselines.dba_average`,
  metres, unscaled) at the average's samples DTW-aligned to ``j`` (their mean);
* ``dba_smoothed``: the same for the RTS-smoothed DBA average
  (:func:`~pipeline.align.baselines.smooth`);
* ``best_smoothed_demo`` / ``mean_smoothed_demo``: each demo's own smoother
  (:func:`~pipeline.align.baselines.per_demo_smooth`) at sample ``j``.

The headline ``align_sim_refs_learned_best`` counts the references on which the learned
trajectory's mean RMSE over the seeds is below that of every baseline (best single demo, DBA,
smoothed DBA, best per-demo smoother).

**The seed's airframe** (issue 15 Build item 2, "Optionally, on simulated demos only, the seed-004
Yak54 model with the §12 errata and no lift term (β absorbs it)"): the references of
:data:`~pipeline.simulate.demos.YAK54_REFERENCES` are flown by the Yak54 model *with* a lift term
(:func:`~pipeline.simulate.demos.simulate_yak54_demos`, 17 columns: state and controls) and learned
with ``dynamics="yak54"`` (no lift), beside two more candidates: ``learned_no_bias`` (the same
without β: §6.1.3, "Without providing the bias terms the learning algorithm was unable to learn
the intended trajectory") and ``learned_kinematic`` (the generic kinematic model on the demos'
positions). ``align_sim_yak54_refs_learned_best`` counts those references where the learned
trajectory beats every baseline.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import fields
from typing import Any

import numpy as np
import pandas as pd

from ..align.baselines import dba_average, per_demo_smooth, smooth
from ..align.dtw import dtw
from ..align.trajectory import TrajectoryLearner
from ..simulate.demos import (REFERENCES, YAK54_REFERENCES, DemoSet, DemoSimSettings, simulate_demos,
                              simulate_yak54_demos)

#: the simulated study's settings and their defaults (``small``); ``simulate`` overrides
#: :class:`~pipeline.simulate.demos.DemoSimSettings` fields, ``learner`` the learner's keywords
SIM_DEFAULTS: dict[str, Any] = {
    "n_seeds": 10,
    "n_demos": 5,
    "references": list(REFERENCES),
    "duration_s": 30.0,
    "window_C": 20,
    "max_iter": 30,
    "tol": 1e-6,
    "dba_iter": 10,
    "simulate": {},
    "learner": {},
    "yak54_references": list(YAK54_REFERENCES),
    "yak54_duration_s": 12.0,
    "yak54_n_seeds": 10,
}
#: per-size overrides (tiny: short references, few iterations; still ≥ 10 seeds)
SIM_SIZES: dict[str, dict[str, Any]] = {
    "tiny": {"duration_s": 6.0, "max_iter": 8, "window_C": 10, "dba_iter": 5, "yak54_duration_s": 4.0,
             "yak54_n_seeds": 4},
    "small": {},
    "thesis": {"duration_s": 60.0, "yak54_duration_s": 20.0},
}
#: the candidates, in table order; the baselines the learned trajectory must beat
METHODS = ("learned", "best_demo", "mean_demo", "dba", "dba_smoothed", "best_smoothed_demo", "mean_smoothed_demo")
BASELINES = ("best_demo", "dba", "dba_smoothed", "best_smoothed_demo")
#: the Yak54 references' extra candidates
YAK54_METHODS = METHODS + ("learned_no_bias", "learned_kinematic")


def _rmse(e: np.ndarray) -> float:
    """RMS of the position error norm over rows."""
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=-1))))


def _through_dtw(avg: np.ndarray, demo: np.ndarray, scale) -> np.ndarray:
    """The rows of ``avg`` DTW-aligned to each demo sample, averaged: (N, D)."""
    p = dtw(avg, demo, step_pattern="symmetric1", local="sqeuclidean", scale=scale, path=True).path
    out = np.zeros((len(demo), avg.shape[1]))
    cnt = np.zeros(len(demo))
    np.add.at(out, p[:, 1], avg[p[:, 0]])
    np.add.at(cnt, p[:, 1], 1.0)
    return out / cnt[:, None]


def learned_rmse(ds: DemoSet, learner: TrajectoryLearner, demos: list | None = None) -> float:
    """Fit ``learner`` to ``demos`` (default the set's) and return the learned trajectory's
    position RMSE (m) against the truth, at each sample's learned index vs its true one."""
    learner.fit(ds.demos if demos is None else demos)
    x = ds.intended[:, :3]
    return _rmse(np.concatenate([learner.mean_[learner.tau_[k], :3] - x[tk] for k, tk in enumerate(ds.tau_true)]))


def evaluate_case(ds: DemoSet, *, learner: TrajectoryLearner, dba_iter: int = 10) -> tuple[dict[str, float], TrajectoryLearner]:
    """Position RMSE (m) of every candidate against the truth on one demo set (module docstring)."""
    x = ds.intended[:, :3]
    demos = ds.demos
    rm: dict[str, float] = {"learned": learned_rmse(ds, learner)}
    T = learner.T_
    per = [_rmse(y[:, :3] - x[tk]) for y, tk in zip(demos, ds.tau_true)]
    rm["best_demo"], rm["mean_demo"] = float(np.min(per)), float(np.mean(per))
    # DBA on the positions, in metres without scaling: a per-feature std scale lets the noisiest
    # columns (accelerations; the down axis of level flight) steer the alignment
    pos = [y[:, :3] for y in demos]
    avg = dba_average(pos, n_iter=dba_iter)
    sm = smooth(avg, ds.dt)
    for name, a in (("dba", avg), ("dba_smoothed", sm)):
        err = [(_through_dtw(a, y, None) - x[tk]) for y, tk in zip(pos, ds.tau_true)]
        rm[name] = _rmse(np.concatenate(err))
    pds = per_demo_smooth([y[:, :3] for y in demos], ds.dt)
    per = [_rmse(s - x[tk]) for s, tk in zip(pds, ds.tau_true)]
    rm["best_smoothed_demo"], rm["mean_smoothed_demo"] = float(np.min(per)), float(np.mean(per))
    rm["T"] = T
    return rm, learner


def _settings(settings: Mapping | None) -> dict[str, Any]:
    s = {**SIM_DEFAULTS, **{k: v for k, v in dict(settings or {}).items() if k in SIM_DEFAULTS}}
    if int(s["n_seeds"]) < 1 or int(s["n_demos"]) < 2:
        raise ValueError(f"study_trajectory_learning: n_seeds must be >= 1 and n_demos >= 2, got "
                         f"{s['n_seeds']}, {s['n_demos']}")
    bad = sorted(set(s["references"]) - set(REFERENCES))
    if bad:
        raise ValueError(f"study_trajectory_learning.references: unknown {bad}; known: {', '.join(REFERENCES)}")
    bad = sorted(set(s["yak54_references"]) - set(YAK54_REFERENCES))
    if bad:
        raise ValueError(f"study_trajectory_learning.yak54_references: unknown {bad}; known: "
                         f"{', '.join(YAK54_REFERENCES)}")
    known = {f.name for f in fields(DemoSimSettings)}
    bad = sorted(set(s["simulate"] or {}) - known)
    if bad:
        raise ValueError(f"study_trajectory_learning.simulate: unknown key(s) {bad}; known: {sorted(known)}")
    return s


def simulated_study(settings: Mapping | None, *, seed: int,
                    progress: Callable[[str], Any] | None = None) -> tuple[dict[str, pd.DataFrame], list[tuple[str, Any, str]]]:
    """Run the simulated comparison.

    Parameters
    ----------
    settings : mapping
        Keys of :data:`SIM_DEFAULTS` (others are ignored: the real-data part's); already merged
        for the size (e.g. with :data:`SIM_SIZES`). ``simulate`` holds
        :class:`~pipeline.simulate.demos.DemoSimSettings` fields (config ``align.simulate``),
        whose ``duration_s`` the study's own ``duration_s`` replaces; ``learner`` holds extra
        :class:`~pipeline.align.trajectory.TrajectoryLearner` keywords.
    seed : int
        Master seed; case ``(reference r, seed i)`` uses ``default_rng([seed, r, i])``.
    progress : callable, optional
        Called with one line per reference.

    Returns
    -------
    tables : dict of DataFrame
        ``sim_cases`` (one row per reference, seed and method: ``rmse_m``) and ``sim_summary``
        (per reference and method: mean, std, min, max over the seeds, ``learned_best``).
    results : list of (name, value, definition)
        ``align_sim_refs_learned_best`` and per reference ``align_sim_<ref>_learned_rmse_m``,
        ``align_sim_<ref>_best_baseline_rmse_m``.
    """
    s = _settings(settings)
    # the study's (per-size) duration wins over align.simulate's: tiny must stay short
    sim = DemoSimSettings(**{**dict(s["simulate"] or {}), "duration_s": float(s["duration_s"])})
    rows = []
    for r_i, ref in enumerate(REFERENCES):
        if ref not in s["references"]:
            continue
        t0 = time.perf_counter()
        for i in range(int(s["n_seeds"])):
            rng = np.random.default_rng([int(seed), r_i, i])
            ds = simulate_demos(ref, n_demos=int(s["n_demos"]), rng=rng, settings=sim)
            lk = {"window_C": int(s["window_C"]), "max_iter": int(s["max_iter"]), "tol": float(s["tol"]),
                  **dict(s["learner"] or {})}
            rm, L = evaluate_case(ds, learner=TrajectoryLearner(dt=ds.dt, **lk), dba_iter=int(s["dba_iter"]))
            for m in METHODS:
                rows.append({"reference": ref, "seed": i, "method": m, "rmse_m": rm[m],
                             "n_iter": L.n_iter_, "converged": bool(L.converged_)})
        if progress is not None:
            progress(f"trajectory sim: {ref}: {s['n_seeds']} seeds in {time.perf_counter() - t0:.1f} s")
    ysim = DemoSimSettings(**{**dict(s["simulate"] or {}), "duration_s": float(s["yak54_duration_s"])})
    for r_i, ref in enumerate(YAK54_REFERENCES):
        if ref not in s["yak54_references"]:
            continue
        t0 = time.perf_counter()
        for i in range(int(s["yak54_n_seeds"])):
            rng = np.random.default_rng([int(seed), len(REFERENCES) + r_i, i])
            ds = simulate_yak54_demos(ref, n_demos=int(s["n_demos"]), rng=rng, settings=ysim)
            lk = {"window_C": int(s["window_C"]), "max_iter": int(s["max_iter"]), "tol": float(s["tol"]),
                  **dict(s["learner"] or {})}
            rm, L = evaluate_case(ds, learner=TrajectoryLearner(dt=ds.dt, **{**lk, "dynamics": "yak54"}),
                                  dba_iter=int(s["dba_iter"]))
            # the extra candidates need only their learned RMSE (the baselines are the same demos')
            rm["learned_no_bias"] = learned_rmse(
                ds, TrajectoryLearner(dt=ds.dt, **{**lk, "dynamics": "yak54", "use_bias": False}))
            rm["learned_kinematic"] = learned_rmse(ds, TrajectoryLearner(dt=ds.dt, **lk), [y[:, :3] for y in ds.demos])
            for m in YAK54_METHODS:
                rows.append({"reference": ref, "seed": i, "method": m, "rmse_m": rm[m],
                             "n_iter": L.n_iter_, "converged": bool(L.converged_)})
        if progress is not None:
            progress(f"trajectory sim: {ref}: {s['yak54_n_seeds']} seeds in {time.perf_counter() - t0:.1f} s")
    cases = pd.DataFrame(rows)
    g = cases.groupby(["reference", "method"], sort=False)["rmse_m"]
    summ = g.agg(["mean", "std", "min", "max", "count"]).reset_index()
    summ = summ.rename(columns={"mean": "rmse_mean_m", "std": "rmse_std_m", "min": "rmse_min_m",
                                "max": "rmse_max_m", "count": "n_seeds"})
    results: list[tuple[str, Any, str]] = []
    flags = {}
    for ref in summ["reference"].unique():
        m = summ[summ["reference"] == ref].set_index("method")["rmse_mean_m"]
        best_base = float(min(m[b] for b in BASELINES))
        flags[ref] = bool(m["learned"] < best_base)
        results.append((f"align_sim_{ref}_learned_rmse_m", round(float(m["learned"]), 4),
                        f"{ref}: mean position RMSE (m) of the learned trajectory vs the intended one"))
        results.append((f"align_sim_{ref}_best_baseline_rmse_m", round(best_base, 4),
                        f"{ref}: the best baseline's mean position RMSE (m) ({', '.join(BASELINES)})"))
        for extra, what in (("learned_no_bias", "the Yak54 learner without the bias terms β"),
                            ("learned_kinematic", "the kinematic learner on the demos' positions")):
            if extra in m:
                results.append((f"align_sim_{ref}_{extra}_rmse_m", round(float(m[extra]), 4),
                                f"{ref}: mean position RMSE (m) of {what}"))
    summ["learned_best"] = summ["reference"].map(flags)
    kin = [r for r in flags if r in REFERENCES]
    yak = [r for r in flags if r in YAK54_REFERENCES]
    results.insert(0, ("align_sim_refs_learned_best", int(sum(flags[r] for r in kin)),
                       f"references (of {len(kin)}) where the learned trajectory's mean RMSE beats every baseline"))
    if yak:
        results.insert(1, ("align_sim_yak54_refs_learned_best", int(sum(flags[r] for r in yak)),
                           f"Yak54 references (of {len(yak)}; learned with dynamics=yak54, no lift, β) where the "
                           "learned trajectory's mean RMSE beats every baseline"))
    return {"sim_cases": cases, "sim_summary": summ}, results
