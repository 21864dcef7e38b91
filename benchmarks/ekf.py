"""Vectorised EKF Monte Carlo against a Python loop over runs (filterpy), same runs.

Truth: ``--runs`` runs × ``--steps`` steps at 5 Hz drawn from the white-jerk CA model (seed 000
§3), measured by the seed-000 radar (:class:`~pipeline.estimate.models.RadarModel`). Ours:
:func:`~pipeline.estimate.ekf.run_filter`, every run at once (a loop over time only), Joseph
form, keeping posterior means and covariances. Baseline: filterpy's ``ExtendedKalmanFilter``
stepping the runs one by one with the radar's analytic Jacobian (same Joseph update), keeping
the same; it times ``--baseline-runs`` of them and scales to all runs. The results are checked
equal on the runs the baseline filters. Ends with ``RESULT`` lines.

Both sides run in one process under the same settings: single-threaded BLAS (the work is
many 9×9 products; threads only contend, badly so on a shared machine) and a fixed glibc
mmap/trim threshold (the vectorised side's ~650 KB temporaries would otherwise go back to the
OS after every operation and page-fault back in, ~1 ms a step on a VM; filterpy's 9×9
temporaries are unaffected). Neither setting changes a result. Timing: ``--repeat`` full runs of ours interleaved
with as many chunks of the baseline runs (both see the same machine load); the median of ours,
and the median per-run time × runs for the baseline, both in process CPU time
(:data:`CLOCK`).
"""

from __future__ import annotations

import os

# before numpy loads OpenBLAS
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import ctypes  # noqa: E402
import ctypes.util  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from pipeline.estimate.base import ConstantAcceleration, GaussianState
from pipeline.estimate.ekf import ExtendedKalmanFilter, run_filter
from pipeline.estimate.models import RadarModel, ca_transition, initial_cov, white_jerk_q
from pipeline.estimate.montecarlo import measure, simulate_white_jerk

DT, DT_NS, Q_JERK = 0.2, 200_000_000, 1.0
#: CPU seconds of this process (user + system, page faults included): on a shared machine,
#: wall time mostly measures the other tenants; with single-threaded BLAS the two agree
#: on an idle machine
CLOCK = time.process_time
X0 = np.array([400.0, -300.0, -120.0, 8.0, 5.0, -1.0, 0.3, -0.2, 0.1])


def keep_heap() -> bool:
    """glibc: keep freed large blocks in the heap (M_TRIM_THRESHOLD, M_MMAP_THRESHOLD)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        return bool(libc.mallopt(-1, 1 << 30)) and bool(libc.mallopt(-3, 1 << 30))
    except (OSError, AttributeError):
        return False


def baseline(radar: RadarModel, z: np.ndarray, runs: range) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """filterpy, one run after another: posterior means and covariances (len(runs), T, ...)
    and the seconds each run took."""
    from filterpy.kalman import ExtendedKalmanFilter as FPEKF

    T = z.shape[0]
    xs, Ps = np.empty((len(runs), T, 9)), np.empty((len(runs), T, 9, 9))
    secs = np.empty(len(runs))
    F, Q, R = ca_transition(DT), white_jerk_q(DT, Q_JERK), radar.R
    for i, r in enumerate(runs):
        t0 = CLOCK()
        f = FPEKF(dim_x=9, dim_z=4)
        f.x, f.P, f.F, f.Q, f.R = X0.copy(), initial_cov(), F, Q, R
        for k in range(T):
            if k:
                f.predict()
            f.update(z[k, r], HJacobian=radar.jacobian, Hx=radar.h)
            xs[i, k], Ps[i, k] = f.x, f.P
        secs[i] = CLOCK() - t0
    return xs, Ps, secs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=325)
    ap.add_argument("--baseline-runs", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--seed", type=int, default=20261201)
    a = ap.parse_args(argv)
    heap = keep_heap()
    rng = np.random.default_rng(a.seed)
    radar = RadarModel(site_ned_m=(-200.0, 150.0, 0.0))
    truth = simulate_white_jerk(a.runs, a.steps, DT, Q_JERK, X0, rng=rng)
    z = measure(radar, truth, rng)
    t_ns = np.arange(a.steps, dtype=np.int64) * DT_NS
    ekf = ExtendedKalmanFilter(ConstantAcceleration(Q_JERK), radar)
    prior = GaussianState(np.broadcast_to(X0, (a.runs, 9)), np.broadcast_to(initial_cov(), (a.runs, 9, 9)), 0)

    # ours and the baseline interleaved, so both see the same load on a shared machine
    nb = min(a.baseline_runs, a.runs)
    chunks = np.array_split(np.arange(nb), max(1, a.repeat))
    times, xs, Ps, secs = [], [], [], []
    for chunk in chunks:
        track = None  # free the previous run's arrays first
        t0 = CLOCK()
        track = run_filter(ekf, prior, t_ns, z, store="filtered")
        times.append(CLOCK() - t0)
        x_b, P_b, s_b = baseline(radar, z, range(int(chunk[0]), int(chunk[-1]) + 1))
        xs.append(x_b), Ps.append(P_b), secs.append(s_b)
    xs, Ps, secs = np.concatenate(xs), np.concatenate(Ps), np.concatenate(secs)
    t_ours = float(np.median(times))
    t_base = float(np.median(secs)) * a.runs

    dx = np.max(np.linalg.norm(track.mean[:nb] - xs, axis=-1) / np.linalg.norm(xs, axis=-1))
    dP = np.max(np.linalg.norm(track.cov[:nb] - Ps, axis=(-2, -1)) / np.linalg.norm(Ps, axis=(-2, -1)))
    ok = dx < 1e-9 and dP < 1e-6
    print(f"runs {a.runs} x steps {a.steps}; ours {t_ours:.3f} s (all runs at once, median of "
          f"{len(times)}: {', '.join(f'{t:.3f}' for t in times)}); filterpy loop {t_base:.1f} s "
          f"(median of {nb} timed runs x {a.runs}); BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}, "
          f"heap kept {heap}")
    print(f"equal on the {nb} baseline runs: max relative difference mean {dx:.2e}, cov {dP:.2e} "
          f"({'ok' if ok else 'MISMATCH'})")
    print(f"RESULT ekf_mc_seconds {t_ours:.4f}")
    print(f"RESULT ekf_python_loop_seconds {t_base:.3f}")
    print(f"RESULT ekf_mc_speedup_vs_python_loop {t_base / t_ours:.1f}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
