import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.simulate.run import run_simulate_logs

run_simulate_logs(snakemake.params.outdir, snakemake.params.sim, snakemake.params.seed)
