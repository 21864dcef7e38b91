# uavpipe main workflow: `snakemake --cores 2` over datasets/flights.tsv -> results/index.html
from snakemake.utils import min_version

min_version("9.1")


configfile: "datasets/config.yaml"


report: "reports/workflow.rst"


include: "rules/common.smk"
include: "rules/ingest.smk"
include: "rules/simulate.smk"
include: "rules/preprocess.smk"
include: "rules/models.smk"
include: "rules/classify.smk"
include: "rules/report.smk"
include: "rules/studies.smk"


rule all:
    input:
        get_final_output(),
    default_target: True
