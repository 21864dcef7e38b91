"""Configuration and errors of the maneuver models (``hmm:`` section of the dataset config).

Defaults and types are the config schema's (``rules/schemas/config.schema.yaml``, ``hmm``);
:class:`ModelsConfig` reads them from there (:func:`pipeline.config.cfield`).

Defaults follow seed 000 (Strong 2021) where it gives a value and §13 of the digest where it
does not (every such choice is logged in the model's ``meta.json``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from ..config import ConfigError, build, cfield, validate_section


class ModelError(ValueError):
    """Training or classification cannot proceed (bad input data, bad model file)."""


_hmm = functools.partial(cfield, "hmm")
_MODES = ("cumulative", "windowed", "reset")
_DECISIONS = ("confidence", "oneclass", "both", "confidence_bg")


@dataclass(frozen=True, kw_only=True)
class ModelsConfig:
    """Hyperparameters of :mod:`pipeline.models`.

    Parameters
    ----------
    feature_set : str
        ``state9`` (thesis), ``state9h`` (initial-heading frame), ``state9box`` (box frame), ``box`` or
        ``aero`` (see :mod:`pipeline.models.features`).
    rate_hz : float
        Model sample rate (thesis: 5 Hz, dt = 0.2 s).
    n_states : int, "auto" or dict
        States per maneuver HMM; a dict maps labels to counts with a ``default`` entry.
        Thesis: λ1 = 5, λ2–λ4 = 6. ``auto``: BIC over ``n_states_range``.
    n_states_range : tuple of int
        Inclusive range searched by ``auto`` (thesis GMM search: 3..10).
    n_mix : int
        Gaussians per state (1 = the thesis's single full-covariance Gaussian).
    n_iter, tol : int, float
        Baum-Welch iteration cap and log-likelihood tolerance (not given in the thesis).
    min_covar : float
        Added to covariance diagonals (normalised units) to keep them positive definite.
    self_prob : float
        Initial ``a_ii``; off-diagonals share ``1 - self_prob`` so no transition starts at zero
        (Baum-Welch keeps zeros; §13.1).
    gmm_restarts : int
        EM restarts of the Calinon GMM pre-training.
    init_min_samples : int
        Minimum samples for the GMM pre-training; the one random run is extended with further
        random runs until it has this many (short real segments).
    hmm_restarts : int
        Whole-model restarts from different random runs; the best training LL is kept.
    seed : int
        Seed of every random choice in training (run pick, GMM, hmmlearn, the background
        model's ``[seed, crc32("background")]``). Not a key of the ``hmm`` section: the caller
        passes the master ``seed`` (:meth:`from_section`, ``build(..., seed=config["seed"])``);
        0 when constructed directly.
    threshold_percentile : float
        One-class threshold: this percentile of the training log-likelihoods at the same
        elapsed time (default 0.5th).
    threshold_slack : float or "auto"
        Per-sample allowance (nats) subtracted from the one-class threshold; ``auto``
        estimates it leave-one-recording-out where a label has several recordings (real
        flights: phases of one recording are near-duplicates, so their percentile is
        optimistic). Default 0 (thesis-style percentile only).
    threshold_fraction : float
        ``f`` of the impostor-scaled one-class threshold
        :math:`\\theta_m(n) = f\\,q_m(n) + (1-f)\\,n\\,\\bar\\ell_m - s\\,n`: how far from the mean
        per-sample log-likelihood of model ``m`` on the other training maneuvers
        (:math:`\\bar\\ell_m`) towards its training percentile curve ``q_m`` the threshold
        sits (:mod:`pipeline.models.classifier`). Default 1 (the percentile curve).
    mode : str
        ``cumulative`` (thesis, from t = 1), ``windowed`` (sliding window of predictive
        log-likelihood increments with a restart transition) or ``reset`` (windowed change
        detection that restarts the cumulative forward pass).
    window_s : float or "auto"
        Window length of ``windowed``/``reset``, s. ``auto``: half the median length of the
        training recordings, resolved at training and stored with the model (aerobatic
        maneuvers last 10–60 s; the seed-000 switch scenarios want ~1.6 s).
    restart_prob : float
        Per-step probability of jumping back to π in ``windowed``/``reset`` (lets a model
        re-enter its first state after a maneuver switch).
    confirm_s : float
        ``reset``: how long the windowed label must disagree before a change is declared.
    confidence_threshold : float
        Label ``c`` only when ``V_c`` is below this (thesis: −1).
    decision : str
        ``confidence`` (thesis's chosen classifier), ``oneclass``, ``both`` (confidence and
        one-class) or ``confidence_bg`` (confidence with the background model as one more rival:
        where it is the most likely hypothesis, or too close to the best maneuver, the label is
        unknown).
    background : int
        Gaussians of the background model fitted at training to the pooled normalised
        observations of every maneuver (a universal background model; 0 = none). It is never a
        label; ``confidence_bg`` uses it so a maneuver unlike all trained ones is unknown
        without a threshold (the thesis's M5 under the confidence classifier, Table 3.4).
    gate_mps2 : float
        GMR outlier gate, per axis and step (seed 000 §8: 15 m/s²).
    gmr_input : str
        GMR conditioning block: ``pos_fd`` (default: position increments and the
        position-only velocity increment from the last three positions — the information of
        a finite difference, which it beats on every simulated maneuver), ``pos`` (thesis
        3.28, position increments only) or ``pos_vel`` (position and velocity increments;
        ``Δv`` then observed). See :mod:`.gmr`.
    gmr_align : str
        ``sample`` (default): ``â = Δv/dt + (dt/2)ĵ``, the acceleration at the sample time as
        the EKF+HMM uses it; ``interval``: ``â = Δv/dt`` as printed (§13.3), half a sample late.
    phases : bool
        Train on every phase-offset decimation of a faster source (more sequences; required
        for the single-sequence leave-one-phase-out threshold).
    """

    feature_set: str = _hmm("feature_set")
    rate_hz: float = _hmm("rate_hz")
    n_states: Any = _hmm("n_states")
    n_states_range: tuple[int, int] = _hmm("n_states_range")
    n_mix: int = _hmm("n_mix")
    n_iter: int = _hmm("n_iter")
    tol: float = _hmm("tol")
    min_covar: float = _hmm("min_covar")
    self_prob: float = _hmm("self_prob")
    gmm_restarts: int = _hmm("gmm_restarts")
    init_min_samples: int = _hmm("init_min_samples")
    hmm_restarts: int = _hmm("hmm_restarts")
    seed: int = field(default=0, metadata={"config_key": None})
    threshold_percentile: float = _hmm("threshold_percentile")
    threshold_slack: Any = _hmm("threshold_slack")
    threshold_fraction: float = _hmm("threshold_fraction")
    mode: str = _hmm("mode")
    window_s: Any = _hmm("window_s")
    restart_prob: float = _hmm("restart_prob")
    confirm_s: float = _hmm("confirm_s")
    confidence_threshold: float = _hmm("confidence_threshold")
    decision: str = _hmm("decision")
    background: int = _hmm("background")
    gate_mps2: float = _hmm("gate_mps2")
    gmr_input: str = _hmm("gmr_input")
    gmr_align: str = _hmm("gmr_align")
    phases: bool = _hmm("phases")

    @classmethod
    def from_section(cls, sec: Mapping | None, *, seed: int = 0, **overrides) -> "ModelsConfig":
        """Validate the ``hmm`` section (with a model set's ``hmm`` overrides) against the
        config schema and build; ``seed`` is the master seed (top-level ``seed``), passed by
        the caller: the ``hmm`` section holds no seed.

        Raises
        ------
        ConfigError
            One line naming the key (unknown keys, wrong types, values out of range).
        """
        cfg = build(cls, validate_section("hmm", {**dict(sec or {}), **overrides}), seed=int(seed))
        cfg.validate()
        return cfg

    def validate(self) -> None:
        """Check choices, ranges and cross-field rules; raise :class:`ConfigError` (one line
        naming the ``hmm.`` key) at the first violation."""
        if self.mode not in _MODES:
            raise ConfigError(f"hmm.mode must be one of {_MODES}, got {self.mode!r}")
        if self.decision not in _DECISIONS:
            raise ConfigError(f"hmm.decision must be one of {_DECISIONS}, got {self.decision!r}")
        if self.gmr_input not in ("pos", "pos_vel", "pos_fd"):
            raise ConfigError(f"hmm.gmr_input must be 'pos', 'pos_vel' or 'pos_fd', got {self.gmr_input!r}")
        if self.gmr_align not in ("interval", "sample"):
            raise ConfigError(f"hmm.gmr_align must be 'interval' or 'sample', got {self.gmr_align!r}")
        if not (isinstance(self.background, int) and self.background >= 0):
            raise ConfigError(f"hmm.background must be an int >= 0, got {self.background!r}")
        if self.decision == "confidence_bg" and self.background == 0:
            raise ConfigError("hmm.decision 'confidence_bg' needs hmm.background >= 1")
        if not 0.0 < self.self_prob < 1.0:
            raise ConfigError("hmm.self_prob must lie in (0, 1)")
        if not 0.0 <= self.restart_prob < 1.0:
            raise ConfigError("hmm.restart_prob must lie in [0, 1)")
        if not 0.0 <= self.threshold_percentile <= 100.0:
            raise ConfigError("hmm.threshold_percentile must lie in [0, 100]")
        if self.rate_hz <= 0 or not (self.window_s == "auto" or (
                isinstance(self.window_s, (int, float)) and self.window_s > 0)):
            raise ConfigError("hmm.rate_hz must be positive and hmm.window_s positive or 'auto'")
        if not (self.threshold_slack == "auto" or isinstance(self.threshold_slack, (int, float))):
            raise ConfigError("hmm.threshold_slack must be a number or 'auto'")
        if not (isinstance(self.threshold_fraction, (int, float)) and 0.0 <= self.threshold_fraction <= 1.0):
            raise ConfigError(f"hmm.threshold_fraction must lie in [0, 1], got {self.threshold_fraction!r}")
        lo, hi = self.n_states_range
        if not 2 <= lo <= hi:
            raise ConfigError("hmm.n_states_range must be [lo, hi] with 2 <= lo <= hi")
        ns = self.n_states
        vals = ns.values() if isinstance(ns, dict) else [ns]
        for v in vals:
            if not (v == "auto" or (isinstance(v, int) and v >= 1)):
                raise ConfigError(f"hmm.n_states: {v!r} is neither a positive int nor 'auto'")

    def states_for(self, label: str) -> int | str:
        """State count (or ``"auto"``) for one maneuver label."""
        ns = self.n_states
        if isinstance(ns, dict):
            return ns.get(label, ns.get("default", 6))
        return ns

    @property
    def window(self) -> int:
        """Window length in samples."""
        if self.window_s == "auto":
            raise ModelError("hmm.window_s 'auto' is resolved when the models are trained")
        return max(1, int(round(self.window_s * self.rate_hz)))

    def to_dict(self) -> dict:
        """Every field, ``seed`` included, as a JSON-ready dict (``n_states_range`` a list): the
        ``config`` of a model's ``meta.json``, read back by :meth:`from_section`."""
        d = asdict(self)
        d["n_states_range"] = list(self.n_states_range)
        return d
