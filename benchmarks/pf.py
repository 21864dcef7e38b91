"""Particle-filter speed (issue 17): our kernels against Stone Soup's particle filter, one run.

Two problems, both at ``--n`` particles (default 10⁵) with one 2-D position measurement a step:

1. **CV bootstrap.** One particle step = predict (CV, white acceleration), the likelihood of one
   2-D position measurement, weight normalisation and systematic resampling. Ours:
   :func:`pipeline.estimate.pf_fast.cv_bootstrap_run` (fused numba kernels + numpy's SIMD exp);
   also the generic :class:`pipeline.estimate.pf.ParticleFilter` (numpy, every-step systematic).
   Stone Soup: ``ParticlePredictor`` + ``ParticleUpdater`` with ``SystematicResampler``.
   ``RESULT pf_particle_steps_per_s`` is ours (fast path).
2. **5-mode jump-Markov** (seed 001 §7: STOP, ACCEL, DECEL, COAST, TURN with Π_p of Table 6.1
   at 40 Hz; STOP/COAST → CV, ACCEL/DECEL → CA, TURN → CT, digest D4). Ours:
   :func:`pipeline.estimate.pf_fast.jm_run` (and the generic filter); Stone Soup:
   ``MultiModelPredictor`` + ``MultiModelParticleUpdater`` with ``SystematicResampler``, its
   models mapped into a 6-D [x, vx, ax, y, vy, ay] state. ``RESULT pf_speedup_vs_stonesoup`` is
   Stone Soup's time per step over ours (fast path).

Timing: process CPU time (``time.process_time``; on a shared machine wall time mostly measures
the other tenants), after a warm-up step (numba compiles/caches), ``--repeat`` interleaved
rounds, medians. Threads: numba's pool is set to ``--threads`` (default 1) and BLAS to one
thread, so the CPU time is the work done; ``RESULT pf_threads`` says what was used. The models
of the two sides are of the same kind and size, not draw-for-draw identical (Stone Soup's
noise is the continuous white-noise-acceleration Q, ours the piecewise-constant one), except the
turn: Stone Soup has no particle model with a turn-rate state, so its TURN mode is
``KnownTurnRate`` at a fixed 10 deg/s in the 6-D state, while ours is the 7-D augmented
coordinated turn with its own ω and σ_ω: ours does more work per particle, so the jump-Markov
ratio understates ours. Stone Soup is timed over ``--ss-steps`` (4) steps, ours over ``--steps``
(20), both as time per step. Outputs are checked: each filter's final position must lie within
3σ_z of the straight-line truth, and ours and Stone Soup's CV means on the same steps within
0.5 m of each other (``RESULT pf_outputs_checked``; exit 1 otherwise).
"""

from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import datetime as _dt  # noqa: E402
import time  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.estimate import pf_fast  # noqa: E402
from pipeline.estimate.markov import retime  # noqa: E402
from pipeline.estimate.models import (PfAugmentedCoordinatedTurn, PfConstantAcceleration,  # noqa: E402
                                      PfConstantVelocity)
from pipeline.estimate.pf import GaussianPositionLikelihood, ParticleFilter  # noqa: E402

CLOCK = time.process_time
DT = 0.025  # 40 Hz (seed 001)
SIG_A, SIG_J, SIG_W, SIG_Z = 0.5, 0.5, 0.05, 2.0
#: Π_p (seed 001 Table 6.1), order STOP, ACCEL, DECEL, COAST, TURN
PI_P = np.array([[0.990, 0.010, 0.000, 0.000, 0.000],
                 [0.000, 0.986, 0.004, 0.008, 0.002],
                 [0.006, 0.002, 0.984, 0.004, 0.004],
                 [0.000, 0.004, 0.004, 0.990, 0.002],
                 [0.000, 0.006, 0.002, 0.004, 0.988]])
KINDS = [pf_fast.KIND_CV, pf_fast.KIND_CA, pf_fast.KIND_CA, pf_fast.KIND_CV, pf_fast.KIND_CT]
SIGMA = [0.05, SIG_J, SIG_J, SIG_A, SIG_A]
SIGMA_W = [0.0, 0.0, 0.0, 0.0, SIG_W]
ENTER = [0.0, 2.0, 2.0, 0.0, 0.1]


def measurements(steps: int) -> np.ndarray:
    rng = np.random.default_rng(11)
    t = np.arange(steps + 1) * DT
    return np.c_[3.0 * t, -1.0 * t] + SIG_Z * rng.standard_normal((steps + 1, 2))


def jm_models():
    return [PfConstantVelocity(0.05), PfConstantAcceleration(SIG_J, 2.0), PfConstantAcceleration(SIG_J, 2.0),
            PfConstantVelocity(SIG_A), PfAugmentedCoordinatedTurn(SIG_A, SIG_W, omega_init_sigma=0.1)]


# --- ours ---------------------------------------------------------------------------------------

def ours_cv_fast(x0, z, seed):
    t = CLOCK()
    mean, _ = pf_fast.cv_bootstrap_run(x0, z, DT, SIG_A, SIG_Z, seed)
    return (CLOCK() - t) / len(z), np.asarray(mean[-1, :2])


def ours_generic(models, Pi, x0, modes, z, seed):
    pf = ParticleFilter(models, Pi, GaussianPositionLikelihood(SIG_Z), n_particles=len(x0),
                        every_step=True, rng=seed)
    pf.init(x0, modes=modes)
    t = CLOCK()
    for zk in z:
        pf.step(DT, zk)
    return (CLOCK() - t) / len(z)


def ours_jm_fast(x0, modes, z, seed):
    t = CLOCK()
    mean = pf_fast.jm_run(x0, modes, z, DT, PI_P, KINDS, SIGMA, SIGMA_W, ENTER, SIG_Z, seed)[0]
    return (CLOCK() - t) / len(z), np.asarray(mean[-1, :2])


# --- Stone Soup -----------------------------------------------------------------------------------

def stonesoup_cv(x0, z, seed):
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (CombinedLinearGaussianTransitionModel,
                                                    ConstantVelocity)
    from stonesoup.predictor.particle import ParticlePredictor
    from stonesoup.resampler.particle import SystematicResampler
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import ParticleState, StateVectors
    from stonesoup.updater.particle import ParticleUpdater

    np.random.seed(seed)  # Stone Soup draws from numpy's global generator
    n = len(x0)
    cv = CombinedLinearGaussianTransitionModel([ConstantVelocity(SIG_A ** 2)] * 2)
    mm = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=SIG_Z ** 2 * np.eye(2))
    pred, upd = ParticlePredictor(cv), ParticleUpdater(mm, resampler=SystematicResampler())
    t0 = _dt.datetime(2026, 1, 1)
    sv = StateVectors(x0[:, [0, 2, 1, 3]].T.copy())
    st = ParticleState(sv, log_weight=np.full(n, -np.log(n)), timestamp=t0)
    t = CLOCK()
    for k, zk in enumerate(z, start=1):
        ts = t0 + _dt.timedelta(seconds=DT * k)
        p = pred.predict(st, timestamp=ts)
        st = upd.update(SingleHypothesis(p, Detection(zk.reshape(2, 1), timestamp=ts, measurement_model=mm)))
    return (CLOCK() - t) / len(z), np.asarray(st.mean, dtype=float).ravel()[[0, 2]]


def stonesoup_jm(x0, modes, z, seed):
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (CombinedLinearGaussianTransitionModel,
                                                    ConstantAcceleration, ConstantVelocity,
                                                    KnownTurnRate)
    from stonesoup.predictor.particle import MultiModelPredictor
    from stonesoup.resampler.particle import SystematicResampler
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import MultiModelParticleState, StateVectors
    from stonesoup.updater.particle import MultiModelParticleUpdater

    np.random.seed(seed)
    n = len(x0)
    stop = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.05 ** 2)] * 2)
    cv = CombinedLinearGaussianTransitionModel([ConstantVelocity(SIG_A ** 2)] * 2)
    ca = CombinedLinearGaussianTransitionModel([ConstantAcceleration(SIG_J ** 2)] * 2)
    ct = KnownTurnRate((SIG_A ** 2, SIG_A ** 2), np.radians(10.0))
    pos_vel, full = (0, 1, 3, 4), (0, 1, 2, 3, 4, 5)
    mp = MultiModelPredictor(transition_models=[stop, ca, ca, cv, ct], transition_matrix=PI_P,
                             model_mappings=[pos_vel, full, full, pos_vel, pos_vel])
    mm = LinearGaussian(ndim_state=6, mapping=(0, 3), noise_covar=SIG_Z ** 2 * np.eye(2))
    upd = MultiModelParticleUpdater(measurement_model=mm, predictor=mp, resampler=SystematicResampler())
    t0 = _dt.datetime(2026, 1, 1)
    sv = StateVectors(x0[:, [0, 2, 5, 1, 3, 6]].T.copy())
    st = MultiModelParticleState(sv, log_weight=np.full(n, -np.log(n)), dynamic_model=modes.copy(), timestamp=t0)
    t = CLOCK()
    for k, zk in enumerate(z, start=1):
        ts = t0 + _dt.timedelta(seconds=DT * k)
        p = mp.predict(st, timestamp=ts)
        st = upd.update(SingleHypothesis(p, Detection(zk.reshape(2, 1), timestamp=ts, measurement_model=mm)))
    return (CLOCK() - t) / len(z), np.asarray(st.mean, dtype=float).ravel()[[0, 3]]


def truth_at(k: int) -> np.ndarray:
    """The straight-line truth of :func:`measurements` at step ``k``."""
    return np.array([3.0, -1.0]) * DT * k


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="particles")
    ap.add_argument("--steps", type=int, default=20, help="steps per timed run (ours)")
    ap.add_argument("--ss-steps", type=int, default=4, help="steps per timed run (Stone Soup)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1, help="numba threads")
    ap.add_argument("--no-generic", action="store_true", help="skip the generic numpy filter")
    a = ap.parse_args(argv)
    numba.set_num_threads(a.threads)
    rng = np.random.default_rng(0)
    x0 = np.zeros((a.n, 7))
    x0[:, :4] = rng.standard_normal((a.n, 4)) * [2.0, 2.0, 1.0, 1.0] + [0.0, 0.0, 3.0, -1.0]
    modes = rng.integers(0, 5, a.n)
    z = measurements(a.steps)[1:]
    zs = z[: a.ss_steps]
    Pi_dt = retime(PI_P, DT, DT)
    # warm-up: numba compile / cache load, Stone Soup imports
    pf_fast.cv_bootstrap_run(x0[:64, :4], z[:2], DT, SIG_A, SIG_Z, 0)
    pf_fast.jm_run(x0[:64], modes[:64], z[:2], DT, Pi_dt, KINDS, SIGMA, SIGMA_W, ENTER, SIG_Z, 0)
    stonesoup_cv(x0[:64, :4], z[:1], 0)
    stonesoup_jm(x0[:64], modes[:64], z[:1], 0)
    t = {k: [] for k in ("cv", "cv_generic", "cv_ss", "jm", "jm_generic", "jm_ss")}
    last = {}
    for r in range(a.repeat):
        for key, (dt_step, pos) in (("cv", ours_cv_fast(x0[:, :4], z, r)), ("cv_ss", stonesoup_cv(x0[:, :4], zs, r)),
                                    ("jm", ours_jm_fast(x0, modes, z, r)),
                                    ("jm_ss", stonesoup_jm(x0, modes, zs, r))):
            t[key].append(dt_step)
            last[key] = pos
        if not a.no_generic:
            t["cv_generic"].append(ours_generic([PfConstantVelocity(SIG_A)], None, x0[:, :4], 0, zs, r))
            t["jm_generic"].append(ours_generic(jm_models(), PI_P, x0, modes, zs, r))
    med = {k: float(np.median(v)) for k, v in t.items() if v}
    # both sides must track the same straight line: the ratio is of filters doing the work, and
    # on the same 4 steps ours and Stone Soup's CV means must agree (the models are the same
    # kind; only the noise discretisation and the draws differ)
    err = {k: float(np.hypot(*(p - truth_at(a.steps if k in ("cv", "jm") else a.ss_steps)))) for k, p in last.items()}
    cv_same = float(np.hypot(*(ours_cv_fast(x0[:, :4], zs, 0)[1] - last["cv_ss"])))
    for k, e in err.items():
        print(f"# {k}: final position error {e:.2f} m (measurement sigma {SIG_Z} m)")
    print(f"# cv: ours vs Stone Soup on the same {a.ss_steps} steps: means {cv_same:.3f} m apart")
    ok = all(e < 3 * SIG_Z for e in err.values()) and cv_same < 0.5
    for k, v in med.items():
        print(f"# {k}: {v * 1e3:.2f} ms/step ({a.n / v:.3g} particle steps/s)")
    print(f"RESULT pf_particle_steps_per_s {a.n / med['cv']:.4g}")
    print(f"RESULT pf_stonesoup_particle_steps_per_s {a.n / med['cv_ss']:.4g}")
    print(f"RESULT pf_cv_speedup_vs_stonesoup {med['cv_ss'] / med['cv']:.3g}")
    print(f"RESULT pf_jm_particle_steps_per_s {a.n / med['jm']:.4g}")
    print(f"RESULT pf_speedup_vs_stonesoup {med['jm_ss'] / med['jm']:.3g}")
    if "jm_generic" in med:
        print(f"RESULT pf_generic_particle_steps_per_s {a.n / med['cv_generic']:.4g}")
        print(f"RESULT pf_generic_jm_speedup_vs_stonesoup {med['jm_ss'] / med['jm_generic']:.3g}")
    print(f"RESULT pf_threads {a.threads}")
    print(f"RESULT pf_outputs_checked {int(ok)}")
    if not ok:
        print("pf: a filter did not track the line (final error >= 3 sigma) or the two CV filters disagree "
              "(> 0.5 m): the speed-ups are not of the same work", file=__import__("sys").stderr)
        return 1
    print(f"RESULT pf_n_particles {a.n}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
