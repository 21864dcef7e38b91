"""Shared helpers of the study tests: run a study at a size into tmp_path, read its outputs."""

from __future__ import annotations

import time
from pathlib import Path

import pandas as pd
import pytest
from threadpoolctl import threadpool_limits

from pipeline.studies import run_study, study_outputs
from pipeline.report.study import read_results

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "studies"
SEED = 20261123          # the config's master seed (datasets/config.yaml), as the goldens


class Ran:
    """One study run: its declared outputs, result object, RESULT figures and wall time."""

    def __init__(self, name, tmp: Path, config: dict, inputs=None, **sections):
        self.outputs = study_outputs(name, results_dir=tmp / "results")
        t0 = time.perf_counter()
        # one BLAS thread, as Snakemake gives a `threads: 1` job (OMP/OPENBLAS_NUM_THREADS): the
        # many small GMM solves run several times slower when BLAS threads fight over 2 cores
        with threadpool_limits(1):
            self.result = run_study(name, inputs, self.outputs, config, seed=SEED, **sections)
        self.wall_s = time.perf_counter() - t0
        self.figures = read_results(self.outputs["results"])

    def table(self, key: str) -> pd.DataFrame:
        return pd.read_parquet(self.outputs[key])


@pytest.fixture(scope="session")
def golden() -> Path:
    """``tests/data/studies/``: the old scripts' tiny-size tables (see its make_golden.py)."""
    return GOLDEN


def _text_as_objects(df: pd.DataFrame) -> pd.DataFrame:
    # the goldens were written before the study tables were declared (io/schema.py): their
    # text columns are pandas' default str, ours the declared "string" (missing = NA); the
    # values, names, order and numeric types must still agree
    out = df.copy()
    for c in out.columns:
        if isinstance(out[c].dtype, pd.StringDtype) or out[c].dtype == object:
            out[c] = out[c].astype(object).where(out[c].notna(), None)
    return out


@pytest.fixture(scope="session")
def same_as_golden():
    """``same_as_golden(got, want)``: :func:`pandas.testing.assert_frame_equal` with text
    columns compared as Python strings."""
    def check(got: pd.DataFrame, want: pd.DataFrame) -> None:
        pd.testing.assert_frame_equal(_text_as_objects(got), _text_as_objects(want))
    return check


@pytest.fixture(scope="session")
def gmr_error_summary():
    """The summary the ``gmr_error`` golden is kept as (``make_golden.gmr_error_summary``)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_golden", GOLDEN / "make_golden.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.gmr_error_summary


@pytest.fixture(scope="session")
def ran():
    """``ran(name, tmp, config, inputs=None, **sections)`` → :class:`Ran`."""
    return Ran
