# Estimate, issue 17: the seed-003 weave classifier (hmpf) per flight of estimate.pf.hmpf.vehicles
# (default f3a-plane) -> results/estimate/hmpf/<flight>.parquet. delta_max/theta_max come from the
# labelled segments of the vehicle's *other* role-train flights (never the flight classified). The
# f3a flights exist only with the real logs (../shared/realdata): without them there is no job and
# one notice, the main job is unchanged. Included before rules/estimate.smk (its `estimate` target
# takes hmpf_paths()).

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
        "train_states": [f"results/state/{f}.parquet" for f in tr],
        "train_segments": [f"results/segments/{f}.parquet" for f in tr],
    }


rule estimate_hmpf:
    input:
        unpack(hmpf_inputs),
    output:
        hmpf="results/estimate/hmpf/{flight}.parquet",
    params:
        code_version=PIPELINE_VERSION,
        config=HMPF_CONFIG,
        job=lambda wc: {"flight_id": wc.flight, "seed": config["seed"]},
    log:
        "results/logs/estimate_hmpf/{flight}.log",
    benchmark:
        "results/benchmarks/estimate_hmpf/{flight}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/estimate_hmpf.py"


def flight_hmpf(wildcards):
    # the flight page's weave panel (rules/report.smk)
    return [f"results/estimate/hmpf/{wildcards.flight}.parquet"] if wildcards.flight in HMPF_FLIGHTS else []
