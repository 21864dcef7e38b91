"""Preprocessing: FlightLog -> per-flight ``state`` (uniform grid, NED/FRD), ``segments`` and
the barometer calibration table (seed 004 §6; style.md §3.2).

Modules: :mod:`.resample` (time base), :mod:`.filters` (Butterworth), :mod:`.calibrate` (BPM),
:mod:`.mount` (sensor mounts), :mod:`.derivatives`, :mod:`.controls`, :mod:`.segment`,
:mod:`.state` (:func:`~.state.run_preprocess` orchestration and file output).
"""


#: the stage's entry points (``run.py``), importable from the package; loaded on first use so
#: importing the package stays light
_ENTRY_POINTS = {'run_preprocess': 'run'}


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_ENTRY_POINTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
