import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.align import run_align_report

run_align_report(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
