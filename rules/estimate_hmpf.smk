# Estimate, issue 17: the seed-003 weave classifier (hmpf) per flight of estimate.pf.hmpf.vehicles
# (default f3a-plane) -> results/estimate/hmpf/<flight>.parquet. delta_max/theta_max come from the
# labelled segments of the vehicle's *other* role-train flights (never the flight classified). The
# f3a flights exist only with the real logs (../shared/realdata): without them there is no job and
# one notice, the main job is unchanged. Included before rules/estimate.smk (its `estimate` target
# takes hmpf_paths()). Its planning (HMPF_FLIGHTS, hmpf_inputs, ...) is in rules/common.smk.

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
