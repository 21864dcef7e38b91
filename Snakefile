# uavpipe main workflow: `snakemake --cores 2` over datasets/flights.tsv -> results/index.html
from snakemake.utils import min_version

min_version("9.1")

# the config file read once by our reader first: a YAML mistake (or a key given twice) is one
# 'uavpipe:' line with the file's line and column, not Snakemake's "not valid JSON or YAML"
import sys
from pipeline.config import ConfigError, read_config_file

try:
    read_config_file("datasets/config.yaml")
except ConfigError as _exc:
    sys.exit(f"uavpipe: {_exc}")


configfile: "datasets/config.yaml"


report: "reports/workflow.rst"


include: "rules/common.smk"
include: "rules/ingest.smk"
include: "rules/simulate.smk"
include: "rules/preprocess.smk"
include: "rules/estimate_sets.smk"
include: "rules/models.smk"
include: "rules/classify.smk"
include: "rules/estimate_hmpf.smk"
include: "rules/estimate.smk"
include: "rules/estimate_pf.smk"
include: "rules/align.smk"
include: "rules/report.smk"
include: "rules/studies.smk"


# the end of every run, success or not: flights ok/partial/failed with the reason, skipped
# manifest rows, model sets, where the report is (pipeline/report/summary.py)
onsuccess:
    print(run_summary(FLIGHTS, MODEL_SETS, "results", skipped=SKIPPED,
                      model_inputs=model_set_inputs()), file=sys.stderr)


onerror:
    print(run_summary(FLIGHTS, MODEL_SETS, "results", skipped=SKIPPED,
                      model_inputs=model_set_inputs()), file=sys.stderr)


rule all:
    input:
        get_final_output(),
    default_target: True
