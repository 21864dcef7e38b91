"""EKF estimates of the simulated bulk sets: the noise-aware training data (issue 14, item 4).

Truth-trained maneuver models classify noisy, filtered states poorly (seed 000 Tables 3.5–3.8:
M1 MAoT 98 % on truth, 77–88 % on EKF estimates). This stage gives the models the data they
meet online: for every run of a bulk set (``results/sim/sets/<set>.parquet``, 5 Hz truth in
:data:`pipeline.io.schema.SIM_SET`) it synthesises the seed-000 radar from the truth and runs
the 9-state CA EKF over it (seed 000 §3), and writes the EKF posteriors in the same schema
(``results/estimate/sets/<set>.parquet``), so model sets with ``input: ekf`` train and evaluate
on them exactly as on truth.

Per run ``i`` and step ``k`` (``dt`` = the set's 0.2 s grid):

.. math::

    z_{i,k} = h(x_{i,k}) + \\nu_{i,k},\\quad \\nu \\sim N(0, R)  \\quad
    \\text{(:meth:`~pipeline.estimate.models.RadarModel.measure`)}

    \\hat x_{i,0} = x_{i,0} + P_0^{1/2} \\varepsilon_i,\\quad
    P_0 = \\operatorname{diag}(1^2 I_3, 0.1^2 I_3, 0.01^2 I_3)
    \\quad\\text{(the Ch. 2 Monte Carlo initialisation, digest §3)}

then the CA EKF with the white-jerk ``Q(dt, q)`` (:func:`~pipeline.estimate.models.white_jerk_q`,
Joseph form), the first step an update at ``t_0``. Every run of a set is filtered at once
(:func:`~pipeline.estimate.ekf.run_filter` loops over time only); runs of a set must share one
time grid (``uavpipe simulate`` writes them so).

Output columns: ``pos/vel/acc_*`` the EKF posterior means, ``alt_cal_m = −pos_d`` of the
estimate (it is a position), ``jerk_*`` NaN (the CA EKF has no jerk state), every other column
(attitude, rates, sticks, thrust, ``gap``, ``run_id``, ``label``, ``t_ns``) the truth's: the
state9h features take the heading from the attitude, which the thesis's classifier also had
from truth.

Seed: each set draws from ``np.random.default_rng([seed, crc32("ekf/<set name>")])`` — first
the initial-state noise ``(R, 9)``, then the radar noise ``(R, T, 4)`` — so a set's estimate
depends only on the master seed, its name and its truth, never on which other sets were
filtered. The ``ekf/`` prefix keeps it apart from the simulator's own generators
(``[seed, crc32(name), chunk]``).

Config (``estimate.sets``): ``q`` (jerk spectral density, m²/s⁵), ``p0_sigma`` (the P₀
standard deviations of position, velocity, acceleration) and ``increments``: with ``prior``
(default) the written ``pos/vel/acc`` are :func:`prior_increment_set`'s pseudo-track of the
EKF's predicted increments — what the EKF+HMM's classifier sees with
``estimate.ekf_hmm.increments: prior`` (the thesis's printed (4.1)) — and with ``posterior`` the
posteriors themselves; the two settings should agree. The RMSE diagnostics are always the
posteriors'. The radar is the simulated flights'
radar, ``simulate.sensors.radar`` (site, τ_RD, σ: seed 000 Table 2.1), passed as
``config["radar"]``: one radar for the sets and the log flights, so a model trained on these
sets sees the noise the flights' radar stream has.
"""

from __future__ import annotations

import sys
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..config import ConfigError, validate_section
from ..io import schema
from ..io.parquet import read_table, write_table
from ..io.stage import declared_list
from .base import ConstantAcceleration, GaussianState
from .ekf import ExtendedKalmanFilter, run_filter
from .ekf_hmm import INCREMENTS, prior_increment_track
from .models import STATE_COLUMNS, RadarModel, initial_cov

#: the bulk-set columns (``simulate.datasets.SET_COLUMNS`` is this very tuple)
SET_COLUMNS: tuple[schema.Column, ...] = schema.SIM_SET
#: a run whose final position error exceeds this (m) counts as diverged (``n_diverged``)
DIVERGED_M = 10.0
#: the truth's jerk columns, NaN in an EKF set
JERK_COLUMNS: tuple[str, ...] = tuple(f"jerk_{a}_mps3" for a in "ned")


@dataclass(frozen=True)
class EkfSetsResult:
    """What :func:`run_ekf_sets` did: ``status`` (``ok``) and per-set diagnostics (runs,
    steps, the RMSE of the estimate against the truth per group)."""

    status: str
    diagnostics: dict = field(default_factory=dict)


def ekf_rng(seed: int, set_name: str) -> np.random.Generator:
    """The generator of one set's radar and initial-state noise: ``[seed, crc32("ekf/<name>")]``."""
    return np.random.default_rng([int(seed), zlib.crc32(f"ekf/{set_name}".encode())])


def _say(msg: str) -> None:
    print(f"uavpipe estimate: {msg}", file=sys.stderr, flush=True)


def truth_runs(df: pd.DataFrame, *, where: str = "set") -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """A bulk set sorted by run and time, its states ``(R, T, 9)`` and the shared grid ``(T,)``.

    Raises
    ------
    ValueError
        One line naming ``where`` when a state column is missing or non-finite, or the runs do
        not share one time grid (the vectorised filter steps every run at once).
    """
    missing = [c for c in ("t_ns", "run_id", *STATE_COLUMNS) if c not in df.columns]
    if missing:
        raise ValueError(f"{where}: not a bulk set, missing column(s) {missing}")
    df = df.sort_values(["run_id", "t_ns"], kind="stable").reset_index(drop=True)
    sizes = df.groupby("run_id", sort=False).size()
    n_runs = len(sizes)
    if n_runs == 0:
        return df, np.zeros((0, 0, 9)), np.zeros(0, dtype=np.int64)
    if sizes.nunique() != 1:
        raise ValueError(f"{where}: runs differ in length ({sizes.min()}..{sizes.max()} samples); the "
                         "EKF over a set needs equal run lengths")
    T = int(sizes.iloc[0])
    t = df["t_ns"].to_numpy(np.int64).reshape(n_runs, T)
    if not (t == t[0]).all():
        raise ValueError(f"{where}: runs do not share one time grid (first run {t[0, 0]}..{t[0, -1]} ns)")
    if T > 1 and not (np.diff(t[0]) > 0).all():
        raise ValueError(f"{where}: time not strictly increasing within a run")
    x = df[list(STATE_COLUMNS)].to_numpy(np.float64).reshape(n_runs, T, 9)
    if not np.isfinite(x).all():
        raise ValueError(f"{where}: non-finite truth state values")
    return df, x, t[0]


def ekf_set(truth: pd.DataFrame, *, radar: RadarModel, q: float, rng: np.random.Generator,
            p0_sigma: tuple[float, float, float] = (1.0, 0.1, 0.01),
            where: str = "set") -> tuple[pd.DataFrame, dict]:
    """The EKF estimate of every run of one bulk set (see the module docstring).

    Parameters
    ----------
    truth : DataFrame
        A bulk set (:data:`SET_COLUMNS`); runs of equal length on one time grid.
    radar : RadarModel
        The radar synthesised from the truth (and the EKF's measurement model).
    q : float
        Jerk spectral density of the white-jerk Q (m²/s⁵).
    rng : Generator
        Draws the initial-state noise ``(R, 9)`` then the radar noise ``(R, T, 4)``.
    p0_sigma : 3 floats
        Standard deviations of P₀ for position, velocity, acceleration.
    where : str
        Named in error messages (the set's file).

    Returns
    -------
    estimate : DataFrame
        The set sorted by run and time, ``pos/vel/acc`` replaced by the EKF posterior means,
        ``alt_cal_m`` = −(estimated ``pos_d``), jerk NaN.
    diagnostics : dict
        ``runs``, ``steps``, ``rmse_{pos,vel,acc}`` (estimate vs truth over all samples),
        ``nis_mean``, ``n_diverged`` (runs ending more than :data:`DIVERGED_M` from the truth:
        with the radar on the ground, mostly runs tracked as their mirror image below the
        radar's horizontal plane, which range and the two direction cosines cannot tell apart).
    """
    df, x, t_ns = truth_runs(truth, where=where)
    R_, T = x.shape[:2]
    out = df.copy()
    if R_ == 0 or T == 0:
        for c in JERK_COLUMNS:
            out[c] = np.nan
        return out, {"runs": 0, "steps": 0, "n_diverged": 0}
    P0 = initial_cov(tuple(float(s) for s in p0_sigma))
    x0 = x[:, 0] + rng.standard_normal((R_, 9)) * np.sqrt(np.diag(P0))
    z = np.ascontiguousarray(np.swapaxes(radar.measure(x, rng), 0, 1))  # (T, R, 4)
    ekf = ExtendedKalmanFilter(ConstantAcceleration(float(q)), radar)
    prior = GaussianState(x0, np.broadcast_to(P0, (R_, 9, 9)), int(t_ns[0]))
    try:
        track = run_filter(ekf, prior, t_ns, z, store="mean")
    except ValueError as exc:
        raise ValueError(f"{where}: EKF failed: {exc}") from None
    est = track.mean.reshape(R_ * T, 9)
    for i, c in enumerate(STATE_COLUMNS):
        out[c] = est[:, i]
    for c in JERK_COLUMNS:
        out[c] = np.nan
    if "alt_cal_m" in out.columns:
        out["alt_cal_m"] = -out["pos_d_m"]
    err = track.mean - x
    # a direction-cosine radar does not see the sign of the third cosine: a target near the
    # radar's horizontal plane can be tracked as its mirror image below it (the down error
    # then grows to twice the height above the site); counted, not hidden
    diverged = np.linalg.norm(err[:, -1, 0:3], axis=-1) > DIVERGED_M
    diag = {"runs": int(R_), "steps": int(T), "nis_mean": float(track.nis.mean()),
            "n_diverged": int(diverged.sum())}
    for g, sl in (("pos", slice(0, 3)), ("vel", slice(3, 6)), ("acc", slice(6, 9))):
        diag[f"rmse_{g}"] = float(np.sqrt(np.mean(err[..., sl] ** 2)))
    return out, diag


def prior_increment_set(estimate: pd.DataFrame, *, where: str = "set") -> pd.DataFrame:
    """An EKF set (:func:`ekf_set`) with its ``pos/vel/acc`` replaced, run by run, by the pseudo-track
    of the EKF's predicted increments ``x̂⁻_{k+1} − x̂⁺_k`` (the thesis's printed (4.1),
    :func:`~pipeline.estimate.ekf_hmm.prior_increment_track`): what the classifier sees with
    ``increments: prior``. ``alt_cal_m`` follows ``pos_d``; the rest is unchanged."""
    df, x, t_ns = truth_runs(estimate, where=where)
    out = df.copy()
    if x.size == 0:
        return out
    p = prior_increment_track(x, t_ns).reshape(-1, 9)
    for i, c in enumerate(STATE_COLUMNS):
        out[c] = p[:, i]
    if "alt_cal_m" in out.columns:
        out["alt_cal_m"] = -out["pos_d_m"]
    return out


def classifier_set(estimate: pd.DataFrame, increments: str, *, where: str = "set") -> pd.DataFrame:
    """What the classifier reads of an EKF set (the set-table twin of
    :func:`~pipeline.estimate.ekf_hmm.classifier_state`): :func:`prior_increment_set` (``prior``,
    the thesis's printed (4.1)) or the set itself (``posterior``, digest §13.4)."""
    if increments not in INCREMENTS:
        raise ConfigError(f"{where}: increments must be one of {', '.join(INCREMENTS)}, not {increments!r}")
    return prior_increment_set(estimate, where=where) if increments == "prior" else estimate


@dataclass(frozen=True, kw_only=True)
class SetsSettings:
    """``estimate.sets`` (validated and defaulted by the config schema) and the radar."""

    q: float
    p0_sigma: tuple[float, float, float]
    radar: RadarModel
    increments: str = "prior"

    @classmethod
    def from_config(cls, config: Mapping | None) -> "SetsSettings":
        """From ``estimate.sets`` with the radar section under ``radar`` (default
        ``simulate.sensors.radar``'s defaults); a bad key is a :class:`ConfigError` naming it."""
        cfg = dict(config or {})
        radar_sec = cfg.pop("radar", None)
        sec = validate_section("estimate.sets", cfg)
        return cls(q=float(sec["q"]), p0_sigma=tuple(float(s) for s in sec["p0_sigma"]),
                   radar=RadarModel.from_config(radar_sec), increments=str(sec["increments"]))


def run_ekf_sets(inputs, outputs, config: Mapping | None, *, seed: int) -> EkfSetsResult:
    """Filter bulk sets with the CA EKF on synthesised radar; write them in the bulk-set schema.

    Parameters
    ----------
    inputs : mapping
        ``sets``: truth sets (``results/sim/sets/<set>.parquet``).
    outputs : mapping
        ``sets``: one path per input, same order and same file name (the set name, which
        seeds its noise): ``results/estimate/sets/<set>.parquet``.
    config : mapping
        ``estimate.sets`` (``q``, ``p0_sigma``) plus ``radar`` (the ``simulate.sensors.radar``
        section).
    seed : int
        The master seed.

    Returns
    -------
    EkfSetsResult
        ``diagnostics[<set>]``: runs, steps, RMSE per group, mean NIS.
    """
    ins, outs = declared_list(inputs, "sets"), declared_list(outputs, "sets")
    if len(ins) != len(outs):
        raise ConfigError(f"ekf_sets: {len(ins)} input set(s) but {len(outs)} output(s)")
    for i, o in zip(ins, outs):
        if Path(i).name != Path(o).name:
            raise ConfigError(f"ekf_sets: output {o} does not match input {i} (same set name expected)")
    st = SetsSettings.from_config(config)
    diagnostics = {}
    for i, o in zip(ins, outs):
        name = Path(o).stem
        truth = read_table(i, SET_COLUMNS)
        est, diag = ekf_set(truth, radar=st.radar, q=st.q, rng=ekf_rng(seed, name), p0_sigma=st.p0_sigma,
                            where=str(i))
        est = classifier_set(est, st.increments, where=str(i))
        write_table(est, o, SET_COLUMNS, name="simulate_set",
                    extra={"set": name, "seed": int(seed), "input": "ekf", "truth": str(i), "q": st.q,
                           "increments": st.increments,
                           "p0_sigma": list(st.p0_sigma), "radar_site_ned_m": list(st.radar.site_ned_m),
                           "runs": diag["runs"], "n_diverged": diag.get("n_diverged", 0),
                           **{k: v for k, v in diag.items() if k.startswith("rmse")}})
        diagnostics[name] = diag
        _say(f"ekf set {name}: {diag['runs']} runs x {diag['steps']} steps"
             + (f", RMSE pos/vel/acc {diag['rmse_pos']:.2f} m / {diag['rmse_vel']:.2f} m/s / "
                f"{diag['rmse_acc']:.2f} m/s2, {diag['n_diverged']} diverged" if diag["runs"] else ""))
    return EkfSetsResult("ok", diagnostics)
