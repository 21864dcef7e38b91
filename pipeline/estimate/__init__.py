"""estimate subpackage (issue 14's estimator framework).

Modules (imported on demand, so ``simulate``'s use of :mod:`.models` stays light):
:mod:`.models` (radar, CA transition, white-jerk Q, A_H/B, P₀), :mod:`.base` (GaussianState,
model protocols), :mod:`.ekf` (vectorised EKF, ``run_filter``), :mod:`.smoother` (RTS),
:mod:`.metrics` (RMSE, NEES/NIS, χ² bands, best/worst), :mod:`.montecarlo` (truth, Monte
Carlo, ``tune_q``), :mod:`.markov` (row-stochastic checks, Π(Δt)), :mod:`.table` (the
``estimate`` output table).
"""


#: the stage's entry points, importable from the package; loaded on first use so importing the
#: package stays light
_ENTRY_POINTS = {'run_estimate': 'run', 'run_q2': 'run', 'run_ekf_sets': 'sets', 'run_bearing_replay': 'bearing_run',
                'run_pf_jm': 'pf_run', 'run_hmpf': 'weave_run'}


def __getattr__(name: str):
    if name in _ENTRY_POINTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_ENTRY_POINTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
