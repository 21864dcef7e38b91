"""Seeding of the simulation: one generator per named set (and chunk).

Every set draws from ``np.random.default_rng([seed, crc32(set name), chunk])``, so a set does not
depend on which other sets were generated (see :mod:`pipeline.simulate.datasets`).
"""

from __future__ import annotations

import zlib

import numpy as np


def set_rng(seed: int, name: str, chunk: int = 0) -> np.random.Generator:
    """The generator of one set (and chunk): independent of which other sets are generated."""
    return np.random.default_rng([int(seed), zlib.crc32(name.encode()), int(chunk)])
