import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.run import run_compare_report

run_compare_report(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
