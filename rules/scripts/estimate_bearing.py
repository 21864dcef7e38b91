import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.bearing import run_bearing_report

run_bearing_report(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
