import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.run import run_plotly_js

run_plotly_js(snakemake.input, snakemake.output)
