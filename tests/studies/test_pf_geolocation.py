"""The seed-001 section of study_pf at tiny size: tables, RESULT rows, metadata and panels."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pipeline.io.parquet import write_table
from pipeline.studies.pf_geolocation import geolocation_panels, geolocation_study


@pytest.mark.slow
def test_the_tiny_geolocation_study_returns_its_tables_rows_and_panels():
    tables, rows = geolocation_study({}, seed=3, size="tiny")
    assert set(tables) == {"geo_summary", "geo_series", "geo_config", "geo_timing"}
    summ = tables["geo_summary"]
    assert summ["case"].tolist() == ["base", "maneuvering", "mobile", "particles_10", "particles_80",
                                     "observers_1", "observers_2"]
    assert np.all(np.isfinite(summ["eps_m"])) and np.all(np.isfinite(summ["eta_pct"]))
    names = [r[0] for r in rows]
    for n in ("geo_eta_pct_base", "geo_eta_pct_maneuvering", "geo_eta_base_met", "geo_obs_1_to_2_met",
              "geo_particles_10_vs_80_met", "geo_bound_pct", "geo_sigma_px", "geo_mobile_dist_60_80_pct"):
        assert n in names
    assert all(isinstance(d, str) and d for _, _, d in rows)
    meta = {k: json.loads(v) for k, v in zip(tables["geo_config"]["key"], tables["geo_config"]["value"])}
    assert meta["focal_px"] == 800.0 and meta["size"] == "tiny" and np.isclose(meta["threshold"], 1 / 3)

    # the RESULT rows recomputed from the tables. At tiny size every case is one run, so the series
    # (per step, mean over runs) is that run's own and the summary's pooled means are the series'
    # means after the first second (digest D11)
    rv = dict((n, v) for n, v, _ in rows)
    assert len(rv) == len(rows) and set(summ["n_runs"]) == {1}
    ser = tables["geo_series"]
    assert list(dict.fromkeys(ser["case"])) == summ["case"].tolist()
    rec = {}
    for case, g in ser.groupby("case", sort=False):
        g = g[g["t_s"] >= 1.0]
        d = g["mean_dist_m"].to_numpy()
        d = d[np.isfinite(d)]
        rec[case] = {"eps_m": float(np.nanmean(g["eps_m"].to_numpy())),
                     "eta_pct": float(np.nanmean(g["eta_pct"].to_numpy())),
                     "dist_60_80_pct": 100.0 * float(np.mean((d >= 60.0) & (d <= 80.0)))}
    by = summ.set_index("case")
    for case, r in rec.items():
        assert by.loc[case, "eps_m"] == pytest.approx(r["eps_m"], rel=1e-12), case
        assert by.loc[case, "eta_pct"] == pytest.approx(r["eta_pct"], rel=1e-12), case
        assert by.loc[case, "dist_60_80_pct"] == pytest.approx(r["dist_60_80_pct"], rel=1e-12), case
    for name in ("base", "maneuvering", "mobile"):
        s = by.loc[name]
        assert rv[f"geo_eta_pct_{name}"] == pytest.approx(rec[name]["eta_pct"], abs=0.005 + 1e-9), name
        assert rv[f"geo_eps_m_{name}"] == pytest.approx(rec[name]["eps_m"], abs=0.005 + 1e-9), name
        assert rv[f"geo_lost_runs_{name}"] == f"{s['n_lost']}/1", name
        # one run: its own mean is the median over runs; lost, no run is left for the not-lost mean
        assert rv[f"geo_eta_pct_{name}_run_median"] == pytest.approx(rec[name]["eta_pct"], abs=0.005 + 1e-9), name
        if s["n_lost"]:
            assert np.isnan(rv[f"geo_eta_pct_{name}_not_lost"]), name
        else:
            assert rv[f"geo_eta_pct_{name}_not_lost"] == pytest.approx(rec[name]["eta_pct"], abs=0.005 + 1e-9), name
    for kind, k in (("particles", 10), ("particles", 80), ("observers", 1), ("observers", 2)):
        case = f"{kind}_{k}"
        assert rv[f"geo_eps_m_{case}"] == pytest.approx(rec[case]["eps_m"], abs=0.005 + 1e-9), case
        assert rv[f"geo_lost_runs_{case}"] == f"{by.loc[case, 'n_lost']}/1", case
        if by.loc[case, "n_lost"]:
            assert np.isnan(rv[f"geo_eps_m_{case}_not_lost"]), case
        else:
            assert rv[f"geo_eps_m_{case}_not_lost"] == pytest.approx(rec[case]["eps_m"], abs=0.005 + 1e-9), case
    assert rv["geo_mobile_dist_60_80_pct"] == pytest.approx(rec["mobile"]["dist_60_80_pct"], abs=0.05 + 1e-9)
    # σ_px = f tan σ_ψ and the bound 100 sin σ_ψ, from the written settings
    assert rv["geo_sigma_px"] == pytest.approx(meta["focal_px"] * np.tan(meta["sigma_psi_rad"]), abs=0.005 + 1e-9)
    assert rv["geo_bound_pct"] == pytest.approx(100.0 * np.sin(meta["sigma_psi_rad"]), abs=0.05 + 1e-9)
    # each acceptance flag is its formula (issue 17) on the summary's eps and eta
    eps, eta = by["eps_m"], by["eta_pct"]
    assert {n: v for n, v in rv.items() if n.endswith("_met")} == {
        "geo_eta_base_met": int(eta["base"] <= 15.0), "geo_eta_maneuvering_met": int(eta["maneuvering"] <= 15.0),
        "geo_obs_1_to_2_met": int(eps["observers_2"] <= eps["observers_1"] / 2),
        "geo_particles_10_vs_80_met": int(eps["particles_10"] >= 1.5 * eps["particles_80"])}
    panels = geolocation_panels(tables)
    assert len(panels) == 5 and all(isinstance(f, dict) and "data" in f for _, f in panels)


def test_the_geolocation_study_is_seeded_and_rejects_an_unknown_size(tmp_path):
    short = {"geo_sizes": {"tiny": {"particles": [], "observers": [], "base_s": 1.5, "maneuvering_s": 1.5,
                                     "mobile_s": 1.5}}}
    a, ra = geolocation_study(short, seed=5, size="tiny")
    b, rb = geolocation_study(short, seed=5, size="tiny")
    for t in ("geo_summary", "geo_series", "geo_config"):  # the step times live in geo_timing alone
        assert a[t].equals(b[t]), t
        # same seed, same bytes: the files as study_pf writes them
        write_table(a[t], tmp_path / "a.parquet", name=f"pf_{t}", extra={"seed": 5})
        write_table(b[t], tmp_path / "b.parquet", name=f"pf_{t}", extra={"seed": 5})
        assert (tmp_path / "a.parquet").read_bytes() == (tmp_path / "b.parquet").read_bytes(), t
    assert "step_us" not in a["geo_summary"] and a["geo_timing"]["case"].tolist() == a["geo_summary"]["case"].tolist()
    assert [r for r in ra if "step_us" not in r[0]] == [r for r in rb if "step_us" not in r[0]]
    with pytest.raises(ValueError, match="unknown size 'huge'"):
        geolocation_study({}, seed=5, size="huge")


def test_the_geolocation_study_spread_over_worker_processes_gives_the_same_tables():
    sizes = {"particles": [10], "observers": [2], "base_s": 1.0, "maneuvering_s": 1.0, "mobile_s": 1.0,
             "sweep_s": 1.0, "runs": 2, "particle_runs": 2, "observer_runs": 1}
    one, r1 = geolocation_study({"geo_sizes": {"tiny": {**sizes, "workers": 1}}}, seed=7, size="tiny")
    two, r2 = geolocation_study({"geo_sizes": {"tiny": {**sizes, "workers": 2}}}, seed=7, size="tiny")
    for t in ("geo_summary", "geo_series", "geo_config"):
        pd.testing.assert_frame_equal(one[t], two[t], check_exact=True, obj=t)
    assert [(n, v) for n, v, _ in r1 if "step_us" not in n] == [(n, v) for n, v, _ in r2 if "step_us" not in n]
    assert one["geo_summary"]["n_runs"].tolist() == [2, 2, 2, 2, 1]


def test_the_observer_sweep_takes_its_own_particle_count_and_run_count_and_a_bad_plan_key_is_named():
    # studies.pf.geo: e.g. more runs per observer count, or the sweep at another particle count;
    # the runs are the same scenes (run r of every point replays the same target)
    plan = {"particles": [], "observers": [2], "base_s": 1.0, "maneuvering_s": 1.0, "mobile_s": 1.0,
            "sweep_s": 1.5, "observer_runs": 2}
    a, _ = geolocation_study({"geo_sizes": {"tiny": plan}}, seed=4, size="tiny")
    b, _ = geolocation_study({"geo_sizes": {"tiny": {**plan, "observer_particles": 30}}}, seed=4, size="tiny")
    sa, sb = (t["geo_summary"].set_index("case") for t in (a, b))
    assert sa.loc["observers_2", "n_particles"] == 50 and sb.loc["observers_2", "n_particles"] == 30
    assert sa.loc["observers_2", "n_runs"] == sb.loc["observers_2", "n_runs"] == 2
    assert sa.loc["observers_2", "eps_m"] != sb.loc["observers_2", "eps_m"]
    # the setups are untouched by the sweep's count
    pd.testing.assert_frame_equal(sa.drop(index="observers_2"), sb.drop(index="observers_2"))
    assert json.loads(b["geo_config"].set_index("key").loc["runs", "value"])["observer_particles"] == 30
    with pytest.raises(ValueError, match=r"unknown run-plan key\(s\) \['observer_runz'\]"):
        geolocation_study({"geo_sizes": {"tiny": {"observer_runz": 3}}}, seed=4, size="tiny")
