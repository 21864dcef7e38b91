import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.simulate.run import run_simulate_logs

run_simulate_logs(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
