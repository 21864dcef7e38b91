"""The seed-003 weave classifier (``hmpf``) on real flights: one job per flight of
``estimate.pf.hmpf.vehicles`` writes ``results/estimate/hmpf/<flight>.parquet`` (table ``hmpf``).

The flight's preprocessed horizontal position (``state`` ``pos_n_m``, ``pos_e_m``) is sampled
every T = ``dt_s`` (linear interpolation; a step inside a ``gap`` or without a finite position is
a predict-only step) and filtered as a GPS track (σ = ``gps_sigma_m``) by
:func:`pipeline.estimate.weave.hmpf_filter`.

δ_max and θ_max (digest 003 §11 item 5): with ``from_train`` (default) they come from the
labelled segments of the vehicle's **role-train** flights, never from the flight being
classified (a train flight is classified with the maxima of the *other* train flights). On each
training flight, resampled at T, a step whose course changes faster than
``turn_threshold_radps`` is a curve step; inside each labelled segment the runs of straight
steps give straight lengths δ and the runs of same-sign curve steps give turn angles |θ|. δ_max
and θ_max are the largest of each — "larger than every observed weave segment", as the thesis
set its final values (§4.3). With no other training flight (or ``from_train: false``) the
config values are used; the output metadata says which.

Process noise (digest 003 A12: the thesis's ship values, σ_aN = 1.754e-5 m/s², are "likely too
tight for UAVs"): with ``noise_from_train`` (default) σ_aT, σ_aN and σ_xy come from the same
training segments by moments (:func:`weave_noise`). On the shipped F3A flights the ship values
left every particle's likelihood below the smallest double on 85–124 of 442–569 steps, each a
re-initialisation that resets the mode fractions; the F3A levels from fc-p23-036 (along-track
RMS 4.3 m/s² on straights, 6.3 on curves) re-initialise on none of them. A flight with no
*other* role-train flight of its vehicle (fc-p23-036 itself, the one F3A training flight, or
any flight of a vehicle without one) takes the noise from its own labelled segments
(``segments``): noise levels are the airframe's, not its labels', so this is no in-sample fit of
what the classifier decides (δ_max and θ_max stay out-of-sample: config); with the ship values
fc-p23-036 re-initialised on 92 of its 496 steps, 9.5 / 12.7 m N/E RMS from its state.

Failures are placeholders with the reason (no positions, fewer than two samples), never crashes.
"""

from __future__ import annotations

import sys
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..config import validate_section
from ..io import schema
from ..io.parquet import read_table, write_table
from .models import wrap_angle
from .table import upper_triangle
from .weave import MODES, SUBMODES, GpsSensor, HmpfConfig, HmpfTrack, hmpf_filter

#: the output table (``pipeline.io.schema.HMPF``)
TABLE = "hmpf"


@dataclass(frozen=True)
class HmpfResult:
    """What :func:`run_hmpf` did: ``status`` ``ok`` or ``failed`` (placeholder), the reason, diagnostics."""

    flight_id: str | None
    status: str
    error: str = ""
    diagnostics: dict[str, Any] = field(default_factory=dict)


def _say(msg: str) -> None:
    print(f"hmpf: {msg}", file=sys.stderr, flush=True)


def sample_positions(state: pd.DataFrame, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """``(t_ns (T,), z (T, 2))``: the state's (N, E) every ``dt_s`` from its first finite sample;
    steps inside a gap or between non-finite positions are NaN (predict-only)."""
    t = state["t_ns"].to_numpy(np.int64)
    p = state[["pos_n_m", "pos_e_m"]].to_numpy(np.float64)
    ok = np.all(np.isfinite(p), axis=1)
    if "gap" in state:
        ok &= ~state["gap"].to_numpy(bool)
    if ok.sum() < 2:
        return np.empty(0, np.int64), np.empty((0, 2))
    t, p = t[ok], p[ok]
    step = int(round(dt_s * 1e9))
    tk = np.arange(t[0], t[-1] + 1, step, dtype=np.int64)
    z = np.stack([np.interp(tk, t, p[:, i]) for i in range(2)], axis=1)
    # a step farther than 2 T from any finite sample is a gap: predict-only
    j = np.clip(np.searchsorted(t, tk), 1, len(t) - 1)
    near = np.minimum(np.abs(tk - t[j - 1]), np.abs(t[j] - tk)) <= 2 * step
    z[~near] = np.nan
    return tk, z


def segment_runs(t_ns: np.ndarray, z: np.ndarray, dt_s: float, turn_threshold: float) -> tuple[list[float], list[float]]:
    """Straight lengths (m) and |turn angles| (rad) of one resampled track (see the module docstring)."""
    d = np.diff(z, axis=0)
    ok = np.all(np.isfinite(d), axis=1)
    length = np.hypot(d[:, 0], d[:, 1])
    course = np.arctan2(d[:, 1], d[:, 0])
    dchi = np.full(len(d), np.nan)
    dchi[1:] = wrap_angle(course[1:] - course[:-1])
    moving = length > 1e-6
    dchi[1:][~(moving[1:] & moving[:-1])] = np.nan
    kind = np.where(~np.isfinite(dchi) | ~ok, 0, np.where(np.abs(dchi) / dt_s > turn_threshold, np.sign(dchi), 2))
    # 2 = straight, ±1 = curve by sign, 0 = unusable (breaks a run)
    straights, turns = [], []
    i = 0
    while i < len(kind):
        j = i
        while j + 1 < len(kind) and kind[j + 1] == kind[i]:
            j += 1
        if kind[i] == 2:
            straights.append(float(length[i:j + 1].sum()))
        elif kind[i] != 0:
            turns.append(float(abs(np.nansum(dchi[i:j + 1]))))
        i = j + 1
    return straights, turns


def _segment_tracks(states: Sequence[pd.DataFrame], segments: Sequence[pd.DataFrame], dt_s: float):
    """``(t_ns, z)`` of each labelled segment of each training flight, resampled at ``dt_s``
    (:func:`sample_positions`); segments shorter than three steps are left out."""
    for st, sg in zip(states, segments):
        for r in sg.itertuples():
            if not str(r.label):
                continue
            part = st[(st["t_ns"] >= r.t_start_ns) & (st["t_ns"] <= r.t_end_ns)]
            tk, z = sample_positions(part, dt_s)
            if len(tk) >= 3:
                yield tk, z


def weave_maxima(states: Sequence[pd.DataFrame], segments: Sequence[pd.DataFrame], dt_s: float,
                 turn_threshold: float) -> tuple[float, float, dict[str, Any]]:
    """δ_max (m) and θ_max (rad) from training flights' labelled segments (module docstring).

    Returns ``(delta_max, theta_max, diagnostics)``; NaN where no straight (turn) was found.
    """
    straights, turns, n_seg = [], [], 0
    for tk, z in _segment_tracks(states, segments, dt_s):
        n_seg += 1
        s_, t_ = segment_runs(tk, z, dt_s, turn_threshold)
        straights += s_
        turns += t_
    dm = max(straights) if straights else float("nan")
    tm = max(turns) if turns else float("nan")
    return dm, tm, {"n_segments": n_seg, "n_straights": len(straights), "n_turns": len(turns),
                    "straight_median_m": float(np.median(straights)) if straights else None,
                    "turn_median_rad": float(np.median(turns)) if turns else None}


#: fewest second differences a noise level is estimated from (else the config value stays)
MIN_NOISE_SAMPLES = 10


def weave_noise(states: Sequence[pd.DataFrame], segments: Sequence[pd.DataFrame], dt_s: float,
                turn_threshold: float) -> tuple[dict[str, float], dict[str, Any]]:
    r"""The filter's process noise from training flights' labelled segments, by moments.

    On each segment resampled at T, the step velocities are v_k = (z_{k+1} − z_k)/T and the
    second differences a_k = (v_{k+1} − v_k)/T; a transition whose course changes faster than
    ``turn_threshold`` (rad/s) is a curve, otherwise straight. Under the filter's own
    piecewise-constant white acceleration w (x_{k+1} = F x_k + G w_k, G = [T²/2, T]),

    .. math:: z_{k+2} - 2 z_{k+1} + z_k = \tfrac{T^2}{2}(w_k + w_{k+1})
              \;\Rightarrow\; \sigma_w^2 = 2\,\overline{a_k^2},

    so with t = v_k/|v_k| and n ⊥ t (seed 003 §4.2.2, CM: Q = σ_T² t tᵀ + σ_N² n nᵀ; ACT:
    isotropic σ_xy, and a constant turn keeps the speed, so only the along-track part of a curve
    transition is noise):

    * ``sigma_at_mps2`` = √(2 mean((a·t)²)) and ``sigma_an_mps2`` = √(2 mean((a·n)²)) over
      straight transitions;
    * ``sigma_axy_mps2`` = √(2 mean((a·t)²)) over curve transitions.

    Nothing is subtracted for the position's own noise: a fused track is smoother than its
    nominal σ (on fc-p23-036 the straight steps' cross-track RMS is 0.82 m/s², below the 2.45
    m/s² that 1 m of white position noise alone would give), so the estimate is an upper bound,
    erring towards a wider cloud. σ_α (the turn-rate walk) keeps its config value: a course
    projected from 3-D aerobatics is no constant-rate turn to measure it from.

    Returns
    -------
    (dict, dict)
        ``{sigma key: value}`` for each level with at least :data:`MIN_NOISE_SAMPLES`
        transitions (others absent: the config value stays), and diagnostics (counts, RMS).
    """
    at_s, an_s, at_c = [], [], []
    for _, z in _segment_tracks(states, segments, dt_s):
        v = np.diff(z, axis=0) / dt_s
        a = np.diff(v, axis=0) / dt_s
        sp = np.hypot(v[:, 0], v[:, 1])
        dchi = wrap_angle(np.diff(np.arctan2(v[:, 1], v[:, 0])))
        ok = np.all(np.isfinite(a), axis=1) & (sp[:-1] > 1e-6) & (sp[1:] > 1e-6)
        t = v[:-1] / np.where(sp[:-1] > 1e-6, sp[:-1], 1.0)[:, None]
        a_t = a[:, 0] * t[:, 0] + a[:, 1] * t[:, 1]
        a_n = -a[:, 0] * t[:, 1] + a[:, 1] * t[:, 0]
        straight = ok & (np.abs(dchi) / dt_s <= turn_threshold)
        curve = ok & ~straight
        at_s.append(a_t[straight])
        an_s.append(a_n[straight])
        at_c.append(a_t[curve])
    out: dict[str, float] = {}
    diag: dict[str, Any] = {}
    for key, parts in (("sigma_at_mps2", at_s), ("sigma_an_mps2", an_s), ("sigma_axy_mps2", at_c)):
        x = np.concatenate(parts) if parts else np.empty(0)
        diag[key] = {"n": int(len(x)), "rms": float(np.sqrt(np.mean(x * x))) if len(x) else None}
        if len(x) >= MIN_NOISE_SAMPLES and np.mean(x * x) > 0:
            out[key] = float(np.sqrt(2.0 * np.mean(x * x)))
    return out, diag


def hmpf_frame(t_ns: np.ndarray, track: HmpfTrack, run: int = 0) -> pd.DataFrame:
    """The ``hmpf`` table of run ``run`` of ``track`` at times ``t_ns``."""
    names = [c.name for c in schema.HMPF]
    d: dict[str, Any] = {"t_ns": np.asarray(t_ns, np.int64)}
    xs = [c for c in names if c.startswith("x_")]
    for i, c in enumerate(xs):
        d[c] = track.mean[run, :, i]
    d.update(upper_triangle(track.cov[run], 5))
    for k, m in enumerate(MODES):
        d[f"mode_p_{m}"] = track.mode_p[run, :, k]
    for k, m in enumerate(SUBMODES):
        d[f"submode_p_{m}"] = track.submode_p[run, :, k]
    d.update(neff=track.neff[run], resampled=track.resampled[run], af=track.af[run],
             weave_detected=track.weave_detected[run])
    return pd.DataFrame(d)[names]


def _placeholder(path, extra: dict) -> None:
    write_table(schema.empty(TABLE), path, schema.columns(TABLE), name=TABLE, extra=extra)


def _paths_of(inputs: Mapping, key: str) -> list[str]:
    get = getattr(inputs, "get", None)
    v = get(key) if callable(get) else None
    if v is None:
        return []
    return [str(v)] if isinstance(v, (str, Path)) else [str(x) for x in v]


def _raise_noise(cfg: HmpfConfig, sig: Mapping[str, float], source: str) -> tuple[HmpfConfig, str | None]:
    """``cfg`` with each noise level of ``sig`` (:func:`weave_noise`) that exceeds the configured
    one, and the source text (``source``, naming the raised levels unless all three are), or
    ``None`` when none does: never below the config, since a track smoother than the model (a
    noise-free simulation, a heavily fused position) would otherwise starve the cloud."""
    raised = {k: v for k, v in sig.items() if v > getattr(cfg, k)}
    if not raised:
        return cfg, None
    text = source if len(raised) == 3 else f"{source} ({', '.join(sorted(raised))}), config (the others)"
    return cfg.with_(**raised), text


def run_hmpf(inputs: Mapping, outputs: Mapping, config: Mapping | None, *, flight_id: str | None = None,
             seed: int = 0, **_job) -> HmpfResult:
    """Run the weave classifier over one flight and write ``outputs['hmpf']``.

    Parameters
    ----------
    inputs : mapping
        ``state`` (the flight's ``state`` table); optional ``train_states`` and
        ``train_segments`` (lists, the vehicle's *other* role-train flights, in the same order);
        optional ``segments`` (the flight's own, for the noise when there is no other training
        flight).
    outputs : mapping
        ``hmpf``: the output Parquet path.
    config : mapping or None
        The ``estimate.pf.hmpf`` section.
    flight_id : str, optional
        For the messages and the generator (``[seed, crc32(flight_id)]``).
    seed : int
        Master seed.
    """
    out = outputs["hmpf"] if not hasattr(outputs, "hmpf") else outputs.hmpf
    out = out[0] if isinstance(out, (list, tuple)) else out
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    sec = validate_section("estimate.pf.hmpf", config)
    cfg = HmpfConfig.from_config(sec)
    fid = flight_id or "flight"
    state_path = _paths_of(inputs, "state")
    state = read_table(state_path[0]) if state_path and Path(state_path[0]).exists() else None
    if state is None or not {"pos_n_m", "pos_e_m", "t_ns"} <= set(state.columns):
        reason = "no state table with positions"
        _say(f"{fid}: placeholder ({reason})")
        _placeholder(out, {"status": "failed", "reason": reason, "flight_id": fid})
        return HmpfResult(flight_id, "failed", reason)
    tk, z = sample_positions(state, cfg.dt_s)
    if len(tk) < 2 or not np.all(np.isfinite(z[:2])):
        reason = "fewer than two finite positions at the filter step"
        _say(f"{fid}: placeholder ({reason})")
        _placeholder(out, {"status": "failed", "reason": reason, "flight_id": fid})
        return HmpfResult(flight_id, "failed", reason)

    source, mx = "config", {}
    tr_states, tr_segs = _paths_of(inputs, "train_states"), _paths_of(inputs, "train_segments")
    # read once: the maxima and the noise both come from these segments
    train = ([read_table(p) for p in tr_states], [read_table(p) for p in tr_segs]) \
        if tr_states and (sec["from_train"] or sec["noise_from_train"]) else ([], [])
    if sec["from_train"] and tr_states:
        dm, tm, mx = weave_maxima(*train, cfg.dt_s, float(sec["turn_threshold_radps"]))
        if np.isfinite(dm) and np.isfinite(tm) and dm > 0 and tm > 0:
            cfg = cfg.with_(delta_max_m=float(dm), theta_max_rad=float(tm))
            source = "train"
        else:
            source = "config (no straight or turn found in the training flights' segments)"
    elif sec["from_train"]:
        source = "config (no other role-train flight of the vehicle)"
    noise_source, noise_diag = "config", {}
    if sec["noise_from_train"] and tr_states:
        sig, noise_diag = weave_noise(*train, cfg.dt_s, float(sec["turn_threshold_radps"]))
        cfg, raised = _raise_noise(cfg, sig, "train")
        if raised:
            noise_source = raised
        elif sig:
            noise_source = "config (the training flights' segments are no noisier)"
        else:
            noise_source = "config (too few straight or curve steps in the training flights' segments)"
    elif sec["noise_from_train"]:
        noise_source = "config (no other role-train flight of the vehicle)"
        own_seg = _paths_of(inputs, "segments")
        if own_seg and Path(own_seg[0]).exists():
            # the airframe's noise from the flight's own segments (module docstring)
            sig, noise_diag = weave_noise([state], [read_table(own_seg[0])], cfg.dt_s,
                                          float(sec["turn_threshold_radps"]))
            cfg, raised = _raise_noise(cfg, sig, "own segments")
            if raised:
                noise_source = f"{raised} (no other role-train flight of the vehicle)"
    rng = np.random.default_rng([int(seed), zlib.crc32(fid.encode())])
    track = hmpf_filter(z, GpsSensor(cfg.gps_sigma_m), cfg, rng)
    df = hmpf_frame(tk, track)
    flag = df["weave_detected"].to_numpy(bool)
    first = int(tk[np.argmax(flag)]) if flag.any() else None
    diag = {"status": "ok", "flight_id": fid, "n_steps": int(len(tk)), "n_predict_only": int((~np.isfinite(z).all(1)).sum()),
            "delta_max_m": cfg.delta_max_m, "theta_max_rad": cfg.theta_max_rad, "maxima_source": source,
            "train_flights": [Path(p).stem for p in tr_states], "maxima": mx, "n_particles": cfg.n_particles,
            "dt_s": cfg.dt_s, "method": cfg.method, "tau": cfg.tau, "detector_window": cfg.detector_window,
            "startup_steps": cfg.startup_steps, "first_detection_t_ns": first,
            "fraction_flagged": float(flag.mean()), "n_reinit": int(track.n_reinit[0]),
            "sigma_at_mps2": cfg.sigma_at_mps2, "sigma_an_mps2": cfg.sigma_an_mps2,
            "sigma_axy_mps2": cfg.sigma_axy_mps2, "noise_source": noise_source, "noise": noise_diag,
            "n_neff_collapsed": int((track.neff[0] < 2.0).sum())}
    write_table(df, out, schema.columns(TABLE), name=TABLE, extra=diag)
    _say(f"{fid}: {len(tk)} steps, δ_max {cfg.delta_max_m:.0f} m, θ_max {cfg.theta_max_rad:.2f} rad ({source}); "
         f"σ_aT/σ_aN/σ_xy {cfg.sigma_at_mps2:.2f}/{cfg.sigma_an_mps2:.2g}/{cfg.sigma_axy_mps2:.2f} m/s² ({noise_source}); "
         f"{int(track.n_reinit[0])} re-initialised; flagged {100 * flag.mean():.0f} % of steps")
    return HmpfResult(flight_id, "ok", "", diag)
