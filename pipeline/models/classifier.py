"""The set of per-maneuver HMMs: training from ``state`` tables, one-class thresholds,
classification of flights, and npz/JSON persistence (seed 000 §3.3–§3.6).

Data model: a bulk table has the ``schema.STATE`` columns plus ``run_id`` and ``label`` (one
maneuver per training run). Runs faster than ``rate_hz`` are decimated; with ``phases`` every
phase offset becomes its own training sequence (the five 5 Hz phases of a 25 Hz recording).

**Normalisation.** One min-max normaliser is fitted on the observations of *all* maneuvers
and shared by every model, so the log-likelihoods ``LL_m`` of different models are densities
of the same variable and can be compared (per-model scaling would add a different Jacobian
to each). It is frozen with the models (§13.6).

**One-class threshold** (Yeung; value not given by the thesis, §13.7): for model ``m`` the
``p``-th percentile (default 0.5) of the scores of its training sequences at the same elapsed
sample. When a maneuver has a single training recording, its phase decimations are scored
leave-one-phase-out: a model trained on the other phases scores the held-out one. An optional
per-sample slack (``threshold_slack``; ``auto`` estimates it leave-one-recording-out on the
labels that have several recordings) lowers the curve by ``slack · n`` after ``n`` samples.

**Impostor-scaled threshold** (``threshold_fraction`` f, default 1). A constant slack treats
every model alike, but the models' scales differ: on the F3A training flight the mean
per-sample log-likelihood that model ``m`` gives the *other* maneuvers of the training data
(its impostors), :math:`\\bar\\ell_m`, ranges from −12 to +7 nats/sample while the genuine
percentile curves all sit near 12–14 nats/sample, so 1.85 nats/sample is 37 % of ``hB``'s
genuine–impostor gap and 7 % of ``sqL``'s. The threshold is therefore placed a fraction ``f``
of the way from the impostors' expected score to the genuine percentile curve ``q_m(n)``:

.. math:: \\theta_m(n) = f\\,q_m(n) + (1 - f)\\,n\\,\\bar\\ell_m - s\\,n,
          \\qquad \\bar\\ell_m = \\operatorname{mean}_{x \\notin m} LL_m(x_{1:T_x}) / T_x

(the mean over every training sequence of the other labels, cumulative from its first
sample; ``n`` is capped at the window in ``windowed`` mode). ``f = 1`` is the percentile rule
above; ``f = 0`` accepts whatever scores like an average impostor. Only training data enter
``q_m`` and :math:`\\bar\\ell_m`; ``f`` (like ``s``) is a calibration constant.

**Persistence**: ``DIR/params.npz`` (arrays, no pickles; ``np.load(allow_pickle=False)``) and
``DIR/meta.json`` (labels, config, normaliser, training metadata, code version).
"""

from __future__ import annotations

import dataclasses
import json
import os
import zipfile
import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from .. import __version__
from ..io.atomic import atomic_output
from ..io.parquet import write_json
from ..io.stage import one_line
from .base import ModelError, ModelsConfig
from .features import (GMR_FEATURE_SETS, MinMaxNormaliser, decimation_factor, get_feature_set,
                       heading_rotation, observations, raw_features, run_sequences)
from .gmr import fd_velocity_increments, gate, gmr_state9
from .hmm import HMMParams, ManeuverHMM
from .metrics import UNKNOWN
from .online import OnlineClassifier, classify_batch

F64 = NDArray[np.float64]
FORMAT_VERSION = 1


def _pad(seqs: list[F64]) -> F64:
    T = max(len(s) for s in seqs)
    out = np.full((len(seqs), T, seqs[0].shape[1]), np.nan)
    for i, s in enumerate(seqs):
        out[i, :len(s)] = s
    return out


def unusable_features(run: pd.DataFrame, needs: Sequence[str]) -> str | None:
    """Why a training run's feature columns ``needs`` cannot be used, or ``None``: a column
    missing, not numeric, or holding NaN/inf (hmmlearn would stop the whole model set on them
    with "Input X contains NaN", naming no file, column or run)."""
    for c in needs:
        if c not in run.columns:
            return f"no column {c}"
        try:
            x = run[c].to_numpy(dtype=np.float64, na_value=np.nan)
        except (TypeError, ValueError):
            return f"column {c} is not numeric"
        n = int((~np.isfinite(x)).sum())
        if n:
            return f"column {c}: {n} of {len(x)} value(s) NaN or infinite"
    return None


class ManeuverModelSet:
    """One HMM per maneuver plus the shared normaliser and the one-class thresholds.

    Parameters
    ----------
    config : ModelsConfig

    Attributes
    ----------
    labels_ : list of str
    models_ : list of ManeuverHMM
    normaliser_ : MinMaxNormaliser
    thresholds_ : dict
        ``{"cumulative": (M, T), "windowed": (M, W')}`` score thresholds by elapsed sample
        (:math:`\\theta_m(n)`, module docstring).
    threshold_base_ : dict
        The same shapes: the training percentile curves :math:`q_m(n)` (no slack, f = 1).
    impostor_ll_ : ndarray, shape (M,)
        :math:`\\bar\\ell_m`, nats/sample (NaN in model files written before it existed).
    training_ : dict
        Per-label training metadata (runs, sequences, samples, iterations, convergence, BIC).
    """

    def __init__(self, *, config: ModelsConfig | None = None):
        self.config = config or ModelsConfig()
        self.background_: HMMParams | None = None

    # -- features ------------------------------------------------------------------------
    @property
    def feature_set(self):
        """The :class:`~pipeline.models.features.FeatureSet` named by ``config.feature_set``."""
        return get_feature_set(self.config.feature_set)

    def phase_sequences(self, run: pd.DataFrame, *, box_heading_rad: float = 0.0,
                        all_phases: bool | None = None) -> list[F64]:
        """Raw observations (differenced if the set says so, not normalised) of one run at
        ``rate_hz``: one sequence per decimation phase (or phase 0 only)."""
        k = decimation_factor(run["t_ns"].to_numpy(), self.config.rate_hz)
        phases = range(k) if (self.config.phases if all_phases is None else all_phases) else [0]
        raw = raw_features(run, self.config.feature_set, box_heading_rad=box_heading_rad)
        out = []
        for ph in phases:
            o = observations(raw[ph::k], self.feature_set.differenced)
            if len(o) >= 2:
                out.append(o)
        return out

    # -- training --------------------------------------------------------------------------
    def fit(self, data: pd.DataFrame, *, label_col: str = "label", run_col: str = "run_id",
            box_heading_rad: float = 0.0) -> "ManeuverModelSet":
        """Train from a bulk state table (one maneuver label per run)."""
        if label_col not in data.columns:
            raise ModelError(f"training table has no {label_col!r} column")
        recs: dict[str, list[list[F64]]] = {}
        self.dropped_runs_ = {}
        needs = self.feature_set.needs
        for rid, run in run_sequences(data, run_col=run_col):
            labs = run[label_col].dropna().unique()
            if len(labs) != 1:
                raise ModelError(f"training run {rid!r} has {len(labs)} labels; need exactly one")
            bad = unusable_features(run, needs)
            if bad:    # one bad run is left out with its reason; it must not stop the others
                self.dropped_runs_[str(rid)] = bad
                continue
            seqs = self.phase_sequences(run, box_heading_rad=box_heading_rad)
            if seqs:
                recs.setdefault(str(labs[0]), []).append(seqs)
        if not recs and self.dropped_runs_:
            first = next(iter(self.dropped_runs_.items()))
            raise ModelError(f"no usable training run: all {len(self.dropped_runs_)} dropped "
                             f"(first: run {first[0]}: {first[1]})")
        return self.fit_recordings(recs)

    def fit_recordings(self, recordings: dict[str, list[list[F64]]]) -> "ManeuverModelSet":
        """Train from raw observations: ``{label: [recording: [phase sequence (n, d)]]}``."""
        cfg = self.config
        if not recordings:
            raise ModelError("no training data")
        if cfg.window_s == "auto":
            # half the median training maneuver: long enough to recognise a maneuver from part
            # of it, short enough to follow the next one (resolved once, stored in meta.json)
            lens = [max(len(s) for s in rec) for lab in recordings for rec in recordings[lab] if rec]
            w = max(2.0, 0.5 * float(np.median(lens))) / cfg.rate_hz
            cfg = self.config = dataclasses.replace(cfg, window_s=round(w, 3))
        self.labels_ = sorted(recordings)
        allobs = np.concatenate([s for lab in self.labels_ for rec in recordings[lab] for s in rec])
        self.normaliser_ = MinMaxNormaliser.fit(allobs)
        self.background_ = self._fit_background(self.normaliser_.transform(allobs))
        self.models_, self.training_ = [], {}
        curves: dict[str, list[F64]] = {"cumulative": [], "windowed": []}
        for li, lab in enumerate(self.labels_):
            recs = [[self.normaliser_.transform(s) for s in rec] for rec in recordings[lab]]
            seqs = [s for rec in recs for s in rec]
            model = self._new_hmm(lab, li).fit(np.concatenate(seqs), [len(s) for s in seqs])
            self.models_.append(model)
            meta = model.training_meta()
            if len(recs) == 1 and len(recs[0]) > 1:
                held = []
                for k in range(len(recs[0])):
                    rest = [s for j, s in enumerate(recs[0]) if j != k]
                    m_k = self._new_hmm(lab, li, n_states=model.n_states_).fit(
                        np.concatenate(rest), [len(s) for s in rest])
                    held.append((m_k.params_, [recs[0][k]]))
                meta["threshold"] = "leave-one-phase-out"
            else:
                held = [(model.params_, seqs)]
                meta["threshold"] = "training sequences"
            for mode in curves:
                curves[mode].append(self._threshold_curve(held, mode))
            meta.update({"n_recordings": len(recs), "n_sequences": len(seqs),
                         "n_samples": int(sum(len(s) for s in seqs))})
            self.training_[lab] = meta
        self.threshold_slack_ = self._slack(recordings) if cfg.threshold_slack == "auto" \
            else float(cfg.threshold_slack)
        self.impostor_ll_ = self._impostor_ll(recordings)
        self.threshold_base_ = {}
        for mode, cs in curves.items():
            T = max(len(c) for c in cs)
            arr = np.empty((len(cs), T))
            for i, c in enumerate(cs):
                arr[i, :len(c)] = c
                arr[i, len(c):] = c[-1] if mode == "windowed" else np.nan
            if mode == "cumulative":
                # extend short curves linearly so every model has a value at every t
                for i, c in enumerate(cs):
                    if len(c) < T:
                        from .online import extend_threshold
                        arr[i, len(c):] = extend_threshold(c, np.arange(len(c) + 1, T + 1), False)
            self.threshold_base_[mode] = arr
        self.threshold_fraction_ = float(cfg.threshold_fraction)
        self.thresholds_ = self._compose_thresholds(self.threshold_slack_, self.threshold_fraction_)
        return self

    def _compose_thresholds(self, slack: float, fraction: float) -> dict[str, F64]:
        """:math:`\\theta_m(n) = f q_m(n) + (1 - f) n \\bar\\ell_m - s n` for every mode."""
        if fraction != 1.0 and not np.all(np.isfinite(self.impostor_ll_)):
            raise ModelError(f"threshold_fraction {fraction:g} needs the impostor log-likelihoods, which "
                             "this model set lacks (retrain it)")
        out = {}
        for mode, base in self.threshold_base_.items():
            n = np.arange(1, base.shape[1] + 1)
            if mode == "windowed":
                n = np.minimum(n, self.config.window)
            thr = base - slack * n
            if fraction != 1.0:   # f = 1 leaves the percentile curve bit for bit
                thr = thr + (fraction - 1.0) * base + (1.0 - fraction) * self.impostor_ll_[:, None] * n
            out[mode] = thr
        return out

    def with_threshold(self, *, slack: float | None = None, fraction: float | None = None) -> "ManeuverModelSet":
        """A shallow copy whose one-class thresholds use another per-sample ``slack`` and/or
        impostor ``fraction`` (module docstring); the models are shared."""
        import copy

        slack = self.threshold_slack_ if slack is None else float(slack)
        fraction = self.threshold_fraction_ if fraction is None else float(fraction)
        out = copy.copy(self)
        out.thresholds_ = self._compose_thresholds(slack, fraction)
        out.threshold_slack_, out.threshold_fraction_ = slack, fraction
        return out

    def with_slack(self, slack: float) -> "ManeuverModelSet":
        """A shallow copy whose one-class thresholds use another per-sample ``slack``."""
        return self.with_threshold(slack=slack)

    def _impostor_ll(self, recordings: dict[str, list[list[F64]]]) -> F64:
        """:math:`\\bar\\ell_m`: mean per-sample cumulative log-likelihood of model ``m`` over every
        training sequence (all phases) of the other labels; NaN with a single label."""
        seqs, labs = [], []
        for li, lab in enumerate(self.labels_):
            for rec in recordings[lab]:
                for x in rec:
                    seqs.append(self.normaliser_.transform(x))
                    labs.append(li)
        clf = OnlineClassifier([m.params_ for m in self.models_], mode="cumulative", viterbi=False)
        sc = classify_batch(clf, _pad(seqs))["scores"]                       # (R, T, M)
        lens = np.array([len(x) for x in seqs])
        per = sc[np.arange(len(seqs)), lens - 1, :] / lens[:, None]           # (R, M) nats/sample
        labs = np.asarray(labs)
        out = np.full(len(self.labels_), np.nan)
        for m in range(len(self.labels_)):
            other = labs != m
            if other.any():
                out[m] = float(np.mean(per[other, m]))
        return out

    def _slack(self, recordings: dict[str, list[list[F64]]]) -> float:
        """Per-sample allowance for flight-to-flight variation, from the training data alone.

        Phases of one recording (and in-sample sequences) are nearly the same data, so their
        log-likelihood percentile is an optimistic threshold for a *new* flight. For every
        label with ≥ 2 recordings, a model trained on the others scores the left-out
        recording; the slack is the median over these of
        ``(threshold(T) − LL_held(T)) / T`` (nats per sample, ≥ 0), 0 when no label has two
        recordings.
        """
        gaps = []
        for li, lab in enumerate(self.labels_):
            recs = [[self.normaliser_.transform(x) for x in rec] for rec in recordings[lab]]
            if len(recs) < 2:
                continue
            for a in range(len(recs)):
                rest = [x for j, rec in enumerate(recs) if j != a for x in rec]
                m = self._new_hmm(lab, li, n_states=self.models_[li].n_states_).fit(
                    np.concatenate(rest), [len(x) for x in rest])
                curve = self._threshold_curve([(m.params_, rest)], "cumulative")
                clf = OnlineClassifier([m.params_], mode="cumulative", viterbi=False)
                sc = classify_batch(clf, _pad(recs[a]))["scores"][:, :, 0]
                for r, x in enumerate(recs[a]):
                    T = min(len(x), len(curve))
                    gaps.append((curve[T - 1] - sc[r, T - 1]) / T)
        return max(0.0, float(np.median(gaps))) if gaps else 0.0

    def _fit_background(self, X: F64) -> HMMParams | None:
        """The background model: a ``background``-component full-covariance GMM on the pooled
        normalised observations, as a one-state HMM (i.i.d. samples). At most 50,000 rows,
        drawn from ``default_rng([seed, crc32("background")])`` (the master seed)."""
        from sklearn.mixture import GaussianMixture

        cfg = self.config
        if cfg.background == 0:
            return None
        rng = np.random.default_rng([cfg.seed, zlib.crc32(b"background")])
        if len(X) > 50_000:
            X = X[np.sort(rng.choice(len(X), 50_000, replace=False))]
        g = GaussianMixture(cfg.background, covariance_type="full", reg_covar=cfg.min_covar,
                            random_state=int(rng.integers(2 ** 31)), n_init=1).fit(X)
        return HMMParams(np.ones(1), np.ones((1, 1)), g.weights_[None].copy(), g.means_[None].copy(),
                         g.covariances_[None].copy())

    def _new_hmm(self, label: str, index: int, n_states=None) -> ManeuverHMM:
        cfg = self.config
        return ManeuverHMM(n_states=n_states or cfg.states_for(label), n_states_range=cfg.n_states_range,
                           n_mix=cfg.n_mix, n_iter=cfg.n_iter, tol=cfg.tol, min_covar=cfg.min_covar,
                           self_prob=cfg.self_prob, gmm_restarts=cfg.gmm_restarts,
                           init_min_samples=cfg.init_min_samples,
                           hmm_restarts=cfg.hmm_restarts, seed=cfg.seed + 7919 * index)

    def _threshold_curve(self, held: list[tuple[HMMParams, list[F64]]], mode: str) -> F64:
        """Percentile of the scores at each elapsed sample (windowed: pooled after W)."""
        cfg = self.config
        rows = []
        for params, seqs in held:
            clf = OnlineClassifier([params], mode=mode, window=cfg.window,
                                   restart_prob=cfg.restart_prob, viterbi=False)
            res = classify_batch(clf, _pad(seqs))
            rows.extend(res["scores"][:, :, 0])
        T = max(len(r) for r in rows)
        S = np.full((len(rows), T), np.nan)
        for i, r in enumerate(rows):
            S[i, :len(r)] = r
        p = cfg.threshold_percentile
        curve = np.array([np.percentile(S[np.isfinite(S[:, t]), t], p) for t in range(T)])
        if mode == "windowed" and T > cfg.window:
            tail = S[:, cfg.window - 1:]
            curve[cfg.window - 1:] = np.percentile(tail[np.isfinite(tail)], p)
        return curve

    # -- classification ----------------------------------------------------------------------
    def classifier(self, *, mode: str | None = None, decision: str | None = None) -> OnlineClassifier:
        """An :class:`~pipeline.models.online.OnlineClassifier` over the trained models (seed 000
        §5): the one-class thresholds of ``mode`` (``windowed``, else ``cumulative``) and the
        config's window, restart probability, ``confirm_s`` (in samples) and confidence threshold.

        Parameters
        ----------
        mode, decision : str, optional
            Override the config. ``confidence_bg`` appends the background model as a last rival
            that never gates or labels (runs as ``confidence``); it raises :class:`ModelError`
            when the set has no background model.
        """
        cfg = self.config
        mode = mode or cfg.mode
        decision = decision or cfg.decision
        thr = self.thresholds_["windowed" if mode == "windowed" else "cumulative"]
        params = [m.params_ for m in self.models_]
        bg = decision == "confidence_bg"
        if bg:
            if self.background_ is None:
                raise ModelError("decision 'confidence_bg' needs a background model "
                                 "(train with models.background >= 1)")
            params.append(self.background_)
            thr = np.vstack([thr, np.full((1, thr.shape[1]), -1e300)])     # never gates (finite: extrapolated)
            decision = "confidence"
        return OnlineClassifier(params, mode=mode, window=cfg.window,
                                restart_prob=cfg.restart_prob,
                                confirm=max(1, int(round(cfg.confirm_s * cfg.rate_hz))),
                                confidence_threshold=cfg.confidence_threshold,
                                decision=decision, thresholds=thr,
                                thresholds_stationary=(mode == "windowed"), background=bg)

    def gmr(self, X: np.ndarray, best: np.ndarray, state: np.ndarray, *, yaw_rad: float = 0.0,
            box_heading_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """HMM acceleration and jerk (NED; m/s², m/s³; ungated) of one run, as :meth:`classify`
        forms them (seed 000 §3.6, (3.28) with the §13.3 de-normalisation).

        Parameters
        ----------
        X : ndarray (n, 9)
            The run's normalised observations.
        best : ndarray (n,) of int
            Index into :attr:`models_` of the model whose Gaussian is used at each step.
        state : ndarray (n,) of int
            That model's current (online Viterbi) state at each step.
        yaw_rad, box_heading_rad : float
            The run's initial heading (``state9h``) and the box heading (``state9box``): the
            regression runs in the feature frame, and its outputs are rotated back to NED.

        Returns
        -------
        acc, jerk : ndarray (n, 3)
            NaN where ``best`` names no model.
        """
        n, dt = len(X), 1.0 / self.config.rate_hz
        acc = np.full((n, 3), np.nan)
        jerk = np.full((n, 3), np.nan)
        if self.config.gmr_input == "pos_fd":
            X = fd_velocity_increments(X, self.normaliser_, dt)
        for m, model in enumerate(self.models_):
            rows = best == m
            if rows.any():
                p = model.params_
                acc[rows], jerk[rows] = gmr_state9(p.means[:, 0], p.covars[:, 0], X[rows], state[rows],
                                                   self.normaliser_, dt, inputs=self.config.gmr_input,
                                                   align=self.config.gmr_align)
        # the regression ran in the feature frame: rotate its outputs back to NED
        back = None
        if self.config.feature_set == "state9h":
            back = heading_rotation(yaw_rad).T          # initial-heading frame -> NED
        elif self.config.feature_set == "state9box":
            back = heading_rotation(box_heading_rad).T  # box frame -> NED
        if back is not None:
            acc, jerk = acc @ back.T, jerk @ back.T
        return acc, jerk

    def classify(self, state: pd.DataFrame, *, mode: str | None = None, decision: str | None = None,
                 run_col: str = "run_id", reset_t_ns=None, box_heading_rad: float = 0.0,
                 gmr: bool = True) -> pd.DataFrame:
        """Classify every run of a state table online, sample by sample.

        Parameters
        ----------
        state : DataFrame
            ``schema.STATE`` columns (+ ``run_id``, ``label`` optional).
        mode, decision : str, optional
            Override the config.
        reset_t_ns : sequence of int, optional
            Restart the forward passes at the first sample at or after each of these times
            (e.g. labelled segment starts); the classifier is otherwise never told of switches.
        box_heading_rad : float
            Box heading (rad from north) of the ``box``/``state9box`` features; ``state9box``
            GMR outputs are rotated back to NED by it.
        gmr : bool
            Add HMM acceleration/jerk estimates (``state9``, ``state9h``, ``state9box``), in NED.

        Returns
        -------
        DataFrame, one row per model-rate sample that has an observation: ``run_id``, ``t_ns``,
        ``truth`` (if ``label`` given), ``pred`` (label or ``unknown``; ``unknown`` with NaN
        scores where a feature is NaN, e.g. in a gap of the flight), ``best``, ``V_best``,
        ``oneclass_ok``, ``ll_<label>`` per model, ``state`` (online Viterbi state of ``best``),
        ``change``, ``change_t_ns`` and, with GMR, ``acc_hmm_{n,e,d}_mps2``,
        ``jerk_hmm_{n,e,d}_mps3``, ``acc_hmm_gated_{n,e,d}``.
        """
        runs = run_sequences(state, run_col=run_col)
        fs = self.feature_set
        seqs, tks, truths, rids, yaws = [], [], [], [], []
        for rid, run in runs:
            k = decimation_factor(run["t_ns"].to_numpy(), self.config.rate_hz)
            dec = run.iloc[::k].reset_index(drop=True)
            raw = raw_features(dec, self.config.feature_set, box_heading_rad=box_heading_rad)
            obs = self.normaliser_.transform(observations(raw, fs.differenced))
            off = 1 if fs.differenced else 0
            seqs.append(obs)
            tks.append(dec["t_ns"].to_numpy()[off:])
            truths.append(dec["label"].to_numpy(dtype=object)[off:] if "label" in dec else None)
            rids.append(rid)
            yaws.append(float(dec["yaw_rad"].iloc[0]) if "yaw_rad" in dec and len(dec) else 0.0)
        if not seqs or max(len(s) for s in seqs) == 0:
            raise ModelError("no observations to classify (runs shorter than two samples?)")
        seqs = [s if len(s) else np.full((1, len(self.normaliser_.x_min)), np.nan) for s in seqs]
        X = _pad(seqs)
        resets = None
        if reset_t_ns is not None and len(reset_t_ns):
            resets = np.zeros(X.shape[:2], dtype=bool)
            for r, t in enumerate(tks):
                for tr in reset_t_ns:
                    i = np.searchsorted(t, tr)
                    if 0 < i < len(t):
                        resets[r, i] = True
        clf = self.classifier(mode=mode, decision=decision)
        res = classify_batch(clf, X, resets)
        # index M is the background hypothesis when it takes part; -1 is unknown
        labels = np.array([*self.labels_, "background", UNKNOWN], dtype=object)
        frames = []
        for r, rid in enumerate(rids):
            n = len(tks[r])
            lab = res["label"][r, :n]
            best = res["best"][r, :n]
            d = {run_col: np.full(n, rid, dtype=object), "t_ns": tks[r]}
            if truths[r] is not None:
                d["truth"] = np.asarray(truths[r]).astype(str)
            # -2: no observation at this sample (a NaN feature, a gap in the flight): no decision
            # is made, so it is unknown; indexed plainly, -2 read as "background"
            d["pred"] = np.where(lab == -2, UNKNOWN, labels[lab]).astype(str)
            d["best"] = np.where(best == -2, UNKNOWN, labels[best]).astype(str)
            d["V_best"] = np.take_along_axis(res["V"][r, :n], best[:, None], axis=1)[:, 0]
            d["oneclass_ok"] = res["oneclass_ok"][r, :n]
            for m, name in enumerate(self.labels_):
                d[f"ll_{name}"] = res["scores"][r, :n, m]
            if clf.background:
                d["ll_background"] = res["scores"][r, :n, len(self.labels_)]
            d["state"] = res["state"][r, :n]
            d["change"] = res["change"][r, :n]
            ca = res["change_at"][r, :n]
            d["change_t_ns"] = np.where(ca >= 0, tks[r][np.clip(ca, 0, n - 1)], -1)
            if gmr and self.config.feature_set in GMR_FEATURE_SETS:
                acc, jerk = self.gmr(X[r, :n], best, d["state"], yaw_rad=yaws[r], box_heading_rad=box_heading_rad)
                gated, dropped = gate(acc, self.config.gate_mps2)
                for i, ax in enumerate("ned"):
                    d[f"acc_hmm_{ax}_mps2"] = acc[:, i]
                    d[f"jerk_hmm_{ax}_mps3"] = jerk[:, i]
                    d[f"acc_hmm_gated_{ax}"] = dropped[:, i]
            frames.append(pd.DataFrame(d))
        return pd.concat(frames, ignore_index=True)

    # -- persistence ----------------------------------------------------------------------------
    def save(self, out_dir: str | os.PathLike) -> list[Path]:
        """Write ``params.npz`` + ``meta.json`` (atomic; no pickles)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        arrays = {}
        for i, m in enumerate(self.models_):
            arrays.update(m.to_arrays(prefix=f"m{i}_"))
        arrays["norm_min"], arrays["norm_max"] = self.normaliser_.x_min, self.normaliser_.x_max
        for mode, thr in self.thresholds_.items():
            arrays[f"threshold_{mode}"] = thr
        for mode, base in self.threshold_base_.items():
            arrays[f"percentile_{mode}"] = base
        arrays["impostor_ll"] = self.impostor_ll_
        if self.background_ is not None:
            arrays.update(self.background_.to_arrays(prefix="bg_"))
        with atomic_output(out / "params.npz", suffix=".npz") as tmp:
            np.savez(tmp, **arrays)
        meta = {"format_version": FORMAT_VERSION, "code_version": __version__,
                "labels": self.labels_, "threshold_slack": self.threshold_slack_,
                "threshold_fraction": self.threshold_fraction_, "config": self.config.to_dict(),
                "feature_names": list(self.feature_set.names),
                "normaliser": self.normaliser_.to_dict(), "training": self.training_}
        write_json(meta, out / "meta.json")
        return [out / "params.npz", out / "meta.json"]

    @classmethod
    def load(cls, in_dir: str | os.PathLike) -> "ManeuverModelSet":
        """Read a model set written by :meth:`save` (``params.npz`` + ``meta.json``).

        Raises
        ------
        ModelError
            One line naming the folder: a file missing, unreadable (a truncated or empty
            ``params.npz``, ``meta.json`` not a JSON object), of another format version, or the
            two files not fitting together (arrays missing, feature counts differing).
        """
        d = Path(in_dir)
        try:
            meta = json.loads((d / "meta.json").read_text(encoding="utf-8"))
            if not isinstance(meta, dict):
                raise ModelError(f"{d}: unreadable model files: meta.json holds a JSON "
                                 f"{type(meta).__name__}, not an object")
            if meta.get("status") == "failed":   # a placeholder of a failed training: its reason
                raise ModelError(f"{d}: the model set failed to train ({meta.get('error') or 'no reason given'})")
            if "format_version" not in meta:
                raise ModelError(f"{d}: meta.json has no format_version: not the meta.json of a trained "
                                 f"model set (uavpipe train writes format {FORMAT_VERSION})")
            if meta["format_version"] != FORMAT_VERSION:
                raise ModelError(f"{d}: model format {meta['format_version']} (this uavpipe reads format "
                                 f"{FORMAT_VERSION}): retrain the model set")
            # our own handle: np.load leaves its file open when a truncated archive fails to open
            with open(d / "params.npz", "rb") as fh, np.load(fh, allow_pickle=False) as z:
                return cls._from_files(meta, z)  # reads every array it keeps
        except FileNotFoundError as exc:
            raise ModelError(f"{d}: not a model directory ({exc.filename} missing)") from None
        except ModelError:
            raise
        except (OSError, EOFError, zipfile.BadZipFile, json.JSONDecodeError) as exc:
            # np.load raises EOFError on an empty file, BadZipFile on a truncated archive
            raise ModelError(f"{d}: unreadable model files: {type(exc).__name__}: {exc}") from None
        except (KeyError, ValueError, TypeError, IndexError, AttributeError) as exc:
            raise ModelError(f"{d}: params.npz and meta.json do not fit together "
                             f"({type(exc).__name__}: {one_line(exc)})") from None

    @classmethod
    def _from_files(cls, meta: dict, z) -> "ManeuverModelSet":
        cfg = dict(meta["config"])
        seed = cfg.pop("seed", 0)   # persisted with the model; not a key of the hmm section
        self = cls(config=ModelsConfig.from_section(cfg, seed=seed))
        self.labels_ = list(meta["labels"])
        self.training_ = meta.get("training", {})
        self.threshold_slack_ = float(meta.get("threshold_slack", 0.0))
        self.normaliser_ = MinMaxNormaliser(z["norm_min"], z["norm_max"])
        self.models_ = []
        for i, lab in enumerate(self.labels_):
            self.models_.append(ManeuverHMM.from_params(HMMParams.from_arrays(z, prefix=f"m{i}_")))
        self.thresholds_ = {k[len("threshold_"):]: z[k] for k in z.files if k.startswith("threshold_")}
        self.threshold_fraction_ = float(meta.get("threshold_fraction", 1.0))
        self.impostor_ll_ = z["impostor_ll"] if "impostor_ll" in z.files else np.full(len(self.labels_), np.nan)
        if any(k.startswith("percentile_") for k in z.files):
            self.threshold_base_ = {k[len("percentile_"):]: z[k] for k in z.files if k.startswith("percentile_")}
        else:   # written before the impostor fraction: the thresholds are q_m(n) − s n
            self.threshold_base_ = {}
            for mode, thr in self.thresholds_.items():
                n = np.arange(1, thr.shape[1] + 1)
                if mode == "windowed":
                    n = np.minimum(n, self.config.window)
                self.threshold_base_[mode] = thr + self.threshold_slack_ * n
        self.background_ = HMMParams.from_arrays(z, prefix="bg_") if "bg_means" in z.files else None
        n_feat = len(self.feature_set.names)
        if np.shape(self.normaliser_.x_min) != (n_feat,):
            raise ValueError(f"normaliser of {np.size(self.normaliser_.x_min)} features, feature set "
                             f"{self.config.feature_set!r} has {n_feat}")
        return self
