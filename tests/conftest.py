"""Fixtures shared by all tests; helper functions live in ``tests/helpers.py``."""

from __future__ import annotations

import os
import sys
from pathlib import Path

# The test session writes its bytecode caches even under PYTHONDONTWRITEBYTECODE=1: without them
# every xdist worker re-compiles the package and re-rewrites the asserts of ~250 test modules at
# each start (12.6 s before the first test against 4.1 s, measured), and the numba kernels'
# caches land in the same __pycache__ folders whatever that variable says.
sys.dont_write_bytecode = False

import numpy as np
import pytest

from helpers import REALDATA, REQUIRE_SHARED, TEST_SEED, need_shared
from hypothesis import settings

# CI gates a merge: there the property tests draw the same examples every run (a newly found
# counterexample is a local finding to fix, not a red build on someone else's change); locally
# they keep exploring. HYPOTHESIS_PROFILE=ci or =dev chooses explicitly.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev")
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if REQUIRE_SHARED else "dev"))


def pytest_report_header(config):
    return [f"PIPELINE_TEST_SEED={TEST_SEED}  realdata={REALDATA} "
            f"({'present' if REALDATA.is_dir() else 'absent'})  UAVPIPE_REQUIRE_SHARED={int(REQUIRE_SHARED)}"]


@pytest.fixture
def realdata() -> Path:
    """The ../shared/realdata folder (skip, or fail under UAVPIPE_REQUIRE_SHARED=1, when absent)."""
    need_shared()
    return REALDATA


@pytest.fixture
def rng() -> np.random.Generator:
    """A Generator seeded from PIPELINE_TEST_SEED (printed in the header)."""
    return np.random.default_rng(TEST_SEED)
