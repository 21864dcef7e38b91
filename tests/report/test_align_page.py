"""The trajectory-learning page's plots (pipeline/report/align.py): EM convergence, the units of
the panel titles."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.align.demos import DEMO_COLUMNS
from pipeline.report.align import alignment_figure, learned_figure, loglik_figure


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


def test_the_align_panels_name_their_units_in_brackets_as_every_other_report_label():
    n = 5
    learned = pd.DataFrame({"maneuver": "loop", "t": np.arange(n), "t_s": np.arange(n) * 0.1,
                            **{f"{k}_{c}": np.ones(n) for c in DEMO_COLUMNS for k in ("mu", "var", "mpe")}})
    demos = pd.DataFrame({"demo": "f0/0", "j": np.arange(n), "t_s": np.arange(n) * 0.1, "tau": np.arange(n) * 1.0,
                          **{c: np.ones(n) for c in DEMO_COLUMNS}})
    titles = [a.text for fig in (learned_figure("loop", learned, demos), alignment_figure("loop", demos, None, learned))
              for a in fig.layout.annotations]
    assert titles[:3] == ["position north [m]", "position east [m]", "position down [m]"]
    assert "velocity north [m/s]" in titles and "acceleration down [m/s²]" in titles
    assert titles[9:12] == ["roll [°]", "pitch [°]", "yaw [°]"]
    assert "model prediction error, acceleration [m/s²]" in titles
    # no unit in parentheses: '(m)', '(deg)', '(m/s)'
    assert not [t for t in titles if any(f"({u})" in t for u in ("m", "deg", "m/s", "m/s²", "°", "acc"))], titles
