"""Maneuver models (seed 000 §3.3–§3.6): features, per-maneuver HMMs on hmmlearn, online
classification (confidence and one-class), Viterbi, GMR and classification metrics.

Import direction: ``frames -> io -> preprocess -> models``; nothing here imports snakemake.
"""

from .base import ModelError, ModelsConfig
from .classifier import ManeuverModelSet
from .hmm import HMMParams, ManeuverHMM, forward_categorical, forward_log
from .online import OnlineClassifier, classify_batch, confidence
from .viterbi import viterbi, viterbi_log

__all__ = ["ModelError", "ModelsConfig", "ManeuverModelSet", "HMMParams", "ManeuverHMM",
           "forward_categorical", "forward_log", "OnlineClassifier", "classify_batch",
           "confidence", "viterbi", "viterbi_log"]


#: the stage's entry points (``run.py``), importable from the package; loaded on first use so
#: importing the package stays light
_ENTRY_POINTS = {'run_train': 'run', 'run_classify': 'run', 'run_evaluate': 'run'}


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_ENTRY_POINTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
