"""Classification metrics exactly as seed 000 §5 defines them, and the thesis's result tables
(3.1–3.8 per maneuver, 3.10–3.15 switch scenarios; digest §11).

* **Final accuracy (FA)**: the share of runs whose label at the last sample is correct (in a
  switch scenario the initial maneuver is judged at the switch sample, the final one at the end).
* **Mean accuracy over time (MAoT)**: per run the fraction of samples labelled correctly,
  averaged over runs.
* A sample is correct when the label equals the truth; when the truth is *not* one of the
  models' maneuvers (M5, real M2, teleop segments), exactly the label ``"unknown"`` is correct.
  For a known maneuver ``"unknown"`` is wrong.

Both are percentages. Confusion matrices count final labels, truth in rows, prediction
(including ``unknown``) in columns.
"""

from __future__ import annotations

from typing import Iterable, Sequence

import numpy as np
import pandas as pd

UNKNOWN = "unknown"

#: seed 000 Tables 3.1–3.4 (FA %, MAoT %), truth input; M5 is the unknown maneuver.
THESIS_TRUTH = {
    "3.1": {"classifier": "oneclass", "split": "train",
            "M1": (100, 98.21), "M2": (100, 97.87), "M3": (100, 98.81), "M4": (100, 98.73)},
    "3.2": {"classifier": "confidence", "split": "train",
            "M1": (100, 98.21), "M2": (100, 97.47), "M3": (100, 98.81), "M4": (100, 95.24)},
    "3.3": {"classifier": "oneclass", "split": "test",
            "M1": (100, 98.21), "M2": (100, 97.86), "M3": (100, 98.81), "M4": (100, 98.76),
            "M5": (100, 98.12)},
    "3.4": {"classifier": "confidence", "split": "test",
            "M1": (100, 98.21), "M2": (100, 97.43), "M3": (100, 98.81), "M4": (100, 95.38),
            "M5": (100, 96.09)},
}

#: seed 000 Tables 3.5–3.8 (FA %, MAoT %): the truth-trained models classifying EKF estimates
#: (radar-only tracking, digest §11); M5 is the unknown maneuver.
THESIS_EKF = {
    "3.5": {"classifier": "oneclass", "split": "train",
            "M1": (100, 76.45), "M2": (100, 97.68), "M3": (100, 94.29), "M4": (100, 89.40)},
    "3.6": {"classifier": "confidence", "split": "train",
            "M1": (100, 86.94), "M2": (100, 97.64), "M3": (100, 96.04), "M4": (100, 80.83)},
    "3.7": {"classifier": "oneclass", "split": "test",
            "M1": (100, 77.87), "M2": (100, 97.70), "M3": (100, 94.40), "M4": (100, 89.00),
            "M5": (100, 94.21)},
    "3.8": {"classifier": "confidence", "split": "test",
            "M1": (100, 87.88), "M2": (100, 97.64), "M3": (100, 96.06), "M4": (100, 80.60),
            "M5": (100, 91.59)},
}
#: every thesis table of per-maneuver FA/MAoT (truth input 3.1–3.4, EKF input 3.5–3.8)
THESIS_CLASSIFICATION = {**THESIS_TRUTH, **THESIS_EKF}

#: seed 000 Tables 3.10–3.12, confidence classifier, truth input:
#: (switch s, scenario) -> (FA initial, FA final, MAoT initial, MAoT final).
SCENARIOS = {"A": ("M1", "M2"), "B": ("M2", "M4"), "C": ("M3", "M1"), "D": ("M4", "M3")}
THESIS_SWITCH = {
    (3, "A"): (100, 100, 91.26, 73.93), (3, "B"): (100, 100, 87.70, 59.88),
    (3, "C"): (100, 100, 94.43, 40.21), (3, "D"): (18.93, 100, 55.92, 49.12),
    (8, "A"): (100, 100, 95.49, 15.75), (8, "B"): (100, 100, 93.65, 17.10),
    (8, "C"): (100, 100, 97.04, 7.84), (8, "D"): (100, 100, 88.29, 24.09),
    (13, "A"): (100, 0, 97.07, 0), (13, "B"): (100, 13.58, 95.68, 4.15),
    (13, "C"): (100, 0, 98.05, 0), (13, "D"): (100, 100, 91.81, 22.14),
}
SWITCH_TABLE = {3: "3.10", 8: "3.11", 13: "3.12"}
#: seed 000 Tables 3.13–3.15: the same scenarios, confidence classifier, EKF input (truth-trained
#: models): (switch s, scenario) -> (FA initial, FA final, MAoT initial, MAoT final).
THESIS_SWITCH_EKF = {
    (3, "A"): (99.59, 100, 84.30, 77.29), (3, "B"): (100, 100, 88.00, 39.59),
    (3, "C"): (88.48, 100, 80.75, 34.12), (3, "D"): (8.23, 100, 19.20, 34.34),
    (8, "A"): (100, 1.23, 90.90, 0.06), (8, "B"): (100, 11.52, 94.02, 0.52),
    (8, "C"): (97.12, 99.17, 88.29, 13.65), (8, "D"): (99.18, 96.71, 48.94, 13.00),
    (13, "A"): (100, 0, 93.80, 0), (13, "B"): (100, 0, 95.87, 0),
    (13, "C"): (100, 22.63, 93.67, 1.30), (13, "D"): (100, 84.77, 66.33, 10.25),
}
SWITCH_TABLE_EKF = {3: "3.13", 8: "3.14", 13: "3.15"}


def is_correct(pred, truth, known: Iterable[str]) -> np.ndarray:
    """Element-wise correctness per §5 (``unknown`` is right only for unknown maneuvers)."""
    pred = np.asarray(pred, dtype=object)
    truth = np.asarray(truth, dtype=object)
    known_set = set(known)
    tk = np.array([t in known_set for t in truth], dtype=bool) if truth.ndim else truth in known_set
    return np.where(tk, pred == truth, pred == UNKNOWN)


def final_accuracy(pred_final: Sequence, truth_final: Sequence, known: Iterable[str]) -> float:
    """FA in % over runs, from each run's judged label."""
    c = is_correct(pred_final, truth_final, known)
    return 100.0 * float(np.mean(c)) if len(c) else float("nan")


def mean_accuracy_over_time(preds: Sequence[Sequence], truths: Sequence[Sequence],
                            known: Iterable[str]) -> float:
    """MAoT in %: per-run fraction correct, averaged over runs (runs may differ in length)."""
    known = list(known)
    fr = [float(np.mean(is_correct(p, t, known))) for p, t in zip(preds, truths) if len(p)]
    return 100.0 * float(np.mean(fr)) if fr else float("nan")


def per_maneuver_table(df: pd.DataFrame, known: Iterable[str], *, run_col: str = "run_id",
                       truth_col: str = "label", pred_col: str = "pred") -> pd.DataFrame:
    """FA and MAoT per true maneuver of a per-sample result table (one maneuver per run).

    Returns columns ``maneuver``, ``n_runs``, ``FA_pct``, ``MAoT_pct``.
    """
    known = list(known)
    rows = []
    per_run = []
    for rid, g in df.groupby(run_col, sort=False):
        truth = g[truth_col].to_numpy(dtype=object)
        pred = g[pred_col].to_numpy(dtype=object)
        per_run.append((truth[-1], pred[-1], float(np.mean(is_correct(pred, truth, known)))))
    pr = pd.DataFrame(per_run, columns=["maneuver", "final", "frac"])
    for man, g in pr.groupby("maneuver", sort=True):
        fa = final_accuracy(g["final"].to_numpy(), np.full(len(g), man, dtype=object), known)
        rows.append({"maneuver": man, "n_runs": len(g), "FA_pct": fa,
                     "MAoT_pct": 100.0 * float(g["frac"].mean())})
    return pd.DataFrame(rows, columns=["maneuver", "n_runs", "FA_pct", "MAoT_pct"])


def confusion(truth_final: Sequence, pred_final: Sequence, labels: Sequence[str]) -> pd.DataFrame:
    """Counts of final labels: rows = truth, columns = ``labels`` + ``unknown``."""
    cols = [*labels, UNKNOWN]
    rows = sorted(set(truth_final), key=lambda x: (x not in labels, str(x)))
    m = pd.DataFrame(0, index=pd.Index(rows, name="truth"), columns=cols, dtype=np.int64)
    for t, p in zip(truth_final, pred_final):
        m.loc[t, p if p in cols else UNKNOWN] += 1
    return m


def thesis_side_by_side(ours: pd.DataFrame, table: str) -> pd.DataFrame:
    """Our per-maneuver FA/MAoT beside the thesis values of Table ``table`` (3.1–3.8; any other
    table name, e.g. an extension of ours, gets NaN thesis columns)."""
    ref = THESIS_CLASSIFICATION.get(table, {})             # our extensions have no thesis column
    out = ours.copy()
    out.insert(0, "table", table)
    out["thesis_FA_pct"] = [ref.get(m, (np.nan, np.nan))[0] for m in out["maneuver"]]
    out["thesis_MAoT_pct"] = [ref.get(m, (np.nan, np.nan))[1] for m in out["maneuver"]]
    return out
