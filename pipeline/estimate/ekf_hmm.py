"""The EKF+HMM of seed 000 Ch. 4 (digest §8, decisions §13.2, §13.4, §13.7), vectorised across runs.

Two filters run side by side over the same radar measurements:

1. the **baseline EKF** (CA model, white-jerk ``Q``; :mod:`pipeline.estimate.ekf`) always runs,
   and *only its posteriors* feed the maneuver classifier and the GMR (§8 "Inputs"), even after a
   classification;
2. the **EKF+HMM** filter keeps a state of its own (never reset to the EKF's, §13.7). Its
   prediction from step k−1 to k uses, per NED axis, the HMM inputs computed from the EKF's
   posteriors up to step k−1 (causal) when the classifier's output at k−1 is a known maneuver
   (``V_c < −1``, the classifier's decision rule) and the 15 m/s² gate kept that axis:

   .. math::

       x^-_k = A_H x^+_{k-1} + B \\begin{bmatrix}\\hat a_{HMM} \\\\ \\hat\\jmath_{HMM}\\end{bmatrix},
       \\qquad P^-_k = A_H P^+_{k-1} A_H^T + Q_2          \\qquad (4.2–4.4, §13.2 fix)

   and the CA prediction ``A x, A P Aᵀ + Q`` otherwise (per axis: "fall back to CA per axis where
   the gate dropped a value", §13.7). The radar update is the EKF's, unchanged.

**Classifier input** (:data:`INCREMENTS`). The thesis text (seed 000 §4.1: "After each dynamic
update, x̂⁻_{k+1} and x̂⁺_k are passed to the pre-processing block", (4.1) their difference) feeds
the classifier the *predicted* increments; ``increments: prior`` (the default) follows it through
:func:`prior_increment_track`. The digest (§13.4) reads (4.1) as the posterior increments
``x̂⁺_{k+1} − x̂⁺_k`` (``increments: posterior``, kept as the alternative). The two differ in what
the radar update adds: a posterior increment carries the update's correction, a predicted one is
``(A − I) x̂⁺_k``, smooth. The default was chosen after measuring both (seed 20261123, size
``small``; ``study_seed000_classification`` and ``study_seed000_ekf``): with the printed reading
the truth-trained confidence classifier on EKF input keeps FA 100 % on M1–M4 (Table 3.8; thesis
"each maneuver model maintains 100% final classification accuracy"), against 33.3 % on M3 with
the digest's, and 36 of the 40 S1/S2 RMSE changes of the EKF+HMM against the EKF are negative,
against a majority positive with the digest's.

**Output** (:attr:`EkfHmmTrack.output`). The thesis switches the *output*, not only the
prediction (Ch. 4.1: "if the classification is unknown, the output of the filter is the EKF
estimate. [...] Classifications with high confidence (less than -1) result in the EKF+HMM
incorporating HMM information into its estimates and instead outputting the EKF+HMM estimate";
digest §8 "otherwise use the CA prediction with Q; the output is the EKF estimate"). Step k's
output is therefore the EKF+HMM filter's posterior when the classification that chose step k's
prediction (the one at k−1) is a known maneuver (:attr:`EkfHmmTrack.switched`), else the
baseline EKF's; the EKF+HMM filter itself keeps running through unknown stretches (CA, its own
state, no reset). The filter's own state is :attr:`EkfHmmTrack.hmm`.

Per step the transition is assembled per run: the rows of a state component take ``A_H`` when
its axis uses HMM inputs and ``A`` otherwise (both are ``·⊗I₃``, so an axis' rows only touch that
axis), and the process noise takes ``Q₂`` on the HMM axes, ``Q`` on the CA axes, and no cross
terms between the two kinds (which keeps it positive semi-definite).

``Q₂`` (§8: "Bryson's rule on the maximum training HMM-estimate error variance, then hand-tuned";
"it must have off-diagonal r/v–a terms") is here the second moment of the one-step prediction
errors ``e_k = x_{k+1} − (A_H x_k + B u_k)`` of ``[r, v, a]`` on truth training runs, with the
GMR inputs ``u_k`` of the classified model, times one scalar tuned on training data
(:func:`q2_from_runs`). Taking ``E[e eᵀ]`` rather than the mean-removed covariance counts a GMR
bias as noise, which is what the filter has to absorb.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..models.features import GMR_FEATURE_SETS, decimation_factor, run_sequences
from ..models.metrics import UNKNOWN
from .base import GaussianState, check_times
from .ekf import ExtendedKalmanFilter, FilterTrack, run_filter
from .models import STATE_COLUMNS, ca_transition, hmm_input, hmm_transition

F64 = NDArray[np.float64]

#: state index of each component's NED axis (state ordered [r(3), v(3), a(3)])
_AXIS_OF = np.tile(np.arange(3), 3)


class EkfHmmError(ValueError):
    """The EKF+HMM cannot run (a model set without GMR, inputs that do not fit)."""


@dataclass(frozen=True)
class EkfHmmTrack:
    """The baseline EKF, the EKF+HMM and the classifier's per-step outputs (runs × time).

    Attributes
    ----------
    ekf : FilterTrack
        Baseline CA EKF (classification and GMR use only it).
    hmm : FilterTrack
        The EKF+HMM filter's own estimates.
    mode : ndarray of bool, shape (R, T)
        Step k was predicted with HMM inputs on at least one axis.
    hmm_axes : ndarray of bool, shape (R, T, 3)
        Per NED axis.
    pred : ndarray of object, shape (R, T)
        Classifier output at step k (``'unknown'`` before its first output).
    V_best : ndarray, shape (R, T)
        Confidence of the best model at step k (NaN before the first output).
    acc_hmm, jerk_hmm : ndarray, shape (R, T, 3)
        GMR acceleration (m/s²) and jerk (m/s³) in NED at step k (NaN where none).
    gated : ndarray of bool, shape (R, T, 3)
        Dropped by the 15 m/s² gate at step k.
    switched : ndarray of bool, shape (R, T)
        The classification that chose step k's prediction (at k−1) is a known maneuver
        (``V_c < −1``): step k outputs the EKF+HMM estimate, else the EKF's (module docstring).
    """

    ekf: FilterTrack
    hmm: FilterTrack
    mode: NDArray[np.bool_]
    hmm_axes: NDArray[np.bool_]
    pred: NDArray[np.object_]
    V_best: F64
    acc_hmm: F64
    jerk_hmm: F64
    gated: NDArray[np.bool_]
    switched: NDArray[np.bool_]

    @property
    def hmm_share(self) -> F64:
        """Share of steps per run predicted with HMM inputs (any axis), shape (R,)."""
        return self.mode.mean(axis=1)

    @property
    def output(self) -> FilterTrack:
        """The EKF+HMM's output (seed 000 Ch. 4.1, Fig. 4.1): the EKF+HMM filter's posterior
        where :attr:`switched`, the baseline EKF's elsewhere (mean, covariance, NIS and
        measured scalars alike; covariances only where both tracks kept them)."""
        sw = self.switched
        mean = np.where(sw[..., None], self.hmm.mean, self.ekf.mean)
        cov = None
        if self.hmm.cov is not None and self.ekf.cov is not None:
            cov = np.where(sw[..., None, None], self.hmm.cov, self.ekf.cov)
        return FilterTrack(self.ekf.t_ns, mean, cov, np.where(sw, self.hmm.nis, self.ekf.nis),
                           np.where(sw, self.hmm.dof, self.ekf.dof))


def ekf_state_frame(mean, t_ns, *, yaw_rad=None, run_ids=None) -> pd.DataFrame:
    """Filter posteriors as a ``state`` table the maneuver classifier reads.

    Parameters
    ----------
    mean : array_like, shape (R, T, 9) or (T, 9)
        Posterior means ``[r, v, a]`` (NED).
    t_ns : array_like of int, shape (T,)
    yaw_rad : float or array_like, shape (R,) or (R, T), optional
        Heading (``state9h`` uses the first sample of each run): the truth attitude in the bulk
        sets, the ``attitude`` stream on flights.
    run_ids : sequence, optional
        One id per run (default ``0..R−1``).

    Returns
    -------
    DataFrame with ``run_id``, ``t_ns``, :data:`~pipeline.estimate.models.STATE_COLUMNS` and
    ``yaw_rad`` when given, runs one after the other.
    """
    mean = np.asarray(mean, dtype=np.float64)
    if mean.ndim == 2:
        mean = mean[None]
    R, T, n = mean.shape
    if n != len(STATE_COLUMNS):
        raise EkfHmmError(f"ekf_state_frame: states have {n} components, expected {len(STATE_COLUMNS)}")
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if t_ns.shape != (T,):
        raise EkfHmmError(f"ekf_state_frame: {len(t_ns)} times for {T} steps")
    ids = np.arange(R) if run_ids is None else np.asarray(run_ids)
    d = {"run_id": np.repeat(ids, T), "t_ns": np.tile(t_ns, R)}
    flat = mean.reshape(R * T, n)
    for i, c in enumerate(STATE_COLUMNS):
        d[c] = flat[:, i]
    if yaw_rad is not None:
        yaw = np.asarray(yaw_rad, dtype=np.float64)
        d["yaw_rad"] = np.broadcast_to(yaw[..., None] if yaw.ndim == 1 else yaw, (R, T)).reshape(-1)
    return pd.DataFrame(d)


#: what the classifier sees of the baseline EKF (module docstring "Classifier input")
INCREMENTS = ("prior", "posterior")


def prior_increment_track(mean, t_ns) -> F64:
    r"""A pseudo-track whose increments are the EKF's predicted ones, ``x̂⁻_{k+1} − x̂⁺_k``.

    Seed 000 §4.1 as printed: "After each dynamic update, x̂⁻_{k+1} and x̂⁺_k are passed to the
    pre-processing block", whose observation (4.1) is their difference. Under the CA model that
    difference is ``(A(dt_k) − I) x̂⁺_k``: ``Δr = v̂ dt + â dt²/2``, ``Δv = â dt``, ``Δa = 0``. The
    digest (§13.4) reads (4.1) as ``x̂⁺_{k+1} − x̂⁺_k`` instead (``increments: posterior``); this
    is the printed reading (``increments: prior``, the default).

    The track is :math:`q_k = \hat x^+_0 + \sum_{j \le k} (A(dt_j) − I)\hat x^+_j`, stamped at
    ``t_k``, so a differenced feature at ``t_k`` is ``(A − I) x̂⁺_k``: it depends on the posterior
    at ``k`` only (as causal as the posterior increments) and describes the motion predicted
    over ``[t_k, t_{k+1}]``, which is the step the EKF+HMM predicts with the inputs of ``t_k``.
    Its absolute values are not estimates (only increments are meaningful); every GMR
    conditioning block (``pos``, ``pos_fd``, ``pos_vel``) reads increments only.

    Parameters
    ----------
    mean : array_like, shape (R, T, 9) or (T, 9)
        Posterior means ``[r, v, a]`` (NED).
    t_ns : array_like of int, shape (T,)
        Step times; ``dt_k = t_{k+1} − t_k`` (the last step reuses the one before it).

    Returns
    -------
    ndarray, the shape of ``mean``
    """
    mean = np.asarray(mean, dtype=np.float64)
    t_ns = np.asarray(t_ns, dtype=np.int64)
    if mean.shape[-1] != len(STATE_COLUMNS) or mean.shape[-2:-1] != t_ns.shape:
        raise EkfHmmError(f"prior_increment_track: states {mean.shape} do not fit {len(t_ns)} times")
    if len(t_ns) < 2:
        return mean.copy()
    dt = np.diff(t_ns) * 1e-9
    dt = np.append(dt, dt[-1])
    inc = np.empty_like(mean)
    for d in np.unique(dt):                        # regular grids: one matrix
        m = dt == d
        inc[..., m, :] = mean[..., m, :] @ (ca_transition(float(d)) - np.eye(9)).T
    return mean[..., :1, :] + np.cumsum(inc, axis=-2)


def classifier_state(mean, t_ns, increments: str = "prior") -> F64:
    """What the classifier reads of the baseline EKF's posteriors ``mean`` (shape (R, T, 9) or
    (T, 9)): :func:`prior_increment_track` (``prior``, the thesis's printed (4.1), default) or the
    posteriors themselves (``posterior``, digest §13.4)."""
    if increments not in INCREMENTS:
        raise EkfHmmError(f"increments must be one of {', '.join(INCREMENTS)}, not {increments!r}")
    return np.asarray(mean, dtype=np.float64) if increments == "posterior" else prior_increment_track(mean, t_ns)


def _check_gmr(model_set) -> None:
    fs = model_set.config.feature_set
    if fs not in GMR_FEATURE_SETS:
        raise EkfHmmError(f"the EKF+HMM needs HMM acceleration/jerk (GMR), which feature set {fs!r} "
                          f"does not give (GMR feature sets: {', '.join(GMR_FEATURE_SETS)})")


def _batched(prior: GaussianState) -> GaussianState:
    """One run (mean ``(9,)``) as a batch of one."""
    if prior.mean.ndim == 1:
        return GaussianState(prior.mean[None], prior.cov[None], prior.t_ns)
    return prior


def _q2(Q2, caller: str) -> F64:
    Q2 = np.asarray(Q2, dtype=np.float64)
    if Q2.shape != (9, 9) or not np.all(np.isfinite(Q2)):
        raise EkfHmmError(f"{caller}: Q2 must be a finite 9×9 matrix, got shape {Q2.shape}")
    return Q2


def _classified_arrays(cls: pd.DataFrame, t_ns: NDArray[np.int64], R: int, run_index: dict):
    """Classifier rows -> (R, T) arrays, each step holding the newest output at or before it."""
    T = len(t_ns)
    pred = np.full((R, T), UNKNOWN, dtype=object)
    V = np.full((R, T), np.nan)
    acc = np.full((R, T, 3), np.nan)
    jerk = np.full((R, T, 3), np.nan)
    gated = np.zeros((R, T, 3), dtype=bool)
    if cls.empty:
        return pred, V, acc, jerk, gated
    r = cls["run_id"].map(run_index).to_numpy(dtype=np.int64)
    k = np.searchsorted(t_ns, cls["t_ns"].to_numpy(dtype=np.int64))
    ok = (k < T) & (t_ns[np.minimum(k, T - 1)] == cls["t_ns"].to_numpy())
    r, k = r[ok], k[ok]
    # forward fill (steps faster than the model rate keep the last output): index of the newest
    # classified step at or before each step, per run
    have = np.zeros((R, T), dtype=bool)
    have[r, k] = True
    src = np.where(have, np.arange(T)[None, :], -1)
    src = np.maximum.accumulate(src, axis=1)
    row_at = np.full((R, T), -1, dtype=np.int64)
    row_at[r, k] = np.flatnonzero(ok)
    filled = src >= 0
    rows = np.where(filled, np.take_along_axis(row_at, np.maximum(src, 0), axis=1), -1)
    sel = rows[filled]
    pred[filled] = cls["pred"].to_numpy(dtype=object)[sel]
    V[filled] = cls["V_best"].to_numpy(dtype=np.float64)[sel]
    for i, ax in enumerate("ned"):
        acc[..., i][filled] = cls[f"acc_hmm_{ax}_mps2"].to_numpy(dtype=np.float64)[sel]
        jerk[..., i][filled] = cls[f"jerk_hmm_{ax}_mps3"].to_numpy(dtype=np.float64)[sel]
        gated[..., i][filled] = cls[f"acc_hmm_gated_{ax}"].to_numpy(dtype=bool)[sel]
    return pred, V, acc, jerk, gated


def hmm_step(axes, A, Q, A_H, B, Q2, acc, jerk) -> tuple[F64, F64, F64]:
    """Per-run transition, process noise and input of one EKF+HMM prediction (§8, eq. 4.2–4.4).

    Parameters
    ----------
    axes : ndarray of bool, shape (R, 3)
        NED axes predicted with HMM inputs, per run.
    A, Q : ndarray, shape (9, 9)
        CA transition and white-jerk noise for this step.
    A_H, B : ndarray, shapes (9, 9), (9, 6)
        HMM-input transition and input matrix for this step.
    Q2 : ndarray, shape (9, 9)
    acc, jerk : ndarray, shape (R, 3)
        GMR inputs (used on ``axes`` only).

    Returns
    -------
    F : ndarray, shape (R, 9, 9)
        ``A_H`` rows on the HMM axes, ``A`` rows elsewhere.
    Q : ndarray, shape (R, 9, 9)
        ``Q₂`` between HMM-axis components, ``Q`` between CA-axis components, 0 across.
    bu : ndarray, shape (R, 9)
        ``B [â; ĵ]`` with the CA axes' inputs zero.
    """
    axes = np.asarray(axes, dtype=bool)
    rows = axes[:, _AXIS_OF]                                   # (R, 9): component uses HMM inputs
    F = np.where(rows[..., None], A_H, A)
    both = rows[..., :, None] & rows[..., None, :]
    none = ~rows[..., :, None] & ~rows[..., None, :]
    Qk = np.where(both, Q2, 0.0) + np.where(none, Q, 0.0)
    u = np.concatenate([np.where(axes, acc, 0.0), np.where(axes, jerk, 0.0)], axis=1)
    return F, Qk, u @ np.asarray(B).T


def run_ekf_hmm(ekf: ExtendedKalmanFilter, prior: GaussianState, t_ns, z, model_set, Q2, *,
                yaw_rad=None, box_heading_rad: float = 0.0, reset_t_ns=None,
                store: str = "filtered", increments: str = "prior", decision: str | None = None) -> EkfHmmTrack:
    """Run the baseline EKF, classify its posteriors, and run the EKF+HMM (module docstring).

    Parameters
    ----------
    ekf : ExtendedKalmanFilter
        CA transition (white-jerk ``Q``) and the radar model; shared by both filters.
    prior : GaussianState
        Initial estimate of both filters, batch ``(R,)`` or one run.
    t_ns : array_like of int, shape (T,)
        Step times (the radar's), shared by every run.
    z : array_like, shape (T, R, n_z) or (T, R, M, n_z)
        Measurements (NaN rows: gaps), as :func:`~pipeline.estimate.ekf.run_filter`.
    model_set : ManeuverModelSet
        Trained models with GMR (:data:`GMR_FEATURE_SETS`).
    Q2 : array_like, shape (9, 9)
        Process noise of the HMM-input prediction (:func:`q2_from_runs`).
    yaw_rad : float or array_like, shape (R,) or (R, T), optional
        Heading for heading-frame feature sets (truth in sets, ``attitude`` on flights).
    box_heading_rad : float
        Box heading for the box-frame feature set.
    reset_t_ns : sequence of int, optional
        Restart the classifier's forward passes at these times (segment starts).
    store : {"filtered", "mean"}
        What both filter tracks keep (the covariances of a large Monte Carlo are big).
    increments : {"prior", "posterior"}
        What the classifier sees (:func:`classifier_state`): the predicted increments
        ``x̂⁻_{k+1} − x̂⁺_k`` (the thesis's printed (4.1), default) or the posterior ones
        ``x̂⁺_{k+1} − x̂⁺_k`` (digest §13.4). Either way the inputs of step ``k`` depend on posteriors up
        to ``k`` and drive the prediction into ``k + 1``.
    decision : str, optional
        The classifier's decision rule (``confidence``, ``oneclass``, ``both``,
        ``confidence_bg``); default the model set's own. With ``both`` a flight the models do not
        describe (out of class) is mostly ``unknown``, so its steps stay CA.

    Returns
    -------
    EkfHmmTrack
    """
    _check_gmr(model_set)
    if increments not in INCREMENTS:
        raise EkfHmmError(f"run_ekf_hmm: increments must be one of {', '.join(INCREMENTS)}, not {increments!r}")
    if store not in ("filtered", "mean"):
        raise EkfHmmError(f"run_ekf_hmm: store must be 'filtered' or 'mean', not {store!r}")
    prior, Q2 = _batched(prior), _q2(Q2, "run_ekf_hmm")   # before the costly baseline and classification
    try:  # a fractional float stamp is refused here, not truncated (run_filter would see int64)
        t_ns = check_times(t_ns, "run_ekf_hmm", prior.t_ns)
    except ValueError as exc:
        raise EkfHmmError(str(exc)) from None
    base = run_filter(ekf, prior, t_ns, z, store=store)
    R, T = base.mean.shape[:2]
    frame = ekf_state_frame(classifier_state(base.mean, t_ns, increments), t_ns, yaw_rad=yaw_rad)
    cls = model_set.classify(frame, reset_t_ns=reset_t_ns, box_heading_rad=box_heading_rad, decision=decision)
    pred, V, acc, jerk, gated = _classified_arrays(cls, t_ns, R, {i: i for i in range(R)})
    # inputs for the prediction into step k come from step k−1 (causal)
    known = pred != UNKNOWN
    use = known[..., None] & ~gated & np.isfinite(acc) & np.isfinite(jerk)   # at k−1
    axes = np.zeros_like(use)
    axes[:, 1:] = use[:, :-1]
    # the output switch follows the classification that chose the step's prediction (at k−1),
    # gated axes or not: a gated axis falls back to CA inside the EKF+HMM, whose estimate is
    # still the output (§8 outlier gate, §13.7)
    switched = np.zeros((R, T), dtype=bool)
    switched[:, 1:] = known[:, :-1]

    hmm = hmm_filter(ekf, prior, t_ns, z, Q2, axes, acc, jerk, store=store)
    return EkfHmmTrack(base, hmm, axes.any(axis=-1), axes, pred, V, acc, jerk, gated, switched)


def hmm_filter(ekf: ExtendedKalmanFilter, prior: GaussianState, t_ns, z, Q2, axes, acc, jerk, *,
               store: str = "filtered") -> FilterTrack:
    """The EKF+HMM filter alone, given its per-step HMM axes and GMR inputs (module docstring).

    :func:`run_ekf_hmm` calls it after classifying the baseline EKF; a caller searching ``Q₂``
    reuses one classification (``track.hmm_axes``, ``track.acc_hmm``, ``track.jerk_hmm``),
    which does not depend on ``Q₂``.

    Parameters
    ----------
    ekf, prior, t_ns, z
        As :func:`run_ekf_hmm` (``prior`` batch ``(R,)``).
    Q2 : array_like, shape (9, 9)
    axes : ndarray of bool, shape (R, T, 3)
        Step k is predicted with HMM inputs on these NED axes; ``axes[:, 0]`` must be False
        (step 0 has no inputs before it).
    acc, jerk : ndarray, shape (R, T, 3)
        GMR inputs; the prediction into step k takes those of step k−1.
    store : {"filtered", "mean"}

    Returns
    -------
    FilterTrack

    Raises
    ------
    EkfHmmError
        Bad shapes, ``axes[:, 0]`` True, or ``t_ns`` not 1-D, fractional, decreasing or before
        the prior (naming the first bad row).
    """
    prior, Q2 = _batched(prior), _q2(Q2, "hmm_filter")
    try:
        t_ns = check_times(t_ns, "hmm_filter", prior.t_ns)
    except ValueError as exc:
        raise EkfHmmError(str(exc)) from None
    z = np.asarray(z, dtype=np.float64)
    R, T = prior.mean.shape[0], len(t_ns)
    axes = np.asarray(axes, dtype=bool)
    if axes.shape != (R, T, 3) or np.shape(acc) != (R, T, 3) or np.shape(jerk) != (R, T, 3):
        raise EkfHmmError(f"hmm_filter: axes/acc/jerk must be shaped {(R, T, 3)}, got {axes.shape}, "
                          f"{np.shape(acc)}, {np.shape(jerk)}")
    if T and axes[:, 0].any():
        # the prediction into step k takes the inputs of step k−1: step 0 has none before it
        # (index −1 would silently be the last step's, i.e. future data)
        r = int(np.argmax(axes[:, 0].any(axis=-1)))
        raise EkfHmmError(f"hmm_filter: axes[:, 0] must be False (no HMM input before the first step); "
                          f"run {r} has {axes[r, 0].tolist()}")
    mean = np.empty((T, R, 9))
    cov = np.empty((T, R, 9, 9)) if store == "filtered" else None
    nis = np.empty((T, R))
    dof = np.empty((T, R), dtype=np.int64)
    state = prior
    mats: dict[int, tuple] = {}
    for k in range(T):
        if int(t_ns[k]) != state.t_ns:
            step = int(t_ns[k]) - state.t_ns
            if step not in mats:
                dt = step * 1e-9
                mats[step] = (ca_transition(dt), ekf.transition.noise(dt), hmm_transition(dt), hmm_input(dt))
            A, Q, AH, Bm = mats[step]
            ax = axes[:, k]                                    # (R, 3)
            if not ax.any():
                state = ekf.predict(state, int(t_ns[k]), F=A, Q=Q)
            else:
                F, Qk, bu = hmm_step(ax, A, Q, AH, Bm, Q2, acc[:, k - 1], jerk[:, k - 1])
                state = ekf.predict(state, int(t_ns[k]), F=F, Q=Qk, bu=bu)
        state, st = ekf.update_stats(state, z[k], out=None if cov is None else cov[k])
        mean[k] = state.mean
        nis[k], dof[k] = st.nis, st.dof

    def rt(a):
        return None if a is None else np.swapaxes(a, 0, 1)

    return FilterTrack(t_ns, rt(mean), rt(cov), rt(nis), rt(dof))


def q2_from_runs(model_set, truth_state: pd.DataFrame, *, scale: float = 1.0, run_col: str = "run_id",
                 box_heading_rad: float = 0.0, reset_t_ns=None, input_state: pd.DataFrame | None = None) -> F64:
    """``Q₂``: second moment of the A_H/B one-step errors of ``[r, v, a]`` on truth runs × ``scale``.

    For every model-rate sample k with a known classification and every axis kept by the gate,
    ``e_k = x_{k+1} − (A_H x_k + B [â_k; ĵ_k])`` with ``x`` the true state and ``â, ĵ`` the GMR
    inputs of the classified model at k (what the EKF+HMM would use from an exact state), and

    .. math:: Q_2 = s \\cdot \\frac{1}{N} \\sum_k e_k e_k^T

    (seed 000 §8; the thesis tunes ``Q₂`` by hand from the maximum training error variance and
    requires r/v–a cross terms, which this moment has).

    Parameters
    ----------
    model_set : ManeuverModelSet
        With GMR (:data:`GMR_FEATURE_SETS`).
    truth_state : DataFrame
        Training runs: ``STATE_COLUMNS``, ``t_ns``, ``run_col`` (+ ``yaw_rad``, ``label``).
    scale : float
        The one tuned scalar ``s`` (> 0).
    input_state : DataFrame, optional
        What the classifier and the GMR see (same runs and times as ``truth_state``; default
        the truth itself). With the baseline EKF's posteriors of the training runs
        (:func:`ekf_state_frame`), ``e_k`` holds the input errors the EKF+HMM meets at run time
        (GMR fed by estimates, not by the truth); the errors are still taken against the truth.

    Returns
    -------
    ndarray, shape (9, 9)

    Raises
    ------
    EkfHmmError
        A model set without GMR, a bad scale, or no sample with HMM inputs.
    """
    _check_gmr(model_set)
    if not scale > 0:
        raise EkfHmmError(f"q2_from_runs: scale must be > 0, got {scale!r}")
    missing = [c for c in (*STATE_COLUMNS, "t_ns", run_col) if c not in truth_state.columns]
    if missing:
        raise EkfHmmError(f"q2_from_runs: truth table lacks column(s) {missing}")
    if input_state is not None:
        miss = [c for c in (*STATE_COLUMNS, "t_ns", run_col) if c not in input_state.columns]
        if miss:
            raise EkfHmmError(f"q2_from_runs: input_state lacks column(s) {miss}")
    cls = model_set.classify(truth_state if input_state is None else input_state, run_col=run_col,
                             box_heading_rad=box_heading_rad, reset_t_ns=reset_t_ns)
    rate = model_set.config.rate_hz
    errs = []
    by_run = dict(run_sequences(cls, run_col=run_col))
    for rid, run in run_sequences(truth_state, run_col=run_col):
        c = by_run.get(rid)
        if c is None or len(run) < 2:
            continue
        t = run["t_ns"].to_numpy(dtype=np.int64)
        step = decimation_factor(t, rate)
        x = run[list(STATE_COLUMNS)].to_numpy(dtype=np.float64)
        i = np.searchsorted(t, c["t_ns"].to_numpy(dtype=np.int64))
        nxt = i + step
        ok = (nxt < len(t)) & (c["pred"].to_numpy(dtype=object) != UNKNOWN)
        u = np.column_stack([c[[f"acc_hmm_{a}_mps2" for a in "ned"]].to_numpy(dtype=np.float64),
                             c[[f"jerk_hmm_{a}_mps3" for a in "ned"]].to_numpy(dtype=np.float64)])
        g = c[[f"acc_hmm_gated_{a}" for a in "ned"]].to_numpy(dtype=bool)
        ok &= np.isfinite(u).all(axis=1) & ~g.any(axis=1)
        if not ok.any():
            continue
        i, nxt, u = i[ok], nxt[ok], u[ok]
        dt = (t[nxt] - t[i]) * 1e-9
        for d in np.unique(dt):                               # regular grids: one value
            m = dt == d
            pred = x[i[m]] @ hmm_transition(d).T + u[m] @ hmm_input(d).T
            errs.append(x[nxt[m]] - pred)
    if not errs:
        raise EkfHmmError("q2_from_runs: no training sample has HMM inputs (every classification "
                          "unknown or gated)")
    e = np.concatenate(errs)
    return scale * (e.T @ e) / len(e)


def one_step_q2(x, acc, jerk, dt: float) -> F64:
    """Second moment of the A_H/B one-step errors for given inputs on one regular grid (the
    quantity :func:`q2_from_runs` forms from classified runs, without its classification, gate and
    per-run decimation).

    .. math:: e_k = x_{k+1} - (A_H x_k + B [a_k; j_k]), \\qquad Q_2 = \\frac{1}{N}\\sum_k e_k e_k^T

    over the steps where ``x_k``, ``x_{k+1}`` and the inputs are finite. With the true
    acceleration and jerk as inputs this is the Q₂ of an *exact* HMM input (an oracle), the
    yardstick against which the GMR's own inputs are judged (issue 14 diagnosis).

    Parameters
    ----------
    x : array_like, shape (T, 9) or (R, T, 9)
        States ``[r, v, a]`` on a regular grid of step ``dt``.
    acc, jerk : array_like, shape (T, 3) or (R, T, 3)
        Inputs at each step (used for the step that leaves it).
    dt : float
        Step, s.

    Returns
    -------
    ndarray, shape (9, 9)

    Raises
    ------
    EkfHmmError
        Shapes that do not fit, or no finite step.
    """
    x = np.asarray(x, dtype=np.float64)
    acc, jerk = np.asarray(acc, dtype=np.float64), np.asarray(jerk, dtype=np.float64)
    if x.ndim == 2:
        x, acc, jerk = x[None], acc[None], jerk[None]
    if x.shape[-1] != 9 or acc.shape != x.shape[:-1] + (3,) or jerk.shape != acc.shape:
        raise EkfHmmError(f"one_step_q2: states {x.shape}, acc {acc.shape}, jerk {jerk.shape} do not fit")
    u = np.concatenate([acc, jerk], axis=-1)[:, :-1]
    e = x[:, 1:] - x[:, :-1] @ hmm_transition(dt).T - u @ hmm_input(dt).T
    e = e.reshape(-1, 9)
    e = e[np.isfinite(e).all(axis=1)]
    if not len(e):
        raise EkfHmmError("one_step_q2: no step with finite states and inputs")
    return (e.T @ e) / len(e)
