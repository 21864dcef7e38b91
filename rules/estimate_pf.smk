# issue 17, particle filters: the jump-Markov PF pf_jm (CV/CA/CT modes, pipeline/estimate/pf_run.py)
# per flight of estimate.pf.vehicles, measured by the state's NED position, beside the classifier
# of the flight's first model set; outputs join the `estimate` target and the flight pages.
from pipeline.estimate.pf_run import job_config as pf_job_config

PF_ESTIMATED = [f for f in FLIGHTS if flights.loc[f, "vehicle"] in config["estimate"]["pf"]["vehicles"]]


def pf_paths(flight=None):
    return [f"results/estimate/pf_jm/{f}.parquet" for f in (PF_ESTIMATED if flight is None else [flight])]


def flight_pf_estimates(wildcards):
    return pf_paths(wildcards.flight) if wildcards.flight in PF_ESTIMATED else []


def pf_classified(wildcards):
    # the first model set that classifies the flight (none: no classifier columns)
    sets = model_sets_of(wildcards.flight)
    return [f"results/classify/{sets[0]}/{wildcards.flight}.parquet"] if sets else []


rule estimate_pf_jm:
    input:
        state="results/state/{flight}.parquet",
        classified=pf_classified,
    output:
        pf_jm="results/estimate/pf_jm/{flight}.parquet",
    params:
        code_version=PIPELINE_VERSION,
        config=pf_job_config(config["estimate"]["pf"]),
        job=lambda wc: {
            "flight_id": wc.flight,
            "vehicle": flights.loc[wc.flight, "vehicle"],
            "seed": config["seed"],
        },
    log:
        "results/logs/estimate_pf_jm/{flight}.log",
    benchmark:
        "results/benchmarks/estimate_pf_jm/{flight}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/estimate_pf.py"
