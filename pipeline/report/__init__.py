"""report subpackage."""


#: the stage's entry points (``run.py``), importable from the package; loaded on first use so
#: importing the package stays light
_ENTRY_POINTS = {'run_flight_report': 'run', 'run_model_report': 'run', 'run_compare_report': 'run', 'run_index': 'run',
                'run_plotly_js': 'run', 'run_align_report': 'align', 'run_bearing_report': 'bearing'}


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_ENTRY_POINTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
