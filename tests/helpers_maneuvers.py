"""Synthetic maneuver state tables (the models and estimate tests; the simulator is tested elsewhere)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pipeline.io import schema


#: per-label acceleration profiles: (amplitude n/e/d m/s², frequency Hz, phase)
PROFILES = {
    "M1": ((4.0, 0.5, -3.0), (0.10, 0.20, 0.15), 0.0),
    "M2": ((0.5, 5.0, 1.0), (0.20, 0.08, 0.30), 1.0),
    "M3": ((-3.0, -3.0, 0.5), (0.30, 0.12, 0.05), 2.0),
    "U": ((2.0, -4.0, -4.0), (0.40, 0.35, 0.25), 0.5),
}


def synth_run(label: str, rng: np.random.Generator, *, duration_s=25.0, rate_hz=5.0,
              noise=0.3, t0_ns=0) -> pd.DataFrame:
    """One run: acceleration = label profile + white noise, integrated to vel/pos (NED)."""
    amp, freq, ph = PROFILES[label]
    n = int(round(duration_s * rate_hz)) + 1
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    acc = np.stack([a * np.sin(2 * np.pi * f * t + ph + i) for i, (a, f) in enumerate(zip(amp, freq))], 1)
    acc = acc + noise * rng.standard_normal(acc.shape)
    vel = np.array([15.0, 0.0, 0.0]) + rng.normal(0, 0.5, 3) + np.cumsum(acc, 0) * dt
    pos = rng.normal(0, 50, 3) + np.cumsum(vel, 0) * dt
    df = pd.DataFrame({"t_ns": t0_ns + np.round(t * 1e9).astype(np.int64)})
    for i, a in enumerate("ned"):
        df[f"pos_{a}_m"] = pos[:, i]
        df[f"vel_{a}_mps"] = vel[:, i]
        df[f"acc_{a}_mps2"] = acc[:, i]
    for c in schema.STATE:
        if c.name not in df.columns and c.dtype == "float64":
            df[c.name] = 0.0
    df["q_w"] = 1.0
    df["gap"] = False
    df["label"] = label
    return df


def synth_bulk(labels, n_runs, rng, **kw) -> pd.DataFrame:
    frames = []
    for lab in labels:
        for k in range(n_runs):
            frames.append(synth_run(lab, rng, **kw).assign(run_id=f"{lab}-{k}"))
    return pd.concat(frames, ignore_index=True)
