# Simulation: the seed-000 bulk sets, the log-file flights and the demo flight, names fixed by
# config["simulate"] (static DAG).


rule simulate_sets:
    output:
        sets=expand("results/sim/sets/{name}.parquet", name=SIM_SETS),
        summary="results/sim/summary.parquet",
        index="results/sim/index.json",
    params:
        code_version=PIPELINE_VERSION,
        config=config["simulate"],
        job={"seed": config["seed"]},
    log:
        "results/logs/simulate_sets/simulate_sets.log",
    benchmark:
        "results/benchmarks/simulate_sets/simulate_sets.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/simulate_sets.py"


rule simulate_logs:
    output:
        logs=sim_log_outputs(),
        sidecars=[f"results/sim/logs/{s['sidecar']}" for s in SIM_LOGS],
        manifest="results/sim/logs/flights.tsv",
    params:
        code_version=PIPELINE_VERSION,
        config=config["simulate"],
        job={"seed": config["seed"]},
    log:
        "results/logs/simulate_logs/simulate_logs.log",
    benchmark:
        "results/benchmarks/simulate_logs/simulate_logs.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/simulate_logs.py"


rule demo_log:
    output:
        log="results/sim/demo/demo-quad.bin",
    params:
        code_version=PIPELINE_VERSION,
        config=config["simulate"],
        job={"seed": config["seed"]},
    log:
        "results/logs/demo_log/demo-quad.log",
    benchmark:
        "results/benchmarks/demo_log/demo-quad.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/demo_log.py"


rule simulate:
    input:
        rules.simulate_sets.output,
        rules.simulate_logs.output,
