"""Seed-000 simulation: quadcopter dynamics (``quadcopter``), the five maneuvers and scenario
profiles (``maneuvers``, ``scenarios``), sensors (``sensors``; the radar model lives in
``pipeline.estimate.models``), per-set seeding (``seeds``), one flight written as log files
through the io writers (``writers``), the data sets (``datasets``) and the demo flight of the
default dataset (``demo``)."""


#: the stage's entry points (``run.py``), importable from the package; loaded on first use so
#: importing the package stays light
_ENTRY_POINTS = {'run_simulate_sets': 'run', 'run_simulate_logs': 'run', 'run_demo_log': 'run'}


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_ENTRY_POINTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
