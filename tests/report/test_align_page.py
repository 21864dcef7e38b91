"""The trajectory-learning page's EM convergence plot (pipeline/report/align.py)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.report.align import loglik_figure


def test_the_convergence_plot_shows_the_relative_change_against_the_tolerance_and_counts_the_converged():
    # one maneuver creeping (the P23 pattern: -1.4e6, then -4305 ... -3282, never below tol), one converged
    creep = -3282.0 - 1000.0 * np.exp(-np.arange(30) / 8.0)
    creep[0] = -1.4e6
    done = -500.0 - 10.0 * 0.01 ** np.arange(6)
    it = pd.concat([pd.DataFrame({"maneuver": "tHat", "iteration": np.arange(30), "loglik": creep,
                                  "status": "ok", "converged": False}),
                    pd.DataFrame({"maneuver": "iSp", "iteration": np.arange(6), "loglik": done,
                                  "status": "ok", "converged": True})])
    fig = loglik_figure(it, tol=1e-6)
    assert fig.layout.title.text == "EM convergence (1 of 2 maneuvers converged)"
    assert fig.layout.yaxis.type == "log" and fig.layout.shapes[0].y0 == 1e-6
    tr = {t.name: np.asarray(t.y) for t in fig.data}
    np.testing.assert_allclose(tr["tHat"], np.abs(np.diff(creep)) / np.abs(creep[:-1]))
    assert tr["tHat"][-1] > 1e-4 and tr["iSp"][-1] < 1e-6   # above the line: not converged, visibly
    assert fig.data[0].line.color != fig.data[1].line.color
    assert loglik_figure(it.assign(status="failed")) is None
