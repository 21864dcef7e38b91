"""Fixtures shared by the command-line tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from helpers_maneuvers import synth_bulk
from pipeline.cli import main
from pipeline.io import schema
from pipeline.io.parquet import write_table


@pytest.fixture(scope="session")
def model_dir(tmp_path_factory) -> Path:
    """A small trained model set (two maneuvers, three runs each) and the set it was trained on
    (``model_dir.parent / "M12_train.parquet"``); trained once for every CLI test module."""
    d = tmp_path_factory.mktemp("model")
    s = d / "M12_train.parquet"
    runs = synth_bulk(("M1", "M2"), 3, np.random.default_rng(5))
    runs["run_id"] = pd.factorize(runs["run_id"])[0]
    write_table(schema.conform("simulate_set", runs), s, schema.columns("simulate_set"), name="simulate_set",
                extra={"set": "M12_train"})
    assert main(["train", str(s), "-o", str(d / "m"), "--seed", "1"]) == 0
    return d / "m"
