"""tracking.butterworth against scipy.signal's butter and filtfilt, which it replaces (to rounding)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import butter, filtfilt

from ibik_pin.tracking.butterworth import design_lowpass, zero_lag_lowpass


@pytest.mark.parametrize("cutoff", [0.01, 0.05, 0.2, 0.5, 0.9, 0.99])
def test_the_design_is_scipys_second_order_butterworth(cutoff):
    b, a = design_lowpass(cutoff)
    expected_b, expected_a = butter(2, cutoff)
    np.testing.assert_allclose(b, expected_b, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(a, expected_a, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(("frames", "pad"), [(8, 7), (9, 3), (40, 9), (100, 0), (300, 60)])
@pytest.mark.parametrize("cutoff", [0.05, 0.3, 0.95])
def test_forward_and_backward_is_scipys_filtfilt_with_odd_padding(frames, pad, cutoff):
    signal = np.cumsum(np.random.default_rng(frames).normal(size=(frames, 5)), axis=0)
    b, a = design_lowpass(cutoff)
    expected = filtfilt(b, a, signal, axis=0, padlen=pad)
    np.testing.assert_allclose(zero_lag_lowpass(b, a, signal, pad), expected, rtol=0,
                               atol=1e-12 * np.abs(expected).max())


def test_a_constant_passes_unchanged_and_a_line_nearly_so():
    b, a = design_lowpass(0.2)
    np.testing.assert_allclose(zero_lag_lowpass(b, a, np.full((30, 2), 3.5), 10), 3.5, rtol=0, atol=1e-12)
    # Odd reflection continues a line through its ends; what is left is the start from a constant's
    # steady state, decayed over the padding (6e-6 of the line's rise here).
    line = np.linspace(0.0, 1.0, 50)[:, None]
    np.testing.assert_allclose(zero_lag_lowpass(b, a, line, 20), line, rtol=0, atol=1e-4)


@pytest.mark.parametrize("cutoff", [0.0, 1.0, -0.1])
def test_a_cutoff_outside_the_band_is_refused(cutoff):
    with pytest.raises(ValueError, match="cutoff"):
        design_lowpass(cutoff)


def test_a_pad_as_long_as_the_signal_is_refused():
    with pytest.raises(ValueError, match="pad"):
        zero_lag_lowpass(*design_lowpass(0.5), np.zeros((5, 1)), 5)
