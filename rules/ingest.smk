# Ingest: any supported log -> results/ingest/{flight}/{stream}.parquet + meta.json


rule demo_log:
    output:
        "results/sim/demo/demo-quad.bin",
    params:
        code_version=PIPELINE_VERSION,
        seed=config["seed"],
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


rule ingest_flight:
    input:
        log=flight_log,
        labels=flight_labels,
    output:
        multiext(
            "results/ingest/{flight}/",
            *[f"{s}.parquet" for s in STREAMS],
            "meta.json",
        ),
    params:
        code_version=PIPELINE_VERSION,
        fmt=flight_format,
        outdir=lambda wc: f"results/ingest/{wc.flight}",
        ingest=config.get("ingest", {}),
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
