# Models: one HMM set per config["train"] entry, and its evaluation against seed 000's tables.


rule train_model:
    input:
        unpack(train_inputs),
    output:
        params="results/models/{model}/params.npz",
        meta="results/models/{model}/meta.json",
    params:
        code_version=PIPELINE_VERSION,
        models=config["models"],
        spec=lambda wc: MODELS[wc.model],
        outdir=lambda wc: f"results/models/{wc.model}",
    log:
        "results/logs/train_model/{model}.log",
    benchmark:
        "results/benchmarks/train_model/{model}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/train_model.py"


rule evaluate_model:
    input:
        unpack(evaluate_inputs),
        params="results/models/{model}/params.npz",
        meta="results/models/{model}/meta.json",
    output:
        "results/models/{model}/evaluation.parquet",
    params:
        code_version=PIPELINE_VERSION,
        spec=lambda wc: MODELS[wc.model],
        outdir=lambda wc: f"results/models/{wc.model}",
    log:
        "results/logs/evaluate_model/{model}.log",
    benchmark:
        "results/benchmarks/evaluate_model/{model}.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/evaluate_model.py"


rule train:
    input:
        expand("results/models/{model}/evaluation.parquet", model=MODELS),
