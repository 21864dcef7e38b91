"""Studies: research questions answered end to end (simulate or read, train, classify, tabulate).

Each study is a stage with the usual entry point ``run_<study>(inputs, outputs, config, *, seed,
...)`` (``config``: the ``studies`` section), run by its own Snakemake target
``study_<name>`` (``rules/studies.smk``, not part of ``all``) at ``studies.size``
(``tiny|small|thesis``). ``pipeline.studies`` may import every other subpackage; only rules,
the CLI and benchmarks import it.

The study modules (and with them plotly, scikit-learn, ...) load on first use, so the rules
can take the output layout from :mod:`.base` without slowing every workflow start-up.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping

from .base import SIZES, STUDY_TABLES, StudyError, StudyResult, flightcoach_inputs, study_outputs, study_settings

#: study name -> entry point ``module:function``
STUDIES = {
    "seed000_classification": "pipeline.studies.seed000_classification:run_seed000_classification",
    "flightcoach_classification": "pipeline.studies.flightcoach_classification:run_flightcoach_classification",
    "flightcoach_ekf_hmm": "pipeline.studies.flightcoach_ekf_hmm:run_flightcoach_ekf_hmm",
    "seed000_ekf": "pipeline.studies.seed000_ekf:run_seed000_ekf",
    "pf": "pipeline.studies.pf:run_pf",
    "trajectory_learning": "pipeline.studies.trajectory_learning:run_trajectory_learning",
    "bearing_only": "pipeline.studies.bearing_only:run_bearing_only",
}


def entry_point(name: str):
    """The entry point ``run_<name>`` of study ``name``."""
    try:
        mod, fn = STUDIES[name].split(":")
    except KeyError:
        raise StudyError(f"unknown study {name!r}; known: {', '.join(STUDIES)}") from None
    return getattr(importlib.import_module(mod), fn)


def run_study(name: str, inputs: Mapping | None, outputs: Mapping, config: Mapping | None, *, seed: int,
              **sections) -> StudyResult:
    """Run study ``name`` through its entry point (``run_<name>``).

    Parameters
    ----------
    name : str
        A key of :data:`STUDIES`.
    inputs, outputs : mapping
        Declared paths (Snakemake namedlists or dicts); see :func:`.base.study_outputs`.
    config : mapping or None
        The ``studies`` config section.
    seed : int
        The master seed.
    **sections
        Other config sections a study reads (``simulate``, ``hmm`` for the seed-000 study).
    """
    return entry_point(name)(inputs, outputs, config, seed=seed, **sections)


def __getattr__(attr: str):
    # run_seed000_classification etc. without importing every study up front
    for name, target in STUDIES.items():
        if attr == target.split(":")[1]:
            return entry_point(name)
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")


__all__ = ["SIZES", "STUDIES", "STUDY_TABLES", "StudyError", "StudyResult", "entry_point", "flightcoach_inputs",
           "run_bearing_only",
           "run_flightcoach_classification", "run_flightcoach_ekf_hmm", "run_pf", "run_seed000_classification", "run_seed000_ekf",
           "run_study", "run_trajectory_learning", "study_outputs",
           "study_settings"]
