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
    assert np.all(np.isfinite(summ["eps_m"])) and np.all(summ["eps_m"] >= 0)
    names = [r[0] for r in rows]
    for n in ("geo_eta_pct_base", "geo_eta_pct_maneuvering", "geo_eta_base_met", "geo_obs_1_to_2_met",
              "geo_particles_10_vs_80_met", "geo_bound_pct", "geo_sigma_px", "geo_mobile_dist_60_80_pct"):
        assert n in names
    assert all(isinstance(d, str) and d for _, _, d in rows)
    assert all(v in (0, 1) for n, v, _ in rows if n.endswith("_met"))
    meta = {k: json.loads(v) for k, v in zip(tables["geo_config"]["key"], tables["geo_config"]["value"])}
    assert meta["focal_px"] == 800.0 and meta["size"] == "tiny" and np.isclose(meta["threshold"], 1 / 3)
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
