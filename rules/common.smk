# Helpers shared by all rules: config + manifest validation, flight selection, wildcards, the
# declared inputs and outputs of every stage.
import sys
import types

import numpy as np
import pandas as pd
from snakemake.utils import update_config, validate

import pipeline
from pipeline.config import ConfigError, command_line_overrides, read_config_file, validate_config
from pipeline.estimate.run import job_config as estimate_job_config
from pipeline.estimate.pf_run import job_config as pf_job_config
from pipeline.io.manifest import COLUMNS as MANIFEST_COLUMNS, check_manifest, expand_path, log_available
from pipeline.io.schema import STREAM_NAMES
from pipeline.models.run import check_model_set_labels, model_set_config
from pipeline.preprocess.state import check_preprocess_config
from pipeline.simulate.maneuvers import MANEUVERS as SIM_KNOWN_MANEUVERS
from pipeline.report.summary import run_summary
from pipeline.simulate.run import planned_logs, planned_sets
from pipeline.studies.base import STUDY_TABLES

PIPELINE_VERSION = pipeline.__version__

# one schema for the workflow and the CLI: every key typed and defaulted, unknown keys rejected;
# a bad key or value stops the run here with one line naming it. `--config` overrides first get
# their nested scalars typed as in the config file (Snakemake leaves them strings: 'true', '500')
update_config(config, command_line_overrides(workflow.config_settings.config))
try:
    for _cf in workflow.configfiles:  # what Snakemake's reader lets pass: a key given twice
        read_config_file(_cf)
    _sources = [*map(str, workflow.configfiles), *(["--config"] if workflow.config_settings.config else [])]
    _validated = validate_config(config, source=" + ".join(_sources) or "config")
except ConfigError as _exc:
    sys.exit(f"uavpipe: {_exc}")
config.clear()
config.update(_validated)

# simulated outputs are fixed by the config (static DAG): sets and log-file flights
try:
    SIM_SETS = planned_sets(config["simulate"])
    SIM_LOGS = planned_logs(config["simulate"])
except ConfigError as _exc:
    sys.exit(f"uavpipe: {_exc}")

# the manifest: one line per bad row (file, line, flight id, reason) before any job is planned
# (pipeline/io/manifest.py: vehicles, labels, duplicate ids, reader names, simulated logs this
# config does not write); then its schema
try:
    _manifest = pd.DataFrame(
        check_manifest(config["manifest"], config, simulated_logs={s["log"] for s in SIM_LOGS}),
        columns=list(MANIFEST_COLUMNS), dtype=str,
    )
except ConfigError as _exc:  # one line per bad row
    sys.exit("\n".join(f"uavpipe: {_ln}" for _ln in str(_exc).splitlines()))
validate(_manifest, schema="schemas/flights.schema.yaml", set_default=True)


def _expand_path(p):
    """A manifest path with {realdata} (the config's realdata_dir) and a leading ~ expanded."""
    return expand_path(p, config["realdata_dir"])


SIM_MANEUVERS = sorted({n.rsplit("_", 1)[0] for n in SIM_SETS if n.endswith("_test")})
# the maneuver sets the EKF filters (rules/estimate_sets.smk): what model sets with input: ekf read
EKF_SETS = [n for n in SIM_SETS if n.endswith(("_train", "_test"))]
MODEL_SETS = config["model_sets"]
try:
    check_model_set_labels(MODEL_SETS, SIM_MANEUVERS, SIM_KNOWN_MANEUVERS)
    check_preprocess_config(config["preprocess"])   # what the schema cannot: mounts, stick ranges
except ConfigError as _exc:
    sys.exit(f"uavpipe: {_exc}")
STUDY_NAMES = list(STUDY_TABLES)  # rules/studies.smk: one target each, not in `all`

SKIPPED = {}  # manifest rows left out (flight id -> reason), for the end-of-run summary


def _available(row):
    path = _expand_path(row.path)
    if log_available(path):
        return True
    SKIPPED[row.flight_id] = f"{path} not found"
    print(
        f"uavpipe: skipping flight {row.flight_id}: {path} not found",
        file=sys.stderr,
    )
    return False


# a boolean array, not a list: an empty list (a manifest of only its header) would select columns
flights = _manifest[np.array([_available(r) for r in _manifest.itertuples()], dtype=bool)].set_index(
    "flight_id", drop=False
)
FLIGHTS = list(flights.flight_id)
STREAMS = list(STREAM_NAMES)


wildcard_constraints:
    flight="|".join(FLIGHTS) if FLIGHTS else "NO_FLIGHTS",
    model_set="|".join(MODEL_SETS) if MODEL_SETS else "NO_MODEL_SETS",


# --- ingest -----------------------------------------------------------------------------------


def flight_log(wildcards):
    return _expand_path(flights.loc[wildcards.flight, "path"])


def flight_labels(wildcards):
    lab = flights.loc[wildcards.flight, "labels"]
    return [] if lab in ("", "none", "embedded") else [_expand_path(lab)]


def ingest_job(wildcards):
    return {
        "flight_id": wildcards.flight,
        "fmt": flights.loc[wildcards.flight, "format"] or None,
        "labels_embedded": flights.loc[wildcards.flight, "labels"] == "embedded",
    }


def ingest_streams(flight):
    return [f"results/ingest/{flight}/{s}.parquet" for s in STREAMS]


def ingest_outputs(flight):
    return ingest_streams(flight) + [f"results/ingest/{flight}/meta.json"]


def ingest_inputs(wildcards):
    return {
        "meta": f"results/ingest/{wildcards.flight}/meta.json",
        "streams": ingest_streams(wildcards.flight),
    }


# --- simulate ---------------------------------------------------------------------------------


def sim_log_outputs():
    return [
        (
            directory(f"results/sim/logs/{s['log']}")
            if s["is_dir"]
            else f"results/sim/logs/{s['log']}"
        )
        for s in SIM_LOGS
    ]


# --- preprocess -------------------------------------------------------------------------------


def preprocess_job(wildcards):
    return {"vehicle": flights.loc[wildcards.flight, "vehicle"]}


# --- model sets -------------------------------------------------------------------------------


def model_sets_of(flight):
    """The model sets whose vehicles include the flight's vehicle (each classifies it). A set
    trained on EKF estimates (input: ekf) classifies none: its input is the EKF's increments,
    which the EKF+HMM feeds it (estimate.ekf_hmm.model); fed the preprocessed GPS state, simekf
    called the simulated M1 flight M4 on 121 of 125 maneuver samples (its EKF+HMM: M1 on 119)."""
    veh = flights.loc[flight, "vehicle"]
    return [m for m, spec in MODEL_SETS.items()
            if veh in spec["vehicles"] and spec.get("input", "truth") != "ekf"]


CLASSIFIED = [(m, f) for f in FLIGHTS for m in model_sets_of(f)]


def classified_paths():
    return [f"results/classify/{m}/{f}.parquet" for m, f in CLASSIFIED]


def set_config(model_set):
    return model_set_config(config, model_set)


def flights_of(model_set, role):
    vehicles = MODEL_SETS[model_set]["vehicles"]
    return [
        f
        for f in FLIGHTS
        if flights.loc[f, "role"] == role and flights.loc[f, "vehicle"] in vehicles
    ]


def _set_labels(model_set):
    spec = MODEL_SETS[model_set]
    return [m for m in SIM_MANEUVERS if m in spec.get("labels", SIM_MANEUVERS)]


def _sets_dir(model_set):
    """Where a simulated model set's bulk sets are: the truth, or its EKF estimates (input: ekf)."""
    return "results/estimate/sets" if MODEL_SETS[model_set].get("input", "truth") == "ekf" else "results/sim/sets"


def train_inputs(wildcards):
    m = wildcards.model_set
    if MODEL_SETS[m]["data"] == "simulated":
        return {"sets": [f"{_sets_dir(m)}/{l}_train.parquet" for l in _set_labels(m)]}
    fl = flights_of(m, "train")
    return {
        "states": [f"results/state/{f}.parquet" for f in fl],
        "segments": [f"results/segments/{f}.parquet" for f in fl],
    }


def model_set_inputs():
    """Model set -> the files its training reads (the end-of-run summary calls a set trained
    before one of them was rewritten stale)."""
    return {m: [p for v in train_inputs(types.SimpleNamespace(model_set=m)).values() for p in v]
            for m in MODEL_SETS}


def q2_inputs(wildcards):
    """The EKF+HMM's Q2 data of a model set: its training data, and for a model set trained on EKF
    estimates (input: ekf) the truth of the same runs too (the one-step errors are against it)."""
    d = train_inputs(wildcards)
    m = wildcards.model_set
    if MODEL_SETS[m]["data"] == "simulated" and MODEL_SETS[m].get("input", "truth") == "ekf":
        d["truth_sets"] = [f"results/sim/sets/{l}_train.parquet" for l in _set_labels(m)]
    return d


def evaluate_inputs(wildcards):
    m = wildcards.model_set
    if MODEL_SETS[m]["data"] == "simulated":
        return {
            "train_sets": [f"{_sets_dir(m)}/{l}_train.parquet" for l in _set_labels(m)],
            "test_sets": [f"{_sets_dir(m)}/{l}_test.parquet" for l in SIM_MANEUVERS],
        }
    return {
        "classified": [
            f"results/classify/{m}/{f}.parquet" for f in flights_of(m, "test")
        ]
    }


def flight_classified(wildcards):
    return [
        f"results/classify/{m}/{wildcards.flight}.parquet"
        for m in model_sets_of(wildcards.flight)
    ]


# --- estimate ---------------------------------------------------------------------------------

ESTIMATORS = ("ekf", "ekf_rts", "ekf_hmm")
ESTIMATE_MODEL = config["estimate"]["ekf_hmm"]["model"]
ESTIMATED = [f for f in FLIGHTS if flights.loc[f, "vehicle"] in config["estimate"]["vehicles"]]
if ESTIMATED and ESTIMATE_MODEL not in MODEL_SETS:
    sys.exit(
        f"uavpipe: {' + '.join(_sources) or 'config'}: estimate.ekf_hmm.model: "
        f"no model set {ESTIMATE_MODEL!r} (model_sets: {', '.join(MODEL_SETS) or 'none'})"
    )


def estimate_paths(flight=None):
    return [
        f"results/estimate/{e}/{f}.parquet"
        for f in (ESTIMATED if flight is None else [flight])
        for e in ESTIMATORS
    ]


def flight_estimates(wildcards):
    # + the particle filters of rules/estimate_pf.smk (issue 17)
    return (estimate_paths(wildcards.flight) if wildcards.flight in ESTIMATED else []) + flight_pf_estimates(wildcards)


# issue 17: the particle filters (rules/estimate_pf.smk), per flight of estimate.pf.vehicles
PF_ESTIMATED = [f for f in FLIGHTS if flights.loc[f, "vehicle"] in config["estimate"]["pf"]["vehicles"]]


def pf_paths(flight=None):
    return [f"results/estimate/pf_jm/{f}.parquet" for f in (PF_ESTIMATED if flight is None else [flight])]


def flight_pf_estimates(wildcards):
    return pf_paths(wildcards.flight) if wildcards.flight in PF_ESTIMATED else []


def estimate_config(wildcards):
    # the flight's own sub-sections only: its vehicle's synthetic_radar entry, radar, ekf, ekf_hmm
    return estimate_job_config(
        config["estimate"], flights.loc[wildcards.flight, "vehicle"]
    )


def estimate_job(wildcards):
    return {
        "flight_id": wildcards.flight,
        "vehicle": flights.loc[wildcards.flight, "vehicle"],
        "seed": config["seed"],
    }


# --- align ------------------------------------------------------------------------------------

# a demo set is planned only when every one of its flights is in the manifest with its file
# present (static DAG); the others are skipped here with a notice and never break the run
ALIGN_SETS = []
for _name, _spec in config["align"]["sets"].items():
    _absent = [f for f in _spec["flights"] if f not in FLIGHTS]
    if _absent:
        print(
            f"uavpipe: skipping align set {_name}: flight(s) {', '.join(_absent)} not available",
            file=sys.stderr,
        )
    else:
        ALIGN_SETS.append(_name)


wildcard_constraints:
    align_set="|".join(ALIGN_SETS) if ALIGN_SETS else "NO_ALIGN_SETS",


def align_inputs(wildcards):
    fl = config["align"]["sets"][wildcards.align_set]["flights"]
    return {
        "states": [f"results/state/{f}.parquet" for f in fl],
        "segments": [f"results/segments/{f}.parquet" for f in fl],
    }


def align_config(wildcards):
    # the set's own entry only, so editing another set never reruns this one
    sec = {k: v for k, v in config["align"].items() if k not in ("sets", "simulate", "pitch_band_deg")}
    sec["sets"] = {wildcards.align_set: config["align"]["sets"][wildcards.align_set]}
    return sec


def align_paths():
    return [f"results/report/align/{s}.html" for s in ALIGN_SETS]


# --- bearing-only replay (issue 16) ----------------------------------------------------------

BEARING_ESTIMATORS = ("bank_cppv", "bank_mpc", "imm")
BEARING_PAIRS = {}
for _pair, _spec in config["estimate"]["bearing_only"]["replay"].items():
    _missing = [f for f in (_spec["ownship"], _spec["intruder"]) if f not in FLIGHTS]
    if _missing:
        print(
            f"uavpipe: skipping bearing pair {_pair}: flight(s) {', '.join(_missing)} not available",
            file=sys.stderr,
        )
    else:
        BEARING_PAIRS[_pair] = _spec


def bearing_paths():
    return [
        f"results/estimate/{e}/{p}.parquet" for p in BEARING_PAIRS for e in BEARING_ESTIMATORS
    ]


def bearing_pages():
    return [f"results/report/bearing/{p}.html" for p in BEARING_PAIRS]


def bearing_inputs(wildcards):
    spec = BEARING_PAIRS[wildcards.pair]
    own, intr = spec["ownship"], spec["intruder"]
    return {
        "ownship_state": f"results/state/{own}.parquet",
        "ownship_local_position": f"results/ingest/{own}/local_position.parquet",
        "intruder_state": f"results/state/{intr}.parquet",
    }


def get_final_output():
    # the simulated sets and logs are always made (the seed-000 datasets), used by a flight or not
    return [
        *estimate_paths(),
        *align_paths(),
        *bearing_paths(),
        "results/index.html",
        "results/sim/index.json",
        "results/sim/logs/flights.tsv",
    ]


# --- hmpf (issue 17, seed-003 weave classifier; rule in rules/estimate_hmpf.smk) ---------------

HMPF_CONFIG = config["estimate"].get("pf", {}).get("hmpf", {})
HMPF_VEHICLES = HMPF_CONFIG.get("vehicles", ["f3a-plane"])
HMPF_FLIGHTS = [f for f in FLIGHTS if flights.loc[f, "vehicle"] in HMPF_VEHICLES]
if not HMPF_FLIGHTS:
    print(
        f"uavpipe: hmpf: no flight of {', '.join(HMPF_VEHICLES)} available (real logs absent?): "
        "no weave-classifier job",
        file=sys.stderr,
    )


def hmpf_paths():
    return [f"results/estimate/hmpf/{f}.parquet" for f in HMPF_FLIGHTS]


def hmpf_train_flights(flight):
    vehicle = flights.loc[flight, "vehicle"]
    return [
        f
        for f in FLIGHTS
        if f != flight and flights.loc[f, "role"] == "train" and flights.loc[f, "vehicle"] == vehicle
    ]


def hmpf_inputs(wildcards):
    tr = hmpf_train_flights(wildcards.flight)
    return {
        "state": f"results/state/{wildcards.flight}.parquet",
        # its own segments: the process noise of a train flight with no other one (weave_run)
        "segments": f"results/segments/{wildcards.flight}.parquet",
        "train_states": [f"results/state/{f}.parquet" for f in tr],
        "train_segments": [f"results/segments/{f}.parquet" for f in tr],
    }


def flight_hmpf(wildcards):
    # the flight page's weave panel (rules/report.smk)
    return [f"results/estimate/hmpf/{wildcards.flight}.parquet"] if wildcards.flight in HMPF_FLIGHTS else []
