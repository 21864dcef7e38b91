"""Ingest: the canonical schema, the reader registry, readers and writers, the Parquet store."""

from .base import FlightLog, IngestError, LogReader
from .registry import detect, read_log

__all__ = ["FlightLog", "IngestError", "LogReader", "detect", "read_log"]


#: the stage's entry points (``run.py``), importable from the package; loaded on first use so
#: importing the package stays light
_ENTRY_POINTS = {'run_ingest': 'ingest'}


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_ENTRY_POINTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
