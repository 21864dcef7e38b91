"""Online classification throughput: vectorised forward pass vs re-scoring the prefix.

Four full-covariance Gaussian HMMs on 9-D features (5, 6, 6, 6 states, as seed 000's
λ1–λ4) score 1000 runs of 124 samples (one 25 s maneuver at 5 Hz, differenced) with
:class:`pipeline.models.online.OnlineClassifier` — one O(n_states²) update per model, run and
sample, vectorised across models and runs. The baseline is what a naive online classifier
does: call hmmlearn's ``score`` on the whole prefix ``O_{1:t}`` of every model at every sample
(O(t) work per sample). The baseline is timed on a subset of runs (it is ~10⁴× slower) and
both are reported in samples per second; the speed-up is their ratio. Each side is timed
``--repeat`` times after a warm-up call and its best kept (wall clock). Both paths' final
log-likelihoods are checked to agree to 1e-8 relative.

Usage: ``python benchmarks/classify.py [--runs 1000] [--prefix-runs 2] [--seed 0] [--repeat 3]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from hmmlearn import hmm

from pipeline.models.hmm import HMMParams
from pipeline.models.online import OnlineClassifier, classify_batch


def random_model(rng, S, d, seed):
    m = hmm.GaussianHMM(n_components=S, covariance_type="full", init_params="", random_state=seed)
    m.startprob_ = rng.dirichlet(np.ones(S))
    A = np.eye(S) * 0.8 + rng.dirichlet(np.ones(S), size=S) * 0.2
    m.transmat_ = A / A.sum(1, keepdims=True)
    m.means_ = rng.normal(size=(S, d))
    L = rng.normal(size=(S, d, d)) * 0.2
    m.covars_ = L @ L.transpose(0, 2, 1) + 0.1 * np.eye(d)
    m.n_features = d
    return m


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=124)
    ap.add_argument("--prefix-runs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3, help="timed calls per side, the best kept (after a warm-up)")
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    d = 9
    models = [random_model(rng, S, d, k) for k, S in enumerate((5, 6, 6, 6))]
    X = np.stack([models[r % 4].sample(args.samples, random_state=int(rng.integers(1 << 30)))[0]
                  for r in range(args.runs)])
    params = [HMMParams.from_hmmlearn(m) for m in models]

    clf = OnlineClassifier(params, mode="cumulative")
    # best of --repeat after one warm-up call (the first is ~20 % slower: allocation, caches)
    classify_batch(clf, X[: min(10, args.runs)])
    t_vec = float("inf")
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        res = classify_batch(clf, X)
        t_vec = min(t_vec, time.perf_counter() - t0)
    rate_vec = args.runs * args.samples / t_vec

    n_pre = min(args.prefix_runs, args.runs)
    models[0].score(X[0, :2])  # warm-up of the baseline too
    t_pre = float("inf")
    last = np.empty((n_pre, 4))
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        for r in range(n_pre):
            for t in range(1, args.samples + 1):
                for j, m in enumerate(models):
                    last[r, j] = m.score(X[r, :t])
        t_pre = min(t_pre, time.perf_counter() - t0)
    rate_pre = n_pre * args.samples / t_pre

    rel = np.max(np.abs(res["scores"][:n_pre, -1] - last) / np.abs(last))
    acc = np.mean(res["best"][:, -1] == np.arange(args.runs) % 4)
    print(f"vectorised online forward: {args.runs} runs x {args.samples} samples x 4 models "
          f"in {t_vec:.3f} s ({rate_vec:,.0f} samples/s)")
    print(f"prefix re-scoring (hmmlearn score per sample, {n_pre} runs): {t_pre:.3f} s "
          f"({rate_pre:,.1f} samples/s)")
    print(f"max relative LL difference at t=T: {rel:.2e}; final argmax accuracy {acc:.3f}")
    assert rel < 1e-8
    print(f"RESULT classify_samples_per_s {rate_vec:.0f}")
    print(f"RESULT prefix_rescoring_samples_per_s {rate_pre:.2f}")
    print(f"RESULT classify_speedup_vs_prefix_rescoring {rate_vec / rate_pre:.0f}")


if __name__ == "__main__":
    main()
