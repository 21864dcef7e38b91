"""DTW against dtaidistance's C library, and the trajectory learner's EM, at the issue-15 sizes.

**DTW** (:mod:`pipeline.align.dtw`): two random ``--n`` × ``--n`` × ``--dims`` sequences (defaults
1000 × 1000 × 9-D), unwindowed and with a Sakoe–Chiba window ``r = --window`` (100). Both sides
compute the same thing: dtaidistance's DTW is the symmetric1 pattern over the squared Euclidean
local cost (it returns the square root of the sum), so ours runs
``step_pattern="symmetric1", local="sqeuclidean"``, and its ``window = r + 1`` is our ``r``.
Timed: ours with path (:func:`~pipeline.align.dtw.dtw`) against
``dtaidistance.dtw_ndim.warping_path(..., use_c=True)``, and our distance only
(:func:`~pipeline.align.dtw.dtw_distance`) against ``dtw_ndim.distance(..., use_c=True)``. The
results are checked equal (distance to 1e-9 relative, paths identical). Numba's compile time
(or cache load) is excluded: one warm-up call of each kernel before timing. Timing: ``--repeat``
rounds, each calling all four interleaved (so both sides see the same load on a shared
machine); process CPU time, median per call. Each ratio is the worse of unwindowed and
windowed. Our default pattern (symmetric2, Euclidean: one square root per cell) is timed too,
for information.

**EM** (:class:`pipeline.align.trajectory.TrajectoryLearner`, issue 15 "Speed"): 5 demos × 1000
samples, 13-D (NED position, velocity, acceleration, attitude quaternion), C = 20, until
convergence or the learner's ``max_iter`` (at these sizes the cap of 30 iterations comes first:
``align_converged`` says which, and ``align_seconds_5x1000`` times those iterations). The demos are a smooth synthetic pull-up-and-turn, each time-warped by τ steps
drawn from d = (0.25, 0.5, 0.25) on the doubled axis, plus white noise. Timed in process CPU
time (one BLAS thread), wall time printed too. Where the learner is not importable (another
branch of issue 15 writes it), this section says so and prints no numbers.

Ends with ``RESULT`` lines.
"""

from __future__ import annotations

import os

# before numpy loads OpenBLAS
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from pipeline.align.dtw import dtw, dtw_distance  # noqa: E402

#: CPU seconds of this process: on a shared machine wall time mostly measures other tenants
CLOCK = time.process_time


def _timed(f):
    t0 = CLOCK()
    out = f()
    return CLOCK() - t0, out


def bench_dtw(n: int, dims: int, window: int | None, repeat: int, rng: np.random.Generator) -> dict:
    from dtaidistance import dtw_ndim

    x = rng.standard_normal((n, dims))
    y = rng.standard_normal((n, dims))
    kw = {} if window is None else {"window": window + 1}
    ours_path = lambda: dtw(x, y, step_pattern="symmetric1", local="sqeuclidean", window=window)  # noqa: E731
    ours_dist = lambda: dtw_distance(x, y, step_pattern="symmetric1", local="sqeuclidean", window=window)  # noqa: E731
    ours_default = lambda: dtw(x, y, window=window)  # noqa: E731
    theirs_path = lambda: dtw_ndim.warping_path(x, y, use_c=True, **kw)  # noqa: E731
    theirs_dist = lambda: dtw_ndim.distance(x, y, use_c=True, **kw)  # noqa: E731
    # warm-up: numba compiles (or loads its cache) on the first call; not timed
    t_compile, _ = _timed(ours_path)
    t_compile2, _ = _timed(ours_dist)
    ours_default()
    theirs_path(), theirs_dist()
    times: dict[str, list[float]] = {k: [] for k in ("ours_path", "theirs_path", "ours_dist", "theirs_dist", "ours_default")}
    res = {}
    for _ in range(repeat):
        for name, f in (("ours_path", ours_path), ("theirs_path", theirs_path), ("ours_dist", ours_dist),
                        ("theirs_dist", theirs_dist), ("ours_default", ours_default)):
            t, res[name] = _timed(f)
            times[name].append(t)
    med = {k: float(np.median(v)) for k, v in times.items()}
    op, tp = res["ours_path"], np.asarray(res["theirs_path"])
    d_ok = (abs(np.sqrt(op.distance) - res["theirs_dist"]) <= 1e-9 * res["theirs_dist"]
            and abs(np.sqrt(res["ours_dist"]) - res["theirs_dist"]) <= 1e-9 * res["theirs_dist"])
    p_ok = tp.shape == op.path.shape and bool((tp == op.path).all())
    med["ok"] = d_ok and p_ok
    med["warmup"] = t_compile + t_compile2
    return med


def synthetic_demos(M: int, N: int, dt: float, rng: np.random.Generator) -> list[np.ndarray]:
    """M noisy, time-warped 13-D demos (position, velocity, acceleration, quaternion w,x,y,z) of
    one smooth pull-up with a turn, N samples at dt."""
    T = 2 * N
    th = np.arange(T + 3 * N) * dt / 2  # the hidden axis, long enough for the slowest warp
    w = 2 * np.pi / (N * dt)
    pos = np.c_[20 * th, 30 * np.sin(w * th), -40 * (1 - np.cos(w * th))]
    vel = np.gradient(pos, dt / 2, axis=0)
    acc = np.gradient(vel, dt / 2, axis=0)
    yaw = np.arctan2(vel[:, 1], vel[:, 0])
    pitch = np.arctan2(-vel[:, 2], np.hypot(vel[:, 0], vel[:, 1]))
    cy, sy, cp, sp = np.cos(yaw / 2), np.sin(yaw / 2), np.cos(pitch / 2), np.sin(pitch / 2)
    quat = np.c_[cy * cp, -sy * sp, cy * sp, sy * cp]  # roll 0: q = q_z(yaw) ⊗ q_y(pitch)
    ref = np.c_[pos, vel, acc, quat]
    sd = np.r_[np.full(3, 0.5), np.full(3, 0.3), np.full(3, 0.5), np.full(4, 0.01)]
    demos = []
    for _ in range(M):
        steps = rng.choice([1, 2, 3], size=N - 1, p=[0.25, 0.5, 0.25])
        tau = np.r_[0, np.cumsum(steps)]
        d = ref[tau] + rng.standard_normal((N, 13)) * sd
        d[:, 9:] /= np.linalg.norm(d[:, 9:], axis=1, keepdims=True)
        demos.append(d)
    return demos


def bench_em(rng: np.random.Generator, M: int = 5, N: int = 1000, C: int = 20, dt: float = 0.1) -> None:
    print("--- trajectory learner (EM) " + "-" * 50)
    try:
        from pipeline.align.trajectory import TrajectoryLearner
    except ImportError as e:
        print(f"align EM timing not available: pipeline.align.trajectory.TrajectoryLearner cannot be "
              f"imported ({e}); no align_seconds_5x1000 / align_iterations RESULT lines")
        return
    demos = synthetic_demos(M, N, dt, rng)
    t0w, t0c = time.perf_counter(), CLOCK()
    learner = TrajectoryLearner(dt=dt, window_C=C).fit(demos)
    wall, cpu = time.perf_counter() - t0w, CLOCK() - t0c
    print(f"{M} demos x {N} samples, 13-D, C = {C}: {cpu:.2f} s CPU ({wall:.2f} s wall), "
          f"{learner.n_iter_} iterations (converged {getattr(learner, 'converged_', '?')}); "
          "single-threaded BLAS; includes any numba compile/cache load inside the learner")
    # CPU time, as the DTW timings: wall time on a shared machine measures the other tenants;
    # with one BLAS thread the two agree on an idle machine
    print(f"RESULT align_seconds_5x1000 {cpu:.3f}")
    print(f"RESULT align_iterations {learner.n_iter_}")
    print(f"RESULT align_converged {int(bool(getattr(learner, 'converged_', False)))}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--dims", type=int, default=9)
    ap.add_argument("--window", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--seed", type=int, default=20261202)
    ap.add_argument("--skip-em", action="store_true", help="DTW only")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)

    print("--- DTW vs dtaidistance (C) " + "-" * 50)
    ok = True
    ratio_path, ratio_dist = [], []
    for w in (None, a.window):
        m = bench_dtw(a.n, a.dims, w, a.repeat, rng)
        ok &= m["ok"]
        ratio_path.append(m["ours_path"] / m["theirs_path"])
        ratio_dist.append(m["ours_dist"] / m["theirs_dist"])
        print(f"{a.n} x {a.n} x {a.dims}-D, window {'none' if w is None else f'r = {w}'}: "
              f"path ours {m['ours_path'] * 1e3:.2f} ms / dtaidistance {m['theirs_path'] * 1e3:.2f} ms "
              f"(ratio {ratio_path[-1]:.2f}); distance ours {m['ours_dist'] * 1e3:.2f} ms / "
              f"dtaidistance {m['theirs_dist'] * 1e3:.2f} ms (ratio {ratio_dist[-1]:.2f}); "
              f"ours symmetric2 + Euclidean with path {m['ours_default'] * 1e3:.2f} ms; "
              f"equal {'ok' if m['ok'] else 'MISMATCH'}; medians of {a.repeat}, CPU time, "
              f"warm-up (numba compile/cache load, excluded) {m['warmup']:.2f} s")
    print(f"RESULT dtw_path_time_ratio_vs_dtaidistance {max(ratio_path):.3f}")
    print(f"RESULT dtw_distance_time_ratio_vs_dtaidistance {max(ratio_dist):.3f}")

    if not a.skip_em:
        bench_em(rng)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
