"""Butterworth filtering: gap isolation, causality, zero phase, short segments (acceptance §2)."""

import numpy as np
import pytest
from scipy import signal

from pipeline.preprocess.filters import butter_sos, butterworth, padlen

FS = 25.0


def _gapped(rng, n=600, gap=(250, 260)):
    x = np.cumsum(rng.normal(size=n)) * 0.1
    valid = np.ones(n, dtype=bool)
    valid[gap[0]:gap[1]] = False
    return x, valid


@pytest.mark.parametrize("causal", [False, True])
def test_other_side_of_gap_does_not_leak(rng, causal):
    x, valid = _gapped(rng)
    y1, _ = butterworth(x, FS, order=3, cutoff_hz=1.0, causal=causal, valid=valid)
    x2 = x.copy()
    x2[260:] = rng.normal(scale=50.0, size=len(x) - 260)  # right side replaced by random values
    y2, _ = butterworth(x2, FS, order=3, cutoff_hz=1.0, causal=causal, valid=valid)
    assert np.array_equal(y1[:250], y2[:250])  # bit-identical left of the gap
    x3 = x.copy()
    x3[:250] = rng.normal(scale=50.0, size=250)
    y3, _ = butterworth(x3, FS, order=3, cutoff_hz=1.0, causal=causal, valid=valid)
    assert np.array_equal(y1[260:], y3[260:])
    assert np.all(np.isnan(y1[250:260]))
    # and the filter did something (not a pass-through)
    assert np.max(np.abs(y1[:250] - x[:250])) > 1e-3


def test_nan_samples_split_segments_like_gaps(rng):
    x, _ = _gapped(rng)
    x[300] = np.nan
    y, _ = butterworth(x, FS)
    x2 = x.copy()
    x2[301:] = 0.0
    y2, _ = butterworth(x2, FS)
    assert np.array_equal(y[:300], y2[:300]) and np.isnan(y[300])


def test_causal_output_independent_of_future(rng):
    x = rng.normal(size=500)
    y, _ = butterworth(x, FS, causal=True)
    for k in (10, 200, 499):
        x2 = x.copy()
        x2[k:] = rng.normal(size=500 - k) * 7
        y2, _ = butterworth(x2, FS, causal=True)
        assert np.array_equal(y[:k], y2[:k])
    # the zero-phase filter does look ahead (so the causal test above can fail)
    z, _ = butterworth(x, FS)
    x2 = x.copy()
    x2[200:] += 10
    z2, _ = butterworth(x2, FS)
    assert not np.array_equal(z[:200], z2[:200])


def test_causal_matches_scipy_lfilter_steady_state(rng):
    x = rng.normal(size=300) + 4.0
    sos = butter_sos(3, 1.0, FS)
    ref = signal.sosfilt(sos, x, zi=signal.sosfilt_zi(sos) * x[0])[0]
    y, _ = butterworth(x, FS, causal=True)
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12)


def test_zero_phase_step_has_no_group_delay():
    n, k0 = 400, 200
    x = np.zeros(n)
    x[k0:] = 1.0
    y, _ = butterworth(x, FS, order=3, cutoff_hz=1.0)
    # 50 % crossing of the filtered step lies within one sample of the step (between k0-1 and k0)
    cross = np.flatnonzero(y >= 0.5)[0]
    assert abs(cross - (k0 - 0.5)) <= 1.0
    # the causal filter delays it by several samples (group delay ≈ 0.3 s at 1 Hz, 3rd order)
    yc, _ = butterworth(x, FS, order=3, cutoff_hz=1.0, causal=True)
    assert np.flatnonzero(yc >= 0.5)[0] - k0 >= 5


def test_zero_phase_gain_is_squared_butterworth():
    # |H|^2 at the cut-off is 1/2 for a Butterworth, so a forward-backward pass gives 1/2 there
    t = np.arange(0, 200, 1 / FS)
    for f, g in ((1.0, 0.5), (0.1, 1.0)):
        y, _ = butterworth(np.sin(2 * np.pi * f * t), FS, order=3, cutoff_hz=1.0)
        mid = slice(len(t) // 4, 3 * len(t) // 4)
        amp = np.sqrt(2 * np.mean(y[mid] ** 2))
        assert amp == pytest.approx(g, abs=0.01)


def test_short_segment_flagged_not_filtered(rng):
    sos = butter_sos(3, 1.0, FS)
    pl = padlen(sos)
    x = rng.normal(size=200)
    valid = np.ones(200, dtype=bool)
    valid[50] = False
    valid[50 + pl + 1] = False  # segment of exactly pl samples between the two holes
    y, short = butterworth(x, FS, valid=valid)
    seg = slice(51, 51 + pl)
    assert short[seg].all() and short.sum() == pl
    assert np.array_equal(y[seg], x[seg])
    assert not np.allclose(y[:50], x[:50])


@pytest.mark.parametrize("kw", [{"cutoff_hz": 13.0}, {"cutoff_hz": 0.0}, {"order": 0}])
def test_bad_parameters_raise(kw):
    with pytest.raises(ValueError, match="Butterworth"):
        butterworth(np.zeros(100), FS, **{"order": 3, "cutoff_hz": 1.0, **kw})
