"""Synthetic maneuver state tables for the models tests (the simulator is tested elsewhere)."""

from __future__ import annotations

import pytest

from helpers_maneuvers import synth_bulk, synth_run


@pytest.fixture(scope="session")
def synth():
    return synth_run, synth_bulk
