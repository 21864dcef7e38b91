import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.estimate.run import run_q2

run_q2(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
