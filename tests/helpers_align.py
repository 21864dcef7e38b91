"""Synthetic flights for the align tests: a uniform 25 Hz state grid with labelled segments."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.frames.rotations import euler_to_quat
from pipeline.io import schema
from pipeline.io.parquet import write_table

GRID_NS = 40_000_000  # 25 Hz


def synthetic_state(n: int = 1000, *, heading_rad: float = 0.0, seed: int = 0) -> pd.DataFrame:
    """A flight flying along its box x axis (box heading ``heading_rad`` from north) at 20 m/s,
    with a sinusoidal climb, yaw = the box heading; every STATE column present."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.int64) * GRID_NS
    ts = t * 1e-9
    xb = 20.0 * ts + 0.01 * rng.standard_normal(n)          # box x
    yb = 5.0 * np.sin(0.2 * ts)                             # box y
    d = -50.0 - 10.0 * np.sin(0.5 * ts)
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    pn, pe = c * xb - s * yb, s * xb + c * yb              # box -> NED
    df = schema.empty("state").reindex(range(n))
    df["t_ns"] = t
    for name, v in (("pos_n_m", pn), ("pos_e_m", pe), ("pos_d_m", d)):
        df[name] = v
    for a, p in zip("ned", (pn, pe, d)):
        df[f"vel_{a}_mps"] = np.gradient(p, ts)
        df[f"acc_{a}_mps2"] = np.gradient(df[f"vel_{a}_mps"].to_numpy(), ts)
        df[f"jerk_{a}_mps3"] = 0.0
    q = euler_to_quat(np.zeros(n), np.zeros(n), np.full(n, heading_rad))
    for k, cq in enumerate("wxyz"):
        df[f"q_{cq}"] = q[:, k]
    for col in ("roll_rad", "pitch_rad", "p_radps", "q_radps", "r_radps", "ail", "ele", "rud", "thr",
                "delta_a_rad", "delta_e_rad", "delta_r_rad", "thrust_N", "alt_cal_m"):
        df[col] = 0.0
    df["yaw_rad"] = heading_rad
    df["gap"] = False
    return df


def synthetic_segments(bounds_s: list[tuple[float, float, str]]) -> pd.DataFrame:
    return pd.DataFrame({"segment_id": np.arange(len(bounds_s), dtype=np.int64),
                         "t_start_ns": [int(a * 1e9) for a, _, _ in bounds_s],
                         "t_end_ns": [int(b * 1e9) for _, b, _ in bounds_s],
                         "label": [lab for _, _, lab in bounds_s]}).astype({"label": "string"})


def write_flight(root, flight: str, state: pd.DataFrame, segments: pd.DataFrame,
                 box_rotation_rad: float | None = None) -> tuple[str, str]:
    sp, gp = root / "state" / f"{flight}.parquet", root / "segments" / f"{flight}.parquet"
    extra = {"flight_id": flight, "preprocess": {"status": "ok"}}
    if box_rotation_rad is not None:
        extra["box_rotation_rad"] = box_rotation_rad
    write_table(state, sp, schema.STATE, name="state", extra=extra)
    write_table(segments, gp, schema.SEGMENTS, name="segments", extra={"flight_id": flight})
    return str(sp), str(gp)


def synthetic_align_page(tmp, spans: list[tuple[float, float, str]], n_samples: int, *, max_iter: int = 2) -> str:
    """Two synthetic flights (headings 0 and 0.4 rad) with the segments ``spans``, aligned as set
    ``s`` and drawn as its align page; returns the page's HTML."""
    from pathlib import Path

    from pipeline.align.run import ALIGN_OUTPUTS, run_align
    from pipeline.config import load_config
    from pipeline.report.align import build_align_report

    root = Path(__file__).resolve().parents[1]
    seg = synthetic_segments(spans)
    fl = [write_flight(tmp / "in", f"f{k}", synthetic_state(n_samples, heading_rad=0.4 * k, seed=k), seg, 0.4 * k)
          for k in range(2)]
    out = {k: tmp / "align" / f"{k}.parquet" for k in ALIGN_OUTPUTS}
    run_align({"states": [p[0] for p in fl], "segments": [p[1] for p in fl]}, out,
              {**load_config()["align"], "max_iter": max_iter, "sets": {"s": {"flights": ["f0", "f1"], "reference": None}}},
              set_name="s")
    build_align_report(out, tmp / "s.html", set_name="s",
                       template=root / "reports" / "templates" / "align.html.j2", plotly_js="plotly.min.js")
    return (tmp / "s.html").read_text()
