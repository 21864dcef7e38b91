import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.io.ingest import run_ingest

run_ingest(snakemake.input, snakemake.output, snakemake.params.config, **snakemake.params.job)
