import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.estimate.bearing_run import run_bearing_replay

run_bearing_replay(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
