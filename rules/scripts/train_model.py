import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.models.run import train_model

i = snakemake.input
train_model(snakemake.wildcards.model, snakemake.params.spec, snakemake.params.outdir, snakemake.params.models,
            sets=i.get("sets", []), states=i.get("states", []), segments=i.get("segments", []))
