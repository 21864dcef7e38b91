"""Per-maneuver summary of the seed-000 simulation: min/max/RMS acceleration and jerk per axis.

Simulates ``--runs`` disturbed runs of each maneuver (vectorised batch), writes the summary
table as Parquet (``--out``, default ``results/benchmarks/simulate_summary.parquet``) and prints
the headline figures as ``RESULT <name> <value>`` lines, with the limit checks of seed 000 §2.

    python benchmarks/simulate_summary.py --runs 100 --seed 1
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from pipeline.config import load_config, section
from pipeline.io.parquet import write_table
from pipeline.simulate import maneuvers as mv
from pipeline.simulate.datasets import SUMMARY_COLUMNS, summary_table
from pipeline.simulate.scenarios import SimSettings, run_named


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--config", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=Path("results/benchmarks/simulate_summary.parquet"))
    args = ap.parse_args()
    st = SimSettings.from_config(section(load_config(args.config), "simulate"))
    truths = {}
    t0 = time.perf_counter()
    for i, m in enumerate(mv.MANEUVERS):
        truths[m] = [run_named("maneuver", st, args.runs, np.random.default_rng([args.seed, i]), m)]
    elapsed = time.perf_counter() - t0
    tab = summary_table(truths)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_table(tab, args.out, SUMMARY_COLUMNS, name="simulate_summary", extra={"seed": args.seed})
    print(tab.to_string(index=False, float_format=lambda v: f"{v:9.3f}"))
    for m, (tr,) in truths.items():
        a = np.linalg.norm(tr.acc, axis=-1)
        j = np.linalg.norm(tr.jerk, axis=-1)
        print(f"RESULT {m}_acc_rms_mps2 {np.sqrt(np.mean(a * a)):.3f}")
        print(f"RESULT {m}_acc_max_mps2 {a.max():.3f}")
        print(f"RESULT {m}_jerk_rms_mps3 {np.sqrt(np.mean(j * j)):.3f}")
        print(f"RESULT {m}_speed_max_mps {np.linalg.norm(tr.vel, axis=-1).max():.3f}")
        print(f"RESULT {m}_tilt_max_deg {np.rad2deg(np.abs(tr.euler[..., :2])).max():.2f}")
        print(f"RESULT {m}_alt_start_m {-tr.pos[:, 0, 2].mean():.1f}")
        print(f"RESULT {m}_alt_end_m {-tr.pos[:, -1, 2].mean():.1f}")
    print(f"RESULT simulate_runs_per_s {len(mv.MANEUVERS) * args.runs / elapsed:.1f}")


if __name__ == "__main__":
    main()
