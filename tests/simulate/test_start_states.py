"""The HMM sets start as seed 000 §2.4 describes and keep the M2/M4 ambiguity of §3.4.2.

Every run starts in the Monte Carlo's low-dynamic flight (constant thrust and pitch, steady)
and reaches its first command through the §2.4 transition (none for M2), so the first
observation cannot name the maneuver; M4's first seconds have M2's z-acceleration ("Figures
2.7c and 2.11c in particular show that Maneuvers 2 and 4 have similar initial accelerations
for the first 5 -10 seconds of their maneuvers"). Asserted on 200 runs per maneuver drawn by
:func:`pipeline.simulate.datasets.simulate_set` with the config seed: with 50, the best of nine
in-sample thresholds already reaches 0.60 between two independent draws of the *same*
maneuver (M2 vs M2, seeds 20261123 and 99), so 50 runs cannot show "≤ 0.6"; with 200 that
chance level is about 0.58 and the set still takes under 5 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.config import load_config, section
from pipeline.models.features import observations, raw_features
from pipeline.simulate import maneuvers as mv
from pipeline.simulate.datasets import DatasetSettings, simulate_set
from pipeline.simulate.scenarios import SimSettings, run_named, scenario_for
from pipeline.simulate.sensors import SensorSettings

# 200 simulated runs per maneuver (a study-sized set): the full suite runs it
pytestmark = pytest.mark.slow

N_RUNS = 200


@pytest.fixture(scope="module")
def sets():
    cfg = load_config()
    sim = section(cfg, "simulate")
    st, ds, se = SimSettings.from_config(sim), DatasetSettings.from_config(sim), SensorSettings.from_config(sim)
    return {m: simulate_set("maneuver", m, N_RUNS, st, ds, se, int(cfg["seed"]), f"maneuver/{m}")
            for m in ("M1", "M2", "M3", "M4")}


def _first_observations(df, feature_set="state9h"):
    """Row 0 of the differenced ``feature_set`` features of every run: (n_runs, 9)."""
    head = df[df["t_ns"] <= df.groupby("run_id")["t_ns"].transform("min") + 200_000_000]
    return np.stack([observations(raw_features(g, feature_set), True)[0]
                     for _, g in head.groupby("run_id", sort=True)])


def _best_threshold_accuracy(a, b):
    """Best accuracy of a single threshold on one feature separating samples ``a`` from ``b``."""
    x = np.concatenate([a, b])
    y = np.concatenate([np.zeros(len(a)), np.ones(len(b))])
    o = np.argsort(x, kind="stable")
    ys = y[o]
    # predict 1 above the cut (and 0 above, the other direction) for every cut position
    ones_below = np.concatenate([[0], np.cumsum(ys)])
    zeros_below = np.arange(len(x) + 1) - ones_below
    acc_up = (zeros_below + (ys.sum() - ones_below)) / len(x)
    return float(max(acc_up.max(), (1 - acc_up).max()))


def _z_acc_profile(df, t_max_s):
    """Mean (over runs) NED down acceleration on t <= ``t_max_s`` of a set."""
    d = df[df["t_ns"] <= round(t_max_s * 1e9)]
    return d.groupby("t_ns", sort=True)["acc_d_mps2"].mean().to_numpy()


@pytest.mark.parametrize("feature_set", ["state9h", "state9"])
@pytest.mark.parametrize("pair", [("M2", "M4"), ("M1", "M3")])
def test_no_single_feature_separates_the_pair_on_the_first_observation(sets, pair, feature_set):
    a, b = (_first_observations(sets[m], feature_set) for m in pair)
    best = max(_best_threshold_accuracy(a[:, j], b[:, j]) for j in range(a.shape[1]))
    assert best <= 0.6, f"{pair}: a single feature separates them at t = 0 ({best:.2f})"


def test_m4_first_five_seconds_have_m2_z_acceleration(sets):
    z2, z4 = _z_acc_profile(sets["M2"], 5.0), _z_acc_profile(sets["M4"], 5.0)
    assert len(z2) == len(z4) == 26
    assert np.corrcoef(z2, z4)[0, 1] >= 0.9
    rms2, rms4 = np.sqrt(np.mean(z2 ** 2)), np.sqrt(np.mean(z4 ** 2))
    assert max(rms2, rms4) <= 1.5 * min(rms2, rms4)
    assert rms4 > 0.3                           # a real descent entry, not two flat profiles


def test_every_run_starts_in_steady_low_dynamic_flight():
    st = SimSettings()
    low = mv.low_dynamic(st.low_pitch_deg).sample(np.zeros(1))
    v0 = None
    for i, m in enumerate(mv.MANEUVERS):
        tr = run_named("maneuver", st, 3, np.random.default_rng([7, i]), m)
        np.testing.assert_allclose(tr.cmd.thr[0], low.thr[0], rtol=1e-12)
        np.testing.assert_allclose(tr.cmd.euler[0], low.euler[0], atol=1e-12)
        vh = tr.vel[0, 0] if v0 is None else tr.vel[0, 0]
        # same velocity in the heading frame for every maneuver: steady, at equilibrium
        c, s = np.cos(tr.yaw0[0]), np.sin(tr.yaw0[0])
        vh = np.array([c * vh[0] + s * vh[1], -s * vh[0] + c * vh[1], vh[2]])
        v0 = vh if v0 is None else v0
        np.testing.assert_allclose(vh, v0, atol=1e-9)
        assert abs(vh[2]) < 1e-9 and vh[0] > 1.0      # level, forward at the −5° pitch


@pytest.mark.parametrize("man", mv.MANEUVERS)
def test_transition_reaches_the_first_command_except_for_m2(man):
    st = SimSettings()
    sc = scenario_for("maneuver", st, man)
    knots = mv.default_maneuvers()[man]
    first = knots.sample(np.zeros(1))
    lead = st.mc_pre_s - st.mc_ramp_in[0]
    ramp = st.mc_ramp_in[1] - st.mc_ramp_in[0]
    if man == "M2":   # §2.4.2: "does not require a transition period"
        assert sc.meta["maneuver_start_s"] == 0.0 and sc.duration_s == 25.0
        low = mv.low_dynamic(st.low_pitch_deg).sample(np.zeros(1))
        np.testing.assert_allclose(first.thr, low.thr, rtol=1e-12)
        np.testing.assert_allclose(first.euler, low.euler, atol=1e-12)
        return
    assert sc.meta["maneuver_start_s"] == lead == 3.0 and sc.duration_s == lead + 25.0
    t = np.linspace(ramp, lead, 5)
    c = sc.command.sample(t)
    np.testing.assert_allclose(c.thr, first.thr[0], atol=1e-12)
    np.testing.assert_allclose(c.euler, np.broadcast_to(first.euler[0], c.euler.shape), atol=1e-12)
    # after the lead the run is the maneuver itself
    tt = np.linspace(0.0, 25.0, 101)
    np.testing.assert_allclose(sc.command.sample(tt + lead).thr, knots.sample(tt).thr, atol=1e-12)
    assert set(sc.labels_at(np.linspace(0, sc.duration_s, 50))) == {man}
