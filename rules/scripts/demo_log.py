import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.simulate.run import run_demo_log

run_demo_log(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
