import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.estimate.run import run_estimate

run_estimate(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
