import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.flight import write_plotly_js

write_plotly_js(snakemake.output[0])
