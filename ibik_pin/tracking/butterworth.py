"""A 2nd-order Butterworth low-pass, run forward and backward (zero lag), on (F, C) arrays.

The same filter as scipy.signal's butter(2, cutoff) and filtfilt(..., padtype="odd") (equal to
rounding: tests/test_target_filter.py compares them), written here because importing scipy.signal
took 0.7 s of every `ibik` command's 2 s of imports, for these two functions (measured on this
package's imports, docs/method.md).

- The design: the analog prototype 1 / (s^2 + sqrt(2) s + 1), its cutoff prewarped, through the
  bilinear transform (normalised so that a[0] = 1).
- Each pass: the transposed direct form II, started in the steady state of the signal's first
  value (scipy's lfilter_zi scaled by it), over the signal extended at both ends by odd reflection
  (2 x[0] - x[k]), so that the ends start and stop without a transient.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["design_lowpass", "zero_lag_lowpass"]


def design_lowpass(cutoff: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the 2nd-order Butterworth low-pass whose -3 dB point is `cutoff` (a fraction of the
    Nyquist frequency, in (0, 1))."""
    if not 0.0 < cutoff < 1.0:
        raise ValueError(f"cutoff: expected a fraction of the Nyquist frequency in (0, 1), got {cutoff!r}")
    warped = math.tan(0.5 * math.pi * cutoff)
    square = warped * warped
    norm = 1.0 / (1.0 + math.sqrt(2.0) * warped + square)
    b = np.array([square, 2.0 * square, square]) * norm
    a = np.array([1.0, 2.0 * (square - 1.0) * norm, (1.0 - math.sqrt(2.0) * warped + square) * norm])
    return b, a


def _steady_state(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The filter's state (2,) after a unit step has settled (lfilter_zi for a 2nd-order section)."""
    coupling = np.array([[1.0 + a[1], -1.0], [a[2], 1.0]])
    return np.linalg.solve(coupling, b[1:] - a[1:] * b[0])


@njit(cache=True, nogil=True)
def _one_pass(b: np.ndarray, a: np.ndarray, signal: np.ndarray, state: np.ndarray) -> np.ndarray:
    """The (N, C) signal filtered along its rows from `state` (2, C) (transposed direct form II)."""
    out = np.empty_like(signal)
    first = state[0].copy()
    second = state[1].copy()
    for n in range(signal.shape[0]):
        for c in range(signal.shape[1]):
            x = signal[n, c]
            y = b[0] * x + first[c]
            first[c] = b[1] * x - a[1] * y + second[c]
            second[c] = b[2] * x - a[2] * y
            out[n, c] = y
    return out


def zero_lag_lowpass(b: np.ndarray, a: np.ndarray, signal: np.ndarray, pad: int) -> np.ndarray:
    """The (N, C) signal (finite, N > pad >= 0) filtered forward, then backward, along its rows,
    extended by `pad` frames of odd reflection at each end (scipy's filtfilt with padtype="odd")."""
    signal = np.asarray(signal, dtype=float)
    if not 0 <= pad < signal.shape[0]:
        raise ValueError(f"pad: expected 0 to {signal.shape[0] - 1} frames, got {pad}")
    if pad:
        signal = np.concatenate((2.0 * signal[0] - signal[pad:0:-1], signal,
                                 2.0 * signal[-1] - signal[-2:-pad - 2:-1]))
    steady = _steady_state(b, a)[:, None]
    forward = _one_pass(b, a, np.ascontiguousarray(signal), steady * signal[0])
    backward = _one_pass(b, a, np.ascontiguousarray(forward[::-1]), steady * forward[-1])[::-1]
    return backward[pad:backward.shape[0] - pad]
