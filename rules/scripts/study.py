import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.studies import run_study

p = snakemake.params
run_study(p.study, snakemake.input, snakemake.output, p.config, **p.job, **p.sections)
