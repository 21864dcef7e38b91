"""Differentiator study: accuracy on noise-free truth and noise rejection on GPS-like data.

Prints, per method (savgol = the configured default, butter, gradient), the acceleration and
jerk RMS error relative to the RMS truth (50 Hz, noise-free), and the acceleration RMS error
with sigma = 0.5 m position noise at 10 Hz. The truth is the closed-form path of
tests/preprocess/test_derivatives.py. Ends with ``RESULT <name> <value>`` lines.
"""

from __future__ import annotations

import sys

import numpy as np

from pipeline.config import load_config
from pipeline.preprocess.derivatives import Differentiator, differentiate
from pipeline.preprocess.state import PreprocessConfig

W = np.array([[0.31, 0.9, 0.12], [0.22, 0.5, 0.7], [0.5, 0.17, 0.33]])
A = np.array([[40.0, 3.0, 10.0], [35.0, 4.0, 2.0], [5.0, 1.5, 3.0]])


def truth(t, k):
    out = np.zeros((len(t), 3))
    for ax in range(3):
        for w, a in zip(W[ax], A[ax]):
            out[:, ax] += a * w ** k * np.sin(w * t + k * np.pi / 2 + ax)
    return out


def rms(x):
    return float(np.sqrt(np.mean(x ** 2)))


def main(seed: int = 20261123) -> int:
    rng = np.random.default_rng(seed)
    methods = {"savgol": PreprocessConfig.from_config(load_config()).derivatives,
               "butter": Differentiator(method="butter", cutoff_hz=0.5),
               "gradient": Differentiator(method="gradient")}
    t50 = np.arange(0, 120, 0.02)
    p50 = truth(t50, 0)
    t10 = np.arange(0, 300, 0.1)
    p10 = truth(t10, 0) + rng.normal(scale=0.5, size=(len(t10), 3))
    res = {}
    for name, d in methods.items():
        acc = rms(differentiate(p50, 0.02, 2, d) - truth(t50, 2)) / rms(truth(t50, 2))
        jerk = rms(differentiate(p50, 0.02, 3, d) - truth(t50, 3)) / rms(truth(t50, 3))
        noisy = rms(differentiate(p10, 0.1, 2, d) - truth(t10, 2))
        res[name] = (acc, jerk, noisy)
        print(f"{name:9s} acc rel err {acc:.4f}  jerk rel err {jerk:.4f}  noisy acc rms err {noisy:.3f} m/s^2")
    print(f"RESULT savgol_acc_rel_err {res['savgol'][0]:.5f}")
    print(f"RESULT savgol_jerk_rel_err {res['savgol'][1]:.5f}")
    print(f"RESULT savgol_noisy_acc_rms_mps2 {res['savgol'][2]:.4f}")
    print(f"RESULT gradient_noisy_acc_rms_mps2 {res['gradient'][2]:.4f}")
    print(f"RESULT noise_rejection_ratio {res['gradient'][2] / res['savgol'][2]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
