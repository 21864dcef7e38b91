import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.models.run import evaluate_model

i = snakemake.input
evaluate_model(snakemake.wildcards.model, snakemake.params.spec, snakemake.params.outdir, snakemake.output[0],
               train_sets=i.get("train_sets", []), test_sets=i.get("test_sets", []),
               classified=i.get("classified", []))
