# issue 17, particle filters: the jump-Markov PF pf_jm (CV/CA/CT modes, pipeline/estimate/pf_run.py)
# per flight of estimate.pf.vehicles, measured by the state's NED position; outputs join the
# `estimate` target and the flight pages (which put the classifier's softmax beside the mode
# fractions, so the filter itself never waits for, or reruns with, the classifier).


rule estimate_pf_jm:
    input:
        state="results/state/{flight}.parquet",
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
