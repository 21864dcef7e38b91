"""Dataset configuration: ``datasets/config.yaml`` loading and per-stage sections.

The workflow validates the file against ``rules/schemas/config.schema.yaml`` at start-up; the
API and CLI load it here. Stage code receives its own section as a plain dict and turns it into
a ``@dataclass(frozen=True, kw_only=True)`` of its own (style.md §2.4).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CONFIG = ROOT / "datasets" / "config.yaml"


class ConfigError(ValueError):
    """A configuration file or value is invalid; the message names the file and key."""


def load_config(path: str | os.PathLike | None = None) -> dict[str, Any]:
    """Load the dataset config (default ``datasets/config.yaml``)."""
    p = Path(path) if path else DEFAULT_CONFIG
    try:
        data = yaml.safe_load(p.read_text())
    except FileNotFoundError:
        raise ConfigError(f"{p}: config file not found") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: invalid YAML: {exc}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: top level must be a mapping, got {type(data).__name__}")
    return data


def section(cfg: dict[str, Any] | None, name: str) -> dict[str, Any]:
    """One top-level section (``ingest``, ``simulate``, ``preprocess``, ...), ``{}`` if absent."""
    if not cfg:
        return {}
    sec = cfg.get(name) or {}
    if not isinstance(sec, dict):
        raise ConfigError(f"config section {name!r} must be a mapping, got {type(sec).__name__}")
    return sec
