# Classify: each flight whose vehicle has a model -> per-sample maneuver labels and confidence.


rule classify_flight:
    input:
        unpack(classify_model),
        state="results/state/{flight}.parquet",
        segments="results/segments/{flight}.parquet",
    output:
        "results/classify/{flight}.parquet",
    params:
        code_version=PIPELINE_VERSION,
        model=lambda wc: model_of(wc.flight),
        reset=lambda wc: MODELS[model_of(wc.flight)].get("reset_at_segments", True),
    log:
        "results/logs/classify_flight/{flight}.log",
    benchmark:
        "results/benchmarks/classify_flight/{flight}.tsv"
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
        expand("results/classify/{flight}.parquet", flight=CLASSIFIED),
