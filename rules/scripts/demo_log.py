import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.simulate.demo import write_demo_flight

write_demo_flight(snakemake.output[0], seed=snakemake.params.seed)
