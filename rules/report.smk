# Reports: one page per flight and per model set, the index over all of them, one local copy of
# plotly.js.
import re



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
        estimates=lambda wc: flight_estimates(wc) + flight_hmpf(wc),
        template="reports/templates/flight.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
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
        job=lambda wc: {
            "index": "results/index.html",
            "vehicle": flights.loc[wc.flight, "vehicle"],
        },
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


# one comparison page per vehicle of the manifest (its flights' differing parameters and
# overlays on a time-from-takeoff axis), linked from the index
VEHICLES = sorted(set(flights.loc[FLIGHTS, "vehicle"])) if FLIGHTS else []
VEHICLE_FLIGHTS = {
    v: [f for f in FLIGHTS if flights.loc[f, "vehicle"] == v] for v in VEHICLES
}


rule compare_report:
    input:
        metas=lambda wc: [
            f"results/ingest/{f}/meta.json" for f in VEHICLE_FLIGHTS[wc.vehicle]
        ],
        params=lambda wc: [
            f"results/ingest/{f}/params.parquet" for f in VEHICLE_FLIGHTS[wc.vehicle]
        ],
        states=lambda wc: [
            f"results/state/{f}.parquet" for f in VEHICLE_FLIGHTS[wc.vehicle]
        ],
        template="reports/templates/compare.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        page="results/report/compare/{vehicle}.html",
    wildcard_constraints:
        vehicle="|".join(re.escape(v) for v in VEHICLES) if VEHICLES else "NO_VEHICLES",
    params:
        code_version=PIPELINE_VERSION,
        config={},
        job=lambda wc: {
            "vehicle": wc.vehicle,
            "flights": VEHICLE_FLIGHTS[wc.vehicle],
            "index": "results/index.html",
        },
    log:
        "results/logs/compare_report/{vehicle}.log",
    benchmark:
        "results/benchmarks/compare_report/{vehicle}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/compare_report.py"


rule model_report:
    input:
        params="results/models/{model_set}/params.npz",
        meta="results/models/{model_set}/meta.json",
        evaluation="results/models/{model_set}/evaluation.parquet",
        template="reports/templates/model.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
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
        compare=expand("results/report/compare/{vehicle}.html", vehicle=VEHICLES),
        align=align_paths(),
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
            "vehicles": {f: flights.loc[f, "vehicle"] for f in FLIGHTS},
            "skipped": dict(SKIPPED),
            "align_sets": list(ALIGN_SETS),
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
