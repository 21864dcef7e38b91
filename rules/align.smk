# Align: per demo set of align.sets, one trajectory learned per maneuver label from the set's
# flights' state and segments (pipeline/align/run.py); maneuvers are rows, so the DAG is static.
# A set is planned only when all its flights are in the manifest with their files present
# (ALIGN_SETS, rules/common.smk); the others are skipped with a notice at start-up.


rule align_set:
    input:
        unpack(align_inputs),
    output:
        learned="results/align/{align_set}/learned.parquet",
        alignment="results/align/{align_set}/alignment.parquet",
        iterations="results/align/{align_set}/iterations.parquet",
        demos="results/align/{align_set}/demos.parquet",
    params:
        code_version=PIPELINE_VERSION,
        config=align_config,
        job=lambda wc: {"set_name": wc.align_set},
    log:
        "results/logs/align_set/{align_set}.log",
    benchmark:
        "results/benchmarks/align_set/{align_set}.tsv"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=20,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/align.py"


rule align_report:
    input:
        learned="results/align/{align_set}/learned.parquet",
        alignment="results/align/{align_set}/alignment.parquet",
        iterations="results/align/{align_set}/iterations.parquet",
        demos="results/align/{align_set}/demos.parquet",
        template="reports/templates/align.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        page=report(
            "results/report/align/{align_set}.html",
            caption="../reports/captions/align.rst",
            category="Trajectory learning",
            labels={"set": "{align_set}"},
        ),
    params:
        code_version=PIPELINE_VERSION,
        config=lambda wc: {"pitch_band_deg": config["align"]["pitch_band_deg"], "tol": config["align"]["tol"]},
        job=lambda wc: {"set_name": wc.align_set, "index": "results/index.html"},
    log:
        "results/logs/align_report/{align_set}.log",
    benchmark:
        "results/benchmarks/align_report/{align_set}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/align_report.py"


rule align:
    input:
        align_paths(),
