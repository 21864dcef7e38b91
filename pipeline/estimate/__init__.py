"""estimate subpackage (issue 14's estimator framework).

Modules (imported on demand, so ``simulate``'s use of :mod:`.models` stays light):
:mod:`.models` (radar, CA transition, white-jerk Q, A_H/B, P₀), :mod:`.base` (GaussianState,
model protocols), :mod:`.ekf` (vectorised EKF, ``run_filter``), :mod:`.smoother` (RTS),
:mod:`.metrics` (RMSE, NEES/NIS, χ² bands, best/worst), :mod:`.montecarlo` (truth, Monte
Carlo, ``tune_q``), :mod:`.markov` (row-stochastic checks, Π(Δt)), :mod:`.table` (the
``estimate`` output table).
"""
