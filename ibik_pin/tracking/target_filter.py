"""A zero-lag low-pass filter of the targets over time, its cutoff chosen per keypoint from the trial.

Keypoints from motion capture or from triangulated video carry noise from frame to frame, while
human joints move smoothly: most of the power of joint positions in gait lies below about 6 Hz
(Winter, Biomechanics and Motor Control of Human Movement, ch. 2). The tracker meets its targets
exactly at the top priority, so every millimetre of target noise goes into the joints.

The filter is a Butterworth low-pass run forward and backward (tracking.butterworth: no lag; a
2nd-order design twice is a 4th-order response, the biomechanics convention and Pose2Sim's default
filter's order). Its nominal cutoff is corrected for the two passes (Winter: the cutoff of the
design is the wanted -3 dB frequency over (2^(1/passes) - 1)^(1/(2 order))), so that the reported
cutoff is the response's.

The cutoff of each keypoint comes from the residual analysis (Winter's): the residual R(fc)
between the raw and the filtered positions, against the cutoff fc. At high cutoffs only noise is
left to remove: for white noise of variance s^2 per coordinate, R^2 falls along a straight line,
s^2 (1 - fc / f_Nyquist); the line fitted there gives the noise's variance at 0 Hz and the noise
power each hertz of cutoff lets through (minus its slope). Winter takes the cutoff where R meets
the noise's rms; measured on smooth signals with 2-10 mm of noise at 30 and 120 Hz, that cut real
motion (3 Hz components) and left the error above the raw targets'. Here the cutoff minimises the
estimated error instead: the signal removed (R^2 less the noise removed, read off the line) plus
the noise kept (the line's slope times the cutoff), i.e. the minimum of R^2(fc) - 2 slope fc. A
fast motion (a punch) keeps R high up to high cutoffs, so its cutoff rises with it; a noise-free
or already filtered keypoint has a flat noise line, so its cutoff is high and the filter changes it
by a fraction of a millimetre.

The noise line needs cutoffs above the motion's own band: above MOTION_BAND_HZ (6 Hz, Winter's
gait figure) and half the Nyquist frequency. Below about 21 Hz no such band of 2 Hz is left, and
"auto" leaves the targets as they are (report.json says why): at 15 Hz the analysis read a noise-
free walk's footfalls as noise and moved its toes by 16 mm rms.

Missing values (NaN) stay missing. A gap shorter than MAX_BRIDGE_S is bridged by a straight line
for the filter (a dropped frame then moves its neighbours by millimetres, where splitting the track
there moved them by up to 31 mm at 15 Hz); longer gaps split the track into runs, each filtered on
its own (padded by odd reflection, scipy's filtfilt's default, up to two periods of the cutoff); runs too
short to tell motion from noise are left as they are.

A leap is not noise, nor motion: a frame where a keypoint lies farther from the median of the 5
frames around it than it can move in a frame (LEAP_SPEED_M_S over the frame rate) and than
LEAP_FACTOR times the track's median such distance is kept as it is, and the filter reads it as
the line between its neighbours, so that a glitch is neither smeared into its neighbours nor
hidden from the run's self-diagnosis (a frame whose leg targets leap 0.8 m is still flagged there).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ibik_pin.exceptions import InputError
from ibik_pin.tracking.butterworth import design_lowpass, zero_lag_lowpass

__all__ = ["TARGET_FILTER_MODES", "KeypointFilter", "TargetFilterResult", "filter_targets", "lowpass",
           "leaps", "noise_band", "parse_target_filter", "residual_curve", "residual_cutoff"]

TARGET_FILTER_MODES = ("off", "auto")
ORDER = 2  # per pass (tracking.butterworth's); forward and backward make a 4th-order zero-lag response
PASSES = 2
# The design's cutoff is the response's over this factor (Winter's correction for the passes).
PASS_CORRECTION = (2.0 ** (1.0 / PASSES) - 1.0) ** (1.0 / (2 * ORDER))
# Candidate cutoffs span up to this fraction of the Nyquist frequency (the design's own cutoff,
# corrected, stays below Nyquist); the noise line is fitted over the upper part.
HIGHEST_CUTOFF = 0.75
NOISE_LINE_FROM = 0.5
LOWEST_CUTOFF_HZ = 0.5
CUTOFF_STEP_HZ = 0.1
# Shorter runs of valid frames are left unfiltered: too few frames to tell motion from noise.
MIN_RUN_FRAMES = 8
# Gaps shorter than this [s] are bridged for the filter (module docstring).
MAX_BRIDGE_S = 0.5
# The noise line is fitted above the motion's band (Winter: most of gait's power below 6 Hz) and
# needs a band at least this wide [Hz] there.
MOTION_BAND_HZ = 6.0
MIN_NOISE_BAND_HZ = 2.0
# A leap (module docstring): farther from its 5-frame running median than this many times the
# track's median such distance, and than a keypoint moves in one frame at this speed [m/s]: about
# the fist's in a straight punch (9.1 m/s for Olympic boxers, Walilko, Viano and Bir, Br J Sports
# Med 2005), as fast as a body part moves outside throwing; a reversal within a frame at that speed
# departs from the running median by less than a frame's travel.
LEAP_FACTOR = 10.0
LEAP_SPEED_M_S = 10.0


def parse_target_filter(value: str | float | int) -> str | float:
    """"off", "auto" or a cutoff in Hz (a positive number, or a string of one); InputError otherwise."""
    if isinstance(value, str):
        text = value.strip().lower()
        if text in TARGET_FILTER_MODES:
            return text
        try:
            value = float(text.removesuffix("hz"))
        except ValueError:
            raise InputError(f"target_filter: expected off, auto or a cutoff in Hz, found {value!r}",
                             parameter="target_filter") from None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        raise InputError(f"target_filter: expected off, auto or a positive cutoff in Hz, found {value!r}",
                         parameter="target_filter")
    return float(value)


def _runs(valid: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of True in a 1-D bool array."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], valid.astype(np.int8), [0]))))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def lowpass(signal: np.ndarray, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    """The (F, C) signal filtered at `cutoff_hz` (the zero-lag response's -3 dB point), each run of
    frames whose C values are all finite on its own; other frames and short runs unchanged."""
    signal = np.asarray(signal, dtype=float)
    nyquist = 0.5 * rate_hz
    design = min(cutoff_hz / PASS_CORRECTION, 0.99 * nyquist)
    b, a = design_lowpass(design / nyquist)
    valid = np.all(np.isfinite(signal), axis=1)
    bridged = _bridged(signal, _short_gaps(valid, int(MAX_BRIDGE_S * rate_hz)))
    out = bridged.copy()
    pad_frames = int(np.ceil(2.0 * rate_hz / cutoff_hz))
    for start, stop in _runs(np.all(np.isfinite(bridged), axis=1)):
        if stop - start >= MIN_RUN_FRAMES:
            out[start:stop] = zero_lag_lowpass(b, a, bridged[start:stop],
                                               min(stop - start - 1, max(3 * (ORDER + 1), pad_frames)))
    out[~valid] = signal[~valid]
    return out


def _short_gaps(valid: np.ndarray, longest: int) -> np.ndarray:
    """(F,) bool: the missing frames of interior gaps of at most `longest` frames."""
    short = np.zeros_like(valid)
    for start, stop in _runs(~valid):
        if start > 0 and stop < len(valid) and stop - start <= longest:
            short[start:stop] = True
    return short


def noise_band(rate_hz: float) -> tuple[float, float] | None:
    """The cutoffs [Hz] the noise line is fitted over at this frame rate, or None when no band of
    MIN_NOISE_BAND_HZ lies above the motion's (module docstring)."""
    low = max(NOISE_LINE_FROM * 0.5 * rate_hz, MOTION_BAND_HZ)
    high = HIGHEST_CUTOFF * 0.5 * rate_hz
    return (low, high) if high - low >= MIN_NOISE_BAND_HZ else None


def leaps(track: np.ndarray, rate_hz: float) -> np.ndarray:
    """(F,) bool: the frames where the (F, 3) track leaps from the median of the 5 frames around it
    (LEAP_FACTOR, LEAP_SPEED_M_S); missing frames are never leaps."""
    frames = track.shape[0]
    padded = np.concatenate([np.full((2, 3), np.nan), track, np.full((2, 3), np.nan)])
    windows = np.stack([padded[offset:offset + frames] for offset in range(5)])
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-missing window: its median is NaN
        distance = np.linalg.norm(track - np.nanmedian(windows, axis=0), axis=1)
    finite = np.isfinite(distance)
    if not finite.any():
        return np.zeros(frames, dtype=bool)
    threshold = max(LEAP_FACTOR * float(np.median(distance[finite])), LEAP_SPEED_M_S / rate_hz)
    return finite & (distance > threshold)


def _bridged(track: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """The (F, C) track with its `chosen` frames on the line between the nearest valid frames
    around them (the nearest one at an end)."""
    if not chosen.any():
        return track
    valid = np.all(np.isfinite(track), axis=1) & ~chosen
    if not valid.any():
        return track
    frames = np.arange(track.shape[0])
    bridged = track.copy()
    for axis in range(track.shape[1]):
        bridged[chosen, axis] = np.interp(frames[chosen], frames[valid], track[valid, axis])
    return bridged


def candidate_cutoffs(rate_hz: float) -> np.ndarray:
    """The cutoffs the residual analysis tries at this frame rate [Hz]."""
    highest = HIGHEST_CUTOFF * 0.5 * rate_hz
    return np.arange(min(LOWEST_CUTOFF_HZ, highest / 4), highest + 1e-9, min(CUTOFF_STEP_HZ, highest / 40))


def _residual_power(signal: np.ndarray, rate_hz: float, cutoffs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column of the (F, C) signal: the sum over frames of (raw - filtered)^2 at each cutoff,
    (len(cutoffs), C), and the count of frames summed, (C,). All columns go through each filter
    call together: one call per cutoff, not one per keypoint and cutoff."""
    sums = np.empty((len(cutoffs), signal.shape[1]))
    counts = np.zeros(signal.shape[1])
    for k, cutoff in enumerate(cutoffs):
        change = signal - lowpass(signal, rate_hz, float(cutoff))
        finite = np.isfinite(change)
        sums[k] = (np.where(finite, change, 0.0) ** 2).sum(axis=0)
        counts = finite.sum(axis=0)
    return sums, counts


def residual_curve(signal: np.ndarray, rate_hz: float, cutoffs: np.ndarray) -> np.ndarray:
    """The rms over frames and coordinates of (raw - filtered) at each cutoff, over the filtered runs."""
    sums, counts = _residual_power(np.asarray(signal, dtype=float), rate_hz, cutoffs)
    return np.sqrt(sums.sum(axis=1) / max(int(counts.sum()), 1))


def _cutoff_from_power(cutoffs: np.ndarray, power: np.ndarray, band: tuple[float, float]) -> tuple[float, float]:
    """(cutoff, noise rms) from the residual power curve: the noise line fitted over the band's
    cutoffs; the cutoff minimising the signal removed plus the noise kept (module docstring)."""
    upper = cutoffs >= band[0] - 1e-9
    slope, intercept = np.polyfit(cutoffs[upper], power[upper], 1)
    slope = min(float(slope), 0.0)  # a rising residual is no noise
    cutoff = float(cutoffs[np.argmin(power - 2.0 * slope * cutoffs)])
    return cutoff, float(np.sqrt(max(float(intercept), 0.0)))


def _check_band(rate_hz: float) -> tuple[float, float]:
    band = noise_band(rate_hz)
    if band is None:
        raise InputError(f"rate_hz: {rate_hz:g} Hz leaves no band above the motion's {MOTION_BAND_HZ:g} Hz to "
                         "measure the noise in", parameter="rate_hz")
    return band


def residual_cutoff(signal: np.ndarray, rate_hz: float) -> tuple[float, float]:
    """(cutoff [Hz], noise rms per coordinate [signal units]) of the residual analysis on the (F, C)
    signal: the noise line fitted to R^2 at the upper cutoffs; the cutoff that minimises the signal
    removed plus the noise kept (module docstring)."""
    band = _check_band(rate_hz)
    cutoffs = candidate_cutoffs(rate_hz)
    return _cutoff_from_power(cutoffs, residual_curve(signal, rate_hz, cutoffs) ** 2, band)


def _grouped_cutoffs(tracks: dict[int, np.ndarray], rate_hz: float) -> dict[int, tuple[float, float]]:
    """residual_cutoff of every (F, 3) track, the tracks with the same missing values filtered in
    one (F, 3 n) signal per cutoff (a column's filtered values depend on its own column and on
    which frames are valid, which those tracks share): the same cutoffs, about n times fewer calls."""
    band = _check_band(rate_hz)
    cutoffs = candidate_cutoffs(rate_hz)
    groups: dict[bytes, list[int]] = {}
    for k, track in tracks.items():
        groups.setdefault(np.isfinite(track).tobytes(), []).append(k)
    chosen = {}
    for members in groups.values():
        sums, counts = _residual_power(np.concatenate([tracks[k] for k in members], axis=1), rate_hz, cutoffs)
        for i, k in enumerate(members):
            power = sums[:, 3 * i:3 * i + 3].sum(axis=1) / max(int(counts[3 * i:3 * i + 3].sum()), 1)
            chosen[k] = _cutoff_from_power(cutoffs, power, band)
    return chosen


@dataclass
class KeypointFilter:
    """What the filter did to one keypoint: its cutoff [Hz] (None: left unfiltered, too few valid
    frames), the residual analysis's noise estimate (rms per coordinate; None for a fixed cutoff),
    the rms and largest change it made [m], and the frames kept as leaps."""

    cutoff_hz: float | None
    noise_m: float | None
    change_rms_m: float
    change_max_m: float
    leaps: int = 0


@dataclass
class TargetFilterResult:
    """The filtered targets and, per keypoint, the cutoff and the change; `unfiltered_because`
    says why "auto" left every keypoint as it was (a frame rate too low to tell noise from motion)."""

    mode: str
    rate_hz: float
    positions: np.ndarray
    keypoints: dict[str, KeypointFilter] = field(default_factory=dict)
    unfiltered_because: str | None = None

    def report(self) -> dict:
        """For report.json's `target_filter`: the mode, the rate, per keypoint the cutoff [Hz], the
        noise estimate and the rms and largest change [mm], and their medians over keypoints."""
        cutoffs = [k.cutoff_hz for k in self.keypoints.values() if k.cutoff_hz is not None]
        changes = [k.change_rms_m for k in self.keypoints.values()]
        return {
            "mode": self.mode, "frame_rate_hz": self.rate_hz, "unfiltered_because": self.unfiltered_because,
            "median_cutoff_hz": float(np.median(cutoffs)) if cutoffs else None,
            "median_change_rms_mm": float(np.median(changes) * 1e3) if changes else None,
            "keypoints": {name: {"cutoff_hz": k.cutoff_hz,
                                 "noise_mm": None if k.noise_m is None else k.noise_m * 1e3,
                                 "change_rms_mm": k.change_rms_m * 1e3, "change_max_mm": k.change_max_m * 1e3,
                                 "leap_frames": k.leaps}
                          for name, k in self.keypoints.items()},
        }


def filter_targets(names: Sequence[str], positions: np.ndarray, rate_hz: float,
                   setting: str | float = "auto") -> TargetFilterResult:
    """The (F, T, 3) targets low-passed over frames per keypoint: "auto" at each keypoint's cutoff
    from the residual analysis, a number at that cutoff [Hz] (capped below the design's Nyquist
    limit), "off" unchanged."""
    setting = parse_target_filter(setting)
    positions = np.asarray(positions, dtype=float)
    if positions.ndim != 3 or positions.shape[1] != len(names) or positions.shape[2] != 3:
        raise InputError(f"positions: expected shape (F, {len(names)}, 3), found {positions.shape}",
                         parameter="positions")
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(f"rate_hz: expected a positive frame rate, found {rate_hz!r}", parameter="rate_hz")
    mode = setting if isinstance(setting, str) else "fixed"
    result = TargetFilterResult(mode, float(rate_hz), positions.copy())
    if setting == "off":
        return result
    if setting == "auto" and noise_band(rate_hz) is None:
        result.unfiltered_because = (f"at {rate_hz:g} frames/s no band of {MIN_NOISE_BAND_HZ:g} Hz lies above the "
                                     f"motion's {MOTION_BAND_HZ:g} Hz to measure the noise in")
        return result
    highest = HIGHEST_CUTOFF * 0.5 * rate_hz
    raws, leaping, tracks, done = {}, {}, {}, {}
    for k in range(len(names)):
        raws[k] = positions[:, k]
        leaping[k] = leaps(raws[k], rate_hz)
        track = _bridged(raws[k], leaping[k])
        runs = _runs(np.all(np.isfinite(track), axis=1))
        if not any(stop - start >= MIN_RUN_FRAMES for start, stop in runs):
            done[k] = KeypointFilter(None, None, 0.0, 0.0)
            continue
        tracks[k] = track
    chosen: dict[int, tuple[float, float | None]]
    if setting == "auto":
        chosen = dict(_grouped_cutoffs(tracks, rate_hz))
    else:
        chosen = {k: (min(float(setting), highest), None) for k in tracks}
    for k, track in tracks.items():
        cutoff, noise = chosen[k]
        filtered = np.where(leaping[k][:, None], raws[k], lowpass(track, rate_hz, cutoff))
        change = np.linalg.norm(filtered - raws[k], axis=1)
        result.positions[:, k] = filtered
        done[k] = KeypointFilter(cutoff, noise, float(np.sqrt(np.nanmean(change**2))),
                                 float(np.nanmax(change)), int(leaping[k].sum()))
    result.keypoints = {names[k]: done[k] for k in sorted(done)}
    return result
