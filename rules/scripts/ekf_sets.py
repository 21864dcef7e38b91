import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.estimate.sets import run_ekf_sets

run_ekf_sets(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
