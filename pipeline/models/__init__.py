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
