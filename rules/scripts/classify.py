import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.models.run import classify_flight

i = snakemake.input
classify_flight(i.state, i.segments, i.meta.rsplit("/", 1)[0], snakemake.output[0], model=snakemake.params.model,
                reset_at_segments=snakemake.params.reset)
