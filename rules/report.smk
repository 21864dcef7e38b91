# Reports: one page per flight and per model set, the index over all of them, one local copy of
# plotly.js.


rule plotly_js:
    output:
        js="results/report/assets/plotly.min.js",
    params:
        code_version=PIPELINE_VERSION,
    log:
        "results/logs/plotly_js/plotly_js.log",
    benchmark:
        "results/benchmarks/plotly_js/plotly_js.tsv"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/plotly_js.py"


rule flight_report:
    input:
        unpack(ingest_inputs),
        state="results/state/{flight}.parquet",
        segments="results/segments/{flight}.parquet",
        calibration="results/calibration/{flight}.parquet",
        classified=flight_classified,
        estimates=flight_estimates,
        template="reports/templates/flight.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        page=report(
            "results/report/flights/{flight}.html",
            caption="../reports/captions/flight.rst",
            category="Flights",
            labels={"flight": "{flight}"},
        ),
    params:
        code_version=PIPELINE_VERSION,
        config={},
        job={"index": "results/index.html"},
    log:
        "results/logs/flight_report/{flight}.log",
    benchmark:
        "results/benchmarks/flight_report/{flight}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/flight_report.py"


rule model_report:
    input:
        params="results/models/{model_set}/params.npz",
        meta="results/models/{model_set}/meta.json",
        evaluation="results/models/{model_set}/evaluation.parquet",
        template="reports/templates/model.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        page=report(
            "results/report/models/{model_set}.html",
            caption="../reports/captions/model.rst",
            category="Models",
            labels={"model_set": "{model_set}"},
        ),
    params:
        code_version=PIPELINE_VERSION,
        config={},
        job={"index": "results/index.html"},
    log:
        "results/logs/model_report/{model_set}.log",
    benchmark:
        "results/benchmarks/model_report/{model_set}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/model_report.py"


rule report_index:
    input:
        metas=expand("results/ingest/{flight}/meta.json", flight=FLIGHTS),
        pages=expand("results/report/flights/{flight}.html", flight=FLIGHTS),
        segments=expand("results/segments/{flight}.parquet", flight=FLIGHTS),
        classified=classified_paths(),
        models=expand("results/report/models/{model_set}.html", model_set=MODEL_SETS),
        bearing=bearing_pages(),
    output:
        index=report(
            "results/index.html", caption="../reports/captions/index.rst", category="Index"
        ),
    params:
        code_version=PIPELINE_VERSION,
        config={},
        job={
            "flights": FLIGHTS,
            "model_sets": list(MODEL_SETS),
            "studies": list(STUDY_NAMES),
            "bearing_pairs": list(BEARING_PAIRS),
        },
    log:
        "results/logs/report_index/index.log",
    benchmark:
        "results/benchmarks/report_index/index.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/report_index.py"


rule report:
    input:
        "results/index.html",
