"""The one dataclass builder: every stage's settings come from the validated section, the
defaults from the schema; the master seed reaches simulation and training, nothing else does."""

from __future__ import annotations

import dataclasses
import zlib
from typing import Literal

import numpy as np
import pandas as pd
import pytest

from pipeline.config import ConfigError, build, cfield, default_at, load_config, validate_section
from pipeline.estimate.models import RadarModel
from pipeline.io.ros_common import RosConfig
from pipeline.models.base import ModelsConfig
from pipeline.preprocess.calibrate import BPMConfig
from pipeline.preprocess.derivatives import Differentiator
from pipeline.preprocess.state import PreprocessConfig, resolve_config
from pipeline.simulate.datasets import DatasetSettings, simulate_set
from pipeline.simulate.quadcopter import QuadParams
from pipeline.simulate.scenarios import SimSettings
from pipeline.simulate.sensors import SensorSettings

#: (dataclass, the schema section it is built from, a changed key, its value, field, expected)
STAGES = [
    (QuadParams, "simulate.vehicle", {"mass_kg": 1.2}, "mass_kg", 1.2),
    (QuadParams, "simulate.vehicle", {"drag_kgps": 0.3}, "drag_kgps", (0.3, 0.3, 0.3)),
    (SimSettings, "simulate", {"disturbance": {"clip_mps2": 0}}, "dist_clip_mps2", None),
    (SimSettings, "simulate", {"mc": {"post_s": 21}}, "mc_post_s", {m: 21.0 for m in ("M1", "M2", "M3", "M4", "M5")}),
    (SimSettings, "simulate", {"mc": {"post_s": {"M2": 22}}}, "mc_post_s",
     {"M1": 25.0, "M2": 22.0, "M3": 20.0, "M4": 20.0, "M5": 25.0}),
    (SimSettings, "simulate", {"vehicle": {"mass_kg": 2}}, "vehicle", QuadParams(mass_kg=2.0)),
    (SensorSettings, "simulate", {"origin": {"lat_deg": 10}}, "origin", (10.0, -85.4897, 200.0)),
    (SensorSettings, "simulate", {"sensors": {"gps": {"rate_hz": 5}}}, "gps",
     {"rate_hz": 5.0, "sigma_h_m": 0.3, "sigma_v_m": 0.5, "sigma_vel_mps": 0.05, "n_sats": 14,
      "dropout_count": 0, "dropout_s": 2.0}),
    (SensorSettings, "simulate", {"sensors": {"radar": {"sigma_dcos": 1e-4}}}, "radar",
     RadarModel(sigma=(1.5, 1e-4, 1e-4, 0.2))),
    (RadarModel, "simulate.sensors.radar", {"site_ned_m": [1, 2, 3]}, "site_ned_m", (1.0, 2.0, 3.0)),
    (DatasetSettings, "simulate", {"datasets": {"size": "thesis"}}, "runs", 2300),
    (DatasetSettings, "simulate", {"start_time_utc": "2026-01-01T12:00:01Z"}, "start_time_utc_ns",
     (1767268800 + 1) * 10 ** 9),
    (DatasetSettings, "simulate", {"datasets": {"log_formats": ["bin"]}}, "log_formats", ("bin",)),
    (BPMConfig, "preprocess.bpm", {"step_m": None}, "step_m", None),
    (BPMConfig, "preprocess.bpm", {"down_orientations": [25, 24]}, "down_orientations", (25, 24)),
    (Differentiator, "preprocess.derivatives", {"method": "butter"}, "method", "butter"),
    (PreprocessConfig, "preprocess", {"derivatives": {"window_s": 2}}, "derivatives", Differentiator(window_s=2.0)),
    (PreprocessConfig, "preprocess", {"clock_jump_s": None}, "clock_jump_s", None),
    (ModelsConfig, "hmm", {"n_states_range": [2, 4]}, "n_states_range", (2, 4)),
    (ModelsConfig, "hmm", {"window_s": "auto"}, "window_s", "auto"),
    (RosConfig, "ingest.ros", {"world_frames": ["map"]}, "world_frames", ("map",)),
]

OLD_DEFAULTS = {
    # the literal dataclass defaults before the schema held them (kept draws and behaviour)
    QuadParams: dict(mass_kg=0.468, drag_kgps=(0.25, 0.25, 0.25), inertia_kgm2=(4.856e-3, 4.856e-3, 8.801e-3),
                     arm_m=0.225, yaw_coeff_m=0.0383, max_motor_thrust_N=None, g_mps2=9.80665),
    RadarModel: dict(site_ned_m=(0.0, 0.0, 0.0), tau_rd_s=0.0, sigma=(1.5, 45e-6, 45e-6, 0.2),
                     include_tau_in_h=True, rate_hz=5.0, sensor_id=0),
    BPMConfig: dict(min_range_m=0.17, max_range_m=6.0, max_tilt_deg=10.0, max_rate_mps=2.0, spike_m=0.3,
                    spike_window=5, outlier_k=3.5, region_gap_s=5.0, region_max_s=10.0, step_m=0.4,
                    min_points=5, min_region_points=5, drift=True, min_drift_span_s=20.0,
                    tilt_compensate=True, down_orientations=(25,), gps_min_fix=3, gps_fallback=True,
                    p0_Pa=101325.0),
    Differentiator: dict(method="savgol", window_s=1.0, polyorder=3, cutoff_hz=2.0, order=3),
    ModelsConfig: dict(feature_set="state9", rate_hz=5.0, n_states={"default": 6, "M1": 5},
                       n_states_range=(3, 10), n_mix=1, n_iter=100, tol=1e-2, min_covar=1e-4,
                       self_prob=0.9, gmm_restarts=3, init_min_samples=60, hmm_restarts=1, seed=0,
                       threshold_percentile=0.5, threshold_slack=0.0, mode="cumulative", window_s=1.6,
                       restart_prob=0.05, confirm_s=1.0, confidence_threshold=-1.0, decision="confidence",
                       background=1, gate_mps2=15.0, gmr_input="pos_fd", gmr_align="sample", phases=True),
    DatasetSettings: dict(runs=60, mc_runs=20, switch_runs=10, log_flights=1, batch_runs=100,
                          train_fraction=0.7, truth_rate_hz=5.0, log_formats=("bin", "tlog", "bag", "mcap"),
                          start_time_utc_ns=1767268800 * 10 ** 9, maneuvers=("M1", "M2", "M3", "M4", "M5")),
}


@pytest.mark.parametrize("cls, path, change, name, expected", STAGES,
                         ids=[f"{c.__name__}-{n}" for c, _, _, n, _ in STAGES])
def test_every_stage_dataclass_round_trips_through_the_builder(cls, path, change, name, expected):
    sec = validate_section(path, {})
    assert build(cls, sec) == cls()            # defaults: the schema's, once
    got = build(cls, validate_section(path, change))
    assert getattr(got, name) == expected
    assert type(getattr(got, name)) is type(expected)
    moved = {"runs", "mc_runs", "switch_runs", "log_flights"} if name == "runs" else {name}
    others = {f.name for f in dataclasses.fields(cls)} - moved
    assert {f: getattr(got, f) for f in others} == {f: getattr(cls(), f) for f in others}


@pytest.mark.parametrize("cls", list(OLD_DEFAULTS), ids=lambda c: c.__name__)
def test_dataclass_defaults_are_the_old_literal_defaults(cls):
    d = cls()
    for k, v in OLD_DEFAULTS[cls].items():
        assert getattr(d, k) == v, k


def test_the_shipped_config_builds_the_same_settings_as_the_old_explicit_file():
    cfg = load_config()
    assert SimSettings.from_config(cfg["simulate"]) == SimSettings()
    assert SensorSettings.from_config(cfg["simulate"]) == SensorSettings()
    assert DatasetSettings.from_config(cfg["simulate"]) == DatasetSettings()
    m = ModelsConfig.from_section(cfg["hmm"], seed=cfg["seed"])
    assert m == ModelsConfig(feature_set="state9h", seed=20261123)
    yak = PreprocessConfig.from_config(cfg, vehicle="yak54")
    assert yak.vehicle == "yak54" and yak.methods == {"imu": "mean", "control": "linear"}
    assert yak.controls["thr"] == {"channel": "rc_3_us", "min_us": 1012, "max_us": 2100}
    husky = resolve_config(cfg["preprocess"], flight_id="husky-ros1")
    assert husky.vehicle == "husky" and husky.attitude_from_imu and husky.mag_mount == husky.imu_mount
    # `generic` (no entry of its own) gets the `default` entry; the manifest's sim-quad has an
    # entry since issue 13 (an unknown vehicle stops the workflow), with the same settings
    other = resolve_config(cfg["preprocess"], flight_id="x", vehicle="generic")
    assert other.vehicle == "default" and other.controls == default_at("preprocess.vehicles.*.controls")
    sim = resolve_config(cfg["preprocess"], flight_id="x", vehicle="sim-quad")
    assert sim.vehicle == "sim-quad" and \
        dataclasses.replace(sim, vehicle="default", controls_key=other.controls_key) == other
    assert sim.controls_key == "preprocess.vehicles.sim-quad.controls"


def test_the_stage_shims_validate_against_the_schema():
    with pytest.raises(ConfigError, match=r"simulate\.rate_hz: 50 is out of range"):
        SimSettings.from_config({"rate_hz": 50})
    with pytest.raises(ConfigError, match=r"simulate\.sensors\.imu\.bias: unknown key"):
        SensorSettings.from_config({"sensors": {"imu": {"bias": 1}}})
    with pytest.raises(ConfigError, match=r"simulate\.datasets\.size: 'huge' is not one of small, thesis"):
        DatasetSettings.from_config({"datasets": {"size": "huge"}})
    with pytest.raises(ConfigError, match=r"hmm\.mode: 'sliding' is not one of"):
        ModelsConfig.from_section({"mode": "sliding"})
    with pytest.raises(ConfigError, match=r"preprocess\.bogus: unknown key"):
        PreprocessConfig.from_config({"bogus": 1})


@dataclasses.dataclass(frozen=True, kw_only=True)
class Inner:
    order: int = 3


@dataclasses.dataclass(frozen=True, kw_only=True)
class Outer:
    rate: float = 1.0
    pair: tuple[float, float] = (0.0, 0.0)
    many: tuple[int, ...] = ()
    inner: Inner = dataclasses.field(default_factory=Inner)
    opt: float | None = None
    kind: Literal["a", "b"] = "a"
    table: dict[str, Inner] = dataclasses.field(default_factory=dict)
    renamed: float = dataclasses.field(default=0.0, metadata={"config_key": "deep.value"})
    free: int = dataclasses.field(default=7, metadata={"config_key": None})


def test_the_generic_builder_shapes_values_by_type_hint():
    got = build(Outer, {"rate": 2, "pair": [1, 2], "many": [1.0, 2.0], "inner": {"order": 5}, "opt": 3,
                        "kind": "b", "table": {"x": {"order": 1}}, "deep": {"value": 4}, "free": 9}, kind="a")
    assert got == Outer(rate=2.0, pair=(1.0, 2.0), many=(1, 2), inner=Inner(order=5), opt=3.0, kind="a",
                        table={"x": Inner(order=1)}, renamed=4.0)
    assert type(got.rate) is float and type(got.many[0]) is int and got.free == 7
    assert build(Outer, {"opt": None}).opt is None
    with pytest.raises(TypeError, match="no field"):
        build(Outer, {}, nonsense=1)


def test_cfield_takes_its_default_from_the_schema():
    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Bpm:
        spike: float = cfield("preprocess.bpm", "spike_m")
        orient: tuple[int, ...] = cfield("preprocess.bpm", "down_orientations")

    assert Bpm() == Bpm(spike=0.3, orient=(25,))
    assert build(Bpm, {"spike_m": 0.5}).spike == 0.5


# --- the master seed ---------------------------------------------------------------------------

def _sim_m1(cfg: dict) -> pd.DataFrame:
    sim = cfg["simulate"]
    return simulate_set("maneuver", "M1", 2, SimSettings.from_config(sim), DatasetSettings.from_config(sim),
                        SensorSettings.from_config(sim), cfg["seed"], "maneuver/M1")


def test_changing_the_hmm_section_does_not_change_simulated_outputs_and_the_seed_does():
    base = load_config()
    other = load_config()
    other["hmm"] = {**other["hmm"], "n_iter": 3, "feature_set": "box", "background": 0}
    other["model_sets"] = {}
    a, b = _sim_m1(base), _sim_m1(other)
    pd.testing.assert_frame_equal(a, b)
    reseeded = {**base, "seed": base["seed"] + 1}
    assert not np.array_equal(_sim_m1(reseeded)["pos_n_m"].to_numpy(), a["pos_n_m"].to_numpy())


def test_the_background_model_draws_from_the_master_seed_and_crc32_background():
    from sklearn.mixture import GaussianMixture

    from pipeline.models.classifier import ManeuverModelSet

    X = np.random.default_rng(1).normal(size=(400, 3))
    ms = ManeuverModelSet(config=ModelsConfig(seed=5, background=2))
    bg = ms._fit_background(X)
    rng = np.random.default_rng([5, zlib.crc32(b"background")])
    g = GaussianMixture(2, covariance_type="full", reg_covar=1e-4, random_state=int(rng.integers(2 ** 31)),
                        n_init=1).fit(X)
    np.testing.assert_allclose(bg.means[0], g.means_)
