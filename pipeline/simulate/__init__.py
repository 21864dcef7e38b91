"""Seed-000 simulation: quadcopter dynamics (``quadcopter``), the five maneuvers and scenario
profiles (``maneuvers``, ``scenarios``), sensors (``sensors``; the radar model lives in
``pipeline.estimate.models``), log-file writers (``writers``) and the data sets (``datasets``)."""
