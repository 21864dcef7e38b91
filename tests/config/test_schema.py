"""The config schema: every section typed, every default once, one-line errors naming the key.

Oracles: the pre-issue-12 ``datasets/config.yaml`` (kept verbatim beside this file) and the
stage code's literal defaults of that time; Snakemake's own ``validate(set_default=True)``.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import pytest
import yaml

from pipeline import config as C
from pipeline.config import ConfigError, load_config, read_config_file, validate_config, validate_section

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
BEFORE = HERE / "config_before_issue12.yaml"


def _renamed(old: dict) -> dict:
    """The issue-12 renames: models -> hmm (without seed), train -> model_sets, per-set models -> hmm."""
    new = copy.deepcopy(old)
    new["hmm"] = new.pop("models")
    new["hmm"].pop("seed")
    new["model_sets"] = new.pop("train")
    for spec in new["model_sets"].values():
        if "models" in spec:
            spec["hmm"] = spec.pop("models")
    return new


def _f3a_slack(old: dict) -> dict:
    """Issue 13 item 15: the f3a one-class slack, 1.5 before, is 0: the set's one-class rule is the
    impostor-scaled threshold (the new key ``threshold_fraction``, the flightcoach study's P21
    calibration, 0.62); everything else of the set is unchanged."""
    hmm = old["model_sets"]["f3a"]["hmm"]
    assert hmm["threshold_slack"] == 1.5
    hmm["threshold_slack"] = 0.0
    hmm["threshold_fraction"] = 0.62
    return old


def _leaves(d, path=()):
    if isinstance(d, dict) and d:
        for k, v in d.items():
            yield from _leaves(v, path + (k,))
    else:
        yield path, d


def _get(d, path):
    for p in path:
        d = d[p]
    return d


def _write(tmp_path, cfg) -> Path:
    p = tmp_path / "cfg.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


# --- defaults ----------------------------------------------------------------------------------

def test_the_shipped_file_resolves_to_the_values_it_had_before_for_every_key():
    from pipeline.io.ros_common import DEFAULT_CUSTOM_TYPES, RosConfig

    old = _f3a_slack(_renamed(yaml.safe_load(BEFORE.read_text())))
    new = load_config()
    # the simulator's radar message is a built-in of the ROS mapping (merged under any
    # custom_types), no longer repeated in the file: the resolved RosConfig is the same
    assert old["ingest"]["ros"].pop("custom_types") == DEFAULT_CUSTOM_TYPES
    assert RosConfig.from_config(new["ingest"]) == RosConfig.from_config(yaml.safe_load(BEFORE.read_text())["ingest"])
    for path, value in _leaves(old):
        assert _get(new, path) == value, ".".join(map(str, path))
    # the old models.seed was the master seed: training keeps its draws
    assert yaml.safe_load(BEFORE.read_text())["models"]["seed"] == new["seed"]


def test_keys_only_the_code_knew_default_to_the_codes_old_values():
    d = load_config()
    assert d["simulate"]["vehicle"]["max_motor_thrust_N"] is None
    assert d["simulate"]["vehicle"]["g_mps2"] == 9.80665
    assert d["simulate"]["datasets"]["maneuvers"] == ["M1", "M2", "M3", "M4", "M5"]
    assert d["preprocess"]["bpm"]["p0_Pa"] == 101325.0
    assert d["ingest"]["ulog"]["rangefinder_valid_m"] is None
    assert d["preprocess"]["butterworth"] == {"baro.alt_rel_m": {"order": 3, "cutoff_hz": 1.0}}
    assert d["studies"]["size"] == "small"  # the per-study defaults: tests/studies/test_config.py


def test_the_old_file_with_the_renames_validates_to_the_same_dict_as_the_new_one():
    old = _f3a_slack(_renamed(yaml.safe_load(BEFORE.read_text())))
    old["ingest"]["ros"].pop("custom_types")   # built in (see above)
    new = load_config()
    # issue 13: every manifest vehicle has an entry, the `default` settings under its own name
    vehicles = new["preprocess"]["vehicles"]
    added = {k: vehicles.pop(k) for k in set(vehicles) - set(old["preprocess"]["vehicles"])}
    assert added and all({**v, "doc": ""} == {**vehicles["default"], "doc": ""} for v in added.values())
    # issue 14: the simekf model set, sim's maneuvers on the EKF estimates of the sets
    simekf = new["model_sets"].pop("simekf")
    assert simekf == {**new["model_sets"]["sim"], "input": "ekf", "hmm": {"gmr_input": "pos_vel", "gate_mps2": 2.0}}
    # ... which the EKF+HMM classifies with (the schema default is sim)
    assert new["estimate"]["ekf_hmm"].pop("model") == "simekf"
    new["estimate"]["ekf_hmm"]["model"] = "sim"
    # stop 42: kd0aij's radio (throttle-first) for the CSV export without radio parameters
    assert new["preprocess"]["flights"].pop("kd0aij-*")["controls"]["thr"]["channel"] == "rc_1_us"
    # ... and the Husky is a ground vehicle (no takeoff, no altitude numbers)
    assert new["preprocess"]["vehicles"]["husky"]["ground"] is True
    new["preprocess"]["vehicles"]["husky"]["ground"] = False
    assert validate_config(old) == new


def test_defaults_equal_an_empty_file_and_snakemake_fills_the_same_defaults():
    from snakemake.utils import validate

    assert C.defaults() == validate_config({}) == validate_config(None)
    raw = yaml.safe_load((ROOT / "datasets" / "config.yaml").read_text())
    validate(raw, schema=str(C.SCHEMA_PATH), set_default=True)
    assert raw == load_config()
    wf = yaml.safe_load((ROOT / "tests" / "workflow" / "config.yaml").read_text())
    ours = validate_config(wf)
    validate(wf, schema=str(C.SCHEMA_PATH), set_default=True)
    assert wf == ours


def test_the_import_time_default_filler_agrees_with_the_validator():
    inst: dict = {}
    C._fill(C._schema(), inst, C._schema())
    assert inst == C.defaults()


def test_validation_does_not_alias_the_schema_defaults():
    a = validate_config({})
    a["preprocess"]["butterworth"]["x.y"] = {"cutoff_hz": 1.0}
    a["simulate"]["sensors"]["imu"]["acc_bias_mps2"][0] = 99.0
    assert validate_config({}) == C.defaults() and "x.y" not in C.defaults()["preprocess"]["butterworth"]


def test_the_master_seed_is_the_only_seed_key_in_the_schema():
    seen = []

    def walk(node, path):
        if isinstance(node, dict):
            for k, v in (node.get("properties") or {}).items():
                seen.append(path + (k,))
                walk(v, path + (k,))
            for k, v in node.items():
                if k != "properties":
                    walk(v, path + (k,) if k == "$defs" else path)
        elif isinstance(node, list):
            for v in node:
                walk(v, path)

    walk(C.schema(), ())
    # a key named like a seed (seed, *_seed, seed_*); the seed000 study's name is not one
    seeds = [p for p in seen if re.search(r"(^|_)seed($|_)", p[-1].lower())]
    assert seeds == [("seed",)]
    with pytest.raises(ConfigError, match=r"hmm\.seed: unknown key"):
        validate_config({"hmm": {"seed": 1}})


# --- one-line errors for every section ----------------------------------------------------------

BAD = [
    # (section, bad nested key, expected path) ...
    ("ingest", {"ingest": {"ros": {"topicz": {}}}}, "ingest.ros.topicz: unknown key"),
    ("ingest", {"ingest": {"ros": {"world_frames": "map"}}}, "ingest.ros.world_frames: 'map' is not a list"),
    ("ingest", {"ingest": {"ulog": {"imu": 3}}}, "ingest.ulog.imu: 3 is not"),
    ("ingest", {"ingest": {"tabular": {"colmap": "x"}}}, "ingest.tabular.colmap: unknown key"),
    ("ingest", {"ingest": {"ros": {"topics": {"/a": {"strem": "imu"}}}}}, r"ingest.ros.topics\['/a'\].strem: unknown key"),
    ("simulate", {"simulate": {"mc": {"pre_z": 1}}}, "simulate.mc.pre_z: unknown key"),
    ("simulate", {"simulate": {"rate_hz": "fast"}}, "simulate.rate_hz: 'fast' is not a number"),
    ("simulate", {"simulate": {"sensors": {"gps": {"n_sats": 2.5}}}}, "simulate.sensors.gps.n_sats: 2.5 is not an integer"),
    ("simulate", {"simulate": {"datasets": {"log_formats": ["csv"]}}}, r"simulate.datasets.log_formats\[0\]: 'csv' is not one of"),
    ("simulate", {"simulate": {"vehicle": {"mass": 1.0}}}, "simulate.vehicle.mass: unknown key"),
    ("preprocess", {"preprocess": {"rate_hx": 25}}, "preprocess.rate_hx: unknown key"),
    ("preprocess", {"preprocess": {"rate_hz": "fast"}}, "preprocess.rate_hz: 'fast' is not a number"),
    ("preprocess", {"preprocess": {"ned_method": "ecef"}}, "preprocess.ned_method: 'ecef' is not one of wgs84, flat"),
    ("preprocess", {"preprocess": {"bpm": {"spike_window": "5"}}}, "preprocess.bpm.spike_window: '5' is not an integer"),
    ("preprocess", {"preprocess": {"vehicles": {"v": {"controls": {"ail": {"chan": "x"}}}}}},
     "preprocess.vehicles.v.controls.ail.chan: unknown key"),
    ("hmm", {"hmm": {"n_state": 3}}, "hmm.n_state: unknown key"),
    ("hmm", {"hmm": {"n_iter": "many"}}, "hmm.n_iter: 'many' is not an integer"),
    ("hmm", {"hmm": {"window_s": "long"}}, "hmm.window_s: 'long' is not a number > 0 or 'auto'"),
    ("hmm", {"hmm": {"n_states": {"M1": "x"}}}, "hmm.n_states.M1: 'x' is not"),
    ("model_sets", {"model_sets": {"s": {"data": "simulated", "vehicle": ["q"]}}}, "model_sets.s.vehicle: unknown key"),
    ("model_sets", {"model_sets": {"s": {"data": "simulated", "vehicles": ["q"], "reset_at_segments": "yes"}}},
     "model_sets.s.reset_at_segments: 'yes' is not true/false"),
    ("model_sets", {"model_sets": {"s": {"data": "simulated", "vehicles": ["q"], "hmm": {"n_stats": 3}}}},
     "model_sets.s.hmm.n_stats: unknown key"),
    ("estimate", {"estimate": {"ekf": {"qq": 1.0}}}, "estimate.ekf.qq: unknown key"),
    ("estimate", {"estimate": {"ekf_hmm": {"q2_scale": "big"}}}, "estimate.ekf_hmm.q2_scale: 'big' is not a number"),
    ("estimate", {"estimate": {"ekf_hmm": {"increments": "predicted"}}},
     "estimate.ekf_hmm.increments: 'predicted' is not one of prior, posterior"),
    ("estimate", {"estimate": {"synthetic_radar": {"v": {"sigma_rnage_m": 1}}}},
     "estimate.synthetic_radar.v.sigma_rnage_m: unknown key"),
    ("model_sets", {"model_sets": {"s": {"data": "simulated", "vehicles": ["q"], "input": "gps"}}},
     "model_sets.s.input: 'gps' is not one of truth, ekf"),
    ("estimate", {"estimate": {"sets": {"qq": 1}}}, "estimate.sets.qq: unknown key"),
    ("estimate", {"estimate": {"sets": {"q": 0}}}, r"estimate.sets.q: 0 is out of range \(must be > 0\)"),
    ("estimate", {"estimate": {"sets": {"p0_sigma": [1, 2]}}}, "estimate.sets.p0_sigma: .* needs exactly 3"),
    ("align", {"align": {"window_c": 20}}, "align.window_c: unknown key"),
    ("align", {"align": {"window_C": 0}}, r"align.window_C: 0 is out of range"),
    ("align", {"align": {"sets": {"p23": {"flights": ["a"], "ref": "a"}}}}, "align.sets.p23.ref: unknown key"),
    ("studies", {"studies": {"trajectory_learning": {"skip": ["sim"]}}},
     r"studies.trajectory_learning.skip\[0\]: 'sim' is not one of simulated, real"),
    ("studies", {"studies": {"sise": "tiny"}}, "studies.sise: unknown key"),
    ("studies", {"studies": {"seed000_classification": {"ekf_input": "yes"}}},
     "studies.seed000_classification.ekf_input: 'yes' is not true/false"),
    ("studies", {"studies": {"size": "huge"}}, "studies.size: 'huge' is not one of tiny, small, thesis"),
    ("top", {"foo": {}}, "foo: unknown section"),
    ("top", {"seed": "x"}, "seed: 'x' is not an integer"),
    ("top", {"models": {"n_states": 3}}, "models: unknown section"),
    ("top", {"train": {}}, "train: unknown section"),
]


@pytest.mark.parametrize("section, bad, match", BAD, ids=[m.split(":")[0] + "-" + m.split(": ")[1][:12] for _, _, m in BAD])
def test_a_bad_key_or_value_is_one_line_naming_the_file_and_key_path(tmp_path, section, bad, match):
    p = _write(tmp_path, bad)
    with pytest.raises(ConfigError) as exc:
        load_config(p)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"{p}: ") or msg.startswith("cfg.yaml: ")
    assert re.search(match, msg), msg
    # the same message without the file for an in-memory config
    with pytest.raises(ConfigError, match=match):
        validate_config(bad)


def test_every_section_of_the_schema_is_covered_by_the_bad_key_cases():
    covered = {s for s, _, _ in BAD}
    objects = {k for k, v in C.schema()["properties"].items() if v.get("type") == "object"}
    assert objects <= covered


def test_unknown_keys_are_reported_before_sibling_type_errors_deterministically():
    bad = {"preprocess": {"rate_hz": "fast", "gap_multiple": "x", "rate_hx": 1}, "hmm": {"tol": "y"}}
    msgs = {str(_raises(bad)) for _ in range(3)}
    assert msgs == {"preprocess.rate_hx: unknown key (allowed: rate_hz, gap_multiple, clock_jump_s, "
                    "position_source, ned_method, velocity_source, vertical_from_baro, methods, causal, butterworth, "
                    "derivatives, gps_smoother, bpm, segments, vehicles, flights) (also wrong: hmm.tol, "
                    "preprocess.gap_multiple, preprocess.rate_hz)"}
    # no unknown key: the first error in key order
    assert str(_raises({"preprocess": {"rate_hz": "fast", "gap_multiple": "x"}})) == \
        "preprocess.gap_multiple: 'x' is not a number (also wrong: preprocess.rate_hz)"


def test_a_yaml_nan_or_inf_is_not_a_number_even_where_a_range_is_set(tmp_path):
    # NaN compares false with every bound, so only the type check can stop it before a stage
    p = tmp_path / "cfg.yaml"
    p.write_text("preprocess:\n  rate_hz: .nan\nsimulate:\n  rate_hz: .inf\n")
    with pytest.raises(ConfigError, match=r": preprocess\.rate_hz: nan is not a finite number \(also wrong: "
                                          r"simulate\.rate_hz\)$"):
        load_config(p)
    assert str(_raises({"simulate": {"rate_hz": float("-inf")}})) == "simulate.rate_hz: -inf is not a finite number"


def test_an_exponent_yaml_reads_as_text_is_refused_with_the_spelling_it_reads_as_a_number(tmp_path):
    p = tmp_path / "cfg.yaml"
    p.write_text("hmm:\n  min_covar: 1e-4\n")
    with pytest.raises(ConfigError, match=r"hmm\.min_covar: '1e-4' is not a number \(YAML reads 1e-4 as text: "
                                          r"write 1\.0e-4\)$"):
        load_config(p)
    p.write_text("hmm:\n  min_covar: 1.0e-4\n")
    assert load_config(p)["hmm"]["min_covar"] == 1e-4


def _raises(cfg) -> ConfigError:
    with pytest.raises(ConfigError) as exc:
        validate_config(cfg)
    return exc.value


def test_a_section_validated_alone_names_its_full_path_and_unknown_sections_fail():
    with pytest.raises(ConfigError, match=r"^preprocess\.derivatives\.windw_s: unknown key"):
        validate_section("preprocess.derivatives", {"windw_s": 1})
    with pytest.raises(ConfigError, match="unknown section"):
        C.section({}, "models")
    assert C.section({}, "studies")["size"] == "small"


def test_unreadable_files_are_one_line_errors(tmp_path):
    with pytest.raises(ConfigError, match="config file not found"):
        load_config(tmp_path / "nope.yaml")
    p = tmp_path / "bad.yaml"
    p.write_text("a: [1,\n")
    with pytest.raises(ConfigError, match="invalid YAML") as exc:
        load_config(p)
    assert "\n" not in str(exc.value)
    # the place once, as file:line:column, and the problem in words without the reader's marks
    p.write_text("seed: 1\npreprocess: {rate_hz: 25\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml:3:1: invalid YAML: while parsing a flow mapping; "
                                          r"did not find expected ',' or '}'$"):
        load_config(p)
    p.write_text("- 1\n")
    with pytest.raises(ConfigError, match="top level must be a mapping"):
        load_config(p)
    p.write_bytes(b"seed: 3\nnotes: caf\xe9\n")  # latin-1, as an old editor saves it
    with pytest.raises(ConfigError, match=r"bad\.yaml:2: not UTF-8 text \(byte 0xe9\)"):
        load_config(p)
    with pytest.raises(ConfigError, match="cannot read the config: Is a directory"):
        load_config(tmp_path)
    p.write_bytes(b"\xef\xbb\xbfseed: 3\n")  # a byte-order mark is not part of the first key
    assert load_config(p)["seed"] == 3



def test_a_key_given_twice_in_one_mapping_is_an_error_naming_both_lines(tmp_path):
    # YAML keeps the last silently: a second `preprocess:` block would drop the whole first one
    p = tmp_path / "dup.yaml"
    p.write_text("seed: 1\npreprocess:\n  rate_hz: 5\n  gap_multiple: 3\npreprocess:\n  rate_hz: 10\n")
    with pytest.raises(ConfigError, match=r"dup\.yaml:5:1: invalid YAML: duplicate key 'preprocess' "
                                          r"\(first on line 2\)$"):
        load_config(p)
    p.write_text("preprocess:\n  rate_hz: 5\n  rate_hz: 6\n")
    with pytest.raises(ConfigError, match=r"duplicate key 'rate_hz' \(first on line 2\)"):
        load_config(p)
    # the same key in two different mappings, and YAML merge keys, are fine
    p.write_text("base: &b {rate_hz: 5}\n")
    assert read_config_file(p) == {"base": {"rate_hz": 5}}
    p.write_text("a: &x {k: 1}\nb:\n  <<: *x\n  j: 2\nc: {k: 3}\n")
    assert read_config_file(p) == {"a": {"k": 1}, "b": {"k": 1, "j": 2}, "c": {"k": 3}}


def test_an_alias_inside_its_own_anchor_is_one_line_naming_the_key_not_a_recursion_error(tmp_path):
    # `a: &x [*x]` loads as a list that holds itself; validating it recursed without end
    p = tmp_path / "loop.yaml"
    p.write_text("seed: 1\nestimate:\n  vehicles: &v [quad, *v]\n")
    with pytest.raises(ConfigError, match=r"loop\.yaml: estimate\.vehicles\.1: a YAML alias refers to the value "
                                          r"that contains it"):
        load_config(p)
    # the same anchor used twice side by side (no loop) is fine
    p.write_text("a: &x [1]\nb: *x\n")
    assert read_config_file(p) == {"a": [1], "b": [1]}


# --- the schema agrees with the code's vocabularies ----------------------------------------------

def test_the_schema_enums_are_the_codes_vocabularies():
    from pipeline.models.features import FEATURE_SETS
    from pipeline.preprocess.controls import DEFAULT_CONTROLS, PHYSICAL, STICKS
    from pipeline.preprocess.derivatives import DIFF_METHODS
    from pipeline.preprocess.resample import METHODS
    from pipeline.preprocess.segment import SOURCES
    from pipeline.preprocess.state import POSITION_SOURCES
    from pipeline.simulate.maneuvers import MANEUVERS

    s = C._subschema
    assert s("hmm.feature_set")["enum"] == list(FEATURE_SETS)
    assert s("preprocess.methods")["additionalProperties"]["enum"] == list(METHODS)
    assert s("preprocess.segments.source")["enum"] == list(SOURCES)
    assert s("preprocess.derivatives.method")["enum"] == list(DIFF_METHODS)
    assert s("preprocess.position_source")["enum"] == list(POSITION_SOURCES)
    assert s("simulate.datasets.maneuvers")["items"]["enum"] == list(MANEUVERS)
    assert set(s("preprocess.vehicles.*.controls")["properties"]) == set(STICKS)
    assert set(s("preprocess.vehicles.*.physical")["properties"]) == set(PHYSICAL)
    assert C.default_at("preprocess.vehicles.*.controls") == DEFAULT_CONTROLS


def test_a_control_channel_is_exactly_a_column_of_the_control_stream():
    import re

    from pipeline.io import schema

    pat = re.compile(C.schema()["$defs"]["control_channel"]["pattern"])
    cols = {c for c in schema.column_names("control") if c.endswith("_us")}
    assert cols and all(pat.match(c) for c in cols)
    near = {f"{k}_{i}_us" for k in ("rc", "servo") for i in range(0, 100)} | {"rc_1", "RC_1_us", "rc_01_us"}
    assert {c for c in near if pat.match(c)} == cols
    with pytest.raises(ConfigError, match=r"controls\.ail\.channel: 'rc_99_us' is not a control column"):
        validate_config({"preprocess": {"vehicles": {"v": {"controls": {"ail": {"channel": "rc_99_us"}}}}}})


def test_the_hmm_section_and_its_overrides_have_the_same_keys_and_overrides_no_defaults():
    sch = C.schema()
    over = sch["$defs"]["hmm_override"]["properties"]
    assert list(sch["properties"]["hmm"]["properties"]) == list(over)
    assert not any("default" in v for v in over.values())


# --- documentation -----------------------------------------------------------------------------

def test_every_schema_key_is_documented_in_datasets_readme():
    text = (ROOT / "datasets" / "README.md").read_text()
    missing = [p for p, _ in C.key_paths() if f"`{p}`" not in text]
    assert not missing, missing
    begin = text.index("-->\n", text.index("<!-- BEGIN key reference")) + 4
    end = text.index("<!-- END key reference -->")
    assert text[begin:end] == C.markdown_reference(), "regenerate: python -m pipeline.config"


def test_the_shipped_file_points_users_to_the_schema_and_the_readme():
    text = (ROOT / "datasets" / "config.yaml").read_text()
    assert "rules/schemas/config.schema.yaml" in text and "datasets/README.md" in text


def test_command_line_overrides_read_their_nested_scalars_as_the_config_file_does():
    # what Snakemake's parse_config hands over for
    # --config seed=7 studies='{size: thesis, seed000_classification: {ekf_input: true, n_states: 6}}'
    cli = {"seed": 7, "realdata_dir": "/data/real", "studies": {
        "size": "thesis", "seed000_classification": {"ekf_input": "true", "n_states": "6", "skip": ["gmr"]},
        "pf": {"seeds": "null"}}}
    out = C.command_line_overrides(cli)
    assert out == {"seed": 7, "realdata_dir": "/data/real", "studies": {
        "size": "thesis", "seed000_classification": {"ekf_input": True, "n_states": 6, "skip": ["gmr"]},
        "pf": {"seeds": None}}}
    assert C.command_line_overrides(None) == {}
    # still validated: a typed override passes, a wrong one is still one line naming its key
    ok = validate_config({"studies": {"size": "thesis",
                                      "seed000_classification": out["studies"]["seed000_classification"]}})
    assert ok["studies"]["seed000_classification"]["ekf_input"] is True
    with pytest.raises(ConfigError, match=r"studies\.seed000_classification\.ekf_input: 'maybe'"):
        validate_config(C.command_line_overrides({"studies": {"seed000_classification": {"ekf_input": "maybe"}}}))


def test_a_setting_written_out_reordered_or_as_an_integer_validates_to_the_same_repr():
    # Snakemake reruns a job whose params' repr changed: `q: 3` for 3.0, a default written out
    # (it used to land after the filled defaults) or two keys swapped must change nothing
    base = repr(validate_config({}))
    hmm = C.default_at("hmm")
    swapped = dict(reversed(list(hmm.items())))
    variants = [
        {"preprocess": {"rate_hz": int(C.default_at("preprocess.rate_hz"))}},
        {"preprocess": {"rate_hz": float(C.default_at("preprocess.rate_hz"))}},
        {"hmm": {"n_iter": C.default_at("hmm.n_iter")}},
        {"hmm": swapped},
        {"estimate": {"ekf": {"q": C.default_at("estimate.ekf.q")}}},
        {"estimate": {"ekf": {"q": int(C.default_at("estimate.ekf.q"))}}}
        if float(C.default_at("estimate.ekf.q")).is_integer() else {},
    ]
    for v in variants:
        assert repr(validate_config(v)) == base, v
    # a real change still shows
    assert repr(validate_config({"hmm": {"n_iter": C.default_at("hmm.n_iter") + 1}})) != base


def test_an_unquoted_iso_time_that_yaml_reads_as_a_timestamp_is_taken_as_its_text():
    # YAML (and so Snakemake's --configfile reader) turns 2026-01-02T12:00:00Z into a datetime;
    # before, the schema refused it as "datetime.datetime(2026, 1, 2, 12, 0, tzinfo=...)"
    cfg = yaml.safe_load("simulate: {start_time_utc: 2026-01-02T12:00:00Z}")
    out = validate_config(cfg)["simulate"]["start_time_utc"]
    assert out == "2026-01-02T12:00:00+00:00"
    from pipeline.simulate.datasets import DatasetSettings
    assert DatasetSettings.from_config(validate_config(cfg)["simulate"]).start_time_utc_ns == 1767355200 * 10**9


def test_the_schemas_stream_names_are_the_canonical_streams_and_a_bad_ros_stream_fails_at_start_up():
    from pipeline.io.schema import STREAM_NAMES

    raw = yaml.safe_load(C.SCHEMA_PATH.read_text())
    assert raw["$defs"]["stream_name"]["enum"] == list(STREAM_NAMES)
    for bad, where in (({"/imu/data": {"stream": "imuu"}}, "ingest.ros.topics['/imu/data'].stream: 'imuu'"),
                       ({"/imu/data": "imuu"}, "ingest.ros.topics['/imu/data']: 'imuu'")):
        with pytest.raises(ConfigError, match=re.escape(where)):
            validate_config({"ingest": {"ros": {"topics": bad}}})
    ok = {"/a": "ignore", "/b": None, "/c": False, "/d": "gps", "/e": {"stream": "imu", "instance": 1}}
    assert validate_config({"ingest": {"ros": {"topics": ok}}})["ingest"]["ros"]["topics"] == ok
    with pytest.raises(ConfigError, match=re.escape("custom['/r'].stream: 'radr'")):
        validate_config({"ingest": {"ros": {"custom": {"/r": {"stream": "radr", "fields": {"range_m": "r"}}}}}})


def test_a_config_with_several_mistakes_names_the_first_and_the_other_keys_on_one_line():
    with pytest.raises(ConfigError) as err:
        validate_config({"preprocess": {"rate_hzz": 25, "rate_hz": -5, "gap_multiple": "x"}})
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("preprocess.rate_hzz: unknown key")
    assert msg.endswith("(also wrong: preprocess.gap_multiple, preprocess.rate_hz)")
    with pytest.raises(ConfigError) as one:
        validate_config({"preprocess": {"rate_hz": -5}})
    assert "also wrong" not in str(one.value)
