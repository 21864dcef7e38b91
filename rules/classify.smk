# Classify: each flight, with every model set whose vehicles include the flight's vehicle ->
# per-sample maneuver labels and confidence.


rule classify_flight:
    input:
        params="results/models/{model_set}/params.npz",
        meta="results/models/{model_set}/meta.json",
        state="results/state/{flight}.parquet",
        segments="results/segments/{flight}.parquet",
    output:
        classification="results/classify/{model_set}/{flight}.parquet",
    params:
        code_version=PIPELINE_VERSION,
        config=lambda wc: set_config(wc.model_set),
        job=lambda wc: {"model_set": wc.model_set},
    log:
        "results/logs/classify_flight/{model_set}/{flight}.log",
    benchmark:
        "results/benchmarks/classify_flight/{model_set}/{flight}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/classify.py"


rule classify:
    input:
        classified_paths(),
