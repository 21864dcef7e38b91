# Noise-aware training data: the CA EKF over every simulated maneuver set on radar synthesised
# from the truth (pipeline/estimate/sets.py), in the bulk-set schema, for model sets with
# `input: ekf`. One job for all sets: each set filters in a fraction of a second, so one Python
# start-up is most of the cost.


rule ekf_sets:
    input:
        sets=expand("results/sim/sets/{name}.parquet", name=EKF_SETS),
    output:
        sets=expand("results/estimate/sets/{name}.parquet", name=EKF_SETS),
    params:
        code_version=PIPELINE_VERSION,
        # estimate.sets, and the simulated flights' radar (one radar for sets and flights)
        config={**config["estimate"]["sets"], "radar": config["simulate"]["sensors"]["radar"]},
        job={"seed": config["seed"]},
    log:
        "results/logs/ekf_sets/ekf_sets.log",
    benchmark:
        "results/benchmarks/ekf_sets/ekf_sets.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/ekf_sets.py"
