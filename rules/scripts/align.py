import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.align.run import run_align

run_align(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
