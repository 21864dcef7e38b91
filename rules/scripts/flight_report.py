import sys

sys.stderr = open(snakemake.log[0], "w")
from pipeline.report.flight import build_flight_report

i = snakemake.input
build_flight_report(snakemake.params.ingest_dir, snakemake.output[0], template=i.template,
                    plotly_js="../assets/plotly.min.js", index_href="../../index.html", state=i.state,
                    segments=i.segments, calibration=i.calibration, classified=(i.classified or [None])[0])
