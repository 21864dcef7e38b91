import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.preprocess.run import run_preprocess_flight

o = snakemake.output
run_preprocess_flight(snakemake.params.ingest_dir, state_path=o.state, segments_path=o.segments,
                      calibration_path=o.calibration, info_path=o.info, config=snakemake.params.pre,
                      vehicle=snakemake.params.vehicle)
