"""Preprocessing: FlightLog -> per-flight ``state`` (uniform grid, NED/FRD), ``segments`` and
the barometer calibration table (seed 004 §6; style.md §3.2).

Modules: :mod:`.resample` (time base), :mod:`.filters` (Butterworth), :mod:`.calibrate` (BPM),
:mod:`.mount` (sensor mounts), :mod:`.derivatives`, :mod:`.controls`, :mod:`.segment`,
:mod:`.state` (:func:`~.state.run_preprocess` orchestration and file output).
"""
