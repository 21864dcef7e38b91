"""ArduPilot DataFlash ``.bin`` logs: the vectorised decoder, the stream mapping, the reader.

:mod:`.decode` decodes every message type into column tables (:func:`decode_all` is the
benchmarked entry point); :mod:`.streams` maps them to the canonical streams; the reader class
registered here ties both to the ingest registry. The record layout constants
(``HEAD1 HEAD2 FMT_TYPE FMT_LEN FORMAT_CHARS``, :func:`format_dtype`) are the ones
:mod:`pipeline.io.dataflash.writer` writes with.

Note: the package attribute ``decode`` is the function :func:`.decode.decode` (it shadows the
submodule's name); the module itself is ``sys.modules["pipeline.io.dataflash.decode"]``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base import FlightLog, IngestError, LogReader, Progress
from ..registry import register
from .decode import (FMT_LEN, FMT_TYPE, FORMAT_CHARS, HEAD1, HEAD2, Columns, DecodeResult, MsgFormat,
                     decode, decode_all, format_dtype)
from .streams import (GPS_EPOCH_UNIX_S, LEAP_SECONDS, READER_NAME, READER_VERSION, SOURCE_FORMAT,
                      STREAM_SOURCES, to_flightlog)

__all__ = ["Columns", "DataFlashReader", "DecodeResult", "FMT_LEN", "FMT_TYPE", "FORMAT_CHARS", "GPS_EPOCH_UNIX_S",
           "HEAD1", "HEAD2", "LEAP_SECONDS", "MsgFormat", "STREAM_SOURCES", "decode", "decode_all",
           "format_dtype", "to_flightlog"]


def _plausible_density(head: bytes) -> bool:
    """Logs that start mid-stream: many ``A3 95`` headers, spaced like records."""
    if len(head) < 512:
        return False
    h = np.frombuffer(head, dtype=np.uint8)
    pos = np.flatnonzero((h[:-1] == HEAD1) & (h[1:] == HEAD2))
    if len(pos) < 16:
        return False
    # one header per <= 128 bytes on average, and most gaps shorter than an FMT record
    gaps = np.diff(pos)
    return len(pos) * 128 >= len(h) and np.median(gaps) <= FMT_LEN


@register
class DataFlashReader(LogReader):
    """ArduPilot DataFlash ``.bin`` logs (old TimeMS and modern TimeUS/FMTU formats)."""

    name = READER_NAME
    source_format = SOURCE_FORMAT
    version = READER_VERSION
    priority = 20
    reads_bytes = True

    @classmethod
    def sniff(cls, path: Path, head: bytes) -> str | None:
        if not head:
            return None
        if head[:3] == bytes((HEAD1, HEAD2, FMT_TYPE)) and head[3:4] == bytes((FMT_TYPE,)):
            return "DataFlash FMT-for-FMT record at offset 0 (A3 95 80 80)"
        if head[:3] == bytes((HEAD1, HEAD2, FMT_TYPE)):
            return "DataFlash FMT record at offset 0 (A3 95 80)"
        if _plausible_density(head):
            return "DataFlash record headers (A3 95) at record density"
        return None

    def read(self, path: Path, *, config: dict | None = None, progress: Progress | None = None,
             data=None) -> FlightLog:
        """Decode ``path`` (or ``data``, its bytes, when the registry has read them)."""
        try:
            res = decode(path if data is None else data, progress=progress)
        except IngestError as exc:
            raise IngestError(path, exc.reason) from None
        return to_flightlog(res)
