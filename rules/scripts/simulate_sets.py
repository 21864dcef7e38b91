import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.simulate.run import run_simulate_sets

run_simulate_sets(snakemake.params.outdir, snakemake.params.sim, snakemake.params.seed)
