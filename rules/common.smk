# Helpers shared by all rules: config + manifest validation, flight selection, wildcards.
import sys
from pathlib import Path

import pandas as pd
from snakemake.utils import validate

import pipeline
from pipeline.simulate.run import planned_logs, planned_sets

PIPELINE_VERSION = pipeline.__version__

validate(config, schema="schemas/config.schema.yaml", set_default=True)

_manifest = pd.read_csv(
    config["manifest"], sep="\t", dtype=str, keep_default_na=False, comment="#"
)
validate(_manifest, schema="schemas/flights.schema.yaml", set_default=True)
if _manifest["flight_id"].duplicated().any():
    raise ValueError(
        f"{config['manifest']}: duplicate flight_id(s): "
        f"{sorted(_manifest.flight_id[_manifest.flight_id.duplicated()])}"
    )


def _expand_path(p):
    """Manifest paths may start with {realdata} (the config's realdata_dir)."""
    return p.replace("{realdata}", config["realdata_dir"].rstrip("/"))


# simulated outputs are fixed by the config (static DAG): sets and log-file flights
SIM_SETS = planned_sets(config["simulate"])
SIM_LOGS = planned_logs(config["simulate"])
SIM_MANEUVERS = sorted({n.rsplit("_", 1)[0] for n in SIM_SETS if n.endswith("_test")})
MODELS = config["train"]
for _row in _manifest.itertuples():
    _p = _row.path.rstrip("/")
    if _p.startswith("results/sim/logs/") and _p.split("/")[-1] not in {
        s["log"] for s in SIM_LOGS
    }:
        raise ValueError(
            f"{config['manifest']}: flight {_row.flight_id}: {_row.path} is not written by "
            f"the simulate stage with this config (simulate.datasets: sizes, log_formats)"
        )


def _available(row):
    # files under results/ are produced by the workflow itself (simulated/demo flights)
    path = _expand_path(row.path)
    if path.startswith("results/") or Path(path).exists():
        return True
    print(
        f"uavpipe: skipping flight {row.flight_id}: {path} not found",
        file=sys.stderr,
    )
    return False


flights = _manifest[[_available(r) for r in _manifest.itertuples()]].set_index(
    "flight_id", drop=False
)
FLIGHTS = list(flights.flight_id)
STREAMS = [
    "imu", "gps", "baro", "mag", "attitude", "local_position", "odometry",
    "rangefinder", "airspeed", "control", "mode", "radar", "truth", "labels",
]


wildcard_constraints:
    flight="|".join(FLIGHTS) if FLIGHTS else "NO_FLIGHTS",
    model="|".join(MODELS) if MODELS else "NO_MODELS",


def flight_log(wildcards):
    return _expand_path(flights.loc[wildcards.flight, "path"])


def flight_labels(wildcards):
    lab = flights.loc[wildcards.flight, "labels"]
    return [] if lab in ("", "none", "embedded") else [_expand_path(lab)]


def flight_format(wildcards):
    return flights.loc[wildcards.flight, "format"] or ""


def ingest_outputs(flight):
    return [f"results/ingest/{flight}/{s}.parquet" for s in STREAMS] + [
        f"results/ingest/{flight}/meta.json"
    ]


def sim_log_outputs():
    return [
        directory(f"results/sim/logs/{s['log']}") if s["is_dir"] else f"results/sim/logs/{s['log']}"
        for s in SIM_LOGS
    ]


def flight_vehicle(wildcards):
    return flights.loc[wildcards.flight, "vehicle"]


def model_of(flight):
    """The first model of config['train'] whose vehicles include the flight's vehicle."""
    veh = flights.loc[flight, "vehicle"]
    return next((m for m, spec in MODELS.items() if veh in spec["vehicles"]), None)


CLASSIFIED = [f for f in FLIGHTS if model_of(f)]


def classify_model(wildcards):
    m = model_of(wildcards.flight)
    return {"params": f"results/models/{m}/params.npz", "meta": f"results/models/{m}/meta.json"}


def flights_of(model, role):
    vehicles = MODELS[model]["vehicles"]
    return [f for f in FLIGHTS if flights.loc[f, "role"] == role and flights.loc[f, "vehicle"] in vehicles]


def train_inputs(wildcards):
    spec = MODELS[wildcards.model]
    if spec["data"] == "simulated":
        labels = [m for m in SIM_MANEUVERS if m in spec.get("labels", SIM_MANEUVERS)]
        return {"sets": [f"results/sim/sets/{m}_train.parquet" for m in labels]}
    fl = flights_of(wildcards.model, "train")
    return {
        "states": [f"results/state/{f}.parquet" for f in fl],
        "segments": [f"results/segments/{f}.parquet" for f in fl],
    }


def evaluate_inputs(wildcards):
    spec = MODELS[wildcards.model]
    if spec["data"] == "simulated":
        labels = [m for m in SIM_MANEUVERS if m in spec.get("labels", SIM_MANEUVERS)]
        return {
            "train_sets": [f"results/sim/sets/{m}_train.parquet" for m in labels],
            "test_sets": [f"results/sim/sets/{m}_test.parquet" for m in SIM_MANEUVERS],
        }
    return {
        "classified": [f"results/classify/{f}.parquet" for f in flights_of(wildcards.model, "test")]
    }


def flight_classified(wildcards):
    return [f"results/classify/{wildcards.flight}.parquet"] if model_of(wildcards.flight) else []


def get_final_output():
    # the simulated sets and logs are always made (the seed-000 datasets), used by a flight or not
    return ["results/index.html", "results/sim/index.json", "results/sim/logs/flights.tsv"]
