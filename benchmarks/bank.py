"""Bearing-only EKF bank (seed 002 §4): the vectorised bank against its filters one by one.

Defaults (no arguments) are the issue-16 sizes. Truth: one CT orbit (digest §9: v = 70 m/s,
ω = 6°/s, a 40 m/s CV ownship), T = 0.05 s, 2,400 steps (120 s), σ_β = 0.2°.

1. CPPV (25, 1, 6), 150 filters: :func:`~pipeline.estimate.bank.run_bank` (every filter at
   once; the loop is over time only, weights, combination and entropy included) against the
   same filters stepped one by one in a Python loop (each a one-component bank through the very
   same :func:`~pipeline.estimate.bank.components_step`, so the EKF arithmetic is identical and
   only the vectorisation differs; the loop's weights/combination are not even computed). The
   loop times ``--loop-filters`` of the 150 (evenly spaced) and scales the median per-filter
   time to all 150; its filter means are checked equal to the bank's.
2. MPC (15, 5, 2), 150 filters, 50 Euler substeps per step (numba): one full run, after a
   3-step warm-up that loads (or compiles) the numba kernel.

Timing is process CPU time (user + system) with single-threaded BLAS: on a shared machine,
wall time mostly measures the other tenants. Ends with ``RESULT`` lines.
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from pipeline.estimate.bank import (Components, bank_prior, components_step, model_for,  # noqa: E402
                                    run_bank, settings_for)
from pipeline.estimate.models import cppv_transition  # noqa: E402

CLOCK = time.process_time
DT = 0.05
SIGMA = np.deg2rad(0.2)
VO = np.array([40.0, 0.0])
X0 = np.array([3000.0, 1500.0, 70.0, 1.0, np.deg2rad(6.0)])


def scenario(steps: int, seed: int):
    rng = np.random.default_rng(seed)
    X = np.empty((steps, 5))
    X[0] = X0
    for k in range(1, steps):
        X[k] = cppv_transition(X[k - 1], DT, VO * DT)
    z = np.arctan2(X[:, 1], X[:, 0]) + SIGMA * rng.standard_normal(steps)
    return np.arange(steps) * DT, X, z, np.broadcast_to(np.r_[0.0, 0.0, VO], (steps, 4))


def loop_filters(preset: str, t, z, own, idx):
    """The filters ``idx`` one after another (a one-component bank each): their means
    (len(idx), T, 5) and the CPU seconds each took."""
    s = settings_for(preset)
    model = model_for(s)
    prior = bank_prior(s, z[:1], SIGMA, own[:1, 2:])
    out = np.empty((len(idx), len(t), 5))
    secs = np.empty(len(idx))
    vo = own[:, 2:]
    for n, i in enumerate(idx):
        t0 = CLOCK()
        c = Components(prior.mean[:, i:i + 1], prior.cov[:, i:i + 1], np.zeros((1, 1)), np.zeros((1, 1), bool))
        out[n, 0] = c.mean[0, 0]
        for k in range(1, len(t)):
            c, _ = components_step(model, c, t[k] - t[k - 1], 0.5 * (vo[k - 1] + vo[k])[None], z[k:k + 1], SIGMA)
            out[n, k] = c.mean[0, 0]
        secs[n] = CLOCK() - t0
    return out, secs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2400)
    ap.add_argument("--cppv", default="cppv_25_1_6")
    ap.add_argument("--mpc", default="mpc_15_5_2")
    ap.add_argument("--loop-filters", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=20261202)
    a = ap.parse_args(argv)
    t, X, z, own = scenario(a.steps, a.seed)
    N = settings_for(a.cppv).n_filters
    idx = np.unique(np.linspace(0, N - 1, min(a.loop_filters, N)).round().astype(int))
    chunks = np.array_split(idx, max(1, a.repeat))
    times, xs, secs = [], [], []
    track = None
    for chunk in chunks:  # interleaved, so both sides see the same machine load
        track = None
        t0 = CLOCK()
        track = run_bank(a.cppv, t, z, SIGMA, own, store_weights=False, store_components=True)
        times.append(CLOCK() - t0)
        x_b, s_b = loop_filters(a.cppv, t, z, own, chunk)
        xs.append(x_b), secs.append(s_b)
    xs, secs = np.concatenate(xs), np.concatenate(secs)
    t_bank = float(np.median(times))
    t_loop = float(np.median(secs)) * N
    ref = track.component_mean[0][:, idx].transpose(1, 0, 2)
    dx = float(np.max(np.abs(ref - xs) / np.maximum(1.0, np.abs(xs))))
    ok = dx < 1e-8
    print(f"CPPV {a.cppv}: {N} filters x {a.steps} steps; bank {t_bank:.3f} s (median of {len(times)}: "
          f"{', '.join(f'{x:.3f}' for x in times)}); Python loop over filters {t_loop:.1f} s (median of "
          f"{len(idx)} timed filters {', '.join(f'{x:.2f}' for x in secs)} s, x {N}, extrapolated)")
    print(f"equal on the {len(idx)} looped filters: max relative difference of the means {dx:.2e} "
          f"({'ok' if ok else 'MISMATCH'})")
    s_mpc = settings_for(a.mpc)
    run_bank(s_mpc, t[:3], z[:3], SIGMA, own[:3])  # loads (or compiles) the numba kernel
    t0 = CLOCK()
    mt = run_bank(s_mpc, t, z, SIGMA, own, store_weights=False)
    t_mpc = CLOCK() - t0
    r = np.hypot(X[:, 0], X[:, 1])
    err = lambda m: abs(np.hypot(m[-1, 0], m[-1, 1]) - r[-1]) / r[-1]  # noqa: E731
    print(f"MPC {a.mpc}: {s_mpc.n_filters} filters x {a.steps} steps, {round(DT / s_mpc.mpc_substep_s)} "
          f"substeps: {t_mpc:.3f} s; final relative range error CPPV {err(track.cppv_mean[0]):.3f}, "
          f"MPC {err(mt.cppv_mean[0]):.3f}; diverged filters CPPV {int(track.diverged.sum())}, "
          f"MPC {int(mt.diverged.sum())}")
    print(f"RESULT bank_seconds {t_bank:.4f}")
    print(f"RESULT bank_python_loop_seconds {t_loop:.2f}")
    print(f"RESULT bank_speedup_vs_python_loop {t_loop / t_bank:.1f}")
    print(f"RESULT bank_mpc_seconds {t_mpc:.3f}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
