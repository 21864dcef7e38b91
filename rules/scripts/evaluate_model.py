import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.models.run import run_evaluate

run_evaluate(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
