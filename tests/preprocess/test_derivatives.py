"""Derivatives: smoothing differentiator accuracy and noise rejection (acceptance §5),
body rates from attitude."""

import numpy as np
import pytest

from pipeline.config import load_config
from pipeline.frames.rotations import quat_multiply
from pipeline.preprocess.derivatives import Differentiator, body_rates_from_quat, differentiate
from pipeline.preprocess.state import PreprocessConfig

# a smooth 3-D flight path (m): a turn, a weave and a climb; derivatives in closed form
W = np.array([[0.31, 0.9, 0.12], [0.22, 0.5, 0.7], [0.5, 0.17, 0.33]])  # rad/s per axis, 3 terms
A = np.array([[40.0, 3.0, 10.0], [35.0, 4.0, 2.0], [5.0, 1.5, 3.0]])    # m


def truth(t, k):
    """k-th derivative of the path at times t, shape (n, 3)."""
    out = np.zeros((len(t), 3))
    for ax in range(3):
        for w, a in zip(W[ax], A[ax]):
            # d^k/dt^k sin(w t) = w^k sin(w t + k pi/2)
            out[:, ax] += a * w ** k * np.sin(w * t + k * np.pi / 2 + ax)
    return out


def configured() -> Differentiator:
    return PreprocessConfig.from_config(load_config()).derivatives


def _rms(x):
    return np.sqrt(np.mean(x ** 2, axis=0))


def test_noise_free_truth_at_50hz():
    dt = 0.02
    t = np.arange(0, 120, dt)
    pos = truth(t, 0)
    d = configured()
    acc = differentiate(pos, dt, 2, d)
    jerk = differentiate(pos, dt, 3, d)
    vel = differentiate(pos, dt, 1, d)
    # measured worst axis: 5.4e-5, 8.2e-3, 2.3e-2 (the smoothing's bias grows with the order);
    # a half-sample time shift of the velocity gives 4.7e-3, 25x the velocity bound
    for est, k, tol in ((vel, 1, 2e-4), (acc, 2, 1.2e-2), (jerk, 3, 3e-2)):
        ref = truth(t, k)
        ratio = _rms(est - ref) / _rms(ref)
        assert np.all(ratio <= tol), (k, ratio)


def test_gps_like_noise_configured_beats_finite_differences(rng):
    dt = 0.1
    t = np.arange(0, 300, dt)
    pos = truth(t, 0) + rng.normal(scale=0.5, size=(len(t), 3))
    ref = truth(t, 2)
    err_cfg = _rms(differentiate(pos, dt, 2, configured()) - ref)
    err_fd = _rms(differentiate(pos, dt, 2, Differentiator(method="gradient")) - ref)
    assert np.all(err_fd >= 5.0 * err_cfg), (err_fd, err_cfg)
    # the Butterworth alternative also smooths
    err_bw = _rms(differentiate(pos, dt, 2, Differentiator(method="butter", cutoff_hz=0.5)) - ref)
    assert np.all(err_fd >= 5.0 * err_bw)


def test_gaps_are_respected(rng):
    dt = 0.02
    t = np.arange(0, 20, dt)
    pos = truth(t, 0)
    valid = np.ones(len(t), dtype=bool)
    valid[400:450] = False
    a1 = differentiate(pos, dt, 2, valid=valid)
    pos2 = pos.copy()
    pos2[450:] = rng.normal(size=(len(t) - 450, 3)) * 100
    a2 = differentiate(pos2, dt, 2, valid=valid)
    assert np.isnan(a1[400:450]).all()
    np.testing.assert_array_equal(a1[:400], a2[:400])


def test_short_segment_still_differentiated():
    dt = 0.1
    t = np.arange(5) * dt
    x = 1.0 + 2.0 * t + 3.0 * t ** 2
    np.testing.assert_allclose(differentiate(x, dt, 1), 2.0 + 6.0 * t, atol=1e-9)
    np.testing.assert_allclose(differentiate(x, dt, 2), 6.0, atol=1e-9)


def test_body_rates_from_constant_rate_attitude():
    # q(t) = q0 ⊗ exp(ω t / 2) rotates at constant body rate ω
    dt = 0.04
    t = np.arange(0, 10, dt)
    w = np.array([0.4, -0.7, 1.1])
    ang = np.linalg.norm(w) * t
    ax = w / np.linalg.norm(w)
    dq = np.c_[np.cos(ang / 2), np.sin(ang / 2)[:, None] * ax]
    q0 = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])
    q = quat_multiply(q0, dq)
    q[::3] *= -1  # sign flips as a reader may deliver them
    rates = body_rates_from_quat(q, dt)
    # Savitzky–Golay (1 s, cubic) on sinusoidal quaternion components: 0.1 % bias
    np.testing.assert_allclose(rates, np.broadcast_to(w, rates.shape), rtol=2e-3)


def test_bad_method_rejected():
    with pytest.raises(ValueError, match="derivatives"):
        Differentiator(method="spline")
    with pytest.raises(ValueError, match="unknown key"):
        Differentiator.from_dict({"windw_s": 1})


def test_a_slow_source_interpolated_onto_the_grid_gets_a_window_of_ten_of_its_own_samples(rng):
    # a 2.5 Hz GPS (the Husky's) with 0.5 m noise, linearly interpolated onto the 25 Hz grid
    d = configured()
    assert d.min_source_samples == 10
    assert d.for_source(0.4).window_s == pytest.approx(4.0) and d.for_source(0.1) is d   # 10 Hz: 1 s already
    assert d.for_source(0.04) is d and d.for_source(float("nan")) is d
    assert Differentiator(method="butter").for_source(0.4).method == "butter"
    dt, ts = 0.04, np.arange(0, 300, 0.4)
    t = np.arange(0, 299.6, dt)
    pos = np.stack([np.interp(t, ts, truth(ts, 0)[:, i] + rng.normal(scale=0.5, size=len(ts))) for i in range(3)], 1)
    e1 = _rms(differentiate(pos, dt, 1, d) - truth(t, 1))
    e10 = _rms(differentiate(pos, dt, 1, d.for_source(0.4)) - truth(t, 1))
    a1 = _rms(differentiate(pos, dt, 2, d) - truth(t, 2))
    a10 = _rms(differentiate(pos, dt, 2, d.for_source(0.4)) - truth(t, 2))
    # 2.5 source samples per 1 s window barely smooth; ten of them do (the signal's highest
    # rate, 0.9 rad/s, is slow enough for a 4 s cubic)
    assert np.all(e10 < 0.5 * e1) and np.all(a10 < 0.25 * a1), (e1, e10, a1, a10)
