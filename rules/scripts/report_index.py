import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.index import build_index

i, p = snakemake.input, snakemake.params
build_index(p.flights, i.metas, snakemake.output[0], links={f: f"report/flights/{f}.html" for f in p.flights},
            segments=dict(zip(p.flights, i.segments)), classified=dict(zip(p.classified, i.classified)),
            models={m: f"report/models/{m}.html" for m in p.models})
