"""Seed-000 simulation: quadcopter dynamics (``quadcopter``), the five maneuvers and scenario
profiles (``maneuvers``, ``scenarios``), sensors (``sensors``; the radar model lives in
``pipeline.estimate.models``), per-set seeding (``seeds``), one flight written as log files
through the io writers (``writers``), the data sets (``datasets``) and the demo flight of the
default dataset (``demo``)."""
