"""Deferred imports: ``from .lazy import pandas as pd`` binds a stand-in that imports pandas on
first attribute access.

Why: ``uavpipe ingest``/``info`` on a DataFlash or tlog log never touches pandas, and
importing it costs ~0.4 s of a ~1 s run. Every reader module is imported for format detection,
so a module-level ``import pandas`` in any of them would put that cost on every ingest; with
the stand-in only the readers that build pandas frames pay it, when they read.
"""

from __future__ import annotations

import importlib
from types import ModuleType


class LazyModule:
    """Attribute access imports the module (once; ``sys.modules`` caches it) and forwards."""

    def __init__(self, name: str):
        self._name = name

    def _load(self) -> ModuleType:
        return importlib.import_module(self._name)

    def __getattr__(self, attr: str):
        return getattr(self._load(), attr)

    def __repr__(self) -> str:
        return f"<lazy module {self._name!r}>"


pandas = LazyModule("pandas")
