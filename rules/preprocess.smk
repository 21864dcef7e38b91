# Preprocess: ingested flight -> state / segments / calibration tables (placeholders if failed).


rule preprocess_flight:
    input:
        unpack(ingest_inputs),
    output:
        state="results/state/{flight}.parquet",
        segments="results/segments/{flight}.parquet",
        calibration="results/calibration/{flight}.parquet",
        info="results/state/{flight}.json",
    params:
        code_version=PIPELINE_VERSION,
        config=config["preprocess"],
        job=preprocess_job,
    log:
        "results/logs/preprocess_flight/{flight}.log",
    benchmark:
        "results/benchmarks/preprocess_flight/{flight}.tsv"
    threads: 1
    resources:
        mem_mb=lambda wc, input: max(1000, int(20 * input.size_mb)),
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/preprocess.py"


rule preprocess:
    input:
        expand("results/state/{flight}.parquet", flight=FLIGHTS),
