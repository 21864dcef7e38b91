# Studies: one target per study, not part of `all`: `snakemake study_<name>` at config studies.size
# (tiny | small | thesis) writes results/studies/<name>/ and results/report/studies/<name>.html.
from pipeline.studies.base import flightcoach_inputs, study_outputs


rule study_seed000_classification:
    input:
        template="reports/templates/study.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        **study_outputs("seed000_classification"),
    params:
        code_version=PIPELINE_VERSION,
        study="seed000_classification",
        config=config["studies"],
        job={"seed": config["seed"]},
        sections={"simulate": config["simulate"], "hmm": config["hmm"], "estimate": config["estimate"]},
    log:
        "results/logs/study_seed000_classification/study.log",
    benchmark:
        "results/benchmarks/study_seed000_classification/study.tsv"
    threads: 1
    resources:
        mem_mb=8000,
        runtime=120,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"


rule study_flightcoach_classification:
    input:
        # the real FlightCoach logs; when absent the rule stops with one line naming the file
        unpack(lambda wc: flightcoach_inputs(config["realdata_dir"])),
        template="reports/templates/study.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        **study_outputs("flightcoach_classification"),
    params:
        code_version=PIPELINE_VERSION,
        study="flightcoach_classification",
        config=config["studies"],
        job={"seed": config["seed"]},
        sections={},
    log:
        "results/logs/study_flightcoach_classification/study.log",
    benchmark:
        "results/benchmarks/study_flightcoach_classification/study.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"
