"""Seed-000 classification study on simulated truth: Tables 3.1–3.4, 3.10–3.12, GMR errors;
with ``ekf_input`` also on EKF estimates: Tables 3.5–3.8, 3.13–3.15.

Steps (seed 000 §2, §3.3–§3.6, §5, §11; corrections §13):

1. Simulate ``runs`` runs of each maneuver M1–M5 (thesis: 2300) with
   :func:`pipeline.simulate.datasets.simulate_set` (random N/E start and heading, Gauss–Markov
   disturbance, truth at 5 Hz) and split them 70/30 exactly as ``uavpipe simulate`` does — or
   read an existing ``uavpipe simulate`` output (input ``sets``: its folder).
2. Train one HMM per known maneuver M1–M4 (``hmm:`` config; thesis state counts 5/6/6/6).
3. Tables 3.1–3.4: one-class and confidence classifiers, cumulative mode (thesis-faithful),
   train and test sets; M5 is the unknown maneuver. Confusion matrices of final labels, the
   per-sample confusion of Table 3.4, ``3.4+1c`` (ours): the confidence decision gated by
   the one-class threshold (decision ``both``, as on real data), and ``3.4+bg`` (ours): the
   confidence decision with a background GMM as one more rival hypothesis (``confidence_bg``).
4. Tables 3.10–3.12: change scenarios A–D at 3/8/13 s (``switch_runs`` per cell, thesis 243),
   truth input, confidence classifier, in ``cumulative``, ``windowed`` and ``reset`` modes;
   final MAoT counted from the end of the 2 s blend; detection delay = time from the switch to
   the first sample from which the final maneuver is labelled for ≥ 1 s. The reset-mode change
   point is also measured with each switch time moved by ±1 s.
5. GMR (§3.6.4, §7): on test runs, per maneuver and NED axis, mean error and error variance
   over time of the HMM acceleration and jerk estimates, and scalar RMSE against the
   finite-difference acceleration from the last three 5 Hz truth positions, all on the same
   samples. Besides the configured GMR (``acc``/``jerk``; default ``pos_fd``: conditioned on
   ``Δr`` and the position-only ``Δv̂`` — the FD's own information) it scores ``acc_pos``
   ((3.28), ``Δr`` only), ``acc_interval`` (``â = Δv/dt`` as printed, §13.3) and ``acc_posvel``
   (conditioned on ``Δr`` and the true ``Δv``: information a position-only FD does not have).

6. With ``ekf_input: true`` (``studies.seed000_classification``): the same train/test runs
   filtered by the CA EKF on radar synthesised from the truth, exactly as the ``ekf_sets`` rule
   filters the workflow's sets (:func:`pipeline.estimate.sets.ekf_set`, ``estimate.sets``,
   radar ``simulate.sensors.radar``, ``ekf_rng(seed, "<M>_<train|test>")``): Tables 3.5–3.8
   (one-class/confidence, train/test, cumulative) with the truth-trained models — the thesis
   setup — and with models trained the same way on the EKF estimates of the training runs
   (``trained_on``: truth | ekf); Tables 3.13–3.15: the switch cells on EKF estimates
   (``ekf_rng(seed, "switch_<K>_<t>s")``), confidence classifier, cumulative (thesis) and
   windowed (ours), both trainings. Thesis values: digest §11 (truth-trained on EKF input).
   What the classifier sees of the EKF runs is ``increments`` (column ``increments``): ``prior``
   (default) — the thesis text's (4.1), "After each dynamic update, x̂⁻_{k+1} and x̂⁺_k are passed
   to the pre-processing block": the predicted increments ``x̂⁻_{k+1} − x̂⁺_k``
   (:func:`~pipeline.estimate.sets.prior_increment_set`), as the EKF+HMM's classifier sees them
   — or ``posterior``, the digest's reading (§13.4), ``x̂⁺_{k+1} − x̂⁺_k``. The EKF-trained models
   train on the same reading. With ``other_increments`` (default) Tables 3.5–3.8 are also
   computed on the other reading, both trainings, as a diagnosis (``RESULT seed000_ekf_other_*``).
   Column ``MAoT_after_5s_pct`` (ours) leaves out each run's first 5 s (:data:`STARTUP_S`), where
   the EKF settles from P₀ and the cumulative classifier has few samples, and where the misses
   on EKF input gather.

Outputs (:data:`OUTPUT_TABLES` under ``results/studies/seed000_classification/``):
``report.md`` (every table beside the thesis, the acceptance checks, and where our
maneuvers behave differently, with numbers), ``results.txt``, ``tables_3_1_3_4.parquet``,
``confusion.parquet``, ``switch_tables.parquet``, ``switch_shift.parquet``,
``gmr_error.parquet``, ``gmr_rmse.parquet``, ``ekf_tables.parquet`` and ``ekf_switch_tables.parquet``
(empty, marked ``skipped``, without ``ekf_input``), ``models/`` (params.npz + meta.json; the
truth-trained set), and the
page ``results/report/studies/seed000_classification.html``.

Sizes (``studies.size``; ``runs`` per maneuver / ``switch_runs`` per switch cell): ``tiny``
40/4 (tests, ~20 s), ``small`` 300/20 (~1–2 min on 2 cores), ``thesis`` 2300/243 (~15 min).

Seed: the master ``seed`` draws every simulated set (``[seed, crc32(set name), chunk]``, as
``uavpipe simulate``), the 70/30 split (``[seed, crc32("split/<M>")]``) and the training.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from plotly.colors import qualitative

from ..config import ROOT, ConfigError, load_config, section
from ..io.parquet import write_table
from ..models import ManeuverModelSet, ModelsConfig
from ..estimate.ekf_hmm import INCREMENTS
from ..estimate.sets import SetsSettings, classifier_set, ekf_rng, ekf_set
from ..models.metrics import (SCENARIOS, SWITCH_TABLE, SWITCH_TABLE_EKF, THESIS_SWITCH, THESIS_SWITCH_EKF, confusion,
                              is_correct, per_maneuver_table, thesis_side_by_side)
from ..report.study import build_study_page, layout
from ..simulate.datasets import DatasetSettings, set_rng, simulate_set
from ..simulate.scenarios import SimSettings
from ..simulate.sensors import SensorSettings
from .base import (STUDY_TABLES, Progress, Results, StudyResult, input_path, md_table, model_dir, model_variant,
                   output_path, say, study_outputs, study_settings, write_text)

NAME = "seed000_classification"
KNOWN = ("M1", "M2", "M3", "M4")
ALL = (*KNOWN, "M5")

#: Parquet tables the study writes (``<name>.parquet``)
OUTPUT_TABLES = STUDY_TABLES[NAME]

#: settings of every size (``studies.seed000_classification``)
DEFAULTS: dict[str, Any] = {
    "runs": 300,             # runs per maneuver (thesis 2300)
    "switch_runs": 20,       # runs per switch cell (thesis 243)
    "alt_mode": "windowed",  # mode whose switch results are the headline (both are tabulated)
    "features": None,        # override models.feature_set (state9, state9h)
    "n_states": None,        # override models.n_states for every maneuver: an int or "auto"
    "skip": [],              # parts left out: "switch", "gmr" (their tables are written empty)
    "ekf_input": False,      # also classify EKF estimates: Tables 3.5-3.8, 3.13-3.15 (ekf_* tables)
    "increments": "prior",   # with ekf_input: what the classifier sees (prior: printed (4.1); posterior: §13.4)
    "other_increments": True,  # with ekf_input: Tables 3.5-3.8 also on the other reading (diagnosis)
}
#: per-size settings
SIZES: dict[str, dict[str, Any]] = {
    "tiny": {"runs": 40, "switch_runs": 4},
    "small": {"runs": 300, "switch_runs": 20},
    "thesis": {"runs": 2300, "switch_runs": 243},
}


def outputs_for(results_dir: str = "results") -> dict[str, str]:
    """The study's declared outputs under ``results_dir`` (see :func:`.base.study_outputs`)."""
    return study_outputs(NAME, results_dir=results_dir)


@dataclasses.dataclass(frozen=True, kw_only=True)
class _Run:
    """What every step needs: sizes, seed and the simulate section."""

    runs: int
    switch_runs: int
    seed: int
    sim: dict


def simulate_runs(kind, name, n, seed, set_name, sim, t_switch=None):
    """One simulated set, as ``uavpipe simulate`` draws it (``set_rng(seed, set_name, chunk)``)."""
    return simulate_set(kind, name, n, SimSettings.from_config(sim), DatasetSettings.from_config(sim),
                        SensorSettings.from_config(sim), seed, set_name, t_switch=t_switch)


def split(df, seed, man, frac=0.7):
    """The 70/30 run split of ``uavpipe simulate`` (``set_rng(seed, "split/<M>")``)."""
    ids = np.sort(df["run_id"].unique())
    perm = set_rng(seed, f"split/{man}").permutation(len(ids))
    train = np.isin(df["run_id"], ids[np.sort(perm[:int(round(frac * len(ids)))])])
    return df[train], df[~train]


def tag(df, man):
    return df.assign(run_id=man + "-" + df["run_id"].astype(str))


def load_sets(run: _Run, sets: Path | None):
    train, test = {}, {}
    for man in ALL:
        if sets is not None:
            train[man] = pd.read_parquet(sets / "sets" / f"{man}_train.parquet")
            test[man] = pd.read_parquet(sets / "sets" / f"{man}_test.parquet")
        else:
            df = simulate_runs("maneuver", man, run.runs, run.seed, f"maneuver/{man}", run.sim)
            train[man], test[man] = split(df, run.seed, man)
    return train, test


def train_models(train: Mapping[str, pd.DataFrame], hmm: Mapping | None, seed: int, *,
                 features: str | None = None, n_states=None) -> tuple[ModelsConfig, ManeuverModelSet]:
    """Step 2: one HMM per known maneuver M1–M4, fitted to the truth training runs.

    Parameters
    ----------
    train : mapping
        ``{maneuver: training set}`` (bulk-set tables with ``run_id``), at least M1–M4.
    hmm : mapping or None
        The ``hmm`` config section.
    seed : int
        The master seed (training is seeded by it).
    features : str, optional
        Override ``hmm.feature_set`` (``state9``, ``state9h``).
    n_states : int, "auto" or None
        Override ``hmm.n_states`` for every maneuver.

    Returns
    -------
    (ModelsConfig, ManeuverModelSet)
    """
    over: dict[str, Any] = {"feature_set": features} if features else {}
    if n_states is not None:
        over["n_states"] = n_states if n_states == "auto" else int(n_states)
    cfg = ModelsConfig.from_section(hmm, seed=int(seed), **over)
    ms = ManeuverModelSet(config=cfg).fit(pd.concat([tag(train[m], m) for m in KNOWN], ignore_index=True))
    return cfg, ms


def detection_delay(pred, t_s, t_switch, final, hold=5):
    """Seconds from the switch to the first sample from which ``final`` holds ``hold`` samples."""
    ok = (pred == final) & (t_s >= t_switch)
    run = np.convolve(ok.astype(int), np.ones(hold, dtype=int), "full")[hold - 1:len(ok) + hold - 1]
    idx = np.nonzero(run[: len(ok) - hold + 1] == hold)[0] if len(ok) >= hold else []
    return float(t_s[idx[0]] - t_switch) if len(idx) else np.nan


def switch_cell(ms, key, ts, run: _Run, mode):
    """One cell of Tables 3.10–3.12: scenario ``key`` switching at ``ts`` s, in ``mode``."""
    df = simulate_runs("switch", key, run.switch_runs, run.seed, f"switch_{key}_{ts:g}s", run.sim, t_switch=ts)
    return switch_stats(ms, df, key, ts, mode)


def switch_stats(ms, df, key, ts, mode, thesis_cells=THESIS_SWITCH, tables=SWITCH_TABLE):
    """FA/MAoT of the first and final maneuver, detection delay and change point of one switch
    cell's runs ``df`` (truth for Tables 3.10–3.12; EKF estimates with ``THESIS_SWITCH_EKF``
    and ``SWITCH_TABLE_EKF`` for 3.13–3.15), confidence classifier in ``mode``."""
    first, final = SCENARIOS[key]
    res = ms.classify(df, mode=mode, decision="confidence", gmr=False)
    fa_i, fa_f, ma_i, ma_f, delay, cps = [], [], [], [], [], []
    for _, g in res.groupby("run_id", sort=False):
        t_s = g["t_ns"].to_numpy() * 1e-9
        pred = g["pred"].to_numpy(dtype=object)
        before = t_s < ts
        after = t_s >= ts + 2.0                                    # end of the 2 s blend
        i_sw = np.nonzero(before)[0][-1]
        fa_i.append(pred[i_sw] == first)
        fa_f.append(pred[-1] == final)
        ma_i.append(np.mean(is_correct(pred[before], np.full(before.sum(), first, dtype=object), KNOWN)))
        ma_f.append(np.mean(is_correct(pred[after], np.full(after.sum(), final, dtype=object), KNOWN)))
        delay.append(detection_delay(pred, t_s, ts, final))
        ch = g["change_t_ns"].to_numpy()[g["change"].to_numpy()]
        cps.append(ch[0] * 1e-9 if len(ch) else np.nan)
    thesis = thesis_cells.get((int(ts), key), (np.nan,) * 4) if float(ts).is_integer() else (np.nan,) * 4
    return {"table": tables.get(int(ts), ""), "switch_s": ts, "scenario": key, "first": first, "final": final,
            "mode": mode, "n_runs": len(fa_i), "FA_initial_pct": 100 * np.mean(fa_i),
            "FA_final_pct": 100 * np.mean(fa_f), "MAoT_initial_pct": 100 * np.mean(ma_i),
            "MAoT_final_pct": 100 * np.mean(ma_f), "detection_delay_s": float(np.nanmedian(delay))
            if np.isfinite(delay).any() else np.nan, "detected_pct": 100 * np.mean(np.isfinite(delay)),
            "change_point_s": float(np.nanmedian(cps)) if np.isfinite(cps).any() else np.nan,
            "thesis_FA_initial_pct": thesis[0], "thesis_FA_final_pct": thesis[1],
            "thesis_MAoT_initial_pct": thesis[2], "thesis_MAoT_final_pct": thesis[3]}


#: GMR variants scored besides the configured one: (quantity suffix, config overrides)
GMR_VARIANTS = (("_pos", {"gmr_input": "pos", "gmr_align": "sample"}),     # (3.28), at t_k
                ("_interval", {"gmr_input": "pos", "gmr_align": "interval"}),  # â = Δv/dt as printed (§13.3)
                ("_posfd", {"gmr_input": "pos_fd", "gmr_align": "sample"}),  # last three positions
                ("_posvel", {"gmr_input": "pos_vel"}))            # conditions on Δr and Δv


def gmr_errors(ms, test):
    """GMR and finite-difference acceleration errors on the same samples.

    Every estimate at ``t_k`` uses data up to ``t_k`` only and is compared with the truth
    acceleration (jerk) at ``t_k``; RMSEs are over the samples where the FD (which needs three
    positions) and every GMR variant exist, so all quantities share one sample set.
    """
    rows, rmse = [], []
    dt = 1.0 / ms.config.rate_hz
    variants = [("", ms)]
    for suffix, over in GMR_VARIANTS:
        if all(getattr(ms.config, k) == v for k, v in over.items()):
            continue
        variants.append((suffix, model_variant(ms, **over)))
    for man in KNOWN:
        truth = test[man].assign(run_id=test[man]["run_id"].astype(str))
        truth = truth.sort_values(["run_id", "t_ns"], kind="stable")
        merged = None
        for suffix, v in variants:
            res = v.classify(truth, mode="cumulative", decision="confidence")
            res["run_id"] = res["run_id"].astype(str)
            cols = {f"{q}_hmm_{ax}_{u}": f"{q}_hmm_{ax}_{u}{suffix}"
                    for q, u in (("acc", "mps2"), ("jerk", "mps3")) for ax in "ned"}
            res = res[["run_id", "t_ns", *cols]].rename(columns=cols)
            merged = res if merged is None else merged.merge(res, on=["run_id", "t_ns"])
        tr = truth.drop(columns=["label"])
        g = tr.groupby("run_id", sort=False)
        for ax in "ned":
            # finite-difference acceleration from the last three 5 Hz truth positions
            p = g[f"pos_{ax}_m"]
            tr[f"fd_{ax}"] = (tr[f"pos_{ax}_m"] - 2 * p.shift(1) + p.shift(2)) / dt ** 2
        m = merged.merge(tr, on=["run_id", "t_ns"], how="left")
        errs = {}
        for ax in "ned":
            qs = {"acc_fd": m[f"fd_{ax}"] - m[f"acc_{ax}_mps2"]}
            for suffix, _ in variants:
                qs["acc" + suffix] = m[f"acc_hmm_{ax}_mps2{suffix}"] - m[f"acc_{ax}_mps2"]
                qs["jerk" + suffix] = m[f"jerk_hmm_{ax}_mps3{suffix}"] - m[f"jerk_{ax}_mps3"]
            common = np.logical_and.reduce([e.notna().to_numpy() for e in qs.values()])
            t_s = m["t_ns"].to_numpy()[common] * 1e-9
            for q, e in qs.items():
                e = e.to_numpy()[common]
                gq = pd.DataFrame({"t_s": t_s, "e": e}).groupby("t_s")["e"]
                rows.append(pd.DataFrame({"maneuver": man, "quantity": q, "axis": ax,
                                          "t_s": gq.mean().index, "mean_err": gq.mean().to_numpy(),
                                          "err_var": gq.var().to_numpy()}))
                errs.setdefault(q, []).append(e)
        for q, es in errs.items():
            e = np.concatenate(es)
            rmse.append({"maneuver": man, "quantity": q, "rmse": float(np.sqrt(np.mean(e ** 2))),
                         "n": len(e)})
    return pd.concat(rows, ignore_index=True), pd.DataFrame(rmse)


def early_confusion(res: pd.DataFrame, truth: str, labelled: str, within_s: float = 10.0) -> dict:
    """Where the ``truth`` samples labelled ``labelled`` lie in time (seed 000 §3.4.2: "Maneuvers
    2 and 4 have similar initial accelerations for the first 5 -10 seconds").

    Returns the share of ``truth``'s samples given that label (%), the share of those within the
    first ``within_s`` of their run (%), the share of runs with any, and the last time (s).
    """
    r = res[res["truth"] == truth]
    if not len(r):
        return {"samples_pct": float("nan"), "in_first_pct": float("nan"), "runs_pct": float("nan"),
                "last_s": float("nan")}
    t = (r["t_ns"] - r.groupby("run_id", sort=False)["t_ns"].transform("min")).to_numpy() * 1e-9
    wrong = (r["pred"] == labelled).to_numpy()
    return {"samples_pct": 100.0 * float(wrong.mean()),
            "in_first_pct": 100.0 * float((wrong & (t < within_s)).sum()) / max(int(wrong.sum()), 1),
            "runs_pct": 100.0 * r.loc[wrong, "run_id"].nunique() / r["run_id"].nunique(),
            "last_s": float(t[wrong].max()) if wrong.any() else float("nan")}


def shift_table(sh: pd.DataFrame) -> pd.DataFrame:
    """Per scenario and thesis switch time: the median change point with the switch at
    ``base − 1``, ``base``, ``base + 1`` s, and the two shifts (ideal: 1 s each)."""
    piv = sh.pivot_table(index=["scenario", "base_switch_s"], columns="switch_s", values="change_point_s")
    rows = []
    for (key, base), r in piv.iterrows():
        rows.append({"scenario": key, "switch_s": base, "cp(switch−1)": r[base - 1.0],
                     "cp(switch)": r[base], "cp(switch+1)": r[base + 1.0],
                     "shift −1 s": r[base] - r[base - 1.0], "shift +1 s": r[base + 1.0] - r[base]})
    return pd.DataFrame(rows)


def differences(tables: pd.DataFrame, per_sample: pd.DataFrame, m5_diag: dict) -> list[str]:
    """Plain-language notes where our simulated maneuvers behave differently from the thesis."""
    notes = []
    for r in tables.dropna(subset=["thesis_MAoT_pct"]).itertuples():
        d = r.MAoT_pct - r.thesis_MAoT_pct
        if abs(d) > 2 or r.FA_pct != r.thesis_FA_pct:
            notes.append(f"Table {r.table} ({r.classifier}, {r.split}) {r.maneuver}: ours FA/MAoT "
                         f"{r.FA_pct:.2f}/{r.MAoT_pct:.2f} % vs thesis {r.thesis_FA_pct:.2f}/"
                         f"{r.thesis_MAoT_pct:.2f} % ({d:+.2f} points MAoT).")
    m24 = per_sample.loc["M4", "M2"] if "M2" in per_sample.columns and "M4" in per_sample.index else 0.0
    m42 = per_sample.loc["M2", "M4"] if "M4" in per_sample.columns and "M2" in per_sample.index else 0.0
    notes.append(f"M2/M4 confusion (thesis: M4's first 5–10 s look like M2, cf MAoT M4 95.38 %, "
                 f"M2 97.43 %): ours labels {100 * m24:.2f} % of M4 test samples M2 and "
                 f"{100 * m42:.2f} % of M2 samples M4 (confidence, cumulative). Our M4 starts from "
                 f"hover and M2 already descending, and the cumulative likelihood separates them "
                 f"from the first samples.")
    if m5_diag:
        notes.append(f"M5 under the confidence decision alone (thesis Table 3.4: unknown, FA/MAoT "
                     f"100/96.09 %): ours labels it {m5_diag['best']} — its best model leads by a "
                     f"median {m5_diag['ll_gap_to_second_median']:.1f} nats at the end (median V "
                     f"{m5_diag['V_best_median']:.1f}, far below −1), so V cannot flag it; the "
                     f"one-class threshold does ({m5_diag['below_oneclass_pct']:.1f} % of M5 runs "
                     f"below it at the end): Table 3.3 and the combined decision ``3.4+1c``; "
                     f"with the background model as a rival (``3.4+bg``, no threshold) the "
                     f"confidence rule itself calls it unknown.")
    return notes


def write_report(path: Path, run: _Run, size: str, cfg, ms, tables, conf, per_sample, m5_diag, sw=None,
                 sh=None, grmse=None) -> None:
    """``report.md``: every table beside the thesis, the acceptance checks and the differences."""
    L = [f"# Seed-000 classification study ({run.runs} runs per maneuver, seed {run.seed}, size {size})", "",
         f"Features `{cfg.feature_set}`, states "
         f"{'/'.join(str(ms.training_[k]['n_states']) for k in ms.labels_)}, truth input, "
         f"70/30 split. Written by `pipeline/studies/seed000_classification.py` "
         f"(`snakemake {'study_' + NAME}`).", "",
         "## Tables 3.1–3.4 (cumulative mode); ours: 3.4+1c (confidence gated by one-class), "
         "3.4+bg (confidence with a background model as a rival hypothesis)", "",
         md_table(tables), "", "Confusion of final labels:", "", md_table(conf, "{:.0f}"), "",
         "Per-sample confusion, Table 3.4 (rows: truth, %):", "",
         md_table((100 * per_sample).reset_index()), "", "## Where our maneuvers differ from the thesis", ""]
    L += [f"- {n}" for n in differences(tables, per_sample, m5_diag)]
    if sw is not None:
        L += ["", "## Tables 3.10–3.12: switch scenarios (truth input, confidence)", "",
              "Final-maneuver MAoT counted from the end of the 2 s blend; detection delay = switch to the "
              "first sample from which the final maneuver holds 1 s (median).", "",
              md_table(sw.drop(columns=["table"]), "{:.1f}"), ""]
        low = sw[(sw["mode"] != "cumulative") & (sw["thesis_MAoT_final_pct"] < 50)]
        best = low.groupby(["switch_s", "scenario"])["MAoT_final_pct"].max()
        L += [f"Cells where the thesis's cumulative final MAoT is below 50 %: {len(best)}; the better of "
              f"windowed/reset reaches ≥ 80 % in {int((best >= 80).sum())} of them (lowest "
              f"{best.min():.1f} %).", ""]
    if sh is not None:
        L += ["Change point (reset mode, median over runs, s) with the switch moved by ±1 s:", "",
              md_table(shift_table(sh)), ""]
    if grmse is not None:
        L += ["## GMR (§3.6.4) acceleration/jerk RMSE on test runs", "",
              "`acc` is the configured GMR, `acc_fd` the finite difference of the last three 5 Hz truth "
              "positions, on the same samples; variants: `_pos` (3.28, Δr only), `_interval` (â = Δv/dt "
              "as printed), `_posfd` (Δr and the position-only Δv), `_posvel` (Δr and the true Δv).", "",
              md_table(grmse.pivot(index="maneuver", columns="quantity", values="rmse").reset_index(),
                       "{:.3f}"), ""]
    write_text(path, "\n".join(L) + "\n")


def headline(res: Results, run: _Run, cfg, ms, tables, m5_diag, alt_mode, sw=None, sh=None,
             grmse=None) -> None:
    """The study's ``RESULT`` figures, each with its one-sentence definition."""
    cf = tables[(tables.table == "3.4") & tables.maneuver.isin(KNOWN)]
    oc = tables[(tables.table == "3.3")]
    fa = "FA = % of runs whose final label is right"
    maot = "MAoT = % of a run's samples labelled right, averaged over runs"
    res.add("seed000_runs_per_maneuver", run.runs,
            "Simulated runs of each maneuver M1–M5, split 70/30 into train and test runs.")
    res.add("seed000_feature_set", cfg.feature_set, "HMM feature set the four maneuver models use.")
    res.add("seed000_n_states", '/'.join(str(ms.training_[k]['n_states']) for k in ms.labels_),
            "HMM states of the M1/M2/M3/M4 models (thesis 5/6/6/6).")
    res.add("seed000_cf_test_min_FA_pct", f"{cf['FA_pct'].min():.2f}",
            f"Lowest FA over M1–M4 on the test runs, confidence classifier, Table 3.4 ({fa}).")
    res.add("seed000_cf_test_min_MAoT_minus_thesis_pct", f"{(cf['MAoT_pct'] - cf['thesis_MAoT_pct']).min():.2f}",
            f"Lowest of our MAoT minus the thesis's over M1–M4 in Table 3.4 ({maot}).")
    ock = oc[oc.maneuver.isin(KNOWN)]
    res.add("seed000_1c_test_min_FA_pct", f"{ock['FA_pct'].min():.2f}",
            "Lowest FA over M1–M4 on the test runs, one-class classifier, Table 3.3.")
    res.add("seed000_1c_test_min_MAoT_minus_thesis_pct", f"{(ock['MAoT_pct'] - ock['thesis_MAoT_pct']).min():.2f}",
            "Lowest of our MAoT minus the thesis's over M1–M4 in Table 3.3 (one-class).")
    for tab, name, what in (("3.4", "cf", "the confidence classifier (Table 3.4)"),
                            ("3.4+1c", "cf1c", "the confidence classifier gated by the one-class threshold (3.4+1c)"),
                            ("3.4+bg", "cfbg", "the confidence classifier with the background rival (3.4+bg)")):
        m5c = tables[(tables.table == tab) & (tables.maneuver == "M5")]
        if len(m5c):
            res.add(f"seed000_{name}_M5_unknown_FA_pct", f"{m5c['FA_pct'].iloc[0]:.2f}",
                    f"% of the unknown maneuver M5's test runs whose final label is unknown under {what}.")
            res.add(f"seed000_{name}_M5_unknown_MAoT_pct", f"{m5c['MAoT_pct'].iloc[0]:.2f}",
                    f"% of M5's test samples labelled unknown under {what}.")
    both = tables[(tables.table == "3.4+1c") & tables.maneuver.isin(KNOWN)]
    res.add("seed000_cf1c_test_min_FA_pct", f"{both['FA_pct'].min():.2f}",
            "Lowest FA over M1–M4 on the test runs under the gated confidence classifier (3.4+1c).")
    res.add("seed000_cf1c_test_min_MAoT_pct", f"{both['MAoT_pct'].min():.2f}",
            "Lowest MAoT over M1–M4 on the test runs under the gated confidence classifier (3.4+1c).")
    bg = tables[(tables.table == "3.4+bg") & tables.maneuver.isin(KNOWN)]
    thesis34 = tables[(tables.table == "3.4") & tables.maneuver.isin(KNOWN)].set_index("maneuver")["thesis_MAoT_pct"]
    res.add("seed000_cfbg_test_min_FA_pct", f"{bg['FA_pct'].min():.2f}",
            "Lowest FA over M1–M4 on the test runs with the background model as a rival (3.4+bg).")
    res.add("seed000_cfbg_test_min_MAoT_minus_thesis_pct",
            f"{(bg.set_index('maneuver')['MAoT_pct'] - thesis34).min():.2f}",
            "Lowest of the 3.4+bg MAoT minus the thesis's Table 3.4 MAoT over M1–M4.")
    if m5_diag:
        res.add("seed000_cf_M5_median_V_best", f"{m5_diag['V_best_median']:.1f}",
                "Median over M5 test runs of the confidence V of the best model at the end (labelled only below −1).")
        res.add("seed000_cf_M5_below_oneclass_pct", f"{m5_diag['below_oneclass_pct']:.1f}",
                "% of M5 test runs whose final log-likelihood is below the best model's one-class threshold.")
    m5 = oc[oc.maneuver == "M5"]
    if len(m5):
        res.add("seed000_1c_M5_unknown_FA_pct", f"{m5['FA_pct'].iloc[0]:.2f}",
                "% of M5's test runs whose final label is unknown under the one-class classifier (Table 3.3).")
        res.add("seed000_1c_M5_unknown_MAoT_pct", f"{m5['MAoT_pct'].iloc[0]:.2f}",
                "% of M5's test samples labelled unknown under the one-class classifier (Table 3.3).")
    if sw is not None:
        low = sw[(sw["mode"] == alt_mode) & (sw["thesis_MAoT_final_pct"] < 50)]
        res.add(f"seed000_switch_{alt_mode}_min_final_MAoT_pct_where_thesis_below_50",
                f"{low['MAoT_final_pct'].min():.2f}",
                f"Lowest final-maneuver MAoT in {alt_mode} mode over the switch cells where the thesis's "
                f"cumulative classifier is below 50 %.")
        cum = sw[sw["mode"] == "cumulative"]
        res.add("seed000_switch_cumulative_mean_final_MAoT_pct", f"{cum['MAoT_final_pct'].mean():.2f}",
                "Mean final-maneuver MAoT (after the 2 s blend) of the cumulative classifier over the 12 switch cells.")
        d = shift_table(sh)[["shift −1 s", "shift +1 s"]].to_numpy()
        follows = int(np.all(np.abs(d - 1.0) <= 0.4, axis=1).sum())
        res.add("seed000_change_point_shift_per_1s_switch_shift_s", f"{np.nanmedian(d):.2f}",
                "Median shift (s) of the reset-mode change point when the switch moves by 1 s (ideal 1).")
        res.add("seed000_change_point_follows_switch_cells", f"{follows}/{len(d)}",
                "Scenario/switch-time cells whose change point moves by 1 ± 0.4 s with both ±1 s switch shifts.")
    if grmse is not None:
        r = grmse.pivot(index="maneuver", columns="quantity", values="rmse")
        res.add("seed000_gmr_acc_rmse_mps2", f"{r['acc'].mean():.3f}",
                "Mean over M1–M4 of the configured GMR's acceleration RMSE (m/s²) on the test runs.")
        res.add("seed000_fd_acc_rmse_mps2", f"{r['acc_fd'].mean():.3f}",
                "Mean over M1–M4 of the RMSE (m/s²) of the finite difference of the last three 5 Hz positions.")
        res.add("seed000_gmr_jerk_rmse_mps3", f"{r['jerk'].mean():.3f}",
                "Mean over M1–M4 of the configured GMR's jerk RMSE (m/s³) on the test runs.")
        res.add(f"seed000_gmr_align_{cfg.gmr_align}_input_{cfg.gmr_input}", 1,
                "The configured GMR's alignment and conditioning input (named in the metric; value always 1).")
        res.add("seed000_gmr_maneuvers_below_fd", int((r['acc'] < r['acc_fd']).sum()),
                "Maneuvers (of 4) where the configured GMR's acceleration RMSE is below the finite difference's.")
        what = {"_pos": "conditioned on Δr only (3.28)", "_interval": "â = Δv/dt as printed (§13.3)",
                "_posfd": "conditioned on Δr and the position-only Δv", "_posvel": "conditioned on Δr and the true Δv"}
        for suffix, _ in GMR_VARIANTS:
            if "acc" + suffix in r:
                res.add(f"seed000_gmr_acc{suffix}_rmse_mps2", f"{r['acc' + suffix].mean():.3f}",
                        f"Mean over M1–M4 of the acceleration RMSE (m/s²) of the GMR variant {what[suffix]}.")


#: seed 000 Tables 3.5–3.8: (split, decision) of each (EKF input); ``3.8+bg`` (ours): the
#: confidence decision with the background model as a rival, as ``3.4+bg``
EKF_TABLES = {"3.5": ("train", "oneclass"), "3.6": ("train", "confidence"),
              "3.7": ("test", "oneclass"), "3.8": ("test", "confidence"), "3.8+bg": ("test", "confidence_bg")}
#: seconds at the start of every EKF-input run left out of ``MAoT_after_<s>s_pct`` (ours): the
#: EKF's start-up from P₀ and the classifier's first samples, where the misses on EKF input gather
STARTUP_S = 5.0
#: modes of the EKF-input switch tables 3.13–3.15 (thesis: cumulative; windowed: ours)
EKF_SWITCH_MODES = ("cumulative", "windowed")


def ekf_settings(estimate: Mapping | None, simulate: Mapping) -> SetsSettings:
    """The EKF of the ``ekf_sets`` rule: ``estimate.sets`` and the simulated radar
    (``simulate.sensors.radar``)."""
    radar = dict((simulate.get("sensors") or {}).get("radar") or {})
    return SetsSettings.from_config({**dict((estimate or {}).get("sets") or {}), "radar": radar})


def increments_view(sets: Mapping[str, pd.DataFrame], increments: str, part: str) -> dict[str, pd.DataFrame]:
    """What the classifier sees of EKF sets (:func:`ekf_of`), set by set
    (:func:`~pipeline.estimate.sets.classifier_set`)."""
    return {m: classifier_set(d, increments, where=f"{m}_{part}") for m, d in sets.items()}


def ekf_of(sets: Mapping[str, pd.DataFrame], part: str, seed: int, es: SetsSettings,
           diagnostics: dict | None = None) -> dict[str, pd.DataFrame]:
    """EKF estimates of the per-maneuver sets, each drawn as the ``ekf_sets`` rule draws
    ``<M>_<part>`` (``ekf_rng(seed, "<M>_<part>")``); each set's diagnostics go into
    ``diagnostics[<M>]`` when given."""
    out = {}
    for man, df in sets.items():
        out[man], diag = ekf_set(df, radar=es.radar, q=es.q, p0_sigma=es.p0_sigma,
                                 rng=ekf_rng(seed, f"{man}_{part}"), where=f"{man}_{part}")
        if diagnostics is not None:
            diagnostics[man] = diag
    return out


def ekf_tables(models: Mapping[str, ManeuverModelSet], train: Mapping, test: Mapping,
               increments: str = "prior") -> pd.DataFrame:
    """Tables 3.5–3.8 (cumulative mode, EKF input) for every model set of ``models``
    (``{"truth": truth-trained (the thesis setup), "ekf": EKF-trained}``); ``increments`` names
    what ``train``/``test`` hold (``posterior``: the EKF sets; ``prior``: their
    :func:`~pipeline.estimate.sets.prior_increment_set`), written to the ``increments`` column."""
    tabs = []
    for trained_on, ms in models.items():
        for table, (split_name, decision) in EKF_TABLES.items():
            sets_ = train if split_name == "train" else test
            mans = KNOWN if split_name == "train" else ALL
            df = pd.concat([tag(sets_[m], m) for m in mans], ignore_index=True)
            res = ms.classify(df, mode="cumulative", decision=decision, gmr=False)
            t = thesis_side_by_side(per_maneuver_table(res, KNOWN, truth_col="truth"), table)
            t.insert(1, "classifier", decision)
            t.insert(2, "split", split_name)
            t.insert(3, "trained_on", trained_on)
            t.insert(4, "increments", increments)
            # ours: MAoT without each run's first STARTUP_S, where the EKF is still settling from
            # P₀ and the classifier has few samples (a diagnosis; the thesis's MAoT counts every
            # sample, as MAoT_pct does)
            t0 = res.groupby("run_id", sort=False)["t_ns"].transform("min")
            late = per_maneuver_table(res[(res["t_ns"] - t0) >= STARTUP_S * 1e9], KNOWN, truth_col="truth")
            t[f"MAoT_after_{STARTUP_S:g}s_pct"] = t["maneuver"].map(late.set_index("maneuver")["MAoT_pct"])
            tabs.append(t)
    return pd.concat(tabs, ignore_index=True)


def ekf_switch_tables(models: Mapping[str, ManeuverModelSet], run: _Run, es: SetsSettings,
                      progress=None, increments: str = "prior") -> pd.DataFrame:
    """Tables 3.13–3.15: the switch cells on EKF estimates (each cell's runs simulated as for
    3.10–3.12, then filtered as the ``ekf_sets`` rule filters ``switch_<K>_<t>s``), confidence
    classifier, :data:`EKF_SWITCH_MODES`, for every model set of ``models``; the classifier sees
    ``increments`` (:func:`increments_view`)."""
    cells = []
    for ts in (3.0, 8.0, 13.0):
        for key in "ABCD":
            name = f"switch_{key}_{ts:g}s"
            df = simulate_runs("switch", key, run.switch_runs, run.seed, name, run.sim, t_switch=ts)
            est, _ = ekf_set(df, radar=es.radar, q=es.q, p0_sigma=es.p0_sigma, rng=ekf_rng(run.seed, name),
                             where=name)
            est = increments_view({name: est}, increments, "switch")[name]
            for trained_on, ms in models.items():
                for mode in EKF_SWITCH_MODES:
                    if progress is not None:
                        progress(f"EKF input: switch scenario {key} at {ts:g} s, {mode}, {trained_on}-trained")
                    c = switch_stats(ms, est, key, ts, mode, THESIS_SWITCH_EKF, SWITCH_TABLE_EKF)
                    cells.append({**c, "trained_on": trained_on})
    return pd.DataFrame(cells)


def other_reading(increments: str) -> str:
    """The reading of (4.1) that ``increments`` is not."""
    return "posterior" if increments == "prior" else "prior"


#: what each reading of (4.1) means, for reports and RESULT definitions
READING = {"prior": "the printed (4.1) predicted increments x̂⁻_{k+1} − x̂⁺_k",
           "posterior": "the digest's (§13.4) posterior increments x̂⁺_{k+1} − x̂⁺_k"}


def ekf_headline(res: Results, et: pd.DataFrame, esw: pd.DataFrame | None, rmse: pd.DataFrame,
                 increments: str = "prior") -> None:
    """The EKF-input ``RESULT`` figures (Tables 3.5–3.8, 3.13–3.15) on the ``increments`` reading;
    the other reading's rows as ``seed000_ekf_other_*``."""
    other = other_reading(increments)
    pr = et[et.increments == other].set_index("maneuver")
    et = et[et.increments == increments]
    res.add("seed000_ekf_increments", increments,
            f"What the classifier sees of the EKF runs in the seed000_ekf_* figures: {READING[increments]}.")

    def rows(table, trained_on, mans=KNOWN):
        return et[(et.table == table) & (et.trained_on == trained_on) & et.maneuver.isin(mans)].set_index("maneuver")

    res.add("seed000_ekf_diverged_runs", int(rmse["diverged_runs"].sum() + rmse["diverged_train_runs"].sum()),
            "Train and test runs of M1–M5 whose EKF estimate ends more than 10 m from the truth (mirror image "
            "below the radar plane).")
    cf = pd.concat([rows("3.6", "truth"), rows("3.8", "truth")])
    res.add("seed000_ekf_cf_min_FA_pct", f"{cf['FA_pct'].min():.2f}",
            "Lowest FA over M1–M4 of the truth-trained confidence classifier on EKF input, train and test "
            "(Tables 3.6, 3.8; thesis 100).")
    res.add("seed000_ekf_cf_min_MAoT_minus_thesis_pct", f"{(cf['MAoT_pct'] - cf['thesis_MAoT_pct']).min():.2f}",
            "Lowest of our MAoT minus the thesis's over M1–M4 in Tables 3.6 and 3.8 (truth-trained, EKF input).")
    for man in KNOWN:
        r = rows("3.8", "truth").loc[man]
        res.add(f"seed000_ekf_cf_test_{man}_MAoT_pct", f"{r['MAoT_pct']:.2f}",
                f"{man} test-run MAoT of the truth-trained confidence classifier on EKF input (Table 3.8; "
                f"thesis {r['thesis_MAoT_pct']:.2f}).")
        res.add(f"seed000_ekf_cf_test_{man}_MAoT_after_{STARTUP_S:g}s_pct", f"{r[f'MAoT_after_{STARTUP_S:g}s_pct']:.2f}",
                f"As seed000_ekf_cf_test_{man}_MAoT_pct without each run's first {STARTUP_S:g} s (the EKF's "
                f"start-up from P₀ and the classifier's first samples; ours, a diagnosis).")
    for table, name, what in (("3.8", "cf", "confidence classifier (Table 3.8)"),
                              ("3.7", "1c", "one-class classifier (Table 3.7)")):
        m5 = rows(table, "truth", ("M5",))
        if len(m5):
            res.add(f"seed000_ekf_{name}_M5_unknown_FA_pct", f"{m5['FA_pct'].iloc[0]:.2f}",
                    f"% of M5's EKF-estimated test runs whose final label is unknown, truth-trained {what}.")
            res.add(f"seed000_ekf_{name}_M5_unknown_MAoT_pct", f"{m5['MAoT_pct'].iloc[0]:.2f}",
                    f"% of M5's EKF-estimated test samples labelled unknown, truth-trained {what}.")
    oc = pd.concat([rows("3.5", "truth"), rows("3.7", "truth")])
    res.add("seed000_ekf_1c_min_MAoT_minus_thesis_pct", f"{(oc['MAoT_pct'] - oc['thesis_MAoT_pct']).min():.2f}",
            "Lowest of our MAoT minus the thesis's over M1–M4 in Tables 3.5 and 3.7 (one-class, truth-trained, "
            "EKF input).")
    if "ekf" in set(et.trained_on):
        for table, name in (("3.8", "cf"), ("3.7", "1c")):
            tt, ee = rows(table, "truth")["MAoT_pct"].mean(), rows(table, "ekf")["MAoT_pct"].mean()
            res.add(f"seed000_ekf_{name}_test_mean_MAoT_truth_trained_pct", f"{tt:.2f}",
                    f"Mean over M1–M4 of the test-run MAoT on EKF input, truth-trained models (Table {table}).")
            res.add(f"seed000_ekf_{name}_test_mean_MAoT_ekf_trained_pct", f"{ee:.2f}",
                    f"Mean over M1–M4 of the test-run MAoT on EKF input, models trained on EKF estimates "
                    f"(Table {table} setup).")
            res.add(f"seed000_ekf_{name}_test_mean_MAoT_gain_pct", f"{ee - tt:.2f}",
                    f"EKF-trained minus truth-trained mean MAoT over M1–M4 on EKF test runs (Table {table}; "
                    f"target ≥ 0).")
        m5 = rows("3.8", "ekf", ("M5",))
        if len(m5):
            res.add("seed000_ekf_trained_cf_M5_unknown_FA_pct", f"{m5['FA_pct'].iloc[0]:.2f}",
                    "% of M5's EKF-estimated test runs called unknown at the end by the EKF-trained confidence "
                    "classifier.")
    for trained_on in sorted(set(et.trained_on), key=lambda x: x != "truth"):
        bg, m5 = rows("3.8+bg", trained_on), rows("3.8+bg", trained_on, ("M5",))
        if len(bg):
            res.add(f"seed000_ekf_cfbg_{trained_on}_trained_test_mean_MAoT_pct", f"{bg['MAoT_pct'].mean():.2f}",
                    f"Mean over M1–M4 of the EKF-input test MAoT with the background rival (3.8+bg, ours), "
                    f"{trained_on}-trained models.")
        if len(m5):
            res.add(f"seed000_ekf_cfbg_{trained_on}_trained_M5_unknown_FA_pct", f"{m5['FA_pct'].iloc[0]:.2f}",
                    f"% of M5's EKF-estimated test runs called unknown at the end with the background rival "
                    f"(3.8+bg, ours), {trained_on}-trained models.")
    if len(pr):
        pt = pr[pr.trained_on == "truth"]
        p8 = pt[(pt.table == "3.8")]
        p68 = pt[pt.table.isin(["3.6", "3.8"]) & pt.index.isin(KNOWN)]
        what = f"{READING[other]} of the same EKF runs (the other reading; diagnosis)"
        res.add("seed000_ekf_other_cf_min_FA_pct", f"{p68['FA_pct'].min():.2f}",
                f"Lowest FA over M1–M4 of the truth-trained confidence classifier on {what}, train and test "
                f"(Tables 3.6, 3.8).")
        res.add("seed000_ekf_other_cf_min_MAoT_minus_thesis_pct",
                f"{(p68['MAoT_pct'] - p68['thesis_MAoT_pct']).min():.2f}",
                f"Lowest of our MAoT minus the thesis's over M1–M4 in Tables 3.6 and 3.8 on {what} (truth-trained).")
        for man in ALL:
            if man in p8.index:
                r = p8.loc[man]
                res.add(f"seed000_ekf_other_cf_test_{man}_MAoT_pct", f"{r['MAoT_pct']:.2f}",
                        f"{man} test-run MAoT of the truth-trained confidence classifier on {what} (Table 3.8 "
                        f"setup; thesis {r['thesis_MAoT_pct']:.2f}).")
                res.add(f"seed000_ekf_other_cf_test_{man}_FA_pct", f"{r['FA_pct']:.2f}",
                        f"{man} test-run FA of the truth-trained confidence classifier on {what} (Table 3.8 setup).")
        pe = pr[(pr.trained_on == "ekf") & (pr.table == "3.8") & pr.index.isin(KNOWN)]
        if len(pe):
            res.add("seed000_ekf_other_cf_test_mean_MAoT_gain_pct",
                    f"{pe['MAoT_pct'].mean() - p8.loc[p8.index.isin(KNOWN), 'MAoT_pct'].mean():.2f}",
                    f"EKF-trained minus truth-trained mean MAoT over M1–M4 on EKF test runs (Table 3.8) on {what}.")
    if esw is not None and len(esw):
        for trained_on in sorted(set(esw.trained_on), key=lambda x: x != "truth"):
            for mode in EKF_SWITCH_MODES:
                g = esw[(esw.trained_on == trained_on) & (esw["mode"] == mode)]
                res.add(f"seed000_ekf_switch_{mode}_{trained_on}_trained_mean_final_MAoT_pct",
                        f"{g['MAoT_final_pct'].mean():.2f}",
                        f"Mean final-maneuver MAoT over the 12 switch cells on EKF input, {mode} mode, "
                        f"{trained_on}-trained models (Tables 3.13–3.15; thesis cumulative, truth-trained: "
                        f"{np.mean([v[3] for v in THESIS_SWITCH_EKF.values()]):.2f}).")
                res.add(f"seed000_ekf_switch_{mode}_{trained_on}_trained_mean_initial_MAoT_pct",
                        f"{g['MAoT_initial_pct'].mean():.2f}",
                        f"Mean first-maneuver MAoT over the 12 switch cells on EKF input, {mode} mode, "
                        f"{trained_on}-trained models (thesis cumulative, truth-trained: "
                        f"{np.mean([v[2] for v in THESIS_SWITCH_EKF.values()]):.2f}).")


def ekf_report(et: pd.DataFrame, esw: pd.DataFrame | None, es: SetsSettings, rmse: pd.DataFrame,
               increments: str = "prior") -> list[str]:
    """The EKF-input section of ``report.md`` (headline reading ``increments``, the other one as a
    diagnosis)."""
    other = other_reading(increments)
    L = ["", "## EKF input: Tables 3.5–3.8 (cumulative), truth- and EKF-trained models", "",
         f"Radar synthesised from the truth (site {list(es.radar.site_ned_m)} m NED, σ = "
         f"{list(es.radar.sigma)}; `simulate.sensors.radar`), CA EKF with white-jerk q = {es.q:g} m²/s⁵, "
         f"P₀ = diag({', '.join(f'{s:g}²' for s in es.p0_sigma)}), initial state = truth + N(0, P₀) "
         f"(`estimate.sets`, pipeline/estimate/sets.py). `trained_on: truth` is the thesis setup "
         f"(truth-trained models classifying EKF estimates); `trained_on: ekf` trains the same models "
         f"on EKF estimates of the training runs (noise-aware; the thesis columns stay the truth-trained "
         f"thesis values).", "",
         "EKF error (RMSE over all samples of the test runs; diverged: final position error > 10 m, "
         "mostly runs near the radar's horizontal plane tracked as their mirror image below it — range "
         "and two direction cosines do not give the sign of the third):", "", md_table(rmse, "{:.3f}"), "",
         f"The classifier sees {READING[increments]} (`increments: {increments}`); the EKF-trained models "
         f"train on the same.", "", md_table(et[et.increments == increments]), ""]
    pr = et[et.increments == other]
    if len(pr):
        L += [f"### Diagnosis: the other reading of (4.1), `increments: {other}`", "",
              "The thesis text (§4.1: \"After each dynamic update, x̂⁻_{k+1} and x̂⁺_k are passed to the "
              "pre-processing block\") gives the classifier the *predicted* increments x̂⁻_{k+1} − x̂⁺_k = "
              "(A − I) x̂⁺_k (`prior`, pipeline/estimate/ekf_hmm.py `prior_increment_track`); the digest (§13.4) "
              "reads (4.1) as the posterior increments x̂⁺_{k+1} − x̂⁺_k (`posterior`). A predicted increment "
              "carries no radar-update correction, so it is as smooth as the EKF's velocity and acceleration; "
              "the thesis's EKF-input tables lie near its truth tables. Below: the same EKF runs classified on "
              f"{READING[other]}, truth-trained and trained on that reading.", "",
              md_table(pr), ""]
    if esw is not None and len(esw):
        L += ["## EKF input: Tables 3.13–3.15 (switch scenarios, confidence)", "",
              "Thesis values: cumulative mode, truth-trained models.", "",
              md_table(esw.drop(columns=["table", "first", "final"]), "{:.1f}"), ""]
    return L


def figures(tables: pd.DataFrame, sw: pd.DataFrame | None, gerr: pd.DataFrame | None,
            et: pd.DataFrame | None = None, increments: str = "prior") -> list:
    """The page's plots: MAoT beside the thesis, switch-cell final MAoT, GMR error over time and,
    with EKF input, Tables 3.5–3.8."""
    figs = []
    if et is not None and len(et):
        fig = go.Figure()
        keys = ["table", "trained_on", "increments"]
        bars = []
        for (table, trained_on, inc), g in et[et["maneuver"].isin(ALL)].groupby(keys, sort=False):
            if inc != increments and (table != "3.8" or trained_on != "truth"):
                continue
            name = f"{table} ours, {trained_on}-trained" + (f", {inc} increments" if inc != increments else "")
            colour = qualitative.Plotly[len(bars) % 10]
            fig.add_trace(go.Bar(x=g["maneuver"], y=g["MAoT_pct"], name=name, offsetgroup=name, marker_color=colour))
            bars.append((name, colour, g if trained_on == "truth" and inc == increments else None))
        # the thesis's (truth-trained) value over its own bar, in its colour; the other bars hold
        # their place with an empty group (as in the Tables 3.1-3.4 chart)
        for name, colour, g in bars:
            has = g is not None and g["thesis_MAoT_pct"].notna().any()
            fig.add_trace(go.Scatter(x=g["maneuver"] if has else [], y=g["thesis_MAoT_pct"] if has else [],
                                     mode="markers", offsetgroup=name, showlegend=bool(has),
                                     marker=dict(symbol="x", size=9, color=colour),
                                     name=f"{name.split(' ')[0]} thesis"))
        fig.update_layout(barmode="group", scattermode="group", yaxis_title="MAoT [%]")
        ekf_fig = ("Tables 3.5–3.8: MAoT on EKF input",
                   layout(fig, "Tables 3.5–3.8: MAoT on EKF estimates (bars: ours, ×: thesis, truth-trained)"))
    else:
        ekf_fig = None
    t = tables[tables["maneuver"].isin(ALL)]
    fig = go.Figure()
    groups = list(t.groupby("table", sort=False))
    for i, (table, g) in enumerate(groups):
        fig.add_trace(go.Bar(x=g["maneuver"], y=g["MAoT_pct"], name=f"{table} ours", offsetgroup=table,
                             marker_color=qualitative.Plotly[i % 10]))
    # each thesis value as an × in its table's colour over its table's bar (scattermode group, one
    # offset group per table; the tables without a thesis value hold their place empty): the ×s
    # had all sat at the maneuver's centre, over whichever bar was there
    for i, (table, g) in enumerate(groups):
        fig.add_trace(go.Scatter(x=g["maneuver"], y=g["thesis_MAoT_pct"], mode="markers", offsetgroup=table,
                                 marker=dict(symbol="x", size=9, color=qualitative.Plotly[i % 10]),
                                 name=f"{table} thesis", showlegend=bool(g["thesis_MAoT_pct"].notna().any())))
    fig.update_layout(barmode="group", scattermode="group", yaxis_title="MAoT [%]")
    figs.append(("Tables 3.1–3.4: MAoT", layout(fig, "Tables 3.1–3.4: MAoT per maneuver (bars: ours, ×: thesis)")))
    if sw is not None and len(sw):
        fig = go.Figure()
        cell = sw["scenario"] + " @ " + sw["switch_s"].map(lambda x: f"{x:g}") + " s"
        for mode in ("cumulative", "windowed", "reset"):
            m = sw["mode"] == mode
            fig.add_trace(go.Bar(x=cell[m], y=sw.loc[m, "MAoT_final_pct"], name=mode))
        m = sw["mode"] == "cumulative"
        fig.add_trace(go.Scatter(x=cell[m], y=sw.loc[m, "thesis_MAoT_final_pct"], mode="markers",
                                 marker=dict(symbol="x", size=9, color="black"), name="thesis (cumulative)"))
        fig.update_layout(barmode="group", yaxis_title="final-maneuver MAoT [%]")
        figs.append(("Tables 3.10–3.12", layout(fig, "Tables 3.10–3.12: final-maneuver MAoT per switch cell")))
    if gerr is not None and len(gerr):
        fig = go.Figure()
        mans = list(dict.fromkeys(gerr["maneuver"]))
        for (man, q), g in gerr[gerr["quantity"].isin(["acc", "acc_fd"])].groupby(["maneuver", "quantity"]):
            a = g.groupby("t_s")["err_var"].mean()
            # a maneuver's two estimates in one colour (GMR solid, finite difference dotted): the
            # default cycle gave the eight lines eight unrelated colours
            fig.add_trace(go.Scatter(x=a.index, y=np.sqrt(a.to_numpy()), mode="lines",
                                     name=f"{man} {'GMR' if q == 'acc' else 'finite difference'}",
                                     line=dict(color=qualitative.Plotly[mans.index(man) % 10],
                                               dash="dot" if q == "acc_fd" else None)))
        fig.update_layout(xaxis_title="t [s]", yaxis_title="error std, RMS over n/e/d [m/s²]")
        figs.append(("GMR error over time", layout(fig, "GMR vs finite-difference acceleration error over time")))
    if ekf_fig is not None:
        figs.append(ekf_fig)
    return figs


def run_seed000_classification(inputs: Mapping | None, outputs: Mapping, config: Mapping | None, *,
                               seed: int, simulate: Mapping | None = None,
                               hmm: Mapping | None = None, estimate: Mapping | None = None) -> StudyResult:
    """Run the seed-000 classification study and write its tables, report, results and page.

    Parameters
    ----------
    inputs : mapping or None
        Optional ``sets`` (folder of a ``uavpipe simulate`` run, read instead of simulating)
        and ``template`` (default ``reports/templates/study.html.j2``).
    outputs : mapping
        :func:`outputs_for`'s keys: ``report``, ``results``, ``page``, one per table of
        :data:`OUTPUT_TABLES`, ``model_params`` and ``model_meta``.
    config : mapping or None
        The ``studies`` config section (``size``, ``seed000_classification``).
    seed : int
        The master seed (simulation, split and training).
    simulate, hmm : mapping, optional
        The ``simulate`` and ``hmm`` config sections (default: ``datasets/config.yaml``'s).
    estimate : mapping, optional
        The ``estimate`` section (its ``sets`` sub-section: the EKF of ``ekf_input``; default
        ``datasets/config.yaml``'s).

    Returns
    -------
    StudyResult
        ``status`` ``ok``, the headline figures and diagnostics (size, settings, wall time).
    """
    size, st = study_settings(config, NAME, DEFAULTS, SIZES)
    skip = set(st["skip"] or ())
    bad = sorted(skip - {"switch", "gmr"})
    if bad:
        raise ConfigError(f"studies.{NAME}.skip: unknown part(s) {bad}; known: switch, gmr")
    if simulate is None or hmm is None or estimate is None:
        cfg_file = load_config()
        simulate = section(cfg_file, "simulate") if simulate is None else simulate
        hmm = section(cfg_file, "hmm") if hmm is None else hmm
        estimate = section(cfg_file, "estimate") if estimate is None else estimate
    es = ekf_settings(estimate, simulate) if st["ekf_input"] else None  # a bad key fails before any work
    inc = str(st["increments"])
    if inc not in INCREMENTS:
        raise ConfigError(f"studies.{NAME}.increments: {inc!r} is not one of {', '.join(INCREMENTS)}")
    run = _Run(runs=int(st["runs"]), switch_runs=int(st["switch_runs"]), seed=int(seed), sim=dict(simulate))
    sets = input_path(inputs, "sets")
    template = input_path(inputs, "template", ROOT / "reports" / "templates" / "study.html.j2")
    paths = {k: output_path(outputs, k) for k in ("report", "results", "page", *OUTPUT_TABLES,
                                                   "model_params", "model_meta")}
    if not st["ekf_input"]:  # declared outputs are always written: empty, marked skipped
        for k in ("ekf_tables", "ekf_switch_tables"):
            write_table(pd.DataFrame(), paths[k], name=f"{NAME}_{k}", extra={"skipped": True})
    progress = Progress()

    progress(f"simulating {run.runs} runs of each of {', '.join(ALL)}" if sets is None else f"reading {sets}")
    train, test = load_sets(run, sets)
    progress("training one HMM per known maneuver")
    mdir = model_dir(paths)
    cfg, ms = train_models(train, hmm, run.seed, features=st["features"], n_states=st["n_states"])
    ms.save(mdir)
    say(f"trained {ms.labels_} on {sum(train[m]['run_id'].nunique() for m in KNOWN)} runs in "
        f"{progress.elapsed:.0f} s")
    for lab, tr in ms.training_.items():
        say(f"  {lab}: {tr['n_states']} states, {tr['n_sequences']} sequences, "
            f"{tr['n_iter']} iterations, converged={tr['converged']}")

    # Tables 3.1-3.4 (cumulative, truth input)
    progress("Tables 3.1-3.4 (cumulative, truth input)")
    tabs, confs = [], []
    # "3.4+1c" (ours): the confidence decision gated by the one-class threshold (decision
    # "both", as used on real data); "3.4+bg" (ours): the confidence decision with the
    # background model as one more rival hypothesis (decision "confidence_bg", no threshold)
    for table, split_name, decision in (("3.1", "train", "oneclass"), ("3.2", "train", "confidence"),
                                        ("3.3", "test", "oneclass"), ("3.4", "test", "confidence"),
                                        ("3.4+1c", "test", "both"), ("3.4+bg", "test", "confidence_bg")):
        sets_ = train if split_name == "train" else test
        mans = KNOWN if split_name == "train" else ALL
        df = pd.concat([tag(sets_[m], m) for m in mans], ignore_index=True)
        res = ms.classify(df, mode="cumulative", decision=decision, gmr=False)
        if table == "3.4":
            res_cf = res
        t = thesis_side_by_side(per_maneuver_table(res, KNOWN, truth_col="truth"), table)
        t.insert(1, "classifier", decision)
        t.insert(2, "split", split_name)
        tabs.append(t)
        fin = res.groupby("run_id", sort=False).tail(1)
        c = confusion(fin["truth"].tolist(), fin["pred"].tolist(), list(KNOWN)).reset_index()
        confs.append(c.assign(table=table))
    tables = pd.concat(tabs, ignore_index=True)
    write_table(tables, paths["tables_3_1_3_4"], name="seed000_classification_tables_3_1_3_4",
                extra={"runs_per_maneuver": run.runs, "seed": run.seed, "size": size})
    conf = pd.concat(confs, ignore_index=True)
    write_table(conf, paths["confusion"], name="seed000_classification_confusion")
    with pd.option_context("display.width", 200, "display.max_columns", 20):
        say(tables.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
        say(conf.to_string(index=False))

    # why M5 is not "unknown" under the confidence decision alone: how far ahead its best
    # model is (V_best at the end) and how its LL compares with that model's one-class threshold
    per_sample = pd.crosstab(res_cf["truth"], res_cf["pred"], normalize="index")
    fin = res_cf.groupby("run_id", sort=False).tail(1)
    m5f = fin[fin["truth"] == "M5"]
    m5_diag = {}
    if len(m5f):
        lls = m5f[[f"ll_{k}" for k in KNOWN]].to_numpy()
        srt = np.sort(lls, axis=1)
        m5_diag = {"best": m5f["best"].value_counts().to_dict(),
                   "V_best_median": float(m5f["V_best"].median()),
                   "ll_gap_to_second_median": float(np.median(srt[:, -1] - srt[:, -2])),
                   "below_oneclass_pct": 100.0 * float(np.mean(~m5f["oneclass_ok"].to_numpy(bool)))}
        say(f"M5 under the confidence decision: best model {m5_diag['best']}, median V_best "
            f"{m5_diag['V_best_median']:.1f}, median LL gap to the runner-up "
            f"{m5_diag['ll_gap_to_second_median']:.1f} nats, below the best model's one-class "
            f"threshold in {m5_diag['below_oneclass_pct']:.1f} % of runs at the end")

    # Tables 3.10-3.12 (switch scenarios, truth input)
    sw = sh = None
    if "switch" not in skip:
        cells, shifts = [], []
        for ts in (3.0, 8.0, 13.0):
            for key in "ABCD":
                for mode in ("cumulative", "windowed", "reset"):
                    progress(f"switch scenario {key} at {ts:g} s, {mode}")
                    cells.append(switch_cell(ms, key, ts, run, mode))
        sw = pd.DataFrame(cells)
        write_table(sw, paths["switch_tables"], name="seed000_classification_switch_tables",
                    extra={"switch_runs": run.switch_runs, "seed": run.seed, "size": size})
        with pd.option_context("display.width", 250, "display.max_columns", 30):
            say(sw.drop(columns=["first", "final", "table"]).to_string(index=False, float_format=lambda x: f"{x:.1f}"))
        # the switch moved by ±1 s around each thesis switch time (reset-mode change point)
        done = {(c["scenario"], c["switch_s"]): c for c in cells if c["mode"] == "reset"}
        for key in "ABCD":
            for base in (3.0, 8.0, 13.0):
                for ts in (base - 1.0, base, base + 1.0):
                    c = done.get((key, ts)) or switch_cell(ms, key, ts, run, "reset")
                    shifts.append({"scenario": key, "base_switch_s": base, "switch_s": ts,
                                   "change_point_s": c["change_point_s"],
                                   "detection_delay_s": c["detection_delay_s"]})
        sh = pd.DataFrame(shifts)
        write_table(sh, paths["switch_shift"], name="seed000_classification_switch_shift")
        say(sh.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
    else:  # declared outputs are always written: empty, marked skipped
        for k in ("switch_tables", "switch_shift"):
            write_table(pd.DataFrame(), paths[k], name=f"{NAME}_{k}", extra={"skipped": True})

    gerr = grmse = None
    if "gmr" not in skip:
        progress("GMR errors on the test runs")
        gerr, grmse = gmr_errors(ms, test)
        write_table(gerr, paths["gmr_error"], name="seed000_classification_gmr_error")
        write_table(grmse, paths["gmr_rmse"], name="seed000_classification_gmr_rmse")
        say(grmse.pivot(index="maneuver", columns="quantity", values="rmse").to_string(float_format=lambda x: f"{x:.3f}"))
    else:
        for k in ("gmr_error", "gmr_rmse"):
            write_table(pd.DataFrame(), paths[k], name=f"{NAME}_{k}", extra={"skipped": True})

    write_report(paths["report"], run, size, cfg, ms, tables, conf, per_sample, m5_diag, sw=sw, sh=sh, grmse=grmse)
    # the M2/M4 ambiguity the thesis reports (§3.4.2), on the Table 3.4 classification
    m4m2, m2m4 = early_confusion(res_cf, "M4", "M2"), early_confusion(res_cf, "M2", "M4")
    with open(paths["report"], "a") as fh:
        fh.write("\n## M2/M4 confusion in time (thesis §3.4.2)\n\n"
                 "The thesis: \"Maneuvers 2 and 4 have similar initial accelerations for the first 5 -10 "
                 "seconds\". On the Table 3.4 classification (confidence rule, cumulative, truth input):\n\n"
                 "| truth | labelled | share of its samples (%) | of those in the first 10 s (%) | runs with any (%) "
                 "| last (s) |\n|---|---|---|---|---|---|\n"
                 + "".join(f"| {a} | {b} | {d['samples_pct']:.2f} | {d['in_first_pct']:.1f} | {d['runs_pct']:.1f} "
                           f"| {d['last_s']:.1f} |\n" for a, b, d in (("M4", "M2", m4m2), ("M2", "M4", m2m4))))

    et = esw = rmse = None
    if es is not None:
        # EKF input (Tables 3.5-3.8, 3.13-3.15): the same runs, filtered as the ekf_sets rule
        # filters the workflow's sets; the truth-trained models (the thesis setup) and models
        # trained the same way on the EKF estimates of the training runs
        progress("EKF input: filtering the train and test runs (radar synthesised from the truth)")
        d_train, d_test = {}, {}
        ekf_train, ekf_test = ekf_of(train, "train", run.seed, es, d_train), ekf_of(test, "test", run.seed, es, d_test)
        rmse = pd.DataFrame([{"maneuver": m, "pos_m": d_test[m]["rmse_pos"], "vel_mps": d_test[m]["rmse_vel"],
                              "acc_mps2": d_test[m]["rmse_acc"], "runs": d_test[m]["runs"],
                              "diverged_runs": d_test[m]["n_diverged"],
                              "diverged_train_runs": d_train[m]["n_diverged"]} for m in ALL])
        say(rmse.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
        # what the classifier sees: the printed (4.1) x̂⁻_{k+1} − x̂⁺_k (prior) or the digest's
        # x̂⁺_{k+1} − x̂⁺_k (posterior, §13.4); the other reading is tabulated as a diagnosis
        readings = [inc] + ([other_reading(inc)] if st["other_increments"] else [])
        tabs, ekf_trained = [], {}
        for reading in readings:
            v_train, v_test = increments_view(ekf_train, reading, "train"), increments_view(ekf_test, reading, "test")
            progress(f"EKF input ({reading} increments): training one HMM per known maneuver on the EKF estimates")
            ekf_trained[reading] = ManeuverModelSet(config=cfg).fit(pd.concat([tag(v_train[m], m) for m in KNOWN],
                                                                              ignore_index=True))
            progress(f"EKF input ({reading} increments): Tables 3.5-3.8")
            tabs.append(ekf_tables({"truth": ms, "ekf": ekf_trained[reading]}, v_train, v_test, increments=reading))
        et = pd.concat(tabs, ignore_index=True)
        models = {"truth": ms, "ekf": ekf_trained[inc]}
        write_table(et, paths["ekf_tables"], name="seed000_classification_ekf_tables",
                    extra={"runs_per_maneuver": run.runs, "seed": run.seed, "size": size, "q": es.q,
                           "p0_sigma": list(es.p0_sigma)})
        with pd.option_context("display.width", 200, "display.max_columns", 20):
            say(et.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
        if "switch" not in skip:
            esw = ekf_switch_tables(models, run, es, progress, increments=inc)
            write_table(esw, paths["ekf_switch_tables"], name="seed000_classification_ekf_switch_tables",
                        extra={"switch_runs": run.switch_runs, "seed": run.seed, "size": size, "q": es.q})
            with pd.option_context("display.width", 250, "display.max_columns", 30):
                say(esw.drop(columns=["first", "final", "table"]).to_string(index=False, float_format=lambda x: f"{x:.1f}"))
        else:
            write_table(pd.DataFrame(), paths["ekf_switch_tables"], name="seed000_classification_ekf_switch_tables",
                        extra={"skipped": True})
        with open(paths["report"], "a") as fh:
            fh.write("\n".join(ekf_report(et, esw, es, rmse, inc)) + "\n")
    say(f"report: {paths['report']}")

    res = Results()
    headline(res, run, cfg, ms, tables, m5_diag, st["alt_mode"], sw=sw, sh=sh, grmse=grmse)
    if et is not None:
        ekf_headline(res, et, esw, rmse, inc)
    res.add("seed000_m4_as_m2_test_samples_pct", f"{m4m2['samples_pct']:.2f}",
            "Share of the M4 test samples the confidence rule labels M2 (Table 3.4 run; thesis §3.4.2).")
    res.add("seed000_m4_as_m2_in_first_10s_pct", f"{m4m2['in_first_pct']:.1f}",
            "Share of those M4-labelled-M2 samples within the first 10 s of their run.")
    res.add("seed000_m2_as_m4_test_samples_pct", f"{m2m4['samples_pct']:.2f}",
            "Share of the M2 test samples the confidence rule labels M4.")
    res.add("seed000_study_wall_s", f"{progress.elapsed:.0f}",
            "Wall time of the study (s), simulation to results, page excluded.")
    res.write(paths["results"])
    build_study_page(NAME, paths["page"], results=paths["results"], report_md=paths["report"], template=template,
                     definitions=res.definitions, figures=figures(tables, sw, gerr, et, inc),
                     title=f"Study: seed-000 classification ({run.runs} runs per maneuver)",
                     facts=[("size", size), ("seed", str(run.seed)), ("runs per maneuver", str(run.runs)),
                            ("runs per switch cell", str(run.switch_runs)), ("features", cfg.feature_set),
                            ("input", "truth" if es is None else f"truth and EKF estimates (q = {es.q:g} m²/s⁵, "
                                                                 f"{inc} increments)"),
                            ("tables", ", ".join(f"{t}.parquet" for t in OUTPUT_TABLES))])
    return StudyResult(name=NAME, status="ok", results=dict(res.values),
                       diagnostics={"size": size, "seed": run.seed, "settings": st,
                                    "wall_s": round(progress.elapsed, 1)})
