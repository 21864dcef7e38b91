"""The ``studies`` block of the config schema holds the same defaults as the studies' code."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from pipeline.studies import flightcoach_classification as fc
from pipeline.studies import flightcoach_ekf_hmm as fe
from pipeline.studies import seed000_classification as s0

SCHEMA = Path(__file__).resolve().parents[2] / "rules" / "schemas" / "config.schema.yaml"


@pytest.mark.parametrize("mod", [s0, fc, fe], ids=["seed000", "flightcoach", "flightcoach_ekf_hmm"])
def test_schema_defaults_equal_the_study_defaults(mod):
    sec = yaml.safe_load(SCHEMA.read_text())["properties"]["studies"]
    assert sec["properties"]["size"]["default"] == "small"
    props = sec["properties"][mod.NAME]["properties"]
    for key, value in mod.DEFAULTS.items():
        if key in props:
            assert props[key].get("default") == value, key
    sizes = props["sizes"]["properties"]
    for size, over in mod.SIZES.items():
        got = {k: v.get("default") for k, v in sizes[size].get("properties", {}).items()}
        assert got == over, size


def test_every_study_table_is_declared_in_the_schema_under_study_and_table_name():
    from pipeline.io import schema
    from pipeline.studies import STUDY_TABLES

    names = {f"{study}_{t}" for study, tables in STUDY_TABLES.items() for t in tables}
    assert names == set(schema.STUDY_RESULTS)  # none missing, none left over
    assert all(name in schema.TABLES for name in names)
