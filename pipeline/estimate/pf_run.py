"""Entry point of the jump-Markov particle filter over one flight (issue 17, ``pf_jm``).

:func:`run_pf_jm` runs the bootstrap SIR filter of :mod:`pipeline.estimate.pf` with three modes
per particle — constant velocity, constant acceleration and an augmented coordinated turn
(:class:`~pipeline.estimate.models.PfConstantVelocity`,
:class:`~pipeline.estimate.models.PfConstantAcceleration`,
:class:`~pipeline.estimate.models.PfAugmentedCoordinatedTurn`, seed 001 §4/§13 item 2) — over the
horizontal plane of a flight, and writes ``results/estimate/pf_jm/<flight>.parquet`` (``io.schema``
table ``pf``).

**Measurement.** The preprocessed ``state`` table's NED position ``pos_n_m``, ``pos_e_m`` (every
flight that has a position has it there, from GPS or the autopilot's local position, whichever
preprocess chose, named in the metadata), as a 2-D Gaussian position fix with
``estimate.pf.measurement_sigma_m``. The state grid (25 Hz) is thinned to the sample nearest each
tick of ``rate_hz``; a sample without a position is a predict-only step. The vertical channel is
not filtered (the three modes differ in the horizontal plane; seed 001's CT is planar).

**Modes and Π.** Each mode has a mean dwell time ``dwell_s`` (config); Π over a step Δt is the
continuous-time chain that leaves mode i at rate 1/τ_i to the others uniformly,
``Π(Δt) = expm(G Δt)`` (:func:`~pipeline.estimate.pf.dwell_transition`), given for the nominal
step 1/rate_hz and re-timed to every actual Δt of the log by
:func:`pipeline.estimate.markov.retime` (digest 001 D5). On entering CA a particle draws an
along-track acceleration, on entering CT a turn rate (digest D4).

**Init.** Particles around the first position fix (``init_sigma`` m) with the state's velocity
there (``init_sigma`` m/s), ω = a = 0, modes uniform; weights 1/N. Randomness from
``default_rng([seed, crc32("pf_jm"), crc32(flight_id)])``. A step whose every particle falls
outside ``gate_sigma`` standard deviations re-initialises around the fix (counted,
``n_reinit``).

**Beside the classifier.** :func:`classifier_softmax` is the classifier's softmax of its
``ll_<label>`` columns at the nearest classified sample (within two of its periods). The flight
page puts it beside the mode fractions (the workflow's rule does not pass the classification,
so the filter never waits for or reruns with the classifier); given ``inputs.classified``
(``results/classify/<model_set>/<flight>.parquet``, e.g. from a script) it is written into the
table as ``cls_p_<label>``. The two are different class sets (motion modes against maneuvers).

Failures are placeholders: no state, a failed preprocess or no position gives an empty ``pf``
table with ``status: failed`` and the reason.
"""

from __future__ import annotations

import sys
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from ..io import schema
from ..io.parquet import read_table, read_table_meta, write_table
from ..io.stage import declared, declared_list
from .models import PF_STATE, PfAugmentedCoordinatedTurn, PfConstantAcceleration, PfConstantVelocity
from .pf import GaussianPositionLikelihood, ParticleFilter, dwell_transition, run_pf, track_meta
from .table import upper_triangle

F64 = NDArray[np.float64]

#: the pf_jm modes, in ``mode_p_<mode>`` order
PF_JM_MODES: tuple[str, ...] = ("cv", "ca", "ct")

#: ``estimate.pf`` defaults (rules/schemas/config.schema.yaml holds the same, described)
DEFAULTS: dict[str, Any] = {
    "n_particles": 2000,
    "jitter": "regularised",
    "rate_hz": 10.0,
    "measurement_sigma_m": 1.0,
    "resample": "systematic",
    "threshold": 1.0 / 3.0,
    "gate_sigma": 10.0,
    "init_sigma": [3.0, 1.0],
    "dwell_s": {"cv": 10.0, "ca": 3.0, "ct": 5.0},
    "noise": {"cv": {"sigma_a": 2.0},
              "ca": {"sigma_j": 5.0, "acc_init_sigma": 2.0},
              "ct": {"sigma_a": 2.0, "sigma_omega": 0.1, "omega_init_sigma": 0.3}},
}


@dataclass(frozen=True)
class PfResult:
    """What :func:`run_pf_jm` did: ``status`` ``ok``/``failed``, the reason, the diagnostics."""

    flight_id: str | None
    status: str
    error: str = ""
    diagnostics: dict = field(default_factory=dict)


def _say(msg: str) -> None:
    print(f"uavpipe pf_jm: {msg}", file=sys.stderr, flush=True)


def pf_config(section: Mapping[str, Any] | None) -> dict:
    """``estimate.pf`` merged over :data:`DEFAULTS` (nested ``dwell_s`` / ``noise`` per mode)."""
    sec = dict(section or {})
    out = {**DEFAULTS, **{k: v for k, v in sec.items() if k not in ("dwell_s", "noise")}}
    out["dwell_s"] = {**DEFAULTS["dwell_s"], **dict(sec.get("dwell_s") or {})}
    noise = dict(sec.get("noise") or {})
    out["noise"] = {m: {**DEFAULTS["noise"][m], **dict(noise.get(m) or {})} for m in PF_JM_MODES}
    return out


def job_config(section: Mapping[str, Any] | None) -> dict:
    """What one pf_jm job takes from ``estimate.pf``: everything but the vehicle list and the
    sub-objects of other estimators (``hmpf``, ``geolocation``), so editing those never reruns it."""
    return {k: v for k, v in dict(section or {}).items() if k not in ("vehicles", "hmpf", "geolocation")}


def jm_filter(cfg: Mapping[str, Any], dt_ref: float, rng: np.random.Generator) -> ParticleFilter:
    """The CV/CA/CT particle filter of a (merged) ``estimate.pf`` config at nominal step ``dt_ref``."""
    n = cfg["noise"]
    models = [PfConstantVelocity(float(n["cv"]["sigma_a"])),
              PfConstantAcceleration(float(n["ca"]["sigma_j"]), float(n["ca"]["acc_init_sigma"])),
              PfAugmentedCoordinatedTurn(float(n["ct"]["sigma_a"]), float(n["ct"]["sigma_omega"]),
                                         omega_init_sigma=float(n["ct"]["omega_init_sigma"]))]
    Pi = dwell_transition([float(cfg["dwell_s"][m]) for m in PF_JM_MODES], dt_ref)
    lik = GaussianPositionLikelihood(float(cfg["measurement_sigma_m"]), (0, 1),
                                     gate=None if cfg.get("gate_sigma") is None else float(cfg["gate_sigma"]))
    # the regularised PF's kernel over N, E, v_N, v_E after each resampling (jitter): a weave
    # far off CV/CT puts the fixes in the cloud's tail, the few particles there take the weight,
    # and the plain filter's cloud narrowed and fell behind (simulated M3: 5 re-initialisations)
    reg = (0, 1, 2, 3) if cfg["jitter"] == "regularised" else None
    return ParticleFilter(models, Pi, lik, n_particles=int(cfg["n_particles"]), resample=str(cfg["resample"]),
                          threshold=float(cfg["threshold"]), dt_ref=dt_ref, rng=rng, regularise_index=reg)


def pf_rng(seed: int, flight_id: str) -> np.random.Generator:
    """``default_rng([seed, crc32("pf_jm"), crc32(flight_id)])``."""
    return np.random.default_rng([int(seed), zlib.crc32(b"pf_jm"), zlib.crc32(str(flight_id).encode())])


def thin(t_ns: NDArray[np.int64], rate_hz: float | None) -> NDArray[np.int64]:
    """Indices of the samples nearest each tick of a ``rate_hz`` grid (all when None or faster)."""
    if rate_hz is None or len(t_ns) < 2:
        return np.arange(len(t_ns))
    grid = np.arange(t_ns[0], t_ns[-1] + 1, int(round(1e9 / float(rate_hz))), dtype=np.int64)
    j = np.clip(np.searchsorted(t_ns, grid), 1, len(t_ns) - 1)
    j = np.where(np.abs(t_ns[j - 1] - grid) <= np.abs(t_ns[j] - grid), j - 1, j)
    return np.unique(j)


def classifier_softmax(cls: pd.DataFrame, t_ns: NDArray[np.int64]) -> dict[str, F64]:
    """``cls_p_<label>``: softmax over the ``ll_<label>`` columns at the classified sample nearest
    each time (NaN farther than two classifier periods, or where every ll is −∞/NaN)."""
    ll_cols = [c for c in cls.columns if str(c).startswith("ll_")]
    if not ll_cols or not len(cls):
        return {}
    cls = cls.sort_values("t_ns")
    if "run_id" in cls.columns and cls["run_id"].nunique() > 1:
        cls = cls.drop_duplicates("t_ns", keep="last")
    tc = cls["t_ns"].to_numpy(np.int64)
    L = cls[ll_cols].to_numpy(np.float64)
    L = np.where(np.isfinite(L), L, -np.inf)
    m = L.max(axis=1, keepdims=True)
    ok = np.isfinite(m[:, 0])
    E = np.exp(L - np.where(ok[:, None], m, 0.0))
    P = np.where(ok[:, None], E / np.where(ok, E.sum(axis=1), 1.0)[:, None], np.nan)
    period = float(np.median(np.diff(tc))) if len(tc) > 1 else 1e9
    j = np.clip(np.searchsorted(tc, t_ns), 1, max(len(tc) - 1, 1)) if len(tc) > 1 else np.zeros(len(t_ns), int)
    if len(tc) > 1:
        j = np.where(np.abs(tc[j - 1] - t_ns) <= np.abs(tc[j] - t_ns), j - 1, j)
    far = np.abs(tc[j] - t_ns) > 2 * period
    out = {}
    for q, c in enumerate(ll_cols):
        v = P[j, q].copy()
        v[far] = np.nan
        out[f"cls_p_{c[3:]}"] = v
    return out


def pf_frame(t_ns: NDArray[np.int64], mean: F64, cov: F64, mode_p: F64, neff: F64, resampled,
             modes=PF_JM_MODES, extra: Mapping[str, F64] | None = None,
             table: tuple[schema.Column, ...] = schema.PF) -> pd.DataFrame:
    """A ``pf`` table (or ``table``, a tuple of columns extending it) from a filter track.

    ``mean`` (T, n) and ``cov`` (T, n, n) follow :data:`~pipeline.estimate.models.PF_STATE`; a
    filter with a shorter state (e.g. the weave classifier's [N, E, v_N, v_E, ω]) leaves the
    missing components NaN. ``extra``: further columns (``cls_p_*``, or those of ``table``).
    """
    T, n = len(t_ns), mean.shape[1]
    nan = np.full(T, np.nan)
    cols: dict[str, Any] = {"t_ns": np.asarray(t_ns, dtype=np.int64)}
    for i, c in enumerate(PF_STATE):
        cols[f"x_{c}"] = mean[:, i] if i < n else nan
    cols.update(upper_triangle(cov, len(PF_STATE)))
    for k, m in enumerate(modes):
        cols[f"mode_p_{m}"] = mode_p[:, k]
    cols["neff"] = np.asarray(neff, dtype=np.float64)
    cols["resampled"] = np.asarray(resampled, dtype=bool)
    cols.update(extra or {})
    return schema.conform(tuple(table), pd.DataFrame(cols))


def table_columns(df: pd.DataFrame, table: tuple[schema.Column, ...] = schema.PF) -> tuple[schema.Column, ...]:
    """The columns of ``table`` in ``df`` with the wildcard families (``mode_p_*``, ``cls_p_*``) named."""
    return schema.layout(table, df.columns)


def write_pf(df: pd.DataFrame, path, extra: dict, *, table: tuple[schema.Column, ...] = schema.PF,
             name: str = "pf") -> None:
    """Write a ``pf`` table (or ``table`` named ``name``; units per column, wildcard families
    included) atomically."""
    write_table(df, path, table_columns(df, table), name=name, extra=extra)


def _placeholder(path, extra: dict) -> None:
    write_pf(schema.empty("pf"), path, extra)


def run_pf_jm(inputs, outputs, config: Mapping[str, Any], *, flight_id: str | None = None,
              vehicle: str | None = None, seed: int = 0, model_set: str | None = None) -> PfResult:
    """The CV/CA/CT jump-Markov PF over one flight; writes ``outputs.pf_jm`` (module docstring).

    Parameters
    ----------
    inputs : mapping
        ``state`` (``results/state/<flight>.parquet``); optional ``classified`` (the flight's
        ``results/classify/<model_set>/<flight>.parquet``).
    outputs : mapping
        ``pf_jm``: the Parquet path.
    config : mapping
        ``estimate.pf`` (:func:`job_config`; missing keys take :data:`DEFAULTS`).
    flight_id, vehicle : str, optional
    seed : int
        The master seed.
    model_set : str, optional
        Recorded with the classifier columns (default: the classify table's parent folder).
    """
    out = declared(outputs, "pf_jm")
    cfg = pf_config(config)
    fid = flight_id or Path(str(declared(inputs, "state"))).stem
    base = {"flight_id": fid, "vehicle": vehicle, "estimator": "pf_jm", "modes": list(PF_JM_MODES),
            "n_particles": int(cfg["n_particles"]), "seed": int(seed)}
    t_start = time.perf_counter()

    def fail(reason: str) -> PfResult:
        _say(f"{fid}: placeholder ({reason})")
        _placeholder(out, {**base, "status": "failed", "error": reason, "n_steps": 0, "n_predict_only": 0,
                           "n_reinit": 0})
        return PfResult(fid, "failed", reason, {"n_steps": 0})

    sp = declared(inputs, "state")
    if not sp or not Path(sp).exists():
        return fail("no state table")
    st_meta = read_table_meta(sp)
    if st_meta.get("status") == "failed":
        return fail(f"preprocess failed: {st_meta.get('error') or 'unknown reason'}")
    state = read_table(sp)
    if not len(state) or not {"pos_n_m", "pos_e_m"} <= set(state.columns):
        return fail("no position in the state table")
    state = state.sort_values("t_ns").reset_index(drop=True)
    t_all = state["t_ns"].to_numpy(np.int64)
    idx = thin(t_all, cfg.get("rate_hz"))
    t = t_all[idx]
    z = state[["pos_n_m", "pos_e_m"]].to_numpy(np.float64)[idx]
    good = np.flatnonzero(np.all(np.isfinite(z), axis=1))
    if len(good) < 2:
        return fail(f"{len(good)} sample(s) with a position: nothing to filter")
    k0 = good[0]
    t, z = t[k0:], z[k0:]
    vcols = ["vel_n_mps", "vel_e_mps"]
    vel = state[vcols].to_numpy(np.float64)[idx][k0] if set(vcols) <= set(state.columns) else np.zeros(2)
    vel = np.where(np.isfinite(vel), vel, 0.0)  # the first fix's velocity, 0 where the state has none
    dt_ref = 1.0 / float(cfg["rate_hz"]) if cfg.get("rate_hz") else float(np.median(np.diff(t))) * 1e-9
    rng = pf_rng(seed, fid)
    pf = jm_filter(cfg, dt_ref, rng)
    s_pos, s_vel = (float(v) for v in cfg["init_sigma"])
    x0 = np.zeros((pf.N, len(PF_STATE)))
    x0[:, 0:2] = z[0] + s_pos * rng.standard_normal((pf.N, 2))
    x0[:, 2:4] = vel + s_vel * rng.standard_normal((pf.N, 2))
    pf.init(x0)
    tr = run_pf(pf, t, z)
    extra: dict[str, F64] = {}
    cls_info: dict[str, Any] = {"classifier": None}
    for cp in declared_list(inputs, "classified"):
        if not Path(cp).exists():
            continue
        cm = read_table_meta(cp)
        ms = model_set or Path(cp).parent.name
        if cm.get("status") == "failed":
            cls_info = {"classifier": ms, "classifier_error": cm.get("error") or "classification failed"}
            continue
        extra = classifier_softmax(read_table(cp), t)
        cls_info = {"classifier": ms, "classifier_labels": [k[6:] for k in extra]}
        break
    df = pf_frame(t, tr.mean, tr.cov, tr.mode_p, tr.neff, tr.resampled, extra=extra)
    frac = {m: float(np.nanmean(tr.mode_p[:, k])) for k, m in enumerate(PF_JM_MODES)}
    meta = {**base, "status": "ok", "error": "", "n_steps": int(len(t)),
            **track_meta(tr), "dt_ref_s": dt_ref, "rate_hz": cfg.get("rate_hz"),
            "dwell_s": {m: float(cfg["dwell_s"][m]) for m in PF_JM_MODES},
            "Pi_ref": pf.transition_matrix(dt_ref).tolist(), "noise": cfg["noise"],
            "measurement": "state pos_n_m/pos_e_m",
            "position_source": ((st_meta.get("preprocess") or {}).get("sources") or {}).get("position"),
            "measurement_sigma_m": float(cfg["measurement_sigma_m"]), "resample": cfg["resample"],
            "threshold": float(cfg["threshold"]), "gate_sigma": cfg.get("gate_sigma"),
            "init_sigma": [s_pos, s_vel], "mode_fraction_mean": frac, **cls_info}
    # the run time goes to the caller and the Snakemake benchmark file, not into the table:
    # same seed -> same bytes
    wall_s = round(time.perf_counter() - t_start, 3)
    write_pf(df, out, meta)
    _say(f"{fid}: {len(t)} steps, N={pf.N}, {meta['n_resampled']} resampled, {meta['n_reinit']} re-initialised, "
         f"mode fractions " + ", ".join(f"{m} {v:.2f}" for m, v in frac.items()))
    return PfResult(fid, "ok", "", {**{k: meta[k] for k in ("n_steps", "n_predict_only", "n_reinit", "n_resampled",
                                                              "mode_fraction_mean")}, "wall_s": wall_s})
