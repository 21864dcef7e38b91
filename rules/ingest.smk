# Ingest: any supported log -> results/ingest/{flight}/{stream}.parquet + meta.json


rule ingest_flight:
    input:
        log=flight_log,
        labels=flight_labels,
    output:
        streams=multiext(
            "results/ingest/{flight}/", *[f"{s}.parquet" for s in STREAMS]
        ),
        meta="results/ingest/{flight}/meta.json",
    params:
        code_version=PIPELINE_VERSION,
        config=config["ingest"],
        job=ingest_job,
    log:
        "results/logs/ingest_flight/{flight}.log",
    benchmark:
        "results/benchmarks/ingest_flight/{flight}.tsv"
    threads: 1
    resources:
        mem_mb=lambda wc, input: max(1000, int(40 * input.size_mb)),
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/ingest.py"


rule ingest:
    input:
        [ingest_outputs(f) for f in FLIGHTS],
