"""Seed-000 estimation study: the CA EKF/RTS Monte Carlo and the EKF+HMM against the EKF.

Steps (seed 000 §2, §3, §8, §9, §11–§13; issue 14 item 5):

1. Data. Per maneuver M1–M5 ``runs`` bare 25 s runs split 70/30 and ``mc_runs`` padded Monte
   Carlo runs (``mc_<M>``: same start and heading, new disturbance; 65–70 s), simulated in
   process exactly as ``uavpipe simulate`` draws them, or read from its output (input
   ``sets``). Radar measurements are synthesised from the 5 Hz truth with the seed-000 radar
   (Table 2.1: σ_ρ = 1.5 m, σ_u = σ_v = 45 µrad, σ_ρ̇ = 0.2 m/s, τ_RD = 0) at the fixed site
   ``simulate.sensors.radar.site_ned_m`` (default the NED origin on the ground: the Monte Carlo
   start lies ~580 m from it, the bare runs start within ±800 m N/E of it).
2. q. One scalar white-jerk density ``q`` is grid-searched (``q_grid``) on ``tune_runs``
   training runs of each known maneuver M1–M4 by normalised RMSE (the per-component RMSE pooled
   over the maneuvers, divided by its grid median, averaged over the 9 components;
   :func:`~pipeline.estimate.montecarlo.tune_q`) and frozen before any test or Monte Carlo run.
3. EKF/RTS Monte Carlo (Ch. 2) on every ``mc_<M>``: Ch. 2 initialisation
   ``x̂₀ = x₀ + [1·randn(3); 0.1·randn(3); 0.01·randn(3)]``, ``P₀ = diag(1², 0.1², 0.01²)``;
   mean error, error variance and filter variance against time per component, RMSE per group,
   and the run-averaged NEES against the 95 % band of ``χ²(9N)/N``. The truth is the simulator's
   quadcopter, not the filter's white-jerk model, so the NEES is a diagnostic here (the
   consistency proof on the filter's own model is ``tests/estimate/test_ekf.py``).
4. EKF+HMM (Ch. 4, digest §8): HMMs truth-trained as in ``study_seed000_classification``
   (:func:`~pipeline.studies.seed000_classification.train_models`; ``hmm`` section, default
   ``state9h``). Searched on training runs only and then frozen (:func:`tune_ekf_hmm`): the GMR
   conditioning block (``gmr_inputs``; the thesis' 3.28 is ``pos``), the outlier gate
   (``gates``), what the GMR sees when ``Q₂ = q2_from_runs(...)`` is estimated on ``q2_runs``
   training runs (``q2_inputs``: the truth, or the baseline EKF's posteriors — the inputs the
   filter meets at run time; the one-step errors are always against the truth) and the ``Q₂``
   scale (``q2_scale_grid``). Over each maneuver's test runs (truth initialisation, one radar
   realisation each) the run with the lowest summed absolute EKF+HMM error is Scenario 1 (best),
   the highest Scenario 2 (worst) (:func:`~pipeline.estimate.metrics.best_worst`); each is
   re-run ``noise_runs`` times with new radar noise from its true initial state. Reported: RMSE
   per group (pos, v_N, v_E, v_D, acc) EKF vs EKF+HMM, their mean error / error variance /
   filter variance against time, and the classifier MAoT beside the thesis' Chapter-4 table.
   ``increments`` picks what the classifier sees of the baseline EKF: the predicted increments
   of the thesis's printed (4.1) (:func:`~pipeline.estimate.ekf_hmm.prior_increment_track`,
   default) or the posterior ones (digest §13.4); the GMR diagnosis
   (``gmr_decomposition``) always reads the posteriors.

Outputs (:data:`OUTPUT_TABLES` under ``results/studies/seed000_ekf/``): ``q_tuning``,
``mc_time``, ``mc_rmse``, ``q2_tuning``, ``scenarios``, ``hmm_rmse``, ``hmm_time``, plus
``report.md``, ``results.txt`` and the page ``results/report/studies/seed000_ekf.html``.

Sizes (``studies.size``; ``runs`` per maneuver / ``mc_runs`` / ``noise_runs`` / ``tune_runs`` /
``q2_runs``): ``tiny`` 20/10/10/4/10 (tests; the thesis gate only), ``small``
300/100/100/30/100, ``thesis`` 2300/1000/1000/100/400.

Seed: the master ``seed`` draws the simulated sets (as ``uavpipe simulate``), the split, the
training, and every radar realisation (``set_rng(seed, "seed000_ekf/<purpose>/<M>")``).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import dataclasses

import numpy as np
import pandas as pd
import plotly.graph_objects as go

from ..config import ROOT, ConfigError, load_config, section
from ..estimate.base import ConstantAcceleration, GaussianState
from ..estimate.ekf import ExtendedKalmanFilter, run_filter
from ..estimate.ekf_hmm import INCREMENTS, classifier_state, ekf_state_frame, hmm_filter, q2_from_runs, run_ekf_hmm
from ..estimate.metrics import best_worst, chi2_band, fraction_in_band, nees, rmse, rmse_groups
from ..estimate.models import STATE_COLUMNS, RadarModel, initial_cov
from ..estimate.montecarlo import measure, normalised_rmse, tune_q
from ..estimate.smoother import rts_smooth
from ..io.parquet import write_table
from ..models.features import observations, raw_features
from ..models.metrics import is_correct
from ..report.study import build_study_page, layout
from ..simulate.seeds import set_rng
from .base import (STUDY_TABLES, Progress, Results, StudyError, StudyResult, input_path, md_table, model_variant,
                   output_path, say, study_outputs, study_settings, write_text)
from .seed000_classification import KNOWN, simulate_runs, split, train_models

NAME = "seed000_ekf"
ALL = (*KNOWN, "M5")

#: Parquet tables the study writes (``<name>.parquet``)
OUTPUT_TABLES = STUDY_TABLES[NAME]

#: settings of every size (``studies.seed000_ekf``)
DEFAULTS: dict[str, Any] = {
    "runs": 300,             # bare runs per maneuver, split 70/30 (thesis 2300)
    "mc_runs": 100,          # Monte Carlo runs per maneuver (thesis 1000)
    "noise_runs": 100,       # noise realisations of each S1/S2 run (thesis 1000)
    "tune_runs": 30,         # training runs per known maneuver for the q and Q₂-scale searches
    "q_grid": [0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0],
    "q2_runs": 100,          # training runs per known maneuver Q₂ is estimated on
    "q2_scale_grid": [0.3, 1.0, 3.0, 10.0, 30.0, 100.0],
    "gmr_inputs": ["pos", "pos_fd", "pos_vel"],   # GMR conditioning blocks searched (thesis 3.28: pos)
    "gates": [15.0, 5.0, 2.0],  # GMR outlier gates searched (m/s² per step; thesis 15)
    "q2_inputs": ["truth", "ekf"],  # what the GMR sees when Q₂ is estimated
    "mc_maneuvers": list(ALL),
    "features": None,        # override hmm.feature_set (state9, state9h)
    "chunk_runs": 250,       # Monte Carlo runs filtered at once (memory: ~1 MB per run with RTS)
    "skip": [],              # parts left out: "hmm" (the EKF+HMM; its tables are written empty)
    "increments": "prior",  # what the classifier sees: prior (printed (4.1), default) or posterior (digest §13.4)
}
#: per-size settings
SIZES: dict[str, dict[str, Any]] = {
    "tiny": {"runs": 20, "mc_runs": 10, "noise_runs": 10, "tune_runs": 4, "q2_runs": 10, "gates": [15.0]},
    "small": {"runs": 300, "mc_runs": 100, "noise_runs": 100, "tune_runs": 30, "q2_runs": 100},
    "thesis": {"runs": 2300, "mc_runs": 1000, "noise_runs": 1000, "tune_runs": 100, "q2_runs": 400},
}

#: seed 000 Chapter-4 table (digest §11): classifier MAoT (%) of the EKF+HMM Monte Carlo runs
THESIS_CH4_MAOT: dict[tuple[str, str], float] = {
    ("M1", "S1"): 94.79, ("M1", "S2"): 70.27, ("M2", "S1"): 96.83, ("M2", "S2"): 96.82,
    ("M3", "S1"): 96.14, ("M3", "S2"): 96.0, ("M4", "S1"): 89.30, ("M4", "S2"): 76.80,
}

#: the groups compared EKF vs EKF+HMM: name -> state columns (indices)
HMM_GROUPS: dict[str, tuple[int, ...]] = {"pos": (0, 1, 2), "vel_n": (3,), "vel_e": (4,), "vel_d": (5,),
                                          "acc": (6, 7, 8)}
#: the Monte Carlo's groups
MC_GROUPS: dict[str, tuple[int, ...]] = {"pos": (0, 1, 2), "vel": (3, 4, 5), "acc": (6, 7, 8)}
#: each group's SI unit suffix: its RMSE columns are named ``..._<group>_<unit>`` (the schema's
#: unit-in-the-name rule); RESULT names keep the bare group and add the unit themselves
GROUP_UNITS: dict[str, str] = {"pos": "m", "vel": "mps", "vel_n": "mps", "vel_e": "mps", "vel_d": "mps",
                               "acc": "mps2"}


def group_col(grp: str) -> str:
    """The column-name stem of a group's RMSE with its unit: ``pos`` -> ``pos_m``."""
    return f"{grp}_{GROUP_UNITS[grp]}"


def outputs_for(results_dir: str = "results") -> dict[str, str]:
    """The study's declared outputs under ``results_dir`` (see :func:`.base.study_outputs`)."""
    return study_outputs(NAME, results_dir=results_dir, models=False)


# -- data -----------------------------------------------------------------------------------------

def runs_array(df: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A bulk set as arrays: run ids (R,), step times (T,), truth (R, T, 9), yaw (R, T), labels (R, T).

    Raises
    ------
    StudyError
        Runs of unequal length or times (a bulk set has equal runs).
    """
    df = df.sort_values(["run_id", "t_ns"], kind="stable")
    ids, counts = np.unique(df["run_id"].to_numpy(), return_counts=True)
    if len(set(counts)) != 1:
        raise StudyError(f"{NAME}: runs of unequal length in a set ({sorted(set(counts))} samples)")
    R, T = len(ids), int(counts[0])
    t = df["t_ns"].to_numpy(np.int64).reshape(R, T)
    if not np.all(t == t[0]):
        raise StudyError(f"{NAME}: runs of one set do not share their sample times")
    truth = df[list(STATE_COLUMNS)].to_numpy(np.float64).reshape(R, T, 9)
    yaw = df["yaw_rad"].to_numpy(np.float64).reshape(R, T)
    lab = df["label"].astype(str).to_numpy(dtype=object).reshape(R, T)
    return ids, t[0], truth, yaw, lab


def load_data(st: dict, seed: int, sim: Mapping, sets: Path | None, progress) -> tuple[dict, dict, dict]:
    """``train``, ``test`` (bare runs of M1–M4) and ``mc`` (``mc_<M>``) tables, simulated as
    ``uavpipe simulate`` draws them (:func:`~.seed000_classification.simulate_runs`, ``split``)
    or read from its ``sets/`` folder."""
    train, test, mc = {}, {}, {}
    for man in KNOWN:
        if sets is not None:
            train[man] = pd.read_parquet(sets / "sets" / f"{man}_train.parquet")
            test[man] = pd.read_parquet(sets / "sets" / f"{man}_test.parquet")
        else:
            df = simulate_runs("maneuver", man, int(st["runs"]), seed, f"maneuver/{man}", sim)
            train[man], test[man] = split(df, seed, man)
    for man in st["mc_maneuvers"]:
        if sets is not None:
            df = pd.read_parquet(sets / "sets" / f"mc_{man}.parquet")
            keep = np.sort(df["run_id"].unique())[: int(st["mc_runs"])]
            mc[man] = df[df["run_id"].isin(keep)]
        else:
            mc[man] = simulate_runs("mc", man, int(st["mc_runs"]), seed, f"mc_{man}", sim)
    tt = ", ".join(f"{m} {train[m]['run_id'].nunique()}/{test[m]['run_id'].nunique()}" for m in KNOWN)
    mm = ", ".join(f"{m} {d['run_id'].nunique()}" for m, d in mc.items())
    progress(f"data: {tt} train/test runs; mc {mm}")
    return train, test, mc


def first_runs(df: pd.DataFrame, n: int) -> pd.DataFrame:
    """The ``n`` lowest-numbered runs of a set (the tuning subset: deterministic, seed-free)."""
    keep = np.sort(df["run_id"].unique())[:n]
    return df[df["run_id"].isin(keep)]


def radar_z(radar: RadarModel, truth: np.ndarray, seed: int, purpose: str) -> np.ndarray:
    """Radar measurements ``(T, R, 4)`` of ``truth`` (R, T, 9), one seeded draw per purpose."""
    return measure(radar, truth, set_rng(seed, f"{NAME}/{purpose}"))


def truth_prior(truth: np.ndarray, t0: int) -> GaussianState:
    """Ch. 4 initialisation: the true state with ``P₀`` (truth initialisation)."""
    R = truth.shape[0]
    return GaussianState(truth[:, 0], np.broadcast_to(initial_cov(), (R, 9, 9)), t0)


def pooled_rmse(rows: list[tuple[np.ndarray, int]]) -> np.ndarray:
    """RMSE per grid value and component pooled over sets: ``sqrt(Σ n_m RMSE_m² / Σ n_m)``.

    ``rows`` holds ``(rmse (G, 9), n samples)`` per set; equals one RMSE over all samples.
    """
    num = sum(n * r ** 2 for r, n in rows)
    return np.sqrt(num / sum(n for _, n in rows))


# -- q ----------------------------------------------------------------------------------------------

def tune_q_on_training(train: dict, radar: RadarModel, st: dict, seed: int):
    """Step 2: the frozen ``q`` from ``tune_runs`` training runs of each known maneuver.

    Returns ``(q, table)``: the table holds the pooled per-group RMSE and the score per grid value.
    """
    rows, per = [], []
    for man in KNOWN:
        _, t_ns, truth, _, _ = runs_array(first_runs(train[man], int(st["tune_runs"])))
        z = radar_z(radar, truth, seed, f"tune/{man}")
        tq = tune_q(truth, z, t_ns, radar, st["q_grid"])
        rows.append((tq.rmse, truth.shape[0] * truth.shape[1]))
        per.append((man, tq))
    pooled = pooled_rmse(rows)
    score = normalised_rmse(pooled)
    q = float(tq.grid[int(np.argmin(score))])
    recs = []
    for i, g in enumerate(tq.grid):
        rec = {"q": g, "score": float(score[i]), "chosen": g == q}
        rec.update({f"rmse_{c}": float(pooled[i, j]) for j, c in enumerate(STATE_COLUMNS)})
        for grp, idx in MC_GROUPS.items():
            rec[f"rmse_{group_col(grp)}"] = float(np.sqrt(np.sum(pooled[i, list(idx)] ** 2)))
        for man, t in per:
            rec[f"score_{man}"] = float(normalised_rmse(t.rmse)[i])
        recs.append(rec)
    return q, pd.DataFrame(recs)


# -- EKF/RTS Monte Carlo ---------------------------------------------------------------------------

def mc_maneuver(man: str, df: pd.DataFrame, ekf: ExtendedKalmanFilter, radar: RadarModel, seed: int,
                chunk: int) -> tuple[pd.DataFrame, dict]:
    """Step 3 for one maneuver: EKF and RTS over the ``mc_<M>`` runs, chunk by chunk.

    Returns the per-time table (filter, t_s, component, mean_err, err_var, filter_var, nees_avg)
    and the summary (RMSE per group, NEES time mean, fraction of steps in the χ² band).
    """
    _, t_ns, truth, _, _ = runs_array(df)
    R, T = truth.shape[:2]
    z = radar_z(radar, truth, seed, f"mc/{man}")
    rng = set_rng(seed, f"{NAME}/mc_init/{man}")
    # Ch. 2 initialisation: x̂₀ = x₀ + [1·randn(3); 0.1·randn(3); 0.01·randn(3)], P₀ alike
    x0 = truth[:, 0] + rng.standard_normal((R, 9)) * np.sqrt(np.diag(initial_cov()))
    out = {f: {"err": np.empty((R, T, 9)), "var": np.empty((R, T, 9)), "nees": np.empty((R, T))}
           for f in ("ekf", "rts")}
    for lo in range(0, R, chunk):
        hi = min(R, lo + chunk)
        prior = GaussianState(x0[lo:hi], np.broadcast_to(initial_cov(), (hi - lo, 9, 9)), int(t_ns[0]))
        track = run_filter(ekf, prior, t_ns, z[:, lo:hi], store="all")
        sm = rts_smooth(track)
        for f, (m, P) in (("ekf", (track.mean, track.cov)), ("rts", (sm.mean, sm.cov))):
            e = m - truth[lo:hi]
            out[f]["err"][lo:hi] = e
            out[f]["var"][lo:hi] = np.diagonal(P, axis1=-2, axis2=-1)
            out[f]["nees"][lo:hi] = nees(e, P)
        del track, sm
    t_s = (t_ns - t_ns[0]) * 1e-9
    lo_b, hi_b = chi2_band(9, R)
    frames, summ = [], {"maneuver": man, "n_runs": R, "n_steps": T, "nees_band_lo": lo_b, "nees_band_hi": hi_b}
    for f, o in out.items():
        e = o["err"]
        mean_err = e.mean(axis=0)
        err_var = e.var(axis=0, ddof=1) if R > 1 else np.zeros((T, 9))
        fvar = o["var"].mean(axis=0)
        navg = o["nees"].mean(axis=0)
        frames.append(pd.DataFrame({
            "maneuver": man, "filter": f, "t_s": np.repeat(t_s, 9),
            "component": np.tile(np.array(STATE_COLUMNS, dtype=object), T),
            "mean_err": mean_err.ravel(), "err_var": err_var.ravel(), "filter_var": fvar.ravel(),
            "nees_avg": np.repeat(navg, 9)}))
        g = rmse_groups(e)
        for grp in MC_GROUPS:
            summ[f"{f}_rmse_{group_col(grp)}"] = g[grp]
        summ[f"{f}_nees_mean"] = float(navg.mean())
        summ[f"{f}_nees_in_band_pct"] = 100.0 * fraction_in_band(navg, 9, R)
        # P against the Monte Carlo error variance (the thesis' Q: "P exceeds the MC error variance")
        summ[f"{f}_var_ratio_median"] = float(np.median(err_var[1:] / fvar[1:])) if R > 1 else float("nan")
    return pd.concat(frames, ignore_index=True), summ


# -- EKF+HMM ----------------------------------------------------------------------------------------

def ekf_hmm_errors(ekf, ms, Q2, t_ns, truth, yaw, z, increments: str = "prior"):
    """One EKF+HMM run over ``truth`` (R, T, 9) from the true initial state: ``(track, e_ekf, e_hmm)``.

    ``e_hmm`` is the error of the EKF+HMM's *output* (:attr:`~pipeline.estimate.ekf_hmm.EkfHmmTrack.output`:
    the EKF+HMM estimate where a known classification chose the step's prediction, the EKF's
    elsewhere; seed 000 Ch. 4.1 "if the classification is unknown, the output of the filter is the
    EKF estimate"), not of the EKF+HMM filter's internal state. ``increments``: what the classifier
    sees of the EKF (:func:`~pipeline.estimate.ekf_hmm.classifier_state`).
    """
    tr = run_ekf_hmm(ekf, truth_prior(truth, int(t_ns[0])), t_ns, z, ms, Q2, yaw_rad=yaw, store="filtered",
                     increments=increments)
    return tr, tr.ekf.mean - truth, tr.output.mean - truth


def estimated_frames(ekf, train: dict, radar, seed: int, n: int,
                     increments: str = "prior") -> tuple[pd.DataFrame, pd.DataFrame]:
    """Truth and baseline-EKF state tables of ``n`` training runs per known maneuver (same run ids
    and times; truth initialisation, one radar realisation each): ``q2_from_runs``' inputs. The
    EKF table is what the classifier sees of it (``increments``, :func:`classifier_state`)."""
    tt, ee = [], []
    for man in KNOWN:
        ids, t_ns, truth, yaw, _ = runs_array(first_runs(train[man], n))
        z = radar_z(radar, truth, seed, f"q2/{man}")
        tr = run_filter(ekf, truth_prior(truth, int(t_ns[0])), t_ns, z, store="mean")
        rid = np.array([f"{man}-{i}" for i in ids], dtype=object)
        tt.append(ekf_state_frame(truth, t_ns, yaw_rad=yaw, run_ids=rid))
        ee.append(ekf_state_frame(classifier_state(tr.mean, t_ns, increments), t_ns, yaw_rad=yaw, run_ids=rid))
    return pd.concat(tt, ignore_index=True), pd.concat(ee, ignore_index=True)


def tune_ekf_hmm(ekf, ms, train, radar, st, seed, progress):
    """The EKF+HMM's settings, searched on training runs only and then frozen.

    Grid: GMR input (``gmr_inputs``) × gate (``gates``, m/s² per step) × what the GMR sees when
    ``Q₂`` is estimated (``q2_inputs``: ``truth``, or ``ekf``: the baseline EKF's posteriors of
    the same training runs, the inputs the filter meets at run time) × the ``Q₂`` scale
    (``q2_scale_grid``). Each candidate runs the EKF+HMM over ``tune_runs`` training runs per
    known maneuver; score = mean over the 9 components of the pooled EKF+HMM RMSE divided by the
    pooled EKF RMSE of the same runs (< 1: the EKF+HMM is better on average).

    Returns
    -------
    (best, table)
        ``best``: dict with ``gmr_input``, ``gate_mps2``, ``q2_input``, ``q2_scale``, ``Q2`` and
        ``model_set`` (the variant); ``table``: one row per candidate.
    """
    grid = [float(x) for x in st["q2_scale_grid"]]
    if not grid or min(grid) <= 0:
        raise ConfigError(f"studies.{NAME}.q2_scale_grid: must hold positive values, got {grid}")
    data = {}
    for man in KNOWN:
        _, t_ns, truth, yaw, _ = runs_array(first_runs(train[man], int(st["tune_runs"])))
        data[man] = (t_ns, truth, yaw, radar_z(radar, truth, seed, f"tune_q2/{man}"))
    n_of = {m: d[1].shape[0] * d[1].shape[1] for m, d in data.items()}
    truth_q2, ekf_q2 = estimated_frames(ekf, train, radar, seed, int(st["q2_runs"]), st["increments"])
    recs, cands = [], []
    ekf_pooled = None
    for gi in st["gmr_inputs"]:
        for gate in st["gates"]:
            msv = model_variant(ms, gmr_input=gi, gate_mps2=float(gate))
            bases = {src: q2_from_runs(msv, truth_q2, input_state=None if src == "truth" else ekf_q2)
                     for src in st["q2_inputs"]}
            first = next(iter(bases.values()))
            rm = {(src, sc): {} for src in bases for sc in grid}
            ekf_rm = {}
            for man, (t_ns, truth, yaw, z) in data.items():
                prior = truth_prior(truth, int(t_ns[0]))
                tr = run_ekf_hmm(ekf, prior, t_ns, z, msv, first, yaw_rad=yaw, store="mean",
                                 increments=st["increments"])
                ekf_rm[man] = rmse(tr.ekf.mean - truth)
                for src, Qb in bases.items():
                    for sc in grid:
                        h = hmm_filter(ekf, prior, t_ns, z, Qb * sc, tr.hmm_axes, tr.acc_hmm, tr.jerk_hmm,
                                       store="mean")
                        # scored on the EKF+HMM's output (EKF where the classification is unknown)
                        rm[(src, sc)][man] = rmse(dataclasses.replace(tr, hmm=h).output.mean - truth)
            if ekf_pooled is None:
                ekf_pooled = pooled_rmse([(ekf_rm[m][None], n_of[m]) for m in KNOWN])[0]
            for (src, sc), per in rm.items():
                pooled = pooled_rmse([(per[m][None], n_of[m]) for m in KNOWN])[0]
                rec = {"gmr_input": gi, "gate_mps2": float(gate), "q2_input": src, "q2_scale": sc,
                       "score": float(normalised_rmse(pooled[None], ekf_pooled)[0])}
                for grp, idx in HMM_GROUPS.items():
                    rec[f"hmm_rmse_{group_col(grp)}"] = float(np.sqrt(np.sum(pooled[list(idx)] ** 2)))
                    rec[f"ekf_rmse_{group_col(grp)}"] = float(np.sqrt(np.sum(ekf_pooled[list(idx)] ** 2)))
                recs.append(rec)
                cands.append((msv, bases[src] * sc))
            progress(f"  gmr_input {gi}, gate {gate:g}: best score "
                     f"{min(r['score'] for r in recs if r['gmr_input'] == gi and r['gate_mps2'] == gate):.3f}")
    table = pd.DataFrame(recs)
    i = int(table["score"].idxmin())
    table["chosen"] = table.index == i
    best = {k: table.loc[i, k] for k in ("gmr_input", "gate_mps2", "q2_input", "q2_scale", "score")}
    best.update(model_set=cands[i][0], Q2=cands[i][1])
    return best, table


def group_rmse(err: np.ndarray) -> dict[str, float]:
    """RMSE of each :data:`HMM_GROUPS` group over runs and time (3-D for pos and acc)."""
    e = err.reshape(-1, err.shape[-1])
    return {g: float(np.sqrt(np.mean(np.sum(e[:, list(idx)] ** 2, axis=1)))) for g, idx in HMM_GROUPS.items()}


def maot(pred: np.ndarray, labels: np.ndarray) -> float:
    """Classifier MAoT (%) over runs: per run the share of steps from the second on (the first
    has no differenced observation) whose label is right (seed 000 §5), averaged over runs."""
    ok = is_correct(pred[:, 1:].ravel(), labels[:, 1:].ravel(), KNOWN).reshape(pred.shape[0], -1)
    return 100.0 * float(ok.mean(axis=1).mean())


def input_quality(tr, t_ns, truth, e_ekf, e_hmm) -> dict[str, float]:
    """Why the EKF+HMM wins or loses on acceleration: 3-D RMSE (m/s²) over the steps predicted with
    HMM inputs on every axis of the GMR input the prediction uses, ``â_{k−1} + dt ĵ_{k−1}``
    (what the EKF+HMM's acceleration is before the radar update), against the EKF's and the
    EKF+HMM's posterior acceleration on the same steps."""
    dt = np.diff(t_ns) * 1e-9
    u = tr.acc_hmm[:, :-1] + dt[None, :, None] * tr.jerk_hmm[:, :-1]     # input into step k
    on = tr.hmm_axes[:, 1:].all(axis=-1)
    if not on.any():
        return {"gmr_input_acc_rmse_mps2": float("nan"), "ekf_acc_rmse_on_hmm_steps_mps2": float("nan"),
                "ekf_hmm_acc_rmse_on_hmm_steps_mps2": float("nan")}

    def r3(e):
        return float(np.sqrt(np.mean(np.sum(e[on] ** 2, axis=-1))))

    return {"gmr_input_acc_rmse_mps2": r3(u - truth[:, 1:, 6:]), "ekf_acc_rmse_on_hmm_steps_mps2": r3(e_ekf[:, 1:, 6:]),
            "ekf_hmm_acc_rmse_on_hmm_steps_mps2": r3(e_hmm[:, 1:, 6:])}


#: lags (steps) scanned for the GMR's time alignment: estimate at t_k against the truth at t_{k+L}
GMR_LAGS = (-2, -1, 0, 1, 2)


def _gmr_acc(ms, obs, best, state, yaw0: float) -> np.ndarray:
    """The GMR acceleration (NED, m/s², ungated) of one run's normalised observations ``obs`` with
    the given per-step model ``best`` (label) and Viterbi ``state``:
    :meth:`~pipeline.models.classifier.ManeuverModelSet.gmr`, which ``classify`` uses."""
    idx = np.array([ms.labels_.index(m) if m in ms.labels_ else -1 for m in best], dtype=np.int64)
    return ms.gmr(obs, idx, np.asarray(state), yaw_rad=yaw0)[0]


def gmr_decomposition(ms, t_ns, truth, est, yaw) -> dict[str, float]:
    """Why the GMR acceleration is worse on EKF posteriors than on the truth (diagnosis, issue 14).

    On the same runs, the classifier and the GMR of the model set ``ms`` (its GMR input and
    alignment; no gate) are fed once with the truth and once with the baseline EKF's posteriors
    ``est`` (R, T, 9). The GMR acceleration is then recomputed with the observations of one and
    the per-step model and Viterbi state of the other, which splits its 3-D RMSE (m/s², against
    the true acceleration at the estimate's own step) into

    - ``gmr_tt`` (truth observations, truth states): the regression's own error;
    - ``gmr_et`` (EKF observations, the truth's states): + the EKF's increment noise through
      ``Σ_{va,r}Σ_r⁻¹`` (3.28), with the right model and state;
    - ``gmr_te`` (truth observations, the EKF's states): + the model/state the EKF's
      observations select;
    - ``gmr_ee`` (both from the EKF): what the EKF+HMM gets; ``ekf_acc``: the EKF's own.

    Also: ``best_agree_pct`` (same best model on both inputs), ``state_agree_pct`` (same Viterbi
    state where the best model agrees), ``dr_noise_{h,d}_m`` (RMS of the EKF's position-increment
    error, horizontal per axis and down, in the feature frame), ``gain_max_per_s2`` (largest
    ``‖∂â/∂Δr‖₂`` over the states of the models, physical units, 1/s²) and ``gmr_lag_steps`` (the lag
    L of :data:`GMR_LAGS` at which the truth-fed GMR at t_k best matches the truth at t_{k+L};
    0 = aligned with the step the EKF+HMM uses it at).
    """
    R, T = truth.shape[:2]
    fs = ms.config.feature_set
    cls = {}
    for nm, x in (("t", truth), ("e", est)):
        c = ms.classify(ekf_state_frame(x, t_ns, yaw_rad=yaw))
        cls[nm] = (c["best"].to_numpy(dtype=object).reshape(R, T - 1), c["state"].to_numpy().reshape(R, T - 1))
    obs, raw = {"t": [], "e": []}, {"t": [], "e": []}
    for r in range(R):
        for nm, x in (("t", truth[r]), ("e", est[r])):
            run = pd.DataFrame(x, columns=list(STATE_COLUMNS)).assign(yaw_rad=yaw[r])
            d = observations(raw_features(run, fs), True)
            raw[nm].append(d)
            obs[nm].append(ms.normaliser_.transform(d))
    a_true = truth[:, 1:, 6:]

    def r3(e):
        return float(np.sqrt(np.nanmean(np.sum(e ** 2, axis=-1))))

    out = {}
    for key, (o, c) in {"tt": ("t", "t"), "et": ("e", "t"), "te": ("t", "e"), "ee": ("e", "e")}.items():
        acc = np.stack([_gmr_acc(ms, obs[o][r], cls[c][0][r], cls[c][1][r], float(yaw[r, 0])) for r in range(R)])
        out[f"gmr_{key}"] = r3(acc - a_true)
        if key == "tt":
            lag_err = []
            for L in GMR_LAGS:
                k = np.arange(1, T) + L
                ok = (k >= 0) & (k < T)
                lag_err.append(r3(acc[:, ok] - truth[:, k[ok], 6:]))
            out["gmr_lag_steps"] = int(GMR_LAGS[int(np.argmin(lag_err))])
    out["ekf_acc"] = r3(est[:, 1:, 6:] - a_true)
    same = cls["t"][0] == cls["e"][0]
    out["best_agree_pct"] = 100.0 * float(same.mean())
    out["state_agree_pct"] = 100.0 * float((cls["t"][1][same] == cls["e"][1][same]).mean()) if same.any() else float("nan")
    dr = np.concatenate([e[:, :3] - t[:, :3] for e, t in zip(raw["e"], raw["t"])])
    out["dr_noise_h_m"] = float(np.sqrt(np.mean(dr[:, :2] ** 2)))
    out["dr_noise_d_m"] = float(np.sqrt(np.mean(dr[:, 2] ** 2)))
    span, dt = ms.normaliser_.span, 1.0 / ms.config.rate_hz
    g = []
    for m in ms.models_:
        for C in m.params_.covars[:, 0]:
            G = C[3:6, 0:3] @ np.linalg.inv(C[0:3, 0:3])
            g.append(np.linalg.norm(span[3:6, None] * G / span[None, 0:3], 2) / dt)
    out["gain_max_per_s2"] = float(max(g))
    return out


def hmm_maneuver(man, test_df, ekf, ms, Q2, radar, st, seed):
    """Step 4 for one maneuver: S1/S2 over the test runs, then ``noise_runs`` realisations each."""
    ids, t_ns, truth, yaw, lab = runs_array(test_df)
    z = radar_z(radar, truth, seed, f"select/{man}")
    tr_sel, _, e_sel = ekf_hmm_errors(ekf, ms, Q2, t_ns, truth, yaw, z, st["increments"])
    diag = {"maneuver": man, **gmr_decomposition(ms, t_ns, truth, tr_sel.ekf.mean, yaw)}
    i1, i2 = best_worst(e_sel)
    n = int(st["noise_runs"])
    t_s = (t_ns - t_ns[0]) * 1e-9
    scen, rm, times = [], [], []
    for sc, i in (("S1", i1), ("S2", i2)):
        tr_n = np.repeat(truth[i:i + 1], n, axis=0)
        yaw_n = np.repeat(yaw[i:i + 1], n, axis=0)
        zn = radar_z(radar, tr_n, seed, f"noise/{man}/{sc}")
        tr, e_ekf, e_hmm = ekf_hmm_errors(ekf, ms, Q2, t_ns, tr_n, yaw_n, zn, st["increments"])
        m = maot(np.asarray(tr.pred, dtype=object), np.repeat(lab[i:i + 1], n, axis=0))
        scen.append({"maneuver": man, "scenario": sc, "run_id": int(ids[i]),
                     "summed_abs_error": float(np.nansum(np.abs(e_sel[i]))),
                     "n_realisations": n, "MAoT_pct": m, "thesis_MAoT_pct": THESIS_CH4_MAOT[(man, sc)],
                     "hmm_mode_pct": 100.0 * float(np.mean(tr.mode)),
                     "hmm_output_pct": 100.0 * float(np.mean(tr.switched)),
                     "gated_pct": 100.0 * float(np.mean(tr.gated)),
                     **input_quality(tr, t_ns, tr_n, e_ekf, e_hmm)})
        for f, e, P in (("ekf", e_ekf, tr.ekf.cov), ("ekf_hmm", e_hmm, tr.output.cov)):
            rm.append({"maneuver": man, "scenario": sc, "filter": f,
                       **{group_col(g): v for g, v in group_rmse(e).items()}})
            T = e.shape[1]
            times.append(pd.DataFrame({
                "maneuver": man, "scenario": sc, "filter": f, "t_s": np.repeat(t_s, 9),
                "component": np.tile(np.array(STATE_COLUMNS, dtype=object), T),
                "mean_err": e.mean(axis=0).ravel(),
                "err_var": (e.var(axis=0, ddof=1) if n > 1 else np.zeros(e.shape[1:])).ravel(),
                "filter_var": np.diagonal(P, axis1=-2, axis2=-1).mean(axis=0).ravel(),
                "mode_pct": np.repeat(100.0 * np.mean(tr.mode, axis=0), 9)}))
    return scen, rm, pd.concat(times, ignore_index=True), diag


def change_table(hrm: pd.DataFrame) -> pd.DataFrame:
    """EKF+HMM RMSE change against the EKF (%), per maneuver, scenario and group."""
    rows = []
    for (man, sc), g in hrm.groupby(["maneuver", "scenario"], sort=False):
        e = g[g["filter"] == "ekf"].iloc[0]
        h = g[g["filter"] == "ekf_hmm"].iloc[0]
        rows.append({"maneuver": man, "scenario": sc,
                     **{grp: 100.0 * (h[group_col(grp)] / e[group_col(grp)] - 1.0) for grp in HMM_GROUPS}})
    return pd.DataFrame(rows)


def acceptance(ch: pd.DataFrame) -> dict[str, Any]:
    """The issue's RMSE targets (ours) on the change table."""
    s1 = ch[ch["scenario"] == "S1"].set_index("maneuver")
    m13 = [m for m in ("M1", "M2", "M3") if m in s1.index]
    lower = [m for m in m13 if all(s1.loc[m, g] < 0 for g in ("vel_n", "vel_e", "acc"))]
    acc20 = [m for m in m13 if s1.loc[m, "acc"] <= -20.0]
    m4 = bool("M4" in s1.index and all(abs(s1.loc["M4", g]) <= 10.0 for g in HMM_GROUPS))
    return {"m1_m3_lower_vn_ve_acc": lower, "acc_20pct": acc20, "m4_within_10pct": m4,
            "met": len(lower) == len(m13) == 3 and len(acc20) >= 2 and m4}


# -- report ------------------------------------------------------------------------------------------

def write_report(path, size, st, seed, q, qt, mcs, radar, cfg=None, q2_scale=None, q2t=None, scen=None,
                 hrm=None, ch=None, acc=None, best=None, gdec=None) -> None:
    """``report.md``: the q search, the Monte Carlo summary, the EKF+HMM tables and the checks."""
    L = [f"# Seed-000 estimation study (size {size}, seed {seed})", "",
         f"Radar: the seed-000 model (Table 2.1 σ = {radar.sigma}, τ_RD = {radar.tau_rd_s} s) at the fixed "
         f"site {tuple(radar.site_ned_m)} m NED (`simulate.sensors.radar.site_ned_m`), 5 Hz, synthesised from "
         f"the 5 Hz truth. CA EKF in NED, Joseph form, P₀ = diag(1², 0.1², 0.01²) per axis group. Written by "
         f"`pipeline/studies/seed000_ekf.py`.", "",
         "## q (white-jerk density), tuned on training runs and frozen", "",
         f"Grid-searched on {st['tune_runs']} training runs of each of {', '.join(KNOWN)} (truth initialisation), "
         f"score = mean over the 9 components of the pooled RMSE / its grid median. **q = {q:g} m²/s⁵.**", "",
         md_table(qt[["q", "score", *(f"rmse_{group_col(g)}" for g in MC_GROUPS)]], "{:.3f}"), "",
         "## EKF/RTS Monte Carlo (mc sets, Ch. 2 initialisation)", "",
         "RMSE per group over runs and time; NEES = run-averaged NEES, its time mean and the share of steps "
         "inside the 95 % band of χ²(9N)/N. The truth is the quadcopter simulator, not the filter's white-jerk "
         "model, so the NEES is a diagnostic (the thesis' Q is deliberately high: P above the MC error "
         "variance, NEES below 9); `var_ratio` = median over time and components of MC error variance / "
         "filter variance.", "",
         md_table(mcs[["maneuver", "n_runs", *(f"{f}_rmse_{group_col(g)}" for f in ("ekf", "rts") for g in MC_GROUPS),
                       "ekf_nees_mean", "ekf_nees_in_band_pct",
                       "rts_nees_mean", "ekf_var_ratio_median"]], "{:.3f}"), ""]
    if hrm is not None:
        L += ["## EKF+HMM (Ch. 4)", "",
              f"HMMs truth-trained as in `study_seed000_classification` (features `{cfg.feature_set}`, "
              f"{st['runs']} runs per maneuver, 70/30). Searched on training runs only, then frozen: the GMR "
              f"input, the gate, what the GMR sees when Q₂ is estimated (`truth`, or `ekf`: the baseline EKF's "
              f"posteriors of {st['q2_runs']} training runs per maneuver; the one-step errors are always against "
              f"the truth) and the Q₂ scale; score = mean over the 9 components of the EKF+HMM RMSE / the EKF RMSE "
              f"on {st['tune_runs']} training runs per maneuver (< 1: better). **Chosen: GMR input "
              f"`{best['gmr_input']}`, gate {best['gate_mps2']:g} m/s², Q₂ from `{best['q2_input']}` inputs × "
              f"{q2_scale:g}.** Best of each GMR input / Q₂ source:", "",
              md_table(q2t.loc[q2t.groupby(["gmr_input", "gate_mps2", "q2_input"])["score"].idxmin(),
                               ["gmr_input", "gate_mps2", "q2_input", "q2_scale", "score",
                                *[f"hmm_rmse_{group_col(g)}" for g in HMM_GROUPS], "ekf_rmse_acc_mps2"]], "{:.3f}"), "",
              f"S1 (best) / S2 (worst): the test run with the lowest / highest summed absolute EKF+HMM error, "
              f"each re-run {st['noise_runs']}× with new radar noise from its true state. MAoT beside the "
              f"thesis' Chapter-4 table (digest §11); `hmm_mode_pct` = steps predicted with HMM inputs, "
              f"`hmm_output_pct` = steps whose output is the EKF+HMM's (a known classification chose the "
              f"step's prediction; elsewhere the output is the EKF's, Ch. 4.1). The EKF+HMM RMSE below is "
              f"that output's.", "",
              md_table(scen[["maneuver", "scenario", "run_id", "n_realisations", "MAoT_pct", "thesis_MAoT_pct",
                             "hmm_mode_pct", "hmm_output_pct", "gated_pct"]], "{:.2f}"), "",
              "RMSE per group (pos and acc: 3-D):", "", md_table(hrm, "{:.3f}"), "",
              "EKF+HMM RMSE change against the EKF (%; negative = the EKF+HMM is better):", "",
              md_table(ch, "{:+.1f}"), "",
              "## Acceptance (targets ours)", "",
              "- M1–M3 S1, EKF+HMM lowers v_N, v_E and acceleration RMSE: "
              f"{', '.join(acc['m1_m3_lower_vn_ve_acc']) or 'none'} (target all three).",
              f"- acceleration RMSE ≥ 20 % lower: {', '.join(acc['acc_20pct']) or 'none'} (target two of three).",
              f"- M4 S1 within 10 % of the EKF on every group: {'yes' if acc['m4_within_10pct'] else 'no'}.",
              f"- all met: {'yes' if acc['met'] else 'no'}. v_D, position and S2 are reported above "
              "(the digest §12 has the EKF+HMM worse in v3 and position, and the EKF better early in M1 S2).", "",
              "Where it is decided: the EKF+HMM's predicted acceleration is the GMR input â + dt·ĵ computed from "
              "the baseline EKF's posteriors (A_H keeps none of the state's own acceleration), so it can beat the "
              "EKF only where that input is better than the EKF's acceleration. 3-D acceleration RMSE (m/s²) on "
              "the steps predicted with HMM inputs on every axis:", "",
              md_table(scen[["maneuver", "scenario", "gmr_input_acc_rmse_mps2", "ekf_acc_rmse_on_hmm_steps_mps2",
                             "ekf_hmm_acc_rmse_on_hmm_steps_mps2"]], "{:.3f}"), ""]
    if gdec is not None:
        L += ["Why the GMR input is worse on EKF posteriors (`gmr_decomposition`, the selection realisation of "
              "every test run, chosen GMR input, no gate): 3-D acceleration RMSE (m/s²) of the GMR with the "
              "observations (first letter) and the per-step model + Viterbi state (second letter) from the "
              "truth (t) or the baseline EKF (e); `ekf_acc` the EKF's own. `gmr_lag_steps` = 0: the truth-fed "
              "GMR at t_k matches the truth at t_k (no time offset).", "",
              md_table(gdec, "{:.3f}"), ""]
    write_text(path, "\n".join(L) + "\n")


def figures(qt, mc_time, hmm_time=None, hrm=None) -> list:
    """The page's plots: the q score, Monte Carlo error vs filter std and NEES, EKF vs EKF+HMM."""
    from plotly.colors import qualitative
    from plotly.subplots import make_subplots

    figs = []
    fig = go.Figure(go.Scatter(x=qt["q"], y=qt["score"], mode="lines+markers", name="score"))
    fig.update_layout(xaxis_type="log", xaxis_title="q [m²/s⁵]", yaxis_title="normalised RMSE [1]")
    fig.update_xaxes(tickvals=list(qt["q"]))
    figs.append(("q search", layout(fig, "q on the training runs: normalised RMSE")))
    units = {"pos": "position [m]", "vel": "velocity [m/s]", "acc": "acceleration [m/s²]"}
    colours = {"ekf": "#1f77b4", "rts": "#d62728"}
    for man, g in mc_time.groupby("maneuver", sort=False):
        # one panel per unit (a position, a velocity and an acceleration on one axis read as
        # one quantity), the filter by colour, error std solid and the filter's own std dotted
        fig = make_subplots(rows=1, cols=len(MC_GROUPS), subplot_titles=[units.get(k, k) for k in MC_GROUPS])
        for c, (grp, idx) in enumerate(MC_GROUPS.items(), start=1):
            cols = [STATE_COLUMNS[i] for i in idx]
            for f in ("ekf", "rts"):
                h = g[(g["filter"] == f) & g["component"].isin(cols)].groupby("t_s")
                for what, dash in (("err_var", None), ("filter_var", "dot")):
                    v = h[what].mean()
                    name = f"{f.upper()} {'error std' if what == 'err_var' else 'filter std'}"
                    fig.add_trace(go.Scatter(x=v.index, y=np.sqrt(v.to_numpy()), mode="lines", name=name,
                                             legendgroup=name, showlegend=c == 1,
                                             line=dict(color=colours[f], dash=dash)), row=1, col=c)
        # decade labels with 2 and 5 between: the default labelled every minor tick (2 3 4 ... 9)
        fig.update_yaxes(type="log", dtick="D2")
        fig.update_xaxes(title="t [s]")
        figs.append((f"MC {man}", layout(fig, f"Monte Carlo {man}: error std (solid) vs filter std (dotted), "
                                              "RMS over the group's axes")))
    fig = go.Figure()
    mans = list(dict.fromkeys(mc_time["maneuver"]))
    for (man, f), g in mc_time[mc_time["component"] == STATE_COLUMNS[0]].groupby(["maneuver", "filter"], sort=False):
        fig.add_trace(go.Scatter(x=g["t_s"], y=g["nees_avg"], mode="lines", name=f"{man} {f.upper()}",
                                 line=dict(color=qualitative.Plotly[mans.index(man) % 10],
                                           dash="dot" if f == "rts" else None)))
    fig.add_hline(y=9.0, line_dash="dash")
    fig.update_layout(xaxis_title="t [s]", yaxis_title="run-averaged NEES [1] (9 = consistent)", yaxis_type="log")
    fig.update_yaxes(dtick="D2")
    figs.append(("NEES", layout(fig, "Monte Carlo run-averaged NEES (EKF solid, RTS dotted)")))
    if hrm is not None:
        fig = go.Figure()
        for (sc, f), g in hrm.groupby(["scenario", "filter"], sort=False):
            fig.add_trace(go.Bar(x=g["maneuver"], y=g["acc_mps2"], name=f"{sc} {f}"))
        fig.update_layout(barmode="group", yaxis_title="acceleration RMSE [m/s²]")
        figs.append(("EKF vs EKF+HMM", layout(fig, "Acceleration RMSE, EKF vs EKF+HMM, S1/S2")))
        for man, g in hmm_time[hmm_time["scenario"] == "S1"].groupby("maneuver", sort=False):
            fig = go.Figure()
            for f, h in g[g["component"].str.startswith("acc")].groupby("filter", sort=False):
                # per axis, mean square error = error variance + mean error², averaged over n/e/d
                ms_ = h.assign(mse=h["err_var"] + h["mean_err"] ** 2).groupby("t_s")["mse"].mean()
                fig.add_trace(go.Scatter(x=ms_.index, y=np.sqrt(ms_.to_numpy()), mode="lines",
                                         name=f"{f} acc RMS error"))
            fig.update_layout(xaxis_title="t [s]", yaxis_title="RMS acceleration error per axis [m/s²]")
            figs.append((f"S1 {man}", layout(fig, f"{man} S1: acceleration error over time")))
    return figs


# -- entry point -----------------------------------------------------------------------------------------

def run_seed000_ekf(inputs: Mapping | None, outputs: Mapping, config: Mapping | None, *, seed: int,
                    simulate: Mapping | None = None, hmm: Mapping | None = None) -> StudyResult:
    """Run the seed-000 estimation study and write its tables, report, results and page.

    Parameters
    ----------
    inputs : mapping or None
        Optional ``sets`` (folder of a ``uavpipe simulate`` run, read instead of simulating)
        and ``template`` (default ``reports/templates/study.html.j2``).
    outputs : mapping
        :func:`outputs_for`'s keys: ``report``, ``results``, ``page`` and one per table of
        :data:`OUTPUT_TABLES`.
    config : mapping or None
        The ``studies`` config section (``size``, ``seed000_ekf``).
    seed : int
        The master seed (simulation, split, training, radar noise).
    simulate, hmm : mapping, optional
        The ``simulate`` and ``hmm`` config sections (default: ``datasets/config.yaml``'s).

    Returns
    -------
    StudyResult
    """
    size, st = study_settings(config, NAME, DEFAULTS, SIZES)
    skip = set(st["skip"] or ())
    if skip - {"hmm"}:
        raise ConfigError(f"studies.{NAME}.skip: unknown part(s) {sorted(skip - {'hmm'})}; known: hmm")
    for key, known in (("gmr_inputs", ("pos", "pos_fd", "pos_vel")), ("q2_inputs", ("truth", "ekf"))):
        if not st[key] or set(st[key]) - set(known):
            raise ConfigError(f"studies.{NAME}.{key}: {st[key]!r} must be a non-empty list of {', '.join(known)}")
    if st["increments"] not in INCREMENTS:
        raise ConfigError(f"studies.{NAME}.increments: {st['increments']!r} is not one of {', '.join(INCREMENTS)}")
    bad = sorted(set(st["mc_maneuvers"]) - set(ALL))
    if bad:
        raise ConfigError(f"studies.{NAME}.mc_maneuvers: unknown maneuver(s) {bad}; known: {', '.join(ALL)}")
    if simulate is None or hmm is None:
        cfg_file = load_config()
        simulate = section(cfg_file, "simulate") if simulate is None else simulate
        hmm = section(cfg_file, "hmm") if hmm is None else hmm
    seed = int(seed)
    sets = input_path(inputs, "sets")
    template = input_path(inputs, "template", ROOT / "reports" / "templates" / "study.html.j2")
    paths = {k: output_path(outputs, k) for k in ("report", "results", "page", *OUTPUT_TABLES)}
    progress = Progress()
    radar = RadarModel.from_config(dict((dict(simulate).get("sensors") or {}).get("radar") or {}))

    train, test, mc = load_data(st, seed, simulate, sets, progress)

    progress(f"q search over {st['q_grid']} on {st['tune_runs']} training runs per maneuver")
    q, qt = tune_q_on_training(train, radar, st, seed)
    write_table(qt, paths["q_tuning"], name="seed000_ekf_q_tuning", extra={"q": q, "seed": seed, "size": size})
    say(qt.to_string(index=False, float_format=lambda x: f"{x:.4f}"))
    ekf = ExtendedKalmanFilter(ConstantAcceleration(q), radar)  # q frozen from here on

    mts, mcs = [], []
    for man, df in mc.items():
        progress(f"EKF/RTS Monte Carlo {man} ({df['run_id'].nunique()} runs)")
        t_, s_ = mc_maneuver(man, df, ekf, radar, seed, int(st["chunk_runs"]))
        mts.append(t_)
        mcs.append(s_)
    mc_time, mc_sum = pd.concat(mts, ignore_index=True), pd.DataFrame(mcs)
    write_table(mc_time, paths["mc_time"], name="seed000_ekf_mc_time")
    write_table(mc_sum, paths["mc_rmse"], name="seed000_ekf_mc_rmse", extra={"q": q})
    say(mc_sum.to_string(index=False, float_format=lambda x: f"{x:.3f}"))

    cfg = q2_scale = q2t = scen = hrm = hmm_time = ch = acc = best = gdec = None
    if "hmm" not in skip:
        progress("training one HMM per known maneuver (truth)")
        cfg, ms = train_models(train, hmm, seed, features=st["features"])
        progress(f"EKF+HMM search on training runs: gmr_input {st['gmr_inputs']} × gate {st['gates']} × "
                 f"Q2 input {st['q2_inputs']} × scale {st['q2_scale_grid']}")
        best, q2t = tune_ekf_hmm(ekf, ms, train, radar, st, seed, progress)
        q2_scale = best["q2_scale"]
        write_table(q2t, paths["q2_tuning"], name="seed000_ekf_q2_tuning",
                    extra={k: (float(v) if isinstance(v, (float, np.floating)) else str(v))
                           for k, v in best.items() if k not in ("model_set", "Q2")})
        with pd.option_context("display.width", 250, "display.max_columns", 30):
            say(q2t.to_string(index=False, float_format=lambda x: f"{x:.4f}"))
        ms, Q2 = best["model_set"], best["Q2"]  # frozen from here on

        scen, rms, hts, dgs = [], [], [], []
        for man in KNOWN:
            progress(f"EKF+HMM {man}: S1/S2 over {test[man]['run_id'].nunique()} test runs, "
                     f"{st['noise_runs']} realisations each")
            s_, r_, h_, d_ = hmm_maneuver(man, test[man], ekf, ms, Q2, radar, st, seed)
            scen += s_
            rms += r_
            hts.append(h_)
            dgs.append(d_)
        scen, hrm, hmm_time = pd.DataFrame(scen), pd.DataFrame(rms), pd.concat(hts, ignore_index=True)
        gdec = pd.DataFrame(dgs)
        ch = change_table(hrm)
        acc = acceptance(ch)
        write_table(scen, paths["scenarios"], name="seed000_ekf_scenarios")
        write_table(hrm, paths["hmm_rmse"], name="seed000_ekf_hmm_rmse", extra={"q": q, "q2_scale": q2_scale})
        write_table(hmm_time, paths["hmm_time"], name="seed000_ekf_hmm_time")
        with pd.option_context("display.width", 200, "display.max_columns", 20):
            say(scen.to_string(index=False, float_format=lambda x: f"{x:.2f}"))
            say(hrm.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
            say(ch.to_string(index=False, float_format=lambda x: f"{x:+.1f}"))
            say(gdec.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    else:  # declared outputs are always written: empty, marked skipped
        for k in ("q2_tuning", "scenarios", "hmm_rmse", "hmm_time"):
            write_table(pd.DataFrame(), paths[k], name=f"seed000_ekf_{k}", extra={"skipped": True})

    write_report(paths["report"], size, st, seed, q, qt, mc_sum, radar, cfg=cfg, q2_scale=q2_scale, q2t=q2t,
                 scen=scen, hrm=hrm, ch=ch, acc=acc, best=best, gdec=gdec)

    res = Results()
    res.add("seed000_ekf_q_tuned", f"{q:g}",
            "The white-jerk density q (m²/s⁵) grid-searched on training runs by normalised RMSE, then frozen.")
    for r in mc_sum.itertuples():
        for f in ("ekf", "rts"):
            for grp, unit in ((g, GROUP_UNITS[g]) for g in MC_GROUPS):
                res.add(f"seed000_ekf_mc_{r.maneuver}_{f}_rmse_{grp}_{unit}", f"{getattr(r, f'{f}_rmse_{grp}_{unit}'):.4f}",
                        f"Monte Carlo {r.maneuver}: {f.upper()} 3-D {grp} RMSE over runs and time ({unit}).")
        res.add(f"seed000_ekf_mc_{r.maneuver}_ekf_nees_mean", f"{r.ekf_nees_mean:.2f}",
                f"Monte Carlo {r.maneuver}: time mean of the run-averaged EKF NEES (9 if consistent).")
        res.add(f"seed000_ekf_mc_{r.maneuver}_ekf_nees_in_band_pct", f"{r.ekf_nees_in_band_pct:.1f}",
                f"Monte Carlo {r.maneuver}: share of steps whose run-averaged EKF NEES lies in the 95 % χ² band (%).")
    if hrm is not None:
        hmm_results(res, best, scen, ch, acc)
        gmr_diagnosis_results(res, gdec)
    res.add("seed000_ekf_study_wall_s", f"{progress.elapsed:.0f}",
            "Wall time of the study (s), simulation to results, page excluded.")
    res.write(paths["results"])
    facts = [("size", size), ("seed", str(seed)), ("runs per maneuver", str(st["runs"])),
             ("Monte Carlo runs", str(st["mc_runs"])), ("noise realisations", str(st["noise_runs"])),
             ("q", f"{q:g}")]
    if hrm is not None:
        facts += [("features", cfg.feature_set), ("GMR input", str(best["gmr_input"])),
                  ("gate", f"{best['gate_mps2']:g} m/s²"), ("Q₂", f"{best['q2_input']} inputs × {q2_scale:g}"),
                  ("classifier input", f"{st['increments']} increments")]
    build_study_page(NAME, paths["page"], results=paths["results"], report_md=paths["report"], template=template,
                     definitions=res.definitions, figures=figures(qt, mc_time, hmm_time, hrm),
                     title=f"Study: seed-000 EKF, RTS and EKF+HMM ({size})",
                     facts=[*facts, ("tables", ", ".join(f"{t}.parquet" for t in OUTPUT_TABLES))])
    return StudyResult(name=NAME, status="ok", results=dict(res.values),
                       diagnostics={"size": size, "seed": seed, "settings": st, "q": q, "q2_scale": q2_scale,
                                    "wall_s": round(progress.elapsed, 1)})


def gmr_diagnosis_results(res: Results, gdec: pd.DataFrame) -> None:
    """Diagnosis RESULT lines: the GMR error decomposition of :func:`gmr_decomposition`."""
    what = {"gmr_tt": "truth observations and the truth's model/Viterbi states",
            "gmr_et": "EKF observations with the truth's model/Viterbi states (input noise through the regression)",
            "gmr_te": "truth observations with the EKF's model/Viterbi states (model/state choice)",
            "gmr_ee": "EKF observations and states (what the EKF+HMM gets)",
            "ekf_acc": "the baseline EKF's own acceleration"}
    for r in gdec.itertuples():
        m = r.maneuver
        for k, txt in what.items():
            name = f"seed000_ekf_diag_{m}_{k}_acc_rmse_mps2" if k != "ekf_acc" else f"seed000_ekf_diag_{m}_ekf_acc_rmse_mps2"
            res.add(name, f"{getattr(r, k):.3f}",
                    f"{m} test runs (diagnosis): 3-D acceleration RMSE of the GMR from {txt} (m/s², ungated)."
                    if k != "ekf_acc" else f"{m} test runs (diagnosis): 3-D RMSE of {txt} (m/s²).")
        res.add(f"seed000_ekf_diag_{m}_best_agree_pct", f"{r.best_agree_pct:.1f}",
                f"{m} test runs (diagnosis): steps whose best model is the same on EKF and on truth input (%).")
        res.add(f"seed000_ekf_diag_{m}_state_agree_pct", f"{r.state_agree_pct:.1f}",
                f"{m} test runs (diagnosis): steps with the same Viterbi state on EKF and truth input, where the "
                f"best model agrees (%).")
        res.add(f"seed000_ekf_diag_{m}_dr_noise_down_m", f"{r.dr_noise_d_m:.3f}",
                f"{m} test runs (diagnosis): RMS error of the EKF's down position increment (m; horizontal "
                f"{r.dr_noise_h_m:.3f} m per axis).")
        res.add(f"seed000_ekf_diag_{m}_gmr_lag_steps", int(r.gmr_lag_steps),
                f"{m} test runs (diagnosis): lag (steps) at which the truth-fed GMR best matches the truth "
                f"(0 = no time offset).")
    res.add("seed000_ekf_diag_gmr_gain_max_per_s2", f"{gdec['gain_max_per_s2'].max():.2f}",
            "Diagnosis: largest ‖∂â/∂Δr‖₂ (1/s²) of the GMR (3.28) over the states of the models.")


def hmm_results(res: Results, best, scen, ch, acc) -> None:
    """The EKF+HMM's RESULT lines: the frozen settings, MAoT, RMSE change per group, the acceptance counts."""
    res.add("seed000_ekf_hmm_q2_scale", f"{best['q2_scale']:g}",
            "The Q₂ scale grid-searched on training runs (EKF+HMM RMSE / EKF RMSE), then frozen.")
    res.add(f"seed000_ekf_hmm_q2_input_{best['q2_input']}", 1,
            "What the GMR saw when Q₂ was estimated (named in the metric, truth or ekf; value always 1).")
    res.add(f"seed000_ekf_hmm_gmr_input_{best['gmr_input']}", 1,
            "The GMR conditioning block chosen on training runs (named in the metric; value always 1).")
    res.add("seed000_ekf_hmm_gate_mps2", f"{best['gate_mps2']:g}",
            "The GMR outlier gate chosen on training runs (m/s² per step; thesis 15).")
    res.add("seed000_ekf_hmm_training_score", f"{best['score']:.3f}",
            "Training-run score of the chosen settings: mean over components of EKF+HMM RMSE / EKF RMSE.")
    for r in scen.itertuples():
        res.add(f"seed000_ekf_hmm_{r.maneuver}_{r.scenario}_MAoT_pct", f"{r.MAoT_pct:.2f}",
                f"{r.maneuver} {r.scenario}: classifier MAoT over the noise realisations (%; thesis "
                f"{r.thesis_MAoT_pct:.2f}).")
    for r in ch.itertuples():
        for grp in HMM_GROUPS:
            res.add(f"seed000_ekf_hmm_{r.maneuver}_{r.scenario}_{grp}_rmse_change_pct", f"{getattr(r, grp):+.1f}",
                    f"{r.maneuver} {r.scenario}: EKF+HMM {grp} RMSE against the EKF's (%, negative = better).")
    res.add("seed000_ekf_hmm_m1_m3_s1_lower_vn_ve_acc", len(acc["m1_m3_lower_vn_ve_acc"]),
            "Maneuvers of M1–M3 (S1) where the EKF+HMM lowers v_N, v_E and acceleration RMSE (target 3).")
    res.add("seed000_ekf_hmm_m1_m3_s1_acc_20pct", len(acc["acc_20pct"]),
            "Maneuvers of M1–M3 (S1) where the EKF+HMM lowers acceleration RMSE by ≥ 20 % (target ≥ 2).")
    res.add("seed000_ekf_hmm_m4_s1_within_10pct", int(acc["m4_within_10pct"]),
            "1 when M4 S1's EKF+HMM RMSE is within 10 % of the EKF's on every group.")
