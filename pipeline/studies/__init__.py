"""Studies: research questions answered end to end (simulate or read, train, classify, tabulate).

Each study is a stage with the usual entry point ``run_<study>(inputs, outputs, config, *, seed,
...)`` (``config``: the ``studies`` section), run by its own Snakemake target
``study_<name>`` (``rules/studies.smk``, not part of ``all``) at ``studies.size``
(``tiny|small|thesis``). ``pipeline.studies`` may import every other subpackage; only rules,
the CLI and benchmarks import it.
"""

from __future__ import annotations

from collections.abc import Mapping

from .base import SIZES, StudyError, StudyResult, study_outputs, study_settings
from .flightcoach_classification import run_flightcoach_classification
from .seed000_classification import run_seed000_classification

#: study name -> entry point
STUDIES = {
    "seed000_classification": run_seed000_classification,
    "flightcoach_classification": run_flightcoach_classification,
}


def run_study(name: str, inputs: Mapping | None, outputs: Mapping, config: Mapping | None, *, seed: int,
              **sections) -> StudyResult:
    """Run study ``name`` through its entry point (``run_<name>``).

    Parameters
    ----------
    name : str
        A key of :data:`STUDIES`.
    inputs, outputs : mapping
        Declared paths (Snakemake namedlists or dicts); see each study's ``outputs_for``.
    config : mapping or None
        The ``studies`` config section.
    seed : int
        The master seed.
    **sections
        Other config sections a study reads (``simulate``, ``models`` for the seed-000 study).
    """
    try:
        fn = STUDIES[name]
    except KeyError:
        raise StudyError(f"unknown study {name!r}; known: {', '.join(STUDIES)}") from None
    return fn(inputs, outputs, config, seed=seed, **sections)


__all__ = ["SIZES", "STUDIES", "StudyError", "StudyResult", "run_flightcoach_classification",
           "run_seed000_classification", "run_study", "study_outputs", "study_settings"]
