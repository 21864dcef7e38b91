"""The one master seed: changing it changes every simulated and trained output; the stages'
own sections do not reach the simulation (no other key holds a seed)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def sim_cfg() -> dict:
    from pipeline.config import load_config

    sim = load_config(ROOT / "datasets" / "config.yaml")["simulate"]
    sim["datasets"] = {**sim["datasets"], "size": "tiny", "maneuvers": ["M1", "M2"], "log_formats": ["bin"],
                       "sizes": {"tiny": {"runs": 4, "mc_runs": 1, "switch_runs": 1, "log_flights": 1}}}
    sim["switch"] = {**sim["switch"], "times_s": [3]}
    return sim


def _simulate(sim_cfg, out: Path, seed: int) -> Path:
    from pipeline.simulate.run import planned_logs, planned_sets, run_simulate_logs, run_simulate_sets

    run_simulate_sets({}, {"sets": [out / "sets" / f"{n}.parquet" for n in planned_sets(sim_cfg)],
                           "summary": out / "summary.parquet", "index": out / "index.json"}, sim_cfg, seed=seed)
    logs = planned_logs(sim_cfg)
    run_simulate_logs({}, {"logs": [out / "logs" / r["log"] for r in logs],
                           "sidecars": [out / "logs" / r["sidecar"] for r in logs],
                           "manifest": out / "logs" / "flights.tsv"}, sim_cfg, seed=seed)
    return out


def _train(sets: list[Path], out: Path, seed: int) -> dict:
    from pipeline.models.run import run_train

    cfg = {"data": "simulated", "vehicles": ["q"],
           "hmm": {"feature_set": "state9h", "n_states": 3, "n_iter": 3, "gmm_restarts": 1, "init_min_samples": 20}}
    run_train({"sets": sets}, {"params": out / "params.npz", "meta": out / "meta.json"}, cfg, model_set="m", seed=seed)
    return dict(np.load(out / "params.npz"))


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.mark.slow
def test_changing_the_master_seed_changes_every_simulated_and_trained_output(sim_cfg, tmp_path):
    a, b, a2 = (_simulate(sim_cfg, tmp_path / n, s) for n, s in (("a", 1), ("b", 2), ("a2", 1)))
    outputs = sorted(p.relative_to(a) for p in (a / "sets").glob("*.parquet")) + \
        sorted(p.relative_to(a) for p in (a / "logs").iterdir() if p.suffix in (".bin", ".parquet"))
    assert len(outputs) >= 8
    for rel in outputs:
        assert _digest(a / rel) == _digest(a2 / rel), f"{rel}: not reproducible with one seed"
        if rel.suffix == ".parquet":
            assert not pd.read_parquet(a / rel).equals(pd.read_parquet(b / rel)), f"{rel}: seed has no effect"
        else:
            assert _digest(a / rel) != _digest(b / rel), f"{rel}: seed has no effect"
    sets = [a / "sets" / f"{m}_train.parquet" for m in ("M1", "M2")]
    p1, p1b, p2 = _train(sets, tmp_path / "m1", 1), _train(sets, tmp_path / "m1b", 1), _train(sets, tmp_path / "m2", 2)
    assert all(np.array_equal(p1[k], p1b[k]) for k in p1)
    assert any(not np.array_equal(p1[k], p2[k]) for k in p1 if p1[k].dtype.kind == "f")


def test_the_simulate_entry_points_take_only_inputs_outputs_their_section_and_the_master_seed():
    """Every simulate entry point's signature is (inputs, outputs, config, *, seed): no other
    config section and no other seed can reach it (``config`` is the ``simulate`` section)."""
    import inspect

    from pipeline.simulate import run

    for fn in (run.run_simulate_sets, run.run_simulate_logs, run.run_demo_log):
        params = inspect.signature(fn).parameters
        assert list(params) == ["inputs", "outputs", "config", "seed"], fn.__name__
        assert params["seed"].kind is inspect.Parameter.KEYWORD_ONLY, fn.__name__


def test_the_demo_flight_is_the_same_bytes_whatever_its_config_holds_and_changes_with_the_seed(tmp_path):
    from pipeline.simulate.run import run_demo_log

    cfgs = (None, {"datasets": {"size": "tiny"}, "seed": 99, "models": {"hmm": {"n_states": 7}}})
    a, b, c = (tmp_path / f"{n}.bin" for n in "abc")
    run_demo_log({}, {"log": a}, cfgs[0], seed=3)
    run_demo_log({}, {"log": b}, cfgs[1], seed=3)
    run_demo_log({}, {"log": c}, cfgs[0], seed=4)
    assert _digest(a) == _digest(b)
    assert _digest(a) != _digest(c)
