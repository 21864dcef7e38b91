import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.model import build_model_report

build_model_report(snakemake.params.model_dir, snakemake.input.evaluation, snakemake.output[0],
                   template=snakemake.input.template, plotly_js="../assets/plotly.min.js",
                   index_href="../../index.html")
