import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.preprocess.run import run_preprocess

run_preprocess(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
