"""The seed-001 section of ``study_pf``: multi-UAV camera geo-location (digest 001 §10–§13).

:func:`geolocation_study` runs the thesis's scenarios with :mod:`pipeline.simulate.geolocation`
and the config values fixed in ``estimate.pf.geolocation`` (written to the ``geo_config`` table):

- §6.1 *base*: CV target, 3 stationary observers, N = 50;
- §6.2 *maneuvering*: the Π_d five-mode target, 3 stationary observers, Π_p filter, N = 50;
- §6.3 *mobile*: as §6.2 with 3 orbiting observers (30/40/50 m);
- §6.4 particle sweep and §6.5 observer sweep, both on the §6.3 setup.

Every acceptance check of issue 17 is a RESULT row with its number and a 0/1 ``…_met`` row;
nothing is tuned to meet a target. ε is the mean 3-D error (m) pooled over time (after the
first second, digest D11) and runs; η% the mean percent error ``100 ε_k / mean_u ‖p − p^U_u‖``.

The lead wires this into ``pipeline/studies/pf.py`` (its "Seed 001" section):
``tables, rows = geolocation_study(settings, seed=seed, size=size, progress=progress)``, then
``geolocation_panels(tables)`` gives the page panels as **plotly figure dicts** (title, dict).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from contextlib import closing
from typing import Any

import numpy as np
import pandas as pd

from ..simulate.geolocation import GeolocationConfig, per_step_frame, run_scenario, summarise
from .base import run_calls

#: per-size run settings (durations in s); ``small`` is what the RESULT lines in the report use.
#: Thesis size follows the thesis's counts: §6 "Each test run is performed a number of times,
#: usually 50" (the §6.1–§6.3 setups, and the §6.4 particle sweep, which names no count of its
#: own), §6.5 "Each test case is run ten times" (the observer sweep).
GEO_SIZES: dict[str, dict[str, Any]] = {
    "tiny": {"runs": 1, "particle_runs": 1, "observer_runs": 1, "base_s": 3.0, "maneuvering_s": 3.0,
             "mobile_s": 3.0, "sweep_s": 2.0, "particles": [10, 80], "observers": [1, 2], "workers": 1},
    "small": {"runs": 10, "particle_runs": 6, "observer_runs": 6, "base_s": 120.0, "maneuvering_s": 180.0,
              "mobile_s": 180.0, "sweep_s": 90.0, "particles": [10, 20, 40, 80, 160], "observers": [1, 2, 4, 8, 16],
              "workers": 1},
    "thesis": {"runs": 50, "particle_runs": 50, "observer_runs": 10, "base_s": 120.0, "maneuvering_s": 180.0,
               "mobile_s": 180.0, "sweep_s": 180.0, "particles": [10, 20, 40, 80, 160], "observers": [1, 2, 4, 8, 16],
               "workers": 2},
}
#: ``workers``: processes the runs are spread over (each run is seeded on its own, so the tables
#: are the same for any count; only the step times of ``geo_timing`` differ: each worker loads
#: the compiled kernels on its first run, and the workers share the machine)
#: the thesis's percent-error anchors (digest §12)
THESIS_ETA = {"base": "6-9 %", "maneuvering": "5-8 %", "mobile": "~7 % at ~70 m"}
ETA_LIMIT_PCT = 15.0

Row = tuple[str, Any, str]


def _cfg(settings: Mapping) -> GeolocationConfig:
    return GeolocationConfig.from_config(settings.get("geolocation"))


def geolocation_study(settings: Mapping, *, seed: int, size: str,
                      progress: Callable[[str], None] | None = None) -> tuple[dict[str, pd.DataFrame], list[Row]]:
    """Run the seed-001 scenarios and sweeps; return ``(tables, RESULT rows)``.

    Parameters
    ----------
    settings : mapping
        ``geolocation``: the ``estimate.pf.geolocation`` config section (defaults when absent);
        optional ``geo_sizes``: ``{size: {...}}`` overriding :data:`GEO_SIZES` (its keys, and
        ``observer_particles``: the observer sweep's particle count, default the filter's).
    seed : int
        Run ``r`` of a scenario draws from ``default_rng([seed, crc32(scenario), r])``, split
        into independent target / observer / pixel-noise / filter streams: every point of the
        particle and observer sweeps replays the same targets (common random numbers), and the
        observer sweep adds UAVs to the same scene.
    size : str
        ``tiny``, ``small`` or ``thesis``.
    progress : callable, optional
        Stage lines (e.g. :class:`~pipeline.studies.base.Progress`).

    Returns
    -------
    tables : dict
        ``geo_summary`` (one row per scenario / sweep point), ``geo_series`` (per time index,
        averaged over runs, per scenario / sweep point), ``geo_config`` (the chosen values,
        ``key``/``value`` JSON), all three the same for the same seed, and ``geo_timing`` (mean
        µs per filter step of each scenario / sweep point, ``perf_counter_ns``: this machine's).
    rows : list of (name, value, definition)
    """
    say = progress or (lambda msg: None)
    if size not in GEO_SIZES:
        raise ValueError(f"geolocation study: unknown size {size!r}; expected one of {', '.join(GEO_SIZES)}")
    over = dict((settings.get("geo_sizes") or {}).get(size) or {})
    bad = sorted(set(over) - set(GEO_SIZES[size]) - {"observer_particles"})
    if bad:
        raise ValueError(f"geolocation study: unknown run-plan key(s) {bad}; known: "
                         f"{sorted({*GEO_SIZES[size], 'observer_particles'})}")
    run = {**GEO_SIZES[size], **over}
    n_obs_particles = run.get("observer_particles")
    cfg = _cfg(settings)
    summary, series, timing = [], [], []

    # every case planned first: (name, scenario, runs, duration, observers, particles, tag)
    cases = [("base", "base", run["runs"], run["base_s"], 3, None, ""),
             ("maneuvering", "maneuvering", run["runs"], run["maneuvering_s"], 3, None, ""),
             ("mobile", "mobile", run["runs"], run["mobile_s"], 3, None, "")]
    cases += [(f"particles_{n}", "mobile", run["particle_runs"], run["sweep_s"], 3, int(n), f"N{n}")
              for n in run["particles"]]
    cases += [(f"observers_{o}", "mobile", run["observer_runs"], run["sweep_s"], int(o),
               None if n_obs_particles is None else int(n_obs_particles), f"O{o}")
              for o in run["observers"]]
    workers = max(1, int(run.get("workers", 1)))
    if workers > 1:
        say(f"seed 001: {sum(int(c[2]) for c in cases)} runs on {workers} worker processes")
    # one call per run, so the worker processes share every case; results come back in order
    calls = [dict(scenario=scenario, cfg=cfg, n_runs=1, seed=seed, n_observers=n_obs, n_particles=n_particles,
                  duration_s=float(duration), tag=tag, first_run=r)
             for _, scenario, n_runs, duration, n_obs, n_particles, tag in cases for r in range(int(n_runs))]
    done: dict[str, dict[str, float]] = {}
    with closing(run_calls(run_scenario, calls, workers)) as results:
        for name, scenario, n_runs, duration, n_obs, n_particles, tag in cases:
            say(f"seed 001: {name} ({n_runs} runs x {duration:g} s, {n_obs} observers, "
                f"N = {n_particles or cfg.n_particles})")
            runs = [r for _ in range(int(n_runs)) for r in next(results)]
            s = summarise(runs)
            say(f"seed 001: {name}: eps {s['eps_m']:.2f} m, eta {s['eta_pct']:.2f} %, mean distance "
                f"{s['mean_dist_m']:.1f} m, {s['step_us']:.0f} us/step")
            key = {"case": name, "scenario": scenario, "n_observers": n_obs,
                   "n_particles": int(n_particles or cfg.n_particles)}
            # step times apart from the results: the results are the same bytes for the same
            # seed, the times are the machine's (digest 001 §13 item 5 asks for both)
            summary.append({**key, "duration_s": float(duration), **{k: v for k, v in s.items() if k != "step_us"}})
            timing.append({**key, "step_us": s["step_us"]})
            series.append(per_step_frame(runs, case=name))
            done[name] = s
    base, man, mob = done["base"], done["maneuvering"], done["mobile"]
    sw_n = {n: done[f"particles_{n}"] for n in run["particles"]}
    sw_o = {o: done[f"observers_{o}"] for o in run["observers"]}
    eps_n = {n: s["eps_m"] for n, s in sw_n.items()}
    eps_o = {o: s["eps_m"] for o, s in sw_o.items()}

    rows: list[Row] = []
    bound = 100.0 * float(np.sin(cfg.sigma_psi_rad))
    rows.append(("geo_sigma_px", round(cfg.sigma_px, 2), f"pixel noise f*tan(sigma_psi), sigma_psi = {cfg.sigma_psi_rad} rad, f = {cfg.focal_px:g} px"))
    rows.append(("geo_bound_pct", round(bound, 1), "single-bearing relative-error bound 100*sin(sigma_psi) (digest 001 §11)"))
    for name, s in (("base", base), ("maneuvering", man), ("mobile", mob)):
        rows.append((f"geo_eta_pct_{name}", round(s["eta_pct"], 2),
                     f"mean percent error eta% of the §6.{('base', 'maneuvering', 'mobile').index(name) + 1} setup "
                     f"({s['n_runs']} runs, size {size}); thesis {THESIS_ETA[name]}"))
        rows.append((f"geo_eps_m_{name}", round(s["eps_m"], 2), f"mean 3-D error (m), {name}; median {s['median_eps_m']:.2f} m"))
        rows.append((f"geo_lost_runs_{name}", f"{s['n_lost']}/{s['n_runs']}",
                     f"{name}: runs that end with no observer detecting the target (the cameras, aimed at the "
                     "estimate, lost it; the error then grows unchecked)"))
        rows.append((f"geo_eta_pct_{name}_not_lost", round(s["not_lost_eta_pct"], 2),
                     f"eta% of the {name} setup over the runs not lost (diagnosis; the target is geo_eta_pct_{name})"))
        rows.append((f"geo_eta_pct_{name}_run_median", round(s["median_run_eta_pct"], 2),
                     f"median over runs of each run's mean eta%, {name} (diagnosis)"))
    rows.append(("geo_mobile_dist_60_80_pct", round(mob["dist_60_80_pct"], 1),
                 "§6.3 setup: share of time (%) the mean observer-target distance is within 60-80 m (thesis "
                 "Fig. 6.11: 'For the majority of the runs, the UAVs maintain a distance to the target between "
                 f"60-80 meters'); below 50 m {mob['dist_lt_50_pct']:.1f} %, above 80 m {mob['dist_gt_80_pct']:.1f} % "
                 "(thesis: above 80 m while approaching at the start, very little below 50 m)"))
    for name, s in (("base", base), ("maneuvering", man)):
        rows.append((f"geo_eta_{name}_met", int(s["eta_pct"] <= ETA_LIMIT_PCT), f"eta% <= {ETA_LIMIT_PCT:g} % in the {name} setup"))
    for n, e in eps_n.items():
        rows.append((f"geo_eps_m_particles_{n}", round(e, 2), f"mean 3-D error (m) with N = {n} particles (§6.3 setup, §6.4)"))
    for o, e in eps_o.items():
        rows.append((f"geo_eps_m_observers_{o}", round(e, 2), f"mean 3-D error (m) with {o} observers (§6.3 setup, §6.5)"))
    # the sweeps' means are over few runs, so one run whose cameras lose the target moves a point
    for kind, sw in (("particles", sw_n), ("observers", sw_o)):
        for k, st in sw.items():
            rows.append((f"geo_lost_runs_{kind}_{k}", f"{st['n_lost']}/{st['n_runs']}",
                         f"{kind} sweep at {k}: runs that end with no observer detecting the target"))
            rows.append((f"geo_eps_m_{kind}_{k}_not_lost", round(st["not_lost_eps_m"], 2),
                         f"{kind} sweep at {k}: mean 3-D error (m) over the runs not lost (diagnosis)"))
    if 1 in eps_o and 2 in eps_o:
        rows.append(("geo_obs_1_to_2_met", int(eps_o[2] <= eps_o[1] / 2), "eps(2) <= eps(1)/2"))
    if 2 in eps_o and 4 in eps_o:
        rows.append(("geo_obs_2_to_4_met", int(eps_o[4] <= eps_o[2]), "eps(4) <= eps(2)"))
    if all(o in eps_o for o in (4, 8, 16)):
        m = min(eps_o[4], eps_o[8])
        ok = all(abs(eps_o[o] - m) <= 0.2 * m for o in (8, 16))
        rows.append(("geo_obs_plateau_met", int(ok), "eps(8) and eps(16) within 20 % of min(eps(4), eps(8))"))
    if 10 in eps_n and 80 in eps_n:
        rows.append(("geo_particles_10_vs_80_met", int(eps_n[10] >= 1.5 * eps_n[80]), "eps(N=10) >= 1.5 eps(N=80)"))
    if 160 in eps_n and 80 in eps_n:
        rows.append(("geo_particles_160_vs_80_met", int(eps_n[160] >= 0.8 * eps_n[80]), "eps(N=160) >= 0.8 eps(N=80)"))
    rows.append(("geo_step_us_maneuvering", round(man["step_us"], 1), "mean filter step (us) at N = 50, 3 observers, 5 modes (pure Python/numpy core + numba weighting)"))

    # the worker count is how the runs were spread, not what they are: left out of the tables
    meta = {**cfg.meta(), "size": size, "seed": int(seed), "runs": {k: v for k, v in run.items() if k != "workers"}}
    tables = {"geo_summary": pd.DataFrame(summary),
              "geo_series": pd.concat(series, ignore_index=True),
              "geo_timing": pd.DataFrame(timing),
              "geo_config": pd.DataFrame({"key": list(meta), "value": [json.dumps(v) for v in meta.values()]})}
    return tables, rows


def geolocation_panels(tables: Mapping[str, pd.DataFrame]) -> list[tuple[str, dict]]:
    """The digest 001 §13 item 5 page panels as ``(title, plotly figure dict)``.

    Error vs time, percent error vs time (§6.1–§6.3), error vs mean observer distance, the
    particle sweep and the observer sweep.
    """
    import plotly.graph_objects as go

    from ..report.plots import decimate
    from ..report.study import layout

    ser, summ = tables["geo_series"], tables["geo_summary"]
    panels: list[tuple[str, dict]] = []
    main = [c for c in ("base", "maneuvering", "mobile") if c in set(ser["case"])]
    for col, title, ylab in (("eps_m", "Seed 001: mean error vs time", "error [m]"),
                             ("eta_pct", "Seed 001: percent error vs time", "percent error [%]")):
        fig = go.Figure()
        for c in main:
            d = decimate(ser.loc[ser.case == c, ["t_s", col]].reset_index(drop=True), cols=[col])
            fig.add_trace(go.Scatter(x=d["t_s"], y=d[col], name=c, mode="lines"))
        fig.update_layout(xaxis_title="time [s]", yaxis_title=ylab)
        panels.append((title, layout(fig, title).to_dict()))
    fig = go.Figure([go.Scatter(x=ser.loc[ser.case == c, "mean_dist_m"], y=ser.loc[ser.case == c, "eps_m"], name=c,
                                mode="markers", marker={"size": 3}) for c in main])
    fig.update_layout(xaxis_title="mean UAV-target distance [m]", yaxis_title="error [m]")
    panels.append(("Seed 001: error vs distance", layout(fig, "Seed 001: error vs mean observer distance").to_dict()))
    for prefix, xcol, title, xlab in (("particles_", "n_particles", "Seed 001: error vs particle count", "particles N"),
                                      ("observers_", "n_observers", "Seed 001: error vs observer count", "observers")):
        s = summ[summ.case.str.startswith(prefix)]
        fig = go.Figure([go.Scatter(x=s[xcol], y=s["eps_m"], mode="lines+markers", name="mean error")])
        # ticks at the swept counts (10, 20, 40, ...): plotly's log ticks read "9 10 2 3 4 5"
        fig.update_layout(xaxis_title=xlab, yaxis_title="mean error [m]",
                          xaxis_type="log" if len(s) > 2 else None)
        fig.update_xaxes(tickvals=list(s[xcol]))
        panels.append((title, layout(fig, title, showlegend=False, height=360).to_dict()))
    return panels
