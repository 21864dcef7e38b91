"""One-sentence definitions of the metrics the model and study pages show, each citing the
section of the seed digest (``/work/shared/docs/seed-00N-*.md`` in the project; the thesis
section in brackets) that defines it (issue 13, item 4).

A page lists the metrics whose name occurs in its own text (:func:`metrics_in`), so every
abbreviation a reader meets there is defined once, on the page, in one sentence.
"""

from __future__ import annotations

import html
import re
from dataclasses import dataclass


@dataclass(frozen=True)
class Metric:
    """A metric as a page defines it.

    ``name`` as written on the pages, ``long`` spelled out, ``sentence`` the definition,
    ``cite`` the seed digest's section (and the thesis's), ``pattern`` how the name is found
    in a page's text (a regular expression; letters on either side do not match, so ``FA``
    is found in ``seed000_cf_test_min_FA_pct`` but not in ``FAIL``)."""

    name: str
    long: str
    sentence: str
    cite: str
    pattern: str
    flags: int = 0

    def found_in(self, text: str) -> bool:
        return re.search(rf"(?<![A-Za-z])(?:{self.pattern})(?![A-Za-z])", text, self.flags) is not None


#: every metric a model or study page may show, in the order a glossary lists them
METRICS: tuple[Metric, ...] = (
    Metric("FA", "final accuracy",
           "The share of runs whose classifier label at the last sample is the true maneuver "
           "(in a maneuver change, the initial maneuver is judged at the switch).",
           "seed 000 §5 (thesis §3.4)", "FA"),
    Metric("MAoT", "mean accuracy over time",
           "The fraction of a run's samples labelled correctly, averaged over runs; 'unknown' counts "
           "as correct for a maneuver no model knows (M5), and on real data the first 5 s are left out.",
           "seed 000 §5 (thesis §3.4)", "MAoT", re.IGNORECASE),
    Metric("V", "confidence",
           "V_j = log10 Σ_{i≠j} exp(LL_i − LL_j) for the best model j: below −1 the classifier names j, "
           "otherwise it says 'unknown'.",
           "seed 000 §5 (thesis §3.4, Lee & Xu)", r"V_best|confidence|V \[log10\]"),
    Metric("LL", "log-likelihood",
           "log P(O_1:t | model) from the scaled forward pass, cumulative from the first sample; "
           "training maximises its sum over the training sequences (Baum–Welch).",
           "seed 000 §4–§5 (thesis §3.3–§3.4)", r"LL|log-likelihood", re.IGNORECASE),
    Metric("one-class", "one-class decision",
           "The best model is accepted only when its log-likelihood is above a threshold from its training "
           "data (a low percentile of its training sequences' scores, or a set fraction of the way to it from "
           "its mean score on the other training maneuvers); otherwise 'unknown'.",
           "seed 000 §5 (thesis §3.4, Yeung)", r"one-class|oneclass|(?<![0-9])1c(?![0-9])", re.IGNORECASE),
    Metric("RMSE", "root-mean-square error",
           "√(mean over steps (and runs) of |x̂ − x|²) of one state group (position, velocity or "
           "acceleration) against the reference.",
           "seed 002 §8 (a true RMSE, beside the mean relative error of eq. 4.1)", "RMSE", re.IGNORECASE),
    Metric("NEES", "normalised estimation error squared",
           "(x̂ − x)ᵀ P⁻¹ (x̂ − x) per step: χ² with n = dim x degrees of freedom when the filter's "
           "covariance P is consistent with its errors.",
           "seed 002 §8", "A?NEES", re.IGNORECASE),
    Metric("NIS", "normalised innovation squared",
           "νᵀ S⁻¹ ν of the measurement innovation ν with its predicted covariance S: χ² with "
           "m = dim z degrees of freedom when the filter is consistent; needs no truth.",
           "seed 002 §8", "NIS", re.IGNORECASE),
    Metric("summed absolute error", "summed absolute error",
           "Σ_k |x̂_k − x_k| over a run; the runs with the lowest and the highest are the 'best' and "
           "'worst' scenarios.",
           "seed 000 §9 (thesis Ch. 4)", r"summed absolute error|best/worst|sum_abs", re.IGNORECASE),
    Metric("MPE", "model prediction error",
           "The acceleration part of the smoother's correction along the learned trajectory (β), "
           "the dynamics model's one-step error.",
           "seed 004 §3 (thesis §3.2, §5.4.4)", "MPE"),
    Metric("η", "percent error",
           "The position error per 100 m of mean observer–target range, 100 ε_k / mean_u |p_k − p_u,k|.",
           "seed 001 §11 (thesis §5.2)", r"η|percent error|pct_error", re.IGNORECASE),
)


def metrics_in(text: str) -> list[Metric]:
    """The metrics of :data:`METRICS` whose name occurs in ``text`` (tags stripped first)."""
    plain = html.unescape(re.sub(r"<[^>]+>", " ", text))
    return [m for m in METRICS if m.found_in(plain)]


def glossary_rows(text: str) -> list[tuple[str, str, str, str]]:
    """``[(name, spelled out, definition, source)]`` of the metrics shown in ``text``."""
    return [(m.name, m.long, m.sentence, m.cite) for m in metrics_in(text)]
