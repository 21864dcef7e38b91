# Studies: one target per study, not part of `all`: `snakemake study_<name>` at config studies.size
# (tiny | small | thesis) writes results/studies/<name>/ and results/report/studies/<name>.html.
from pipeline.studies.base import FLIGHTCOACH_EKF_HMM_FILES, flightcoach_inputs, study_outputs

# the studies whose thesis size spreads its runs over 2 worker processes by default (bearing_only's
# `workers`, the seed-001 part of pf) claim 2 cores there. Snakemake caps the claim at --cores; the
# study still starts its configured workers
STUDY_THREADS = 2 if config["studies"]["size"] == "thesis" else 1
# `runtime` (minutes) is each study's time limit on a cluster (profiles/slurm, profiles/generic),
# written for the default small size; thesis size runs several times more (seed 000 ~3x, the
# seed-001 part 50 runs a setup): its limit is 10x, a limit and not a measurement
STUDY_RUNTIME_SCALE = 10 if config["studies"]["size"] == "thesis" else 1


rule study_seed000_classification:
    input:
        template="reports/templates/study.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
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
        runtime=120 * STUDY_RUNTIME_SCALE,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"


rule study_flightcoach_classification:
    input:
        # the real FlightCoach logs; when absent the rule stops with one line naming the file
        unpack(lambda wc: flightcoach_inputs(config["realdata_dir"])),
        template="reports/templates/study.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
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
        runtime=30 * STUDY_RUNTIME_SCALE,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"


rule study_flightcoach_ekf_hmm:
    input:
        # the two real FlightCoach logs (train P23 #36, test P23 #350); when absent the rule stops
        # with one line naming the file
        unpack(lambda wc: flightcoach_inputs(config["realdata_dir"], FLIGHTCOACH_EKF_HMM_FILES,
                                             study="flightcoach_ekf_hmm")),
        template="reports/templates/study.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        **study_outputs("flightcoach_ekf_hmm"),
    params:
        code_version=PIPELINE_VERSION,
        study="flightcoach_ekf_hmm",
        config=config["studies"],
        job={"seed": config["seed"]},
        sections={},
    log:
        "results/logs/study_flightcoach_ekf_hmm/study.log",
    benchmark:
        "results/benchmarks/study_flightcoach_ekf_hmm/study.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=30 * STUDY_RUNTIME_SCALE,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"


rule study_seed000_ekf:
    input:
        template="reports/templates/study.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        **study_outputs("seed000_ekf", models=False),
    params:
        code_version=PIPELINE_VERSION,
        study="seed000_ekf",
        config=config["studies"],
        job={"seed": config["seed"]},
        sections={"simulate": config["simulate"], "hmm": config["hmm"]},
    log:
        "results/logs/study_seed000_ekf/study.log",
    benchmark:
        "results/benchmarks/study_seed000_ekf/study.tsv"
    threads: 1
    resources:
        mem_mb=8000,
        runtime=120 * STUDY_RUNTIME_SCALE,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"


rule study_pf:
    input:
        template="reports/templates/study.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        **study_outputs("pf", models=False),
    params:
        code_version=PIPELINE_VERSION,
        study="pf",
        config=config["studies"],
        job={"seed": config["seed"]},
        sections={"estimate": config["estimate"]},
    log:
        "results/logs/study_pf/study.log",
    benchmark:
        "results/benchmarks/study_pf/study.tsv"
    threads: STUDY_THREADS
    resources:
        mem_mb=4000,
        runtime=30 * STUDY_RUNTIME_SCALE,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"


rule study_trajectory_learning:
    input:
        # the real part's flights (the align sets whose flights are all available; the others
        # are skipped with a notice, as by the align target)
        states=[f"results/state/{f}.parquet" for s in ALIGN_SETS for f in config["align"]["sets"][s]["flights"]],
        segments=[f"results/segments/{f}.parquet" for s in ALIGN_SETS for f in config["align"]["sets"][s]["flights"]],
        template="reports/templates/study.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        **study_outputs("trajectory_learning", models=False),
    params:
        code_version=PIPELINE_VERSION,
        study="trajectory_learning",
        config=config["studies"],
        job={"seed": config["seed"]},
        sections={"align": config["align"]},
    log:
        "results/logs/study_trajectory_learning/study.log",
    benchmark:
        "results/benchmarks/study_trajectory_learning/study.tsv"
    threads: 1
    resources:
        mem_mb=4000,
        runtime=60 * STUDY_RUNTIME_SCALE,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"


rule study_bearing_only:
    input:
        template="reports/templates/study.html.j2",
        linked="reports/templates/_linked_axes.html.j2",
        plotly="results/report/assets/plotly.min.js",
    output:
        **study_outputs("bearing_only", models=False),
    params:
        code_version=PIPELINE_VERSION,
        study="bearing_only",
        config=config["studies"],
        job={"seed": config["seed"]},
        sections={"estimate": config["estimate"]},
    log:
        "results/logs/study_bearing_only/study.log",
    benchmark:
        "results/benchmarks/study_bearing_only/study.tsv"
    threads: STUDY_THREADS
    resources:
        mem_mb=8000,
        runtime=240 * STUDY_RUNTIME_SCALE,
    conda:
        "envs/pipeline.yaml"
    script:
        "scripts/study.py"
