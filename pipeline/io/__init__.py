"""Ingest: the canonical schema, the reader registry, readers and writers, the Parquet store."""

from .base import FlightLog, IngestError, LogReader
from .registry import detect, read_log

__all__ = ["FlightLog", "IngestError", "LogReader", "detect", "read_log"]
