# Estimate: per flight of estimate.vehicles, the CA EKF, its RTS smoother and the EKF+HMM from the
# flight's radar (or radar synthesised from its state); Q2 of the EKF+HMM once per model set.


rule estimate_q2:
    input:
        unpack(q2_inputs),
        params="results/models/{model_set}/params.npz",
        meta="results/models/{model_set}/meta.json",
    output:
        q2="results/estimate/q2/{model_set}.json",
    params:
        code_version=PIPELINE_VERSION,
        config={"q2_scale": config["estimate"]["ekf_hmm"]["q2_scale"]},
        job=lambda wc: {"model_set": wc.model_set},
    log:
        "results/logs/estimate_q2/{model_set}.log",
    benchmark:
        "results/benchmarks/estimate_q2/{model_set}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/estimate_q2.py"


rule estimate_flight:
    input:
        unpack(ingest_inputs),
        state="results/state/{flight}.parquet",
        segments="results/segments/{flight}.parquet",
        model_params=f"results/models/{ESTIMATE_MODEL}/params.npz",
        model_meta=f"results/models/{ESTIMATE_MODEL}/meta.json",
        q2=f"results/estimate/q2/{ESTIMATE_MODEL}.json",
    output:
        ekf="results/estimate/ekf/{flight}.parquet",
        ekf_rts="results/estimate/ekf_rts/{flight}.parquet",
        ekf_hmm="results/estimate/ekf_hmm/{flight}.parquet",
    params:
        code_version=PIPELINE_VERSION,
        config=estimate_config,
        job=estimate_job,
    log:
        "results/logs/estimate_flight/{flight}.log",
    benchmark:
        "results/benchmarks/estimate_flight/{flight}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/estimate.py"


rule estimate_bearing:
    # issue 16: bearing-only replay of a pair of flights (estimate.bearing_only.replay)
    input:
        unpack(bearing_inputs),
        plotly="results/report/assets/plotly.min.js",
        template="reports/templates/bearing.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
    output:
        **{e: f"results/estimate/{e}/{{pair}}.parquet" for e in BEARING_ESTIMATORS},
        **{
            f"{e}_weights": f"results/estimate/{e}/{{pair}}.weights.parquet"
            for e in BEARING_ESTIMATORS
        },
        page="results/report/bearing/{pair}.html",
    wildcard_constraints:
        pair="|".join(BEARING_PAIRS) if BEARING_PAIRS else "NO_PAIRS",
    params:
        code_version=PIPELINE_VERSION,
        config=config["estimate"]["bearing_only"],
        job=lambda wc: {"pair": wc.pair, "seed": config["seed"]},
    log:
        "results/logs/estimate_bearing/{pair}.log",
    benchmark:
        "results/benchmarks/estimate_bearing/{pair}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/estimate_bearing.py"


rule estimate:
    input:
        estimate_paths() + hmpf_paths(),
        pf_paths(),
        bearing_paths(),
