import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.estimate.weave_run import run_hmpf

run_hmpf(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
