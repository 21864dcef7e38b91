"""Copy the pre-stage study scripts' tiny-size tables into tests/data/studies/ (the goldens).

The goldens are what ``benchmarks/study_seed000_classification.py`` and
``benchmarks/study_flightcoach_classification.py`` wrote at commit 45c51f6 (before the studies
became a stage), at the ``tiny`` study size and the config's seed 20261123::

    python benchmarks/study_seed000_classification.py --runs 40 --switch-runs 4 --out A
    python benchmarks/study_flightcoach_classification.py --n-iter 5 --slack-grid 1.5 --out B
    python tests/data/studies/make_golden.py A B

The seed-000 goldens were regenerated from the study itself (``run_study("seed000_classification",
None, outputs, {"size": "tiny"}, seed=20261123)``, then ``make_golden.py <its folder>``) when the
issue "Seed-000 maneuvers as the thesis describes them" changed the simulated maneuvers on purpose;
before that change the study's six tables were shown equal to the script's (commit 28a850e; see
the git history of this folder). The FlightCoach goldens (real flights, no simulation) are still the
script's.

Every table is copied as is, except ``gmr_error`` (227 kB: one row per maneuver, quantity, axis
and time step), which is kept as a per-(maneuver, quantity, axis) summary (:func:`gmr_error_summary`).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent


def gmr_error_summary(gerr: pd.DataFrame) -> pd.DataFrame:
    """Rows, Σ t, Σ mean error and Σ error variance per maneuver, quantity and axis."""
    return (gerr.groupby(["maneuver", "quantity", "axis"], sort=True)
            .agg(n=("t_s", "size"), t_s_sum=("t_s", "sum"), mean_err_sum=("mean_err", "sum"),
                 err_var_sum=("err_var", "sum")).reset_index())


def main(seed000_dir: str, flightcoach_dir: str | None = None) -> None:
    out = HERE / "seed000_classification_tiny"
    out.mkdir(exist_ok=True)
    for f in sorted(Path(seed000_dir).glob("*.parquet")):
        df = pd.read_parquet(f)
        if f.stem == "gmr_error":
            gmr_error_summary(df).to_parquet(out / "gmr_error_summary.parquet", index=False)
        else:
            df.to_parquet(out / f.name, index=False)
    if flightcoach_dir:
        out = HERE / "flightcoach_classification_tiny"
        out.mkdir(exist_ok=True)
        for f in sorted(Path(flightcoach_dir).glob("*.parquet")):
            pd.read_parquet(f).to_parquet(out / f.name, index=False)


if __name__ == "__main__":
    main(*sys.argv[1:3])
