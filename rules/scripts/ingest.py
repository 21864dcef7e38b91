import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.io.ingest import run_ingest

labels = snakemake.input.labels[0] if snakemake.input.labels else None
run_ingest(snakemake.input.log, snakemake.params.outdir, flight_id=snakemake.wildcards.flight,
           fmt=snakemake.params.fmt, labels=labels, config=snakemake.params.ingest)
