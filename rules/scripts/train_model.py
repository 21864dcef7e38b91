import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.models.run import run_train

run_train(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
