"""The declared paths a stage entry point receives: Snakemake's ``snakemake.input`` /
``snakemake.output`` (namedlists: key and attribute access) or a plain dict from the CLI.

Every ``run_<stage>(inputs, outputs, config, **job)`` reads its paths through these two
functions, so the two shapes behave the same everywhere.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any


def declared(paths: Any, name: str, default: Any = None) -> Any:
    """``paths[name]`` for a dict or a Snakemake namedlist, ``default`` when not declared."""
    if paths is None:
        return default
    if isinstance(paths, Mapping):
        return paths.get(name, default)
    try:
        return paths[name]
    except (KeyError, IndexError, TypeError, AttributeError):  # a namedlist raises AttributeError
        return getattr(paths, name, default)


def declared_list(paths: Any, name: str) -> list[str]:
    """A declared path or list of paths as a list of str (``[]`` when not declared)."""
    v = declared(paths, name)
    if v is None:
        return []
    return [str(v)] if isinstance(v, (str, os.PathLike)) else [str(x) for x in v]
