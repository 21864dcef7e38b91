import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.estimate.pf_run import run_pf_jm

run_pf_jm(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
