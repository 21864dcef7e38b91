# Model sets: one HMM set per config["model_sets"] entry, and its evaluation against seed 000's
# tables.


rule train_model:
    input:
        unpack(train_inputs),
    output:
        params="results/models/{model_set}/params.npz",
        meta="results/models/{model_set}/meta.json",
    params:
        code_version=PIPELINE_VERSION,
        config=lambda wc: set_config(wc.model_set),
        job=lambda wc: {"model_set": wc.model_set, "seed": config["seed"]},
    log:
        "results/logs/train_model/{model_set}.log",
    benchmark:
        "results/benchmarks/train_model/{model_set}.tsv"
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
        params="results/models/{model_set}/params.npz",
        meta="results/models/{model_set}/meta.json",
    output:
        evaluation="results/models/{model_set}/evaluation.parquet",
    params:
        code_version=PIPELINE_VERSION,
        config=lambda wc: set_config(wc.model_set),
        job=lambda wc: {"model_set": wc.model_set},
    log:
        "results/logs/evaluate_model/{model_set}.log",
    benchmark:
        "results/benchmarks/evaluate_model/{model_set}.tsv"
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
        expand("results/models/{model_set}/evaluation.parquet", model_set=MODEL_SETS),
